//! Property tests: whatever arrives on the bus, the slave and the scanner never panic, and
//! frames not addressed to a connection never change it.
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_can::{Duration, Frame, Id, Instant, Node, Outbox};
use cantwin_devicenet::scanner::ScannerConfig;
use cantwin_devicenet::wire::{self, BodyFormat, DnId, ExplicitFrame, Request};
use cantwin_devicenet::{Scanner, Slave};
use common::*;
use proptest::prelude::*;

/// Slave 9 owned by master 10 (explicit + poll, EPR 100 ms) with a UCMM connection from
/// client 11 (consumes 0x60B), at 2 s.
fn busy_slave() -> (Slave<Drive>, Instant) {
    let mut s = slave(9);
    let t = online(&mut s);
    assert_eq!(deliver(&mut s, "44E#0A4B0301030A", t), ["44B#0ACB00"]);
    assert_eq!(deliver(&mut s, "44C#0A100502096400", t), ["44B#0A906400"]);
    assert_eq!(deliver(&mut s, "78B#094B0130", t), ["749#0BCB01000600"]);
    // Leave a fragmented request half-way on the predefined connection.
    assert_eq!(deliver(&mut s, "44C#8A0010050209E8", t), ["44B#8AC000"]);
    (s, t)
}

fn snapshot(s: &Slave<Drive>) -> String {
    format!(
        "{:?}|{:?}|{:?}|{:?}|{:?}",
        s.explicit_connection(),
        s.poll_connection(),
        s.ucmm_connections(),
        s.devicenet_object(),
        s.link_state()
    )
}

fn arb_frame() -> impl Strategy<Value = Frame> {
    (
        0u16..0x800,
        prop::collection::vec(any::<u8>(), 0..=8),
        any::<bool>(),
    )
        .prop_map(|(id, data, remote)| {
            let id = Id::standard(id).unwrap();
            if remote {
                Frame::remote(id, data.len() as u8).unwrap()
            } else {
                Frame::data(id, &data).unwrap()
            }
        })
}

