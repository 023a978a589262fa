//! `cantwin demo` tells what happens in the order it happens: within each paragraph the bus
//! times at the start of the lines never go backwards (an EMCY the master received follows
//! the frame that carried it, not the frames after it).
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

/// The bus time a demo line starts with (`  0.145732000  …`), if any.
fn time_of(line: &str) -> Option<f64> {
    let first = line.split_whitespace().next()?;
    let (s, frac) = first.split_once('.')?;
    (line.starts_with("  ") && frac.len() == 9 && s.chars().all(|c| c.is_ascii_digit()))
        .then(|| first.parse().ok())
        .flatten()
}

#[test]
fn demo_paragraphs_go_forward_in_bus_time_with_emcy_events_after_their_frames() {
    let (ok, out, err) = cantwin(&["demo"]);
    assert!(ok, "{err}");
    let mut timed = 0;
    for paragraph in out.split("\n\n") {
        let times: Vec<f64> = paragraph.lines().filter_map(time_of).collect();
        timed += times.len();
        assert!(
            times.windows(2).all(|w| w[0] <= w[1]),
            "times go backwards in:\n{paragraph}"
        );
    }
    assert!(timed > 50, "{out}");
    // The EMCY event line comes right after its frame.
    let lines: Vec<&str> = out.lines().collect();
    let event = lines
        .iter()
        .position(|l| l.contains("EMCY from node 5: 0x5000"))
        .unwrap();
    assert!(
        lines[event - 1].contains("085#0050010000000000"),
        "{}",
        lines[event - 1]
    );
    assert_eq!(time_of(lines[event]), time_of(lines[event - 1]));
}
