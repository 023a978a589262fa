//! The scanner (master) against slaves on a zero-latency wire in virtual time: allocate,
//! expected packet rate, cyclic poll, explicit Get/Set (fragmented both ways), UCMM,
//! release, error responses, lost fragments, a silent master, and network browse.
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_can::{Duration, Frame, Node};
use cantwin_devicenet::objects::connection::ConnState;
use cantwin_devicenet::scanner::ScannerConfig;
use cantwin_devicenet::wire::{BodyFormat, choice};
use cantwin_devicenet::{Scanner, ScannerEvent};
use common::*;

fn scanner() -> Scanner {
    Scanner::new(ScannerConfig::new(mac(0), 0x0001, 0x99))
}

fn events(s: &mut Scanner) -> Vec<ScannerEvent> {
    std::iter::from_fn(|| s.poll_event()).collect()
}

/// Scanner (node 0) and slave 9 (node 1) both on-line at 2 s.
fn setup(words: u16) -> (Scanner, cantwin_devicenet::Slave<Drive>, Wire) {
    let mut m = scanner();
    let mut s = slave_with(9, Drive::new(words, words));
    let mut w = Wire::new();
    w.power_up(&mut [&mut m, &mut s]);
    w.run_until(&mut [&mut m, &mut s], at(2 * SEC));
    assert_eq!(events(&mut m), [ScannerEvent::Online]);
    (m, s, w)
}

#[test]
fn allocate_set_epr_poll_cyclically_and_release() {
    let (mut m, mut s, mut w) = setup(2);
    m.allocate(mac(9), choice::EXPLICIT | choice::POLLED)
        .unwrap();
    m.set_expected_packet_rate(mac(9), 2, 50).unwrap();
    let since = w.log.len();
    w.run_until(&mut [&mut m, &mut s], at(2 * SEC));
    assert_eq!(
        w.lines(since),
        [
            "2.000 0 44E#404B03010300",
            "2.000 1 44B#40CB00",
            "2.000 0 44C#00100502093200",
            "2.000 1 44B#00903200",
        ]
    );
    assert_eq!(
        events(&mut m),
        [
            ScannerEvent::Allocated {
                slave: mac(9),
                choice: 3,
                format: BodyFormat::F8_8
            },
            ScannerEvent::Response {
                slave: mac(9),
                service: 0x10,
                data: vec![0x32, 0]
            }
        ]
    );
    m.start_polling(
        mac(9),
        Duration::from_millis(50),
        &[0xAA, 0xBB, 0xCC, 0xDD],
        4,
        at(2 * SEC),
    );
    let since = w.log.len();
    w.run_until(&mut [&mut m, &mut s], at(2 * SEC + 100 * MS));
    assert_eq!(
        w.lines(since),
        [
            "2.000 0 44D#AABBCCDD",
            "2.000 1 3C9#00010203",
            "2.050 0 44D#AABBCCDD",
            "2.050 1 3C9#00010203",
            "2.100 0 44D#AABBCCDD",
            "2.100 1 3C9#00010203",
        ]
    );
    assert_eq!(events(&mut m).len(), 3);
    m.stop_polling(mac(9));
    m.release(mac(9), choice::EXPLICIT | choice::POLLED)
        .unwrap();
    let since = w.log.len();
    w.run_until(&mut [&mut m, &mut s], at(2 * SEC + 100 * MS));
    assert_eq!(
        w.lines(since),
        ["2.100 0 44E#404C030103", "2.100 1 44B#40CC"]
    );
    assert_eq!(
        events(&mut m),
        [ScannerEvent::Released {
            slave: mac(9),
            choice: 3
        }]
    );
    assert_eq!(s.devicenet_object().master, None);
}

#[test]
fn sixteen_word_poll_is_io_fragmented_both_ways() {
    let (mut m, mut s, mut w) = setup(16);
    m.allocate(mac(9), choice::EXPLICIT | choice::POLLED)
        .unwrap();
    m.set_expected_packet_rate(mac(9), 2, 100).unwrap();
    w.run_until(&mut [&mut m, &mut s], at(2 * SEC));
    events(&mut m);
    let output: Vec<u8> = (100..132).collect();
    m.start_polling(mac(9), Duration::from_millis(100), &output, 32, at(2 * SEC));
    let since = w.log.len();
    w.run_until(&mut [&mut m, &mut s], at(2 * SEC));
    let lines = w.lines(since);
    assert_eq!(lines.len(), 10, "{lines:?}");
    assert!(lines[..5].iter().all(|l| l.contains(" 0 44D#")));
    assert!(lines[5..].iter().all(|l| l.contains(" 1 3C9#")));
    assert_eq!(s.app().consumed, vec![output]);
    assert_eq!(
        events(&mut m),
        [ScannerEvent::PollResponse {
            slave: mac(9),
            data: (0..32).collect()
        }]
    );
}

