//! Behaviour of the capture analysis, on records built in code: SDO reassembly (CiA 301
//! §7.2.4.3), heartbeat supervision (§7.2.8.3.2), EMCY meanings (§7.2.7), bus load from each
//! frame's exact length, and the HTML page.
#![allow(clippy::unwrap_used)]

use cantwin_can::{BitRate, Frame, Id};
use cantwin_canopen::abort::AbortCode;
use cantwin_capture::{ErrorFrame, Record, error_class};
use cantwin_report::sdo::{Direction, Mode, Outcome};
use cantwin_report::{AnomalyKind, Kind, Options, Protocol, analyse, render_html};

const T0: u64 = 1_700_000_000_000_000_000;
const MS: u64 = 1_000_000;

fn f(id: u16, data: &[u8]) -> Frame {
    Frame::data(Id::standard(id).unwrap(), data).unwrap()
}

fn rec(t_ms: u64, id: u16, data: &[u8]) -> Record {
    Record::new(T0 + t_ms * MS, "can0", f(id, data))
}

/// A segmented upload of `text` from node 5's 0x1008 (§7.2.4.3.6–7), starting at `t`.
fn segmented_upload(t: u64, text: &[u8]) -> Vec<Record> {
    let n = text.len() as u8;
    let mut r = vec![
        rec(t, 0x605, &[0x40, 0x08, 0x10, 0, 0, 0, 0, 0]),
        rec(t + 1, 0x585, &[0x41, 0x08, 0x10, 0, n, 0, 0, 0]),
    ];
    let mut toggle = 0u8;
    let mut at = t + 2;
    for (i, chunk) in text.chunks(7).enumerate() {
        r.push(rec(at, 0x605, &[0x60 | (toggle << 4), 0, 0, 0, 0, 0, 0, 0]));
        let last = (i + 1) * 7 >= text.len();
        let mut b = [0u8; 8];
        b[0] = (toggle << 4) | (((7 - chunk.len()) as u8) << 1) | u8::from(last);
        b[1..1 + chunk.len()].copy_from_slice(chunk);
        r.push(rec(at + 1, 0x585, &b));
        toggle ^= 1;
        at += 2;
    }
    r
}

#[test]
fn cia301_7_2_4_3_6_segmented_upload_reassembled_into_one_row() {
    let text = b"cantwin generic CiA 301 device";
    let records = segmented_upload(0, text);
    let report = analyse(&records, &Options::default());
    assert_eq!(report.sdo.len(), 1);
    let tr = &report.sdo[0];
    assert_eq!((tr.node, tr.index, tr.sub), (5, 0x1008, 0));
    assert_eq!(tr.direction, Some(Direction::Upload));
    assert_eq!(tr.mode, Some(Mode::Segmented));
    assert_eq!(tr.data, text);
    assert_eq!(tr.size, text.len());
    assert_eq!(tr.outcome, Outcome::Done);
    assert_eq!(tr.start_ns, T0);
    assert_eq!(tr.end_ns, T0 + 11 * MS);
    let rows: Vec<_> = report
        .timeline
        .iter()
        .filter(|r| r.kind == Kind::Sdo)
        .collect();
    assert_eq!(rows.len(), 1);
    assert_eq!(
        rows[0].text,
        "SDO read node 5 0x1008sub0 (segmented): 30 bytes = \"cantwin generic CiA 301 device\""
    );
}

#[test]
fn cia301_7_2_4_3_3_expedited_download_value() {
    // Write 500 (0x01F4) to 0x1017 sub 0 as UNSIGNED16: 0x2B = ccs 1, n = 2, e, s.
    let records = [
        rec(0, 0x605, &[0x2B, 0x17, 0x10, 0, 0xF4, 0x01, 0, 0]),
        rec(1, 0x585, &[0x60, 0x17, 0x10, 0, 0, 0, 0, 0]),
    ];
    let report = analyse(&records, &Options::default());
    let tr = &report.sdo[0];
    assert_eq!(tr.direction, Some(Direction::Download));
    assert_eq!(tr.mode, Some(Mode::Expedited));
    assert_eq!(tr.data, [0xF4, 0x01]);
    assert_eq!(
        report.timeline[0].text,
        "SDO write node 5 0x1017sub0 (expedited): 2 bytes = 0x01F4 (500)"
    );
}

