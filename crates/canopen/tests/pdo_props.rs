//! Property tests of the PDO engine: bit packing round trips (CiA 301 §7.5.2.38), the
//! inhibit time (§7.2.2.5) under random events, and random traffic never panicking nor
//! producing a frame the configuration does not describe.
#![allow(clippy::unwrap_used)]

mod pdo_harness;

use cantwin_can::{Duration, Frame, Id, Instant, Outbox};
use cantwin_canopen::device::NoHooks;
use cantwin_canopen::od::{Access, DataType, ObjectDictionary, OdBuilder, SubObject, Value};
use cantwin_canopen::pdo::{Direction, MapEntry, PdoObjects, Plan};
use pdo_harness::Harness;
use proptest::prelude::*;
use std::sync::Arc;

fn u32_od() -> ObjectDictionary {
    let mut b = OdBuilder::new();
    for i in 0..8u16 {
        b = b.var(
            0x2000 + i,
            SubObject::new(format!("v{i}"), DataType::Unsigned32, Access::Rw).mappable(),
        );
    }
    ObjectDictionary::new(Arc::new(b.build().unwrap()), 1)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn cia301_7_5_2_38_bit_mapping_round_trips(
        fields in proptest::collection::vec((1u8..=32, any::<u32>()), 1..8),
    ) {
        let mut total = 0u32;
        let fields: Vec<(u8, u32)> = fields
            .into_iter()
            .take_while(|(bits, _)| {
                total += u32::from(*bits);
                total <= 64
            })
            .collect();
        prop_assume!(!fields.is_empty());
        let mut src = u32_od();
        let mut dst = u32_od();
        let entries: Vec<MapEntry> = fields
            .iter()
            .enumerate()
            .map(|(i, (bits, _))| MapEntry { index: 0x2000 + i as u16, sub: 0, bits: *bits })
            .collect();
        for (i, (_, v)) in fields.iter().enumerate() {
            src.set(0x2000 + i as u16, 0, &Value::Unsigned32(*v)).unwrap();
        }
        let tx = Plan::build(src.description(), Direction::Tx, false, entries.iter().copied()).unwrap();
        let rx = Plan::build(dst.description(), Direction::Rx, false, entries.iter().copied()).unwrap();
        let data = tx.pack(&src, &mut NoHooks);
        // Bits beyond the mapped length are zero.
        let bits = tx.bits();
        let word = u64::from_le_bytes(data);
        prop_assert!(bits == 64 || word >> bits == 0);
        rx.unpack(&data[..rx.len()], &mut dst, &mut NoHooks).unwrap();
        for (i, (b, v)) in fields.iter().enumerate() {
            let mask = if *b == 32 { u32::MAX } else { (1u32 << b) - 1 };
            prop_assert_eq!(dst.get_unsigned(0x2000 + i as u16, 0), Some(u64::from(v & mask)));
        }
        prop_assert_eq!(rx.pack(&dst, &mut NoHooks), data);
    }

    #[test]
    fn cia301_7_2_2_5_inhibit_time_separates_every_transmission(
        inhibit in 1u16..200,
        gaps in proptest::collection::vec(0u64..5_000_000, 1..40),
        timer in 0u16..30,
    ) {
        let mut h = Harness::new(PdoObjects::new(0, 1).tpdo(0, 254, &[0x6000_0010]));
        let t0 = Instant::ZERO;
        h.write_u32(0x1800, 1, 0x8000_0185, t0).unwrap();
        h.write_u16(0x1800, 3, inhibit, t0).unwrap();
        h.write_u16(0x1800, 5, timer, t0).unwrap();
        h.write_u32(0x1800, 1, 0x185, t0).unwrap();
        h.pdo.set_operational(true, t0);
        let inhibit = Duration::from_micros(u64::from(inhibit) * 100);
        let mut sent: Vec<Instant> = Vec::new();
        let mut now = t0;
        let drive = |h: &mut Harness, now: Instant, sent: &mut Vec<Instant>| {
            h.pdo.on_tick(now, &h.od, &mut NoHooks, &mut h.out);
            for _ in h.out.drain() {
                sent.push(now);
            }
        };
        for gap in gaps {
            let event_at = now + Duration::from_nanos(gap);
            while let Some(d) = h.pdo.next_deadline() {
                if d > event_at { break; }
                now = now.max(d);
                drive(&mut h, now, &mut sent);
            }
            now = event_at;
            h.pdo.trigger_tpdo(0);
            drive(&mut h, now, &mut sent);
        }
        prop_assert!(!sent.is_empty());
        for w in sent.windows(2) {
            prop_assert!(w[1] - w[0] >= inhibit, "{} then {}", w[0], w[1]);
        }
    }

    #[test]
    fn random_traffic_never_panics_and_sends_only_configured_tpdos(
        ops in proptest::collection::vec((0u8..7, any::<u16>(), any::<u32>(), proptest::collection::vec(any::<u8>(), 0..=8)), 1..80),
    ) {
        let mut h = Harness::new(
            PdoObjects::new(2, 2)
                .rpdo(0, 255, &[0x6200_0010, 0x6201_0008])
                .rpdo(1, 1, &[0x6202_0020])
                .tpdo(0, 1, &[0x6000_0010])
                .tpdo(1, 255, &[0x6001_0008, 0x6003_0001]),
        );
        let mut now = Instant::ZERO;
        let mut out = Outbox::new();
        for (op, a, b, data) in ops {
            now += Duration::from_micros(u64::from(a % 1000));
            match op {
                0 => h.pdo.on_sync(Some(b as u8), now, &mut h.od, &mut NoHooks, &mut out),
                1 => {
                    let id = Id::standard(0x180 + (a % 0x400)).unwrap();
                    let f = Frame::data(id, &data).unwrap();
                    h.pdo.on_frame(&f, now, &mut h.od, &mut NoHooks, &mut out);
                }
                2 => {
                    let id = Id::standard(0x180 + (a % 0x400)).unwrap();
                    let f = Frame::remote(id, (b % 9) as u8).unwrap();
                    h.pdo.on_frame(&f, now, &mut h.od, &mut NoHooks, &mut out);
                }
                3 => h.pdo.on_tick(now, &h.od, &mut NoHooks, &mut out),
                4 => h.pdo.set_operational(b % 3 != 0, now),
                5 => {
                    // Any download to any PDO parameter: refused or applied, never a panic.
                    let index = [0x1400, 0x1401, 0x1600, 0x1601, 0x1800, 0x1801, 0x1A00, 0x1A01][usize::from(a % 8)];
                    let sub = (b >> 24) as u8 % 9;
                    let len = h.od.description().get(index, sub).and_then(|d| d.data_type.fixed_size()).unwrap_or(1);
                    let _ = h.sdo_write(index, sub, &b.to_le_bytes()[..len.min(4)], now);
                }
                _ => h.pdo.mark_changed(0x6001, 0),
            }
            while h.pdo.poll_event().is_some() {}
            for f in out.drain() {
                // Every frame is a data frame of a valid TPDO, as long as its mapping.
                prop_assert!(!f.is_remote());
                let od = &h.od;
                let described = (0..2u16).any(|n| {
                    let cob = od.get_unsigned(0x1800 + n, 1).unwrap() as u32;
                    let count = od.get_unsigned(0x1A00 + n, 0).unwrap() as u8;
                    let bits: u32 = (1..=count)
                        .map(|k| u32::from(od.get_unsigned(0x1A00 + n, k).unwrap() as u8))
                        .sum();
                    cob & 0x8000_0000 == 0
                        && cantwin_canopen::pdo::CobId(cob).id() == Some(f.id())
                        && f.len() == bits.div_ceil(8) as usize
                });
                prop_assert!(described, "{}", f);
            }
        }
    }
}