#[test]
fn explicit_get_and_set_with_every_error() {
    let (mut m, mut s, mut w) = setup(2);
    m.allocate(mac(9), choice::EXPLICIT).unwrap();
    m.get_attribute_single(mac(9), 1, 1, 1).unwrap();
    m.get_attribute_single(mac(9), 1, 1, 99).unwrap();
    m.get_attribute_single(mac(9), 0x42, 1, 1).unwrap();
    m.get_attribute_single(mac(9), 1, 2, 1).unwrap();
    m.set_attribute_single(mac(9), 1, 1, 1, &[1, 0]).unwrap();
    m.request(mac(9), 0x4E, 1, 1, &[]).unwrap();
    m.set_attribute_single(mac(9), 3, 1, 3, &[7]).unwrap();
    m.set_attribute_single(mac(9), 3, 1, 3, &[]).unwrap();
    w.run_until(&mut [&mut m, &mut s], at(2 * SEC));
    let err = |general, service| ScannerEvent::Error {
        slave: mac(9),
        service,
        general,
        additional: 0xFF,
    };
    assert_eq!(
        events(&mut m)[1..],
        [
            ScannerEvent::Response {
                slave: mac(9),
                service: 0x0E,
                data: vec![0x23, 0x01]
            },
            err(0x14, 0x0E),
            err(0x16, 0x0E),
            err(0x16, 0x0E),
            err(0x0E, 0x10),
            err(0x08, 0x4E),
            err(0x09, 0x10),
            err(0x13, 0x10),
        ]
    );
}

#[test]
fn allocate_errors_reach_the_scanner() {
    let (mut m, mut s, mut w) = setup(2);
    m.allocate(mac(9), choice::POLLED).unwrap();
    m.allocate(mac(9), choice::EXPLICIT).unwrap();
    m.allocate(mac(9), choice::EXPLICIT).unwrap();
    m.release(mac(9), choice::POLLED).unwrap();
    w.run_until(&mut [&mut m, &mut s], at(2 * SEC));
    let e = |service, general, additional| ScannerEvent::Error {
        slave: mac(9),
        service,
        general,
        additional,
    };
    assert_eq!(
        events(&mut m),
        [
            e(0x4B, 0x20, 0x02),
            ScannerEvent::Allocated {
                slave: mac(9),
                choice: 1,
                format: BodyFormat::F8_8
            },
            e(0x4B, 0x0B, 0x02),
            e(0x4C, 0x0B, 0x02),
        ]
    );
    // A second scanner (MAC 1) is refused: allocated to another master.
    let mut m2 = Scanner::new(ScannerConfig::new(mac(1), 0x0001, 0x98));
    let mut w2 = Wire {
        now: w.now,
        ..Wire::new()
    };
    w2.power_up_one(&mut [&mut m2, &mut s], 0);
    w2.run_until(&mut [&mut m2, &mut s], w.now + Duration::from_secs(2));
    m2.allocate(mac(9), choice::EXPLICIT).unwrap();
    w2.run_until(&mut [&mut m2, &mut s], w.now + Duration::from_secs(2));
    assert_eq!(
        events(&mut m2),
        [
            ScannerEvent::Online,
            ScannerEvent::Error {
                slave: mac(9),
                service: 0x4B,
                general: 0x0C,
                additional: 0x01
            }
        ]
    );
}