#[test]
fn cia301_7_2_4_3_4_segmented_download() {
    let records = [
        rec(0, 0x605, &[0x21, 0x00, 0x20, 0, 9, 0, 0, 0]),
        rec(1, 0x585, &[0x60, 0x00, 0x20, 0, 0, 0, 0, 0]),
        rec(2, 0x605, &[0x00, 1, 2, 3, 4, 5, 6, 7]),
        rec(3, 0x585, &[0x20, 0, 0, 0, 0, 0, 0, 0]),
        // toggle 1, n = 5, c = 1
        rec(4, 0x605, &[0x10 | (5 << 1) | 1, 8, 9, 0, 0, 0, 0, 0]),
        rec(5, 0x585, &[0x30, 0, 0, 0, 0, 0, 0, 0]),
    ];
    let report = analyse(&records, &Options::default());
    assert_eq!(report.sdo.len(), 1);
    assert_eq!(report.sdo[0].data, [1, 2, 3, 4, 5, 6, 7, 8, 9]);
    assert_eq!(report.sdo[0].mode, Some(Mode::Segmented));
    assert_eq!(report.sdo[0].end_ns, T0 + 5 * MS);
}

#[test]
fn cia301_7_2_4_3_9_block_download_with_unused_bytes() {
    let records = [
        // Block download initiate, s = 1, size 10.
        rec(0, 0x605, &[0xC6, 0x00, 0x20, 0, 10, 0, 0, 0]),
        // Response: blksize 127.
        rec(1, 0x585, &[0xA4, 0x00, 0x20, 0, 127, 0, 0, 0]),
        rec(2, 0x605, &[0x01, 1, 2, 3, 4, 5, 6, 7]),
        rec(3, 0x605, &[0x82, 8, 9, 10, 0, 0, 0, 0]),
        // Block ack: ackseq 2, blksize 127.
        rec(4, 0x585, &[0xA2, 2, 127, 0, 0, 0, 0, 0]),
        // End: n = 4 unused bytes in the last segment.
        rec(5, 0x605, &[0xC1 | (4 << 2), 0x12, 0x34, 0, 0, 0, 0, 0]),
        rec(6, 0x585, &[0xA1, 0, 0, 0, 0, 0, 0, 0]),
    ];
    let report = analyse(&records, &Options::default());
    assert_eq!(report.sdo.len(), 1);
    let tr = &report.sdo[0];
    assert_eq!(tr.mode, Some(Mode::Block));
    assert_eq!(tr.direction, Some(Direction::Download));
    assert_eq!(tr.data, [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]);
    assert_eq!(tr.outcome, Outcome::Done);
}

#[test]
fn cia301_7_2_4_3_12_block_upload() {
    let records = [
        rec(0, 0x605, &[0xA4, 0x08, 0x10, 0, 127, 0, 0, 0]),
        rec(1, 0x585, &[0xC6, 0x08, 0x10, 0, 9, 0, 0, 0]),
        rec(2, 0x605, &[0xA3, 0, 0, 0, 0, 0, 0, 0]),
        rec(3, 0x585, &[0x01, b'a', b'b', b'c', b'd', b'e', b'f', b'g']),
        rec(4, 0x585, &[0x82, b'h', b'i', 0, 0, 0, 0, 0]),
        rec(5, 0x605, &[0xA2, 2, 127, 0, 0, 0, 0, 0]),
        // End: n = 5 unused.
        rec(6, 0x585, &[0xC1 | (5 << 2), 0, 0, 0, 0, 0, 0, 0]),
        rec(7, 0x605, &[0xA1, 0, 0, 0, 0, 0, 0, 0]),
    ];
    let report = analyse(&records, &Options::default());
    assert_eq!(report.sdo.len(), 1);
    assert_eq!(report.sdo[0].data, b"abcdefghi");
    assert_eq!(report.sdo[0].direction, Some(Direction::Upload));
    assert_eq!(report.sdo[0].mode, Some(Mode::Block));
    assert_eq!(report.sdo[0].end_ns, T0 + 7 * MS);
}

#[test]
fn cia301_7_2_4_3_17_abort_is_a_row_and_an_anomaly_with_its_meaning() {
    let records = [
        rec(0, 0x605, &[0x40, 0x34, 0x12, 0, 0, 0, 0, 0]),
        rec(1, 0x585, &[0x80, 0x34, 0x12, 0, 0x00, 0x00, 0x02, 0x06]),
    ];
    let report = analyse(&records, &Options::default());
    assert_eq!(
        report.sdo[0].outcome,
        Outcome::Aborted {
            code: AbortCode::NO_OBJECT,
            by_server: true
        }
    );
    assert_eq!(report.anomalies.len(), 1);
    let a = &report.anomalies[0];
    assert_eq!(a.kind, AnomalyKind::SdoAbort);
    assert_eq!(a.t_ns, T0 + MS);
    assert_eq!(
        a.text,
        "SDO read node 5 0x1234sub0 (expedited): aborted by server, 0x06020000 (Object does not exist in the object dictionary)"
    );
}

