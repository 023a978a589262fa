//! `cantwin report` says which bit rate its bus load used: 500k assumed (as the monitor's
//! default) when the capture and the command line do not give one, else the one given.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

#[test]
fn report_says_which_bit_rate_it_used() {
    let dir = temp_dir("report-bit-rate");
    let log = dir.join("run.log");
    std::fs::write(
        &log,
        "(1700000000.000000) can0 705#05\n(1700000000.100000) can0 705#05\n",
    )
    .unwrap();
    let html = dir.join("run.html");
    let (log, html) = (log.to_str().unwrap(), html.to_str().unwrap());
    let (ok, out, err) = cantwin(&["report", log, "-o", html]);
    assert!(ok, "{err}");
    assert!(
        out.contains("2 records, 0 SDO transfers, 0 anomalies"),
        "{out}"
    );
    assert!(
        out.contains("bus load of can0 at 500k assumed (the capture does not record it"),
        "{out}"
    );
    let (ok, out, err) = cantwin(&["report", log, "-o", html, "--bit-rate", "can0=250k"]);
    assert!(ok, "{err}");
    assert!(out.contains("bus load of can0 at 250k"), "{out}");
    assert!(!out.contains("assumed"), "{out}");
    std::fs::remove_dir_all(&dir).unwrap();
}
