//! `cantwin report` on captures of the CiA 301 twin recorded by `cantwin sim`, with SDO
//! traffic from `cantwin sdo` through socketcand; the test reads the page's tables back.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

use std::io::BufRead;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// The cells of each row of the table with `id`, tags stripped and entities decoded.
fn table(html: &str, id: &str) -> Vec<Vec<String>> {
    let start = html
        .find(&format!("<table id=\"{id}\">"))
        .unwrap_or_else(|| panic!("no table {id}"));
    let end = start + html[start..].find("</table>").unwrap();
    let body = &html[start..end];
    let body = &body[body.find("<tbody>").unwrap()..];
    body.split("<tr")
        .skip(1)
        .map(|row| {
            row.split("<td")
                .skip(1)
                .map(|cell| {
                    let text = &cell[cell.find('>').unwrap() + 1..];
                    let text = &text[..text.find("</td>").unwrap()];
                    text.replace("&lt;", "<")
                        .replace("&gt;", ">")
                        .replace("&quot;", "\"")
                        .replace("&#39;", "'")
                        .replace("&amp;", "&")
                })
                .collect()
        })
        .collect()
}

/// Runs the CiA 301 twin for a little while, recording both formats, and sends SDO requests
/// through its socketcand gateway while it runs.
fn record(dir: &Path) -> (PathBuf, PathBuf) {
    let scenario = format!(
        "{}/../../scenarios/cia301-device.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let log = dir.join("run.log");
    let pcap = dir.join("run.pcap");
    let mut child = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args(["sim", &scenario, "--socketcand", "0", "--duration", "1.5"])
        .args(["--candump", log.to_str().unwrap()])
        .args(["--pcap", pcap.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line.split_whitespace().nth(1).unwrap().to_string();
    let sdo = |args: &[&str]| {
        let mut full = vec!["sdo", "--socketcand", addr.as_str()];
        full.extend_from_slice(args);
        cantwin(&full)
    };
    let (ok, out, err) = sdo(&["read", "5", "0x1008", "0", "vs"]);
    assert!(ok, "{err}");
    assert!(out.starts_with("cantwin generic CiA 301 device"), "{out}");
    let (ok, _, err) = sdo(&["write", "5", "0x1017", "0", "u16", "100"]);
    assert!(ok, "{err}");
    let (ok, _, _) = sdo(&["read", "5", "0x6000", "0", "u16"]);
    assert!(!ok);
    assert!(child.wait().unwrap().success());
    (log, pcap)
}

fn check_page(html: &str) {
    let timeline = table(html, "timeline");
    let events: Vec<&str> = timeline.iter().map(|r| r[4].as_str()).collect();
    assert!(events.contains(&"BOOT-UP node 5"), "{events:?}");
    assert!(
        events.contains(&"node 5 heartbeat: pre-operational"),
        "{events:?}"
    );
    let name =
        "cantwin generic CiA 301 device with a 64 KiB DOMAIN at 0x2000, four RPDOs and four TPDOs";
    assert!(
        events
            .iter()
            .any(|e| e.starts_with("SDO read node 5 0x1008sub0")
                && e.ends_with(&format!("{} bytes = \"{name}\"", name.len()))),
        "{events:?}"
    );
    assert!(
        events.contains(&"SDO write node 5 0x1017sub0 (expedited): 2 bytes = 0x0064 (100)"),
        "{events:?}"
    );
    let abort = "SDO read node 5 0x6000sub0 (expedited): aborted by server, \
                 0x06020000 (Object does not exist in the object dictionary)";
    assert!(events.contains(&abort), "{events:?}");
    let anomalies = table(html, "anomalies");
    assert!(
        anomalies
            .iter()
            .any(|r| r[2] == "SDO abort" && r[3] == "5" && r[4] == abort),
        "{anomalies:?}"
    );
    let ids = table(html, "ids");
    let hb = ids.iter().find(|r| r[1] == "0x705").unwrap();
    let frames: u64 = hb[2].parse().unwrap();
    assert!(frames >= 10, "{hb:?}");
    // The heartbeat producer time is 100 ms.
    let avg: f64 = hb[6].parse().unwrap();
    assert!((90.0..=110.0).contains(&avg), "{hb:?}");
    assert!(html.contains("<svg"), "bus load chart");
}

#[test]
fn report_of_a_cia301_twin_capture_decodes_boot_up_sdo_and_abort() {
    let dir = temp_dir("cia301");
    let (log, pcap) = record(&dir);
    // candump log, default output name.
    let (ok, out, err) = cantwin(&["report", log.to_str().unwrap(), "--bit-rate", "can0=500k"]);
    assert!(ok, "{err}");
    let page = dir.join("run.log.html");
    assert!(out.starts_with(page.to_str().unwrap()), "{out}");
    check_page(&std::fs::read_to_string(&page).unwrap());
    // pcap, named output.
    let page = dir.join("pcap.html");
    let (ok, _, err) = cantwin(&[
        "report",
        pcap.to_str().unwrap(),
        "--bit-rate",
        "500k",
        "-o",
        page.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    check_page(&std::fs::read_to_string(&page).unwrap());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn report_rejects_bad_options_and_missing_files() {
    let (ok, _, err) = cantwin(&["report", "missing.log"]);
    assert!(!ok);
    assert!(err.contains("missing.log"), "{err}");
    let (ok, _, err) = cantwin(&["report", "missing.log", "--bit-rate", "can0=3k"]);
    assert!(!ok);
    assert!(err.contains("--bit-rate can0=3k"), "{err}");
    let (ok, _, err) = cantwin(&["report", "missing.log", "--protocol", "can0=profibus"]);
    assert!(!ok);
    assert!(err.contains("unknown protocol"), "{err}");
    let (ok, _, err) = cantwin(&["report", "missing.log", "--window-ms", "0"]);
    assert!(!ok);
    assert!(err.contains("--window-ms must be at least 1"), "{err}");
    let (ok, out, err) = cantwin(&["report", "--help"]);
    assert!(ok, "{err}");
    assert!(out.contains("Examples:"), "{out}");
}

#[test]
fn report_decodes_a_devicenet_channel_when_told() {
    let dir = temp_dir("devicenet");
    let log = dir.join("dn.log");
    let scenario = format!(
        "{}/../../scenarios/adv200-devicenet.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let (ok, _, err) = cantwin(&[
        "sim",
        &scenario,
        "--duration",
        "0.3",
        "--candump",
        log.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    // The protocol for the channel, or for every channel as `dump --decode` takes it.
    for protocol in ["can0=devicenet", "devicenet"] {
        let page = dir.join("dn.html");
        let (ok, _, err) = cantwin(&[
            "report",
            log.to_str().unwrap(),
            "--protocol",
            protocol,
            "--bit-rate",
            "125k",
            "-o",
            page.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
        let html = std::fs::read_to_string(&page).unwrap();
        let timeline = table(&html, "timeline");
        // The drive's card checks its MAC ID (12) when it goes on line (DeviceNet duplicate
        // MAC ID check, group 2 message 7).
        assert!(
            timeline.iter().any(|r| r[2] == "devicenet"
                && r[4].starts_with("G2 MAC 12 msg 7: duplicate MAC ID check")),
            "{protocol}: {timeline:?}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