#[test]
fn sdo_request_without_response_is_an_anomaly() {
    let records = [
        rec(0, 0x609, &[0x40, 0x00, 0x10, 0, 0, 0, 0, 0]),
        // A second request to the same node while the first is unanswered.
        rec(1000, 0x609, &[0x40, 0x18, 0x10, 1, 0, 0, 0, 0]),
    ];
    let report = analyse(&records, &Options::default());
    let missing: Vec<_> = report
        .anomalies
        .iter()
        .filter(|a| a.kind == AnomalyKind::SdoNoResponse)
        .map(|a| (a.t_ns, a.node, a.text.as_str()))
        .collect();
    assert_eq!(
        missing,
        [
            (
                T0,
                Some(9),
                "SDO read node 9 0x1000sub0 (expedited): no response"
            ),
            (
                T0 + 1000 * MS,
                Some(9),
                "SDO read node 9 0x1018sub1 (expedited): no response"
            ),
        ]
    );
}

/// Boot-up, then heartbeats every 100 ms: pre-operational ×3, operational after NMT start.
fn heartbeats() -> Vec<Record> {
    let mut r = vec![rec(0, 0x705, &[0x00])];
    for i in 1..=3 {
        r.push(rec(i * 100, 0x705, &[0x7F]));
    }
    r.push(rec(350, 0x000, &[0x01, 5]));
    for i in 4..=8 {
        r.push(rec(i * 100, 0x705, &[0x05]));
    }
    r
}

#[test]
fn cia301_7_2_8_3_2_heartbeat_rows_only_on_state_change() {
    let report = analyse(&heartbeats(), &Options::default());
    let rows: Vec<_> = report
        .timeline
        .iter()
        .map(|r| (r.t_ns - T0, r.kind, r.text.as_str()))
        .collect();
    assert_eq!(
        rows,
        [
            (0, Kind::Heartbeat, "BOOT-UP node 5"),
            (
                100 * MS,
                Kind::Heartbeat,
                "node 5 heartbeat: pre-operational"
            ),
            (350 * MS, Kind::Nmt, "NMT Start node 5"),
            (400 * MS, Kind::Heartbeat, "node 5 heartbeat: operational"),
        ]
    );
    assert!(report.anomalies.is_empty(), "{:?}", report.anomalies);
}

#[test]
fn heartbeat_gap_over_one_and_a_half_median_periods() {
    let mut records = heartbeats();
    // 800 ms → 1100 ms: a 300 ms gap, then regular again.
    for i in [11, 12, 13, 14] {
        records.push(rec(i * 100, 0x705, &[0x05]));
    }
    let report = analyse(&records, &Options::default());
    let gaps: Vec<_> = report
        .anomalies
        .iter()
        .map(|a| (a.kind, a.t_ns - T0, a.text.as_str()))
        .collect();
    assert_eq!(
        gaps,
        [(
            AnomalyKind::HeartbeatGap,
            1100 * MS,
            "node 5: 300 ms without heartbeat (median period 100 ms)"
        )]
    );
}

#[test]
fn heartbeat_stopped_before_the_end_of_the_capture() {
    let mut records = heartbeats();
    // Other traffic goes on for 500 ms after node 5's last heartbeat at 800 ms.
    records.push(rec(1300, 0x080, &[]));
    let report = analyse(&records, &Options::default());
    assert_eq!(report.anomalies.len(), 1);
    let a = &report.anomalies[0];
    assert_eq!(a.kind, AnomalyKind::HeartbeatStopped);
    assert_eq!(a.t_ns, T0 + 800 * MS);
    assert_eq!(report.channels[0].syncs, 1);
}

#[test]
fn boot_up_without_nmt_reset_is_unexpected() {
    let mut records = heartbeats();
    records.push(rec(850, 0x705, &[0x00]));
    // After an NMT reset node, a boot-up is expected.
    records.push(rec(860, 0x000, &[0x81, 0]));
    records.push(rec(870, 0x705, &[0x00]));
    let report = analyse(&records, &Options::default());
    let unexpected: Vec<_> = report
        .anomalies
        .iter()
        .filter(|a| a.kind == AnomalyKind::UnexpectedBootUp)
        .map(|a| a.t_ns - T0)
        .collect();
    assert_eq!(unexpected, [850 * MS]);
}