/// Fragmented response (Identity Get_Attributes_All, 25 bytes) and fragmented request
/// (typed write over UCMM 8/16), with a lost acknowledge recovered by the retry.
#[test]
fn fragmented_transfers_and_a_lost_acknowledge() {
    let (mut m, mut s, mut w) = setup(2);
    m.open_ucmm(mac(9), BodyFormat::F8_16).unwrap();
    m.request(mac(9), 0x01, 1, 1, &[]).unwrap();
    m.request(mac(9), 0x35, 0x66, 700, &[7, 0x40, 0x0D, 0x03, 0x00])
        .unwrap();
    m.request(mac(9), 0x32, 0x66, 700, &[]).unwrap();
    // Lose the slave's first acknowledge of the typed write's first fragment once.
    let mut lost = false;
    w.drop = Box::new(move |from, f: &Frame| {
        if from == 1 && f.to_string() == "609#C0C000" && !lost {
            lost = true;
            return true;
        }
        false
    });
    w.run_until(&mut [&mut m, &mut s], at(5 * SEC));
    let ev = events(&mut m);
    assert!(matches!(ev[0], ScannerEvent::Opened { .. }), "{ev:?}");
    let ScannerEvent::Response { data, .. } = &ev[1] else {
        panic!("{ev:?}")
    };
    let id = cantwin_devicenet::scanner::parse_identity(data).unwrap();
    assert_eq!(id, identity());
    assert_eq!(
        ev[2..],
        [
            ScannerEvent::Response {
                slave: mac(9),
                service: 0x35,
                data: vec![0, 0]
            },
            ScannerEvent::Response {
                slave: mac(9),
                service: 0x32,
                data: vec![0, 0, 0x40, 0x0D, 0x03, 0x00]
            },
        ]
    );
    // The lost acknowledge cost one acknowledge timeout: the first fragment went twice,
    // 1 s apart.
    let firsts: Vec<String> = w
        .lines(0)
        .into_iter()
        .filter(|l| l.ends_with("600#C9003566BC020740"))
        .collect();
    assert_eq!(
        firsts,
        [
            "2.000 0 600#C9003566BC020740",
            "3.000 0 600#C9003566BC020740"
        ]
    );
    m.close_ucmm(mac(9)).unwrap();
    w.run_until(&mut [&mut m, &mut s], at(6 * SEC));
    assert_eq!(events(&mut m), [ScannerEvent::Closed { slave: mac(9) }]);
    assert!(s.ucmm_connections().is_empty());
}

/// Every fragment acknowledge lost: the scanner retries once and reports a timeout.
#[test]
fn lost_fragments_abort_after_one_retry() {
    let (mut m, mut s, mut w) = setup(2);
    m.open_ucmm(mac(9), BodyFormat::F8_16).unwrap();
    w.run_until(&mut [&mut m, &mut s], at(2 * SEC));
    events(&mut m);
    m.request(mac(9), 0x35, 0x66, 700, &[7, 0x40, 0x0D, 0x03, 0x00])
        .unwrap();
    w.drop = Box::new(|from, f: &Frame| from == 1 && f.data_bytes().get(1) == Some(&0xC0));
    w.run_until(&mut [&mut m, &mut s], at(5 * SEC));
    assert_eq!(
        events(&mut m),
        [ScannerEvent::Timeout {
            slave: mac(9),
            service: 0x35
        }]
    );
}

/// No response at all: timeout after 1 s (the card's erroneous Parameter Set).
#[test]
fn silent_refusal_times_out() {
    let (mut m, mut s, mut w) = setup(2);
    m.open_ucmm(mac(9), BodyFormat::F8_16).unwrap();
    m.set_attribute_single(mac(9), 0x0F, 600, 1, &[0x11, 0x27])
        .unwrap();
    w.run_until(&mut [&mut m, &mut s], at(4 * SEC));
    let ev = events(&mut m);
    assert_eq!(
        ev[1..],
        [ScannerEvent::Timeout {
            slave: mac(9),
            service: 0x10
        }]
    );
    let t: Vec<String> = w
        .lines(0)
        .into_iter()
        .filter(|l| l.contains(" 0 600#"))
        .collect();
    assert_eq!(t, ["2.000 0 600#09100F5802011127"]);
}

/// The master stops polling: the slave's poll connection times out after 4 × EPR.
#[test]
fn silent_master_times_out_the_poll_connection() {
    let (mut m, mut s, mut w) = setup(2);
    m.allocate(mac(9), choice::EXPLICIT | choice::POLLED)
        .unwrap();
    m.set_expected_packet_rate(mac(9), 2, 50).unwrap();
    m.start_polling(
        mac(9),
        Duration::from_millis(50),
        &[1, 2, 3, 4],
        4,
        at(2 * SEC),
    );
    w.run_until(&mut [&mut m, &mut s], at(3 * SEC));
    assert_eq!(s.poll_connection().unwrap().state, ConnState::Established);
    m.stop_polling(mac(9));
    // Last poll at 3.000 s; watchdog 200 ms.
    w.run_until(&mut [&mut m, &mut s], at(3 * SEC + 199 * MS));
    assert_eq!(s.poll_connection().unwrap().state, ConnState::Established);
    w.run_until(&mut [&mut m, &mut s], at(3 * SEC + 200 * MS));
    assert_eq!(s.poll_connection().unwrap().state, ConnState::TimedOut);
    assert!(
        s.app()
            .events
            .iter()
            .any(|(t, e)| *t == 3 * SEC + 200 * MS
                && *e == cantwin_devicenet::SlaveEvent::IoTimedOut)
    );
}

