//! NMT master services on the virtual bus (CiA 301 §7.2.5, §7.2.6, §7.2.8): module control
//! frames, boot-up detection, heartbeat consumer, node guarding master, SYNC and TIME
//! producers, network scan, remote PDO configuration.
#![allow(clippy::unwrap_used)]

mod master_support;

use cantwin_can::Duration;
use cantwin_canopen::AbortCode;
use cantwin_canopen::master::pdo::{MapEntry, PdoOutcome, PdoParams, PdoRef, decode};
use cantwin_canopen::master::{Master, MasterError, MasterEvent, ScanHit};
use cantwin_canopen::od::{TimeOfDay, Value};
use cantwin_canopen::wire::{NmtCs, NmtState};
use master_support::*;

const MS: u64 = 1_000_000;

/// A device that only acknowledges frames (a frame nobody acknowledges is an error frame).
fn listener() -> Device {
    let mut d = Device::new(100);
    d.answer_guarding = false;
    d
}

#[test]
fn cia301_7_2_8_3_1_module_control_frames() {
    let mut n = Net::new(Master::new(), vec![listener()]);
    n.with_master(|m, _, out| {
        m.nmt(NmtCs::Start, 0, out).unwrap();
        m.nmt(NmtCs::Stop, 5, out).unwrap();
        m.nmt(NmtCs::EnterPreOperational, 127, out).unwrap();
        m.nmt(NmtCs::ResetNode, 1, out).unwrap();
        m.nmt(NmtCs::ResetCommunication, 0, out).unwrap();
        assert_eq!(m.nmt(NmtCs::Start, 128, out), Err(MasterError::NodeId(128)));
    });
    n.run_for(Duration::from_millis(1));
    assert_eq!(
        n.frame_strings(),
        ["000#0100", "000#0205", "000#807F", "000#8101", "000#8200"]
    );
}

#[test]
fn cia301_7_2_8_3_2_4_boot_up_detection() {
    let mut d = Device::new(9);
    d.boot = true;
    let mut n = Net::new(Master::new(), vec![d]);
    let (t, e) = n.next_event(Duration::from_millis(10)).unwrap();
    assert_eq!(e, MasterEvent::BootUp { node: 9 });
    assert_eq!(n.frames()[0].1, t.as_nanos());
    let (_, e) = n.next_event(Duration::from_millis(10)).unwrap();
    assert_eq!(
        e,
        MasterEvent::StateChanged {
            node: 9,
            from: None,
            to: NmtState::PreOperational
        }
    );
    assert_eq!(n.master().status(9).unwrap().last_seen, Some(t));
}

#[test]
fn cia301_7_2_8_3_2_2_heartbeat_consumer_state_changes_and_timeout() {
    let mut d = Device::new(3);
    d.heartbeat = Some(Duration::from_millis(100));
    let mut n = Net::new(Master::new(), vec![d]);
    n.master()
        .watch_heartbeat(3, Some(Duration::from_millis(150)))
        .unwrap();
    let (t1, e) = n.next_event(Duration::from_secs(1)).unwrap();
    assert_eq!(
        e,
        MasterEvent::StateChanged {
            node: 3,
            from: None,
            to: NmtState::PreOperational
        }
    );
    assert_eq!(t1.as_nanos(), n.frames()[0].1);
    // The device goes operational: one state change event, at that heartbeat.
    n.run_for(Duration::from_millis(150));
    n.device(0).state = 0x05;
    let (t2, e) = n.next_event(Duration::from_secs(1)).unwrap();
    assert_eq!(
        e,
        MasterEvent::StateChanged {
            node: 3,
            from: Some(NmtState::PreOperational),
            to: NmtState::Operational
        }
    );
    assert_eq!(t2.as_nanos(), n.frames().last().unwrap().1);
    // The device dies: the timeout comes exactly 150 ms after the last heartbeat.
    n.run_for(Duration::from_millis(50));
    let port = n.devices[0];
    n.sim
        .bus_mut(n.bus)
        .unwrap()
        .set_powered(port, false)
        .unwrap();
    let last = n.frames().last().unwrap().1;
    let (t3, e) = n.next_event(Duration::from_secs(1)).unwrap();
    assert_eq!(e, MasterEvent::HeartbeatTimeout { node: 3 });
    assert_eq!(t3.as_nanos(), last + 150 * MS);
    let s = n.master().status(3).unwrap();
    assert!(s.lost);
    assert_eq!(s.last_seen.unwrap().as_nanos(), last);
    // Reported once.
    assert_eq!(n.next_event(Duration::from_secs(1)), None);
}