#[test]
fn cia301_7_2_7_emcy_with_meaning_and_error_frames() {
    let records = [
        rec(0, 0x085, &[0x10, 0x42, 0x08, 1, 2, 3, 4, 5]),
        Record::new(
            T0 + MS,
            "can0",
            ErrorFrame::new(error_class::BUS_OFF, [0; 8]).unwrap(),
        ),
    ];
    let report = analyse(&records, &Options::default());
    assert_eq!(
        report.timeline[0].text,
        "EMCY node 5 code 0x4210 (temperature) register 0x08 data 01 02 03 04 05"
    );
    assert_eq!(report.timeline[1].kind, Kind::Error);
    let kinds: Vec<_> = report.anomalies.iter().map(|a| a.kind).collect();
    assert_eq!(kinds, [AnomalyKind::Emergency, AnomalyKind::ErrorFrame]);
    assert_eq!(report.channels[0].error_frames, 1);
}

#[test]
fn bus_load_from_exact_frame_lengths_per_window() {
    let a = f(0x181, &[1, 2, 3, 4, 5, 6, 7, 8]);
    let b = f(0x705, &[0x05]);
    let records = [
        Record::new(T0, "can0", a),
        Record::new(T0 + 50 * MS, "can0", b),
        Record::new(T0 + 150 * MS, "can0", a),
    ];
    let opts = Options {
        default_bit_rate: Some(BitRate::R500K),
        ..Options::default()
    };
    let report = analyse(&records, &opts);
    let c = &report.channels[0];
    assert_eq!(c.window_ns, 100 * MS);
    // 500 kbit/s × 100 ms = 50 000 bits per window.
    let first = f64::from(a.bit_length() + b.bit_length()) / 50_000.0;
    let second = f64::from(a.bit_length()) / 50_000.0;
    assert_eq!(c.load, [first, second]);
    assert_eq!(c.bits, u64::from(2 * a.bit_length() + b.bit_length()));
    let s = report
        .ids
        .iter()
        .find(|s| s.id == Id::standard(0x181).unwrap())
        .unwrap();
    assert_eq!((s.frames, s.bytes), (2, 16));
    assert_eq!(s.min_period_ns, Some(150 * MS));
    assert_eq!(s.avg_period_ns(), Some(150 * MS));
}

#[test]
fn window_widens_so_long_captures_keep_at_most_2000_windows() {
    let records = [rec(0, 0x080, &[]), rec(1_000_000, 0x080, &[])];
    let report = analyse(&records, &Options::default());
    let c = &report.channels[0];
    // 1000 s in 100 ms bins: 10 001 bins, merged 6 at a time.
    assert_eq!(c.window_ns, 600 * MS);
    assert_eq!(c.load.len(), 1667);
    let bits = f64::from(f(0x080, &[]).bit_length());
    // 600 ms at the default 500 kbit/s hold 300 000 bits.
    assert_eq!(c.load[0], bits / 300_000.0);
    assert_eq!(c.load[1666], bits / 300_000.0);
    assert!(c.load[1..1666].iter().all(|&l| l == 0.0));
}

#[test]
fn timeline_is_capped_with_a_note() {
    // Distinct EMCYs (identical ones in a row collapse into one row).
    let records: Vec<_> = (0..10)
        .map(|i| rec(i, 0x085, &[0, 0, 0, i as u8, 0, 0, 0, 0]))
        .collect();
    let opts = Options {
        max_timeline: 4,
        ..Options::default()
    };
    let report = analyse(&records, &opts);
    assert_eq!(report.timeline.len(), 4);
    assert_eq!(report.timeline_dropped, 6);
    // SDO transfers are kept up to the same cap and counted beyond it.
    let records: Vec<_> = (0..10)
        .flat_map(|i| {
            [
                rec(2 * i, 0x605, &[0x40, 0x00, 0x10, 0, 0, 0, 0, 0]),
                rec(
                    2 * i + 1,
                    0x585,
                    &[0x43, 0x00, 0x10, 0, 0x91, 0x01, 0x0F, 0],
                ),
            ]
        })
        .collect();
    let sdo = analyse(&records, &opts);
    assert_eq!((sdo.sdo.len(), sdo.sdo_total), (4, 10));
    let html = render_html(&report);
    assert!(html.contains("The timeline shows the first 4 rows; 6 more were left out."));
}

