//! The timeline stays readable: repeated identical EMCYs of a node make one row (and one
//! anomaly) with a count, DeviceNet rows name the MAC ID in the node column, node guarding
//! is told from heartbeats, and LSS frames are decoded (CiA 305 §4).
#![allow(clippy::unwrap_used)]

use cantwin_can::{Frame, Id};
use cantwin_capture::Record;
use cantwin_report::{AnomalyKind, Kind, Options, Protocol, analyse, render_html};

const T0: u64 = 1_700_000_000_000_000_000;
const MS: u64 = 1_000_000;

fn rec(t_ms: u64, id: u16, data: &[u8]) -> Record {
    Record::new(
        T0 + t_ms * MS,
        "can0",
        Frame::data(Id::standard(id).unwrap(), data).unwrap(),
    )
}

const PDO_LENGTH_EXCEEDED: [u8; 8] = [0x20, 0x82, 0x04, 0, 0, 0, 0, 0];

#[test]
fn cia301_7_2_7_repeated_identical_emcy_collapse_into_one_row_with_count() {
    let mut records = vec![rec(0, 0x705, &[0x05])];
    // 101 identical EMCYs of node 5, 10 ms apart, with another node's EMCY among them.
    for i in 0..101 {
        records.push(rec(500 + i * 10, 0x085, &PDO_LENGTH_EXCEEDED));
        if i == 50 {
            records.push(rec(1005, 0x086, &PDO_LENGTH_EXCEEDED));
        }
    }
    // The error reset ends the run; the same code afterwards is a new event.
    records.push(rec(2000, 0x085, &[0; 8]));
    records.push(rec(2100, 0x085, &PDO_LENGTH_EXCEEDED));
    let report = analyse(&records, &Options::default());
    let emcy: Vec<_> = report
        .timeline
        .iter()
        .filter(|r| r.kind == Kind::Emcy)
        .map(|r| (r.node, r.repeats, (r.t_ns - T0) / MS, (r.last_ns - T0) / MS))
        .collect();
    assert_eq!(
        emcy,
        [
            (Some(5), 101, 500, 1500),
            (Some(6), 1, 1005, 1005),
            (Some(5), 1, 2000, 2000),
            (Some(5), 1, 2100, 2100),
        ]
    );
    let anomalies: Vec<_> = report
        .anomalies
        .iter()
        .filter(|a| a.kind == AnomalyKind::Emergency)
        .map(|a| (a.node, a.repeats))
        .collect();
    assert_eq!(anomalies, [(Some(5), 101), (Some(6), 1), (Some(5), 1)]);
    let html = render_html(&report);
    let collapsed = format!(
        "code 0x8220 ({}) register 0x04 data 00 00 00 00 00 × 101, first 0.500000 s, last 1.500000 s",
        cantwin_report::canopen::emcy_meaning(0x8220)
    );
    assert!(html.contains(&collapsed), "{html}");
    // One EMCY row for the run, not 101.
    assert_eq!(html.matches("EMCY node 5 code 0x8220").count(), 2 * 2);
}

#[test]
fn a_different_emcy_between_repeats_starts_a_new_row() {
    let records = [
        rec(0, 0x085, &PDO_LENGTH_EXCEEDED),
        rec(10, 0x085, &[0x10, 0x42, 0x09, 0, 0, 0, 0, 0]),
        rec(20, 0x085, &PDO_LENGTH_EXCEEDED),
    ];
    let report = analyse(&records, &Options::default());
    let repeats: Vec<u64> = report.timeline.iter().map(|r| r.repeats).collect();
    assert_eq!(repeats, [1, 1, 1]);
}

#[test]
fn devicenet_rows_name_the_mac_id_in_the_node_column() {
    let records = [
        // Group 2 explicit request to MAC 5, the slave's explicit response, its poll
        // response (group 1 from MAC 5) and a group 4 message (no MAC ID).
        rec(0, 0x42C, &[0x01, 0x0E, 0x01, 0x01, 0x07]),
        rec(1, 0x42B, &[0x01, 0x8E, 0x41, 0x42]),
        rec(2, 0x3C5, &[0x10, 0x20]),
        rec(3, 0x7EF, &[]),
    ];
    let mut opts = Options::default();
    opts.protocols.insert("can0".into(), Protocol::DeviceNet);
    let report = analyse(&records, &opts);
    let nodes: Vec<Option<u8>> = report.timeline.iter().map(|r| r.node).collect();
    assert_eq!(nodes, [Some(5), Some(5), Some(5), None]);
    assert!(render_html(&report).contains("<td class=\"n\">5</td><td>G2 MAC 5 msg 4"));
}

#[test]
fn cia301_7_2_8_3_2_1_node_guarding_is_named_apart_from_heartbeats() {
    let rtr = Record::new(
        T0,
        "can0",
        Frame::remote(Id::standard(0x705).unwrap(), 1).unwrap(),
    );
    let records = [
        rtr,
        // The first guarding answer has toggle 0; only the request says it is guarding.
        rec(1, 0x705, &[0x7F]),
        // Node 6 sends heartbeats.
        rec(2, 0x706, &[0x7F]),
        rec(10, 0x706, &[0x05]),
    ];
    let report = analyse(&records, &Options::default());
    let rows: Vec<&str> = report.timeline.iter().map(|r| r.text.as_str()).collect();
    assert_eq!(
        rows,
        [
            "node 5 node guarding: pre-operational",
            "node 6 heartbeat: pre-operational",
            "node 6 heartbeat: operational"
        ]
    );
}

#[test]
fn cia305_lss_frames_are_decoded_in_the_canopen_decoder() {
    let pdos = Default::default();
    let configure =
        Frame::data(Id::standard(0x7E5).unwrap(), &[0x11, 12, 0, 0, 0, 0, 0, 0]).unwrap();
    assert_eq!(
        cantwin_report::canopen::describe(&configure, &pdos),
        "LSS master: configure node-ID 12"
    );
    let answer = Frame::data(Id::standard(0x7E4).unwrap(), &[0x11, 0, 0, 0, 0, 0, 0, 0]).unwrap();
    assert_eq!(
        cantwin_report::canopen::describe(&answer, &pdos),
        "LSS slave: configure node-ID: success"
    );
}

#[test]
fn cia305_lss_frames_are_timeline_rows() {
    let records = [
        rec(0, 0x7E5, &[0x5E, 0, 0, 0, 0, 0, 0, 0]),
        rec(1, 0x7E4, &[0x5E, 7, 0, 0, 0, 0, 0, 0]),
    ];
    let report = analyse(&records, &Options::default());
    let rows: Vec<&str> = report.timeline.iter().map(|r| r.text.as_str()).collect();
    assert_eq!(
        rows,
        ["LSS master: inquire node-ID", "LSS slave: node-ID 7"]
    );
}

#[test]
fn an_unknown_bit_rate_is_assumed_500k_and_the_page_says_so() {
    let records = [rec(0, 0x080, &[])];
    let report = analyse(&records, &Options::default());
    let c = &report.channels[0];
    assert_eq!(c.bit_rate, cantwin_report::DEFAULT_BIT_RATE);
    assert_eq!(c.bit_rate.bits_per_second(), 500_000);
    assert!(c.bit_rate_assumed);
    assert!(
        render_html(&report)
            .contains("500000 bit/s (assumed: the capture does not record the bit rate)")
    );
    let given = Options {
        default_bit_rate: Some(cantwin_can::BitRate::R250K),
        ..Options::default()
    };
    let report = analyse(&records, &given);
    assert!(!report.channels[0].bit_rate_assumed);
    assert!(!render_html(&report).contains("assumed"));
}