#[test]
fn cia301_7_2_8_3_2_1_guarding_master_polls_and_detects_a_silent_node() {
    let mut n = Net::new(Master::new(), vec![Device::new(4)]);
    let now = n.now();
    n.master()
        .guard(4, Some((Duration::from_millis(100), 3)), now)
        .unwrap();
    n.run_for(Duration::from_millis(250));
    let f = n.frames();
    // A remote frame every guard time, each answered with an alternating toggle bit.
    let polls: Vec<(u64, &str)> = f.iter().map(|r| (r.0, r.2.as_str())).collect();
    assert_eq!(polls[0], (0, "704#R1"));
    assert_eq!(polls[1].1, "704#7F");
    assert_eq!(polls[2], (100 * MS, "704#R1"));
    assert_eq!(polls[3].1, "704#FF");
    assert_eq!(polls[4], (200 * MS, "704#R1"));
    assert_eq!(polls[5].1, "704#7F");
    let (_, e) = n.next_event(Duration::ZERO).unwrap();
    assert_eq!(
        e,
        MasterEvent::StateChanged {
            node: 4,
            from: None,
            to: NmtState::PreOperational
        }
    );
    // The device stops answering: the timeout is one life time (300 ms) after its last
    // answer.
    n.device(0).answer_guarding = false;
    let last = n.frames().last().unwrap().1;
    let (t, e) = n.next_event(Duration::from_secs(1)).unwrap();
    assert_eq!(e, MasterEvent::GuardingTimeout { node: 4 });
    assert_eq!(t.as_nanos(), last + 300 * MS);
    assert!(n.master().status(4).unwrap().lost);
    // Polling goes on; an answer clears the loss.
    n.device(0).answer_guarding = true;
    n.run_for(Duration::from_millis(150));
    assert!(!n.master().status(4).unwrap().lost);
}

#[test]
fn cia301_7_2_8_3_2_1_guarding_toggle_bit_not_alternated() {
    let mut d = Device::new(4);
    d.toggles = false;
    let mut n = Net::new(Master::new(), vec![d]);
    let now = n.now();
    n.master()
        .guard(4, Some((Duration::from_millis(100), 2)), now)
        .unwrap();
    let ev = n.events(Duration::from_millis(450));
    let kinds: Vec<(u64, MasterEvent)> = ev.into_iter().map(|(t, e)| (t.as_nanos(), e)).collect();
    // The first answer sets the toggle; the repeated toggle of the second is an error and
    // does not count as an answer, so the life time (200 ms) from the first one expires
    // (at the instant the third answer arrives, itself a toggle error).
    let first = n.frames()[1].1;
    let second = n.frames()[3].1;
    assert_eq!(
        kinds[..2],
        [
            (
                first,
                MasterEvent::StateChanged {
                    node: 4,
                    from: None,
                    to: NmtState::PreOperational
                }
            ),
            (second, MasterEvent::GuardingToggleError { node: 4 }),
        ]
    );
    let timeouts: Vec<u64> = kinds
        .iter()
        .filter(|k| k.1 == MasterEvent::GuardingTimeout { node: 4 })
        .map(|k| k.0)
        .collect();
    assert_eq!(timeouts, [first + 200 * MS]);
    let errors = kinds
        .iter()
        .filter(|k| k.1 == MasterEvent::GuardingToggleError { node: 4 })
        .count();
    assert_eq!(errors, 4);
}