#[test]
fn browse_finds_devices_by_mac_id() {
    let mut m = scanner();
    let mut a = slave(5);
    let mut b = slave(9);
    let mut w = Wire::new();
    w.power_up(&mut [&mut m, &mut a, &mut b]);
    w.run_until(&mut [&mut m, &mut a, &mut b], at(2 * SEC));
    events(&mut m);
    m.browse((1..=10).map(mac));
    w.run_until(&mut [&mut m, &mut a, &mut b], at(4 * SEC));
    let ev = events(&mut m);
    let found = |slave| ScannerEvent::DeviceFound {
        slave,
        identity: Some(identity()),
    };
    assert!(ev.contains(&found(mac(5))), "{ev:?}");
    assert!(ev.contains(&found(mac(9))), "{ev:?}");
    assert_eq!(
        ev.last(),
        Some(&ScannerEvent::BrowseDone {
            found: vec![mac(5), mac(9)]
        })
    );
    // Browsing leaves the devices unallocated.
    assert_eq!(a.devicenet_object().master, None);
    assert_eq!(b.devicenet_object().master, None);
}

#[test]
fn scanner_with_a_duplicate_mac_id_faults() {
    let mut m = scanner();
    let mut other = scanner();
    let mut w = Wire::new();
    {
        let mut nodes: [&mut dyn Node; 2] = [&mut m, &mut other];
        w.power_up_one(&mut nodes, 0);
        w.run_until(&mut nodes, at(3 * SEC));
        w.power_up_one(&mut nodes, 1);
    }
    assert_eq!(events(&mut other), [ScannerEvent::DuplicateMac]);
    assert_eq!(events(&mut m), [ScannerEvent::Online]);
}

#[test]
fn request_without_a_connection_is_reported_not_sent() {
    let (mut m, mut s, mut w) = setup(2);
    m.get_attribute_single(mac(9), 1, 1, 1).unwrap();
    m.close_ucmm(mac(9)).unwrap();
    let since = w.log.len();
    w.run_until(&mut [&mut m, &mut s], at(3 * SEC));
    assert!(w.lines(since).is_empty());
    assert_eq!(
        events(&mut m),
        [
            ScannerEvent::NotConnected {
                slave: mac(9),
                service: 0x0E
            },
            ScannerEvent::NotConnected {
                slave: mac(9),
                service: 0x4C
            }
        ]
    );
    assert_eq!(
        m.allocate(mac(0), 1),
        Err(cantwin_devicenet::scanner::ScannerError::OwnMac(mac(0)))
    );
}

/// The transaction ID tells a late answer to an abandoned request from the answer to the
/// next one.
#[test]
fn stale_response_with_the_old_xid_is_ignored() {
    let mut m = scanner();
    let mut out = cantwin_can::Outbox::new();
    m.on_power_up(at(0), &mut out);
    m.on_tick(at(SEC), &mut out);
    m.on_tick(at(2 * SEC), &mut out);
    events(&mut m);
    m.allocate(mac(9), choice::EXPLICIT).unwrap();
    m.get_attribute_single(mac(9), 1, 1, 1).unwrap();
    out.clear();
    m.on_tick(at(2 * SEC), &mut out);
    assert_eq!(sent(&mut out), ["44E#404B03010100"]);
    assert_eq!(
        deliver(&mut m, "44B#40CB00", at(2 * SEC)),
        ["44C#000E010101"]
    );
    // No answer to the first Get (XID 0): timeout, then the second Get goes with XID 1.
    m.get_attribute_single(mac(9), 1, 1, 6).unwrap();
    m.on_tick(at(3 * SEC), &mut out);
    assert_eq!(sent(&mut out), ["44C#400E010106"]);
    // The late answer to the first Get (XID 0) is not taken for the second.
    assert!(deliver(&mut m, "44B#008E2301", at(3 * SEC)).is_empty());
    assert!(deliver(&mut m, "44B#408E0D0C0B0A", at(3 * SEC)).is_empty());
    assert_eq!(
        events(&mut m),
        [
            ScannerEvent::Allocated {
                slave: mac(9),
                choice: 1,
                format: BodyFormat::F8_8
            },
            ScannerEvent::Timeout {
                slave: mac(9),
                service: 0x0E
            },
            ScannerEvent::Response {
                slave: mac(9),
                service: 0x0E,
                data: vec![0x0D, 0x0C, 0x0B, 0x0A]
            }
        ]
    );
}