#[test]
fn devicenet_and_cal_channels_decode_by_their_protocol() {
    let records = [
        Record::new(T0, "dnet", f(0x42C, &[0x01, 0x0E, 0x01, 0x01, 0x07])),
        Record::new(T0 + MS, "cal", f(0x181, &[0x85, 0x10, 0x27])),
    ];
    let mut opts = Options::default();
    opts.protocols.insert("dnet".into(), Protocol::DeviceNet);
    opts.protocols.insert("cal".into(), Protocol::Cal);
    let report = analyse(&records, &opts);
    let rows: Vec<_> = report
        .timeline
        .iter()
        .map(|r| (r.kind, r.text.as_str()))
        .collect();
    assert_eq!(
        rows,
        [
            (
                Kind::DeviceNet,
                "G2 MAC 5 msg 4: master explicit request: Get_Attribute_Single (0x0E) class 0x01 instance 1 attribute 7 [MAC 1]"
            ),
            (
                Kind::Cal,
                "COB 0x181 control 0x85 (bit 7 1, multiplexor 5) data 10 27"
            ),
        ]
    );
}

#[test]
fn devicenet_timeline_decodes_each_slave_in_the_body_format_its_allocate_granted() {
    // DeviceNet Vol. 1 §3-5: the ADV200 (MAC 12) answers Allocate with body format 8/16, so
    // the Get_Attribute_Single after it carries a 16-bit instance.
    let records = [
        Record::new(T0, "dnet", f(0x466, &[0x40, 0x4B, 0x03, 0x01, 0x01, 0x00])),
        Record::new(T0 + MS, "dnet", f(0x463, &[0x40, 0xCB, 0x01])),
        Record::new(
            T0 + 2 * MS,
            "dnet",
            f(0x464, &[0x00, 0x0E, 0x01, 0x01, 0x00, 0x07]),
        ),
    ];
    let mut opts = Options::default();
    opts.protocols.insert("dnet".into(), Protocol::DeviceNet);
    let report = analyse(&records, &opts);
    let rows: Vec<_> = report.timeline.iter().map(|r| r.text.as_str()).collect();
    assert_eq!(
        rows,
        [
            "G2 MAC 12 msg 6: unconnected explicit request: Allocate_Master/Slave_Connection_Set (0x4B) class 0x03 instance 1 allocation choice 0x01 (explicit) allocator MAC 0 [MAC 0]",
            "G2 MAC 12 msg 3: slave explicit response: Allocate_Master/Slave_Connection_Set (0x4B) response message body format 8/16 [MAC 0]",
            "G2 MAC 12 msg 4: master explicit request: Get_Attribute_Single (0x0E) class 0x01 instance 1 attribute 7 [MAC 0]",
        ]
    );
}

#[test]
fn pdo_values_named_from_an_eds() {
    let eds = include_bytes!("../../eds/tests/corpus/io_module.eds");
    let mut opts = Options::default();
    cantwin_report::canopen::add_eds_pdos(&mut opts.pdos, 5, eds).unwrap();
    let report = analyse(&[rec(0, 0x205, &[0x12, 0x34])], &opts);
    assert_eq!(report.timeline[0].kind, Kind::Pdo);
    assert_eq!(
        report.timeline[0].text,
        "PDO Outputs 1-8=18 Outputs 9-16=52"
    );
}

#[test]
fn html_escapes_text_from_the_capture_and_loads_nothing() {
    let records = segmented_upload(0, b"<script>alert(1)</script>");
    let html = render_html(&analyse(&records, &Options::default()));
    assert!(html.contains("&lt;script&gt;alert(1)&lt;/script&gt;"));
    assert_eq!(
        html.matches("<script>").count(),
        1,
        "only the filter script"
    );
    for external in ["src=", "href=", "@import", "url("] {
        assert!(!html.contains(external), "{external}");
    }
}

#[test]
fn transfer_cut_off_by_the_end_of_the_capture_is_incomplete_not_unanswered() {
    let mut records = segmented_upload(0, b"cantwin generic CiA 301 device");
    // Keep the initiate, the first segment request and its answer.
    records.truncate(4);
    let report = analyse(&records, &Options::default());
    assert_eq!(report.sdo[0].outcome, Outcome::Incomplete);
    assert_eq!(report.sdo[0].data, b"cantwin");
    assert_eq!(
        report.timeline[0].text,
        "SDO read node 5 0x1008sub0 (segmented): incomplete, 7 bytes seen"
    );
    assert!(report.anomalies.is_empty());
    // Cut after the second segment request: that request went unanswered.
    let mut records = segmented_upload(0, b"cantwin generic CiA 301 device");
    records.truncate(5);
    let report = analyse(&records, &Options::default());
    assert_eq!(report.sdo[0].outcome, Outcome::NoResponse);
    assert_eq!(report.anomalies[0].kind, AnomalyKind::SdoNoResponse);
}