#[test]
fn cia301_7_2_5_sync_producer_with_counter_overflow() {
    let mut n = Net::new(Master::new(), vec![listener()]);
    let now = n.now();
    n.master()
        .set_sync(Some((Duration::from_millis(10), 3)), now)
        .unwrap();
    n.run_for(Duration::from_millis(45));
    let f: Vec<(u64, String)> = n.frames().into_iter().map(|r| (r.0, r.2)).collect();
    assert_eq!(
        f,
        [
            (10, "080#01"),
            (20, "080#02"),
            (30, "080#03"),
            (40, "080#01")
        ]
        .map(|(t, s)| (t * MS, s.to_string()))
    );
    let now = n.now();
    n.master()
        .set_sync(Some((Duration::from_millis(10), 0)), now)
        .unwrap();
    n.run_for(Duration::from_millis(11));
    assert_eq!(n.frames().last().unwrap().2, "080#");
    n.master().set_sync(None, now).unwrap();
    let count = n.frames().len();
    n.run_for(Duration::from_millis(100));
    assert_eq!(n.frames().len(), count);
}

#[test]
fn cia301_7_2_6_time_producer_frame() {
    let mut n = Net::new(Master::new(), vec![listener()]);
    let t = TimeOfDay::from_le_bytes([0x10, 0x27, 0, 0, 0x64, 0x00]);
    n.with_master(|m, _, out| m.send_time(t, out));
    n.run_for(Duration::from_millis(1));
    assert_eq!(n.frame_strings(), ["100#102700006400"]);
}

#[test]
fn cia301_7_3_4_scan_finds_exactly_the_nodes_present() {
    let devices = [3u8, 42, 127].into_iter().map(Device::new).collect();
    let mut n = Net::new(Master::new(), devices);
    n.with_master(|m, now, out| m.scan(now, out)).unwrap();
    assert_eq!(
        n.with_master(|m, now, out| m.scan(now, out)),
        Err(MasterError::ScanRunning)
    );
    let (t, e) = n.next_event(Duration::from_secs(1)).unwrap();
    let hit = |node| ScanHit {
        node,
        device_type: Ok(DEVICE_TYPE),
    };
    assert_eq!(
        e,
        MasterEvent::ScanFinished {
            found: vec![hit(3), hit(42), hit(127)]
        }
    );
    // Concurrently: the whole scan takes one scan timeout (300 ms), not 124 of them.
    assert_eq!(t.as_nanos(), 300 * MS);
    // 127 requests and 3 answers, and no abort frames for the silent ids.
    let f = n.frame_strings();
    assert_eq!(
        f.iter()
            .filter(|s| s.starts_with('6') || s.starts_with('5'))
            .count(),
        130
    );
    assert!(f.iter().all(|s| !s.contains("#80")));
}