/// A single poll through the API, without a cycle.
#[test]
fn one_shot_poll() {
    let (mut m, mut s, mut w) = setup(2);
    m.allocate(mac(9), choice::EXPLICIT | choice::POLLED)
        .unwrap();
    m.set_expected_packet_rate(mac(9), 2, 1000).unwrap();
    w.run_until(&mut [&mut m, &mut s], at(2 * SEC));
    events(&mut m);
    let mut out = cantwin_can::Outbox::new();
    m.poll(mac(9), &[9, 8, 7, 6], 4, &mut out);
    let frames: Vec<Frame> = out.drain().collect();
    assert_eq!(frames.len(), 1);
    w.inject(&mut [&mut m, &mut s], 0, frames[0]);
    assert_eq!(
        events(&mut m),
        [ScannerEvent::PollResponse {
            slave: mac(9),
            data: vec![0, 1, 2, 3]
        }]
    );
    assert_eq!(s.app().consumed, vec![vec![9, 8, 7, 6]]);
}

/// A poll command longer or shorter than the consumed connection size is not consumed, not
/// answered, and reported to the device (the master's I/O sizes do not match the slave's).
#[test]
fn a_poll_command_of_the_wrong_length_is_reported_and_not_consumed() {
    let (mut m, mut s, mut w) = setup(2);
    m.allocate(mac(9), choice::EXPLICIT | choice::POLLED)
        .unwrap();
    m.set_expected_packet_rate(mac(9), 2, 1000).unwrap();
    w.run_until(&mut [&mut m, &mut s], at(2 * SEC));
    events(&mut m);
    for data in [&[9u8, 8][..], &[9, 8, 7, 6, 5]] {
        let mut out = cantwin_can::Outbox::new();
        m.poll(mac(9), data, 4, &mut out);
        let frames: Vec<Frame> = out.drain().collect();
        w.inject(&mut [&mut m, &mut s], 0, frames[0]);
    }
    assert_eq!(events(&mut m), []);
    assert!(s.app().consumed.is_empty());
    let mismatches: Vec<_> = s
        .app()
        .events
        .iter()
        .filter_map(|(_, e)| match e {
            cantwin_devicenet::SlaveEvent::IoLengthMismatch { received, expected } => {
                Some((*received, *expected))
            }
            _ => None,
        })
        .collect();
    assert_eq!(mismatches, [(2, 4), (5, 4)]);
}

#[test]
fn browse_reports_a_device_whose_identity_exceeds_the_explicit_limit_and_releases_it() {
    // A product name long enough that Get_Attributes_All of the Identity needs more than the
    // 32 bytes the card's explicit messages carry: the slave answers general status 0x11, the
    // scanner still reports the device (identity unknown) and releases its allocation.
    let mut m = scanner();
    let mut a = cantwin_devicenet::slave::Slave::new(
        cantwin_devicenet::slave::SlaveConfig::new(
            mac(12),
            cantwin_can::BitRate::R500K,
            cantwin_devicenet::Identity {
                product_name: "ADV200 EXP-CAN/DN-ADV card".into(),
                ..identity()
            },
        ),
        Drive::new(2, 2),
    )
    .unwrap();
    let mut w = Wire::new();
    w.power_up(&mut [&mut m, &mut a]);
    w.run_until(&mut [&mut m, &mut a], at(2 * SEC));
    events(&mut m);
    m.browse((10..=14).map(mac));
    w.run_until(&mut [&mut m, &mut a], at(4 * SEC));
    let ev = events(&mut m);
    assert!(
        ev.contains(&ScannerEvent::DeviceFound {
            slave: mac(12),
            identity: None
        }),
        "{ev:?}"
    );
    assert_eq!(
        ev.last(),
        Some(&ScannerEvent::BrowseDone {
            found: vec![mac(12)]
        })
    );
    assert_eq!(
        a.devicenet_object().master,
        None,
        "the allocation was released"
    );
}