/// Frames that address neither slave 9 on group 2, nor its UCMM (group 3 message 6 with
/// header MAC 9), nor the client-11 UCMM connection (0x60B).
fn unaddressed_frame() -> impl Strategy<Value = Frame> {
    arb_frame().prop_filter("addressed to slave 9", |f| {
        let raw = f.id().as_raw() as u16;
        let g2_ours = (0x448..=0x44F).contains(&raw);
        let ucmm_ours =
            (0x780..=0x7BF).contains(&raw) && f.data_bytes().first().is_some_and(|b| b & 0x3F == 9);
        !g2_ours && !ucmm_ours && raw != 0x60B
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_frames_never_panic_the_slave(
        frames in prop::collection::vec((arb_frame(), 0u64..3_000), 1..40)
    ) {
        let (mut s, t0) = busy_slave();
        let mut now = t0;
        let mut out = Outbox::new();
        for (f, dt) in frames {
            now += Duration::from_millis(dt);
            s.on_frame(&f, now, &mut out);
            if s.next_deadline().is_some_and(|d| d <= now) {
                s.on_tick(now, &mut out);
            }
        }
        // Everything the slave sends is a DeviceNet frame of its own.
        for f in out.drain() {
            let dn = DnId::decode(f.id()).unwrap();
            let ours = match dn {
                DnId::Group1 { mac, .. } | DnId::Group2 { mac, .. } | DnId::Group3 { mac, .. } => mac == mac9(),
                DnId::Group4 { .. } => false,
            };
            prop_assert!(ours, "{f}");
        }
    }

    #[test]
    fn unaddressed_frames_leave_connections_untouched(
        frames in prop::collection::vec(unaddressed_frame(), 1..40)
    ) {
        let (mut s, t) = busy_slave();
        let before = snapshot(&s);
        let mut out = Outbox::new();
        for f in frames {
            s.on_frame(&f, t, &mut out);
        }
        prop_assert!(out.is_empty(), "{:?}", out.frames());
        prop_assert_eq!(snapshot(&s), before);
    }

    #[test]
    fn random_frames_never_panic_the_scanner(
        frames in prop::collection::vec((arb_frame(), 0u64..1_500), 1..40)
    ) {
        let mut m = Scanner::new(ScannerConfig::new(mac(0), 1, 2));
        let mut out = Outbox::new();
        m.on_power_up(at(0), &mut out);
        m.on_tick(at(SEC), &mut out);
        m.on_tick(at(2 * SEC), &mut out);
        m.allocate(mac(9), 3).unwrap();
        m.open_ucmm(mac(5), BodyFormat::F8_16).unwrap();
        m.get_attribute_single(mac(9), 1, 1, 7).unwrap();
        m.start_polling(mac(9), Duration::from_millis(10), &[1; 20], 20, at(2 * SEC));
        let mut now = at(2 * SEC);
        m.on_tick(now, &mut out);
        for (f, dt) in frames {
            now += Duration::from_millis(dt);
            m.on_frame(&f, now, &mut out);
            m.on_tick(now, &mut out);
            while m.poll_event().is_some() {}
        }
    }

    #[test]
    fn explicit_codec_round_trips(
        service in 0u8..0x80, class in any::<u8>(), instance in any::<u16>(),
        data in prop::collection::vec(any::<u8>(), 0..30), xid in any::<bool>()
    ) {
        let req = Request { service, class: u16::from(class), instance, data: &data };
        let body = req.encode(BodyFormat::F8_16);
        prop_assert_eq!(Request::decode(&body, BodyFormat::F8_16).unwrap(), req);
        let frames = wire::explicit_frames(wire::Header::new(xid, mac(3)), &body);
        let mut rx = cantwin_devicenet::fragment::ExplicitReassembler::new(64);
        let mut got = None;
        for f in &frames {
            match ExplicitFrame::decode(f).unwrap() {
                ExplicitFrame::Whole { body, .. } => got = Some(body.to_vec()),
                ExplicitFrame::Fragment { frag, data, .. } => {
                    if let cantwin_devicenet::fragment::RxOutcome::Complete { body, .. } =
                        rx.on_fragment(frag, data)
                    {
                        got = Some(body);
                    }
                }
                ExplicitFrame::Ack { .. } => prop_assert!(false, "ack"),
            }
        }
        prop_assert_eq!(got, Some(body));
    }
}

fn mac9() -> cantwin_devicenet::MacId {
    mac(9)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    /// Lost frames during fragmented transfers (both directions, acknowledges included)
    /// end in the exact response or a timeout, never in wrong data; the slave applies the
    /// typed write whole or not at all.
    #[test]
    fn lost_fragments_give_exact_data_or_timeout(drops in prop::collection::vec(any::<bool>(), 0..40)) {
        use cantwin_devicenet::ScannerEvent;
        let mut m = Scanner::new(ScannerConfig::new(mac(0), 1, 2));
        let mut s = slave(9);
        let mut w = Wire::new();
        w.power_up(&mut [&mut m, &mut s]);
        w.run_until(&mut [&mut m, &mut s], at(2 * SEC));
        m.open_ucmm(mac(9), BodyFormat::F8_16).unwrap();
        w.run_until(&mut [&mut m, &mut s], at(2 * SEC));
        while m.poll_event().is_some() {}
        m.request(mac(9), 0x01, 1, 1, &[]).unwrap();
        m.request(mac(9), 0x35, 0x66, 700, &[7, 0x40, 0x0D, 0x03, 0x00]).unwrap();
        let mut n = 0usize;
        w.drop = Box::new(move |_, _| {
            n += 1;
            drops.get(n - 1).copied().unwrap_or(false)
        });
        w.run_until(&mut [&mut m, &mut s], at(20 * SEC));
        let all = identity();
        for e in std::iter::from_fn(|| m.poll_event()) {
            match e {
                ScannerEvent::Response { service: 0x01, data, .. } => {
                    prop_assert_eq!(cantwin_devicenet::scanner::parse_identity(&data), Some(all.clone()));
                }
                ScannerEvent::Response { service: 0x35, data, .. } => {
                    prop_assert_eq!(data, vec![0, 0]);
                }
                ScannerEvent::Timeout { .. } => {}
                other => prop_assert!(false, "{:?}", other),
            }
        }
        let v = s.app().pars[&700].value;
        prop_assert!(v == 100_000 || v == 200_000, "{}", v);
    }
}