#[test]
fn cia301_7_4_8_2_remote_pdo_read_write_and_decode() {
    let mut n = Net::new(Master::new(), vec![Device::new(6)]);
    let tpdo1 = PdoRef::tpdo(1);
    let id = n
        .with_master(|m, now, out| m.read_pdo(6, tpdo1, now, out))
        .unwrap();
    let (_, e) = n.next_event(Duration::from_secs(1)).unwrap();
    let MasterEvent::Pdo {
        id: got,
        node: 6,
        result: Ok(PdoOutcome::Read(p)),
    } = e
    else {
        panic!("{e:?}")
    };
    assert_eq!(got, id);
    assert_eq!(p.cob_id & 0x7FF, 0x186);
    assert_eq!(
        Value::Unsigned8(p.transmission_type),
        n.device(0).od.get(0x1800, 2).unwrap()
    );
    let count = n.device(0).od.get(0x1A00, 0).unwrap();
    assert_eq!(Value::Unsigned8(p.mapping.len() as u8), count);

    let new = PdoParams {
        cob_id: 0x186,
        transmission_type: 1,
        inhibit_time: p.inhibit_time.map(|_| 10),
        event_timer: p.event_timer.map(|_| 250),
        mapping: vec![
            MapEntry::from_u32(0x6041_0010),
            MapEntry::from_u32(0x6064_0020),
        ],
    };
    let id = n
        .with_master(|m, now, out| m.write_pdo(6, tpdo1, &new, now, out))
        .unwrap();
    let (_, e) = n.next_event(Duration::from_secs(1)).unwrap();
    assert_eq!(
        e,
        MasterEvent::Pdo {
            id,
            node: 6,
            result: Ok(PdoOutcome::Written)
        }
    );
    // The CiA 301 §7.4.8.2 order on the wire: invalidate, parameters, sub 0 = 0, entries,
    // sub 0 = n, validate.
    let requests: Vec<String> = n
        .frame_strings()
        .into_iter()
        .filter(|s| s.starts_with("606#2"))
        .collect();
    let expected_head = ["606#2300180186010080", "606#2F00180201000000"];
    assert_eq!(requests[..2], expected_head);
    let tail = &requests[requests.len() - 5..];
    assert_eq!(
        tail,
        [
            "606#2F001A0000000000",
            "606#23001A0110004160",
            "606#23001A0220006460",
            "606#2F001A0002000000",
            "606#2300180186010000",
        ]
    );
    let id = n
        .with_master(|m, now, out| m.read_pdo(6, tpdo1, now, out))
        .unwrap();
    let (_, e) = n.next_event(Duration::from_secs(1)).unwrap();
    assert_eq!(
        e,
        MasterEvent::Pdo {
            id,
            node: 6,
            result: Ok(PdoOutcome::Read(new.clone()))
        }
    );

    // A received TPDO decoded with the node's dictionary.
    let od = description();
    let v = decode(&new.mapping, &od, &[0x37, 0x02, 0x40, 0xE2, 0x01, 0x00]).unwrap();
    let named: Vec<(&str, Value)> = v
        .iter()
        .map(|v| (v.name.as_str(), v.value.clone()))
        .collect();
    assert_eq!(
        named,
        [
            ("Statusword", Value::Unsigned16(0x0237)),
            ("Position actual value", Value::Integer32(123_456))
        ]
    );
}

#[test]
fn cia301_7_4_8_2_remote_pdo_write_refused_reports_the_abort() {
    let mut n = Net::new(Master::new(), vec![Device::new(6)]);
    // RPDO 2 does not exist on the device.
    let bad = PdoRef::rpdo(2);
    let id = n
        .with_master(|m, now, out| m.write_pdo(6, bad, &PdoParams::default(), now, out))
        .unwrap();
    let (_, e) = n.next_event(Duration::from_secs(1)).unwrap();
    let MasterEvent::Pdo {
        id: got,
        result: Err(err),
        ..
    } = e
    else {
        panic!("{e:?}")
    };
    assert_eq!(got, id);
    assert_eq!(
        err,
        cantwin_canopen::master::pdo::PdoError::Aborted {
            index: 0x1401,
            sub: 1,
            code: AbortCode::NO_OBJECT
        }
    );
}

#[test]
fn cia301_7_2_7_emergency_messages_are_reported() {
    let mut n = Net::new(Master::new(), vec![listener()]);
    let port = n.devices[0];
    n.sim
        .transmit(
            port,
            cantwin_can::Frame::std(0x08A, &[0x10, 0x82, 0x11, 1, 2, 3, 4, 5]).unwrap(),
        )
        .unwrap();
    let (t, e) = n.next_event(Duration::from_millis(1)).unwrap();
    assert_eq!(
        e,
        MasterEvent::Emcy {
            node: 10,
            emcy: cantwin_canopen::wire::Emcy {
                code: 0x8210,
                register: 0x11,
                manufacturer: [1, 2, 3, 4, 5]
            }
        }
    );
    assert_eq!(t.as_nanos(), n.frames()[0].1);
}

#[test]
fn cia301_7_2_8_3_2_2_node_age_from_the_last_heartbeat() {
    let mut d = Device::new(3);
    d.heartbeat = Some(Duration::from_millis(100));
    let mut n = Net::new(Master::new(), vec![d]);
    let now = n.now();
    assert_eq!(n.master().age(3, now), None);
    n.run_for(Duration::from_millis(130));
    let heard = n.frames()[0].1;
    let now = n.now();
    assert_eq!(
        n.master().age(3, now).unwrap().as_nanos(),
        now.as_nanos() - heard
    );
}
