//! CiA 301 §7.3.5 (restricted CAN-IDs) and the COB-ID entries' tables of §7.5.2: one rule for
//! every COB-ID entry of the stack — SYNC 0x1005, TIME 0x1012, EMCY 0x1014, EMCY consumer
//! 0x1028, SDO server 0x1201 and client 0x1280 sub 1/2, RPDO 0x1400 and TPDO 0x1800 sub 1 —
//! checked over every restricted identifier, with the abort code 0x0609 0030.
#![allow(clippy::unwrap_used)]

mod device_harness;

use cantwin_can::{Duration, Frame, Id, Node};
use cantwin_canopen::ObjectAccess;
use cantwin_canopen::abort::AbortCode;
use cantwin_canopen::cob_id::is_restricted;
use cantwin_canopen::device::{Device, DeviceConfig};
use cantwin_canopen::objects::cia301_defaults;
use cantwin_canopen::od::{Access, DataType, OdBuilder, SubObject, Value};
use cantwin_canopen::pdo::PdoObjects;
use device_harness::*;
use proptest::prelude::*;
use std::sync::Arc;

const BIT31: u32 = 1 << 31;
const BIT30: u32 = 1 << 30;
const FRAME: u32 = 1 << 29;

/// The test dictionary with an SDO client parameter (0x1280) besides the server ones.
fn device() -> Device {
    let b = cia301_defaults(OdBuilder::new(), &options())
        .var(
            0x6000,
            SubObject::new("Inputs", DataType::Unsigned16, Access::Ro).mappable(),
        )
        .var(
            0x6200,
            SubObject::new("Outputs", DataType::Unsigned8, Access::Rww).mappable(),
        )
        .record(
            0x1280,
            "SDO client parameter",
            [
                (
                    1,
                    SubObject::unsigned32("COB-ID client to server", Access::Rw, BIT31),
                ),
                (
                    2,
                    SubObject::unsigned32("COB-ID server to client", Access::Rw, BIT31),
                ),
                (
                    3,
                    SubObject::new("Node-ID of the SDO server", DataType::Unsigned8, Access::Rw)
                        .default(Value::Unsigned8(1)),
                ),
            ],
        );
    let b = PdoObjects::new(1, 1)
        .tpdo(0, 1, &[0x6000_0010])
        .rpdo(0, 255, &[0x6200_0008])
        .add_to(b);
    Device::new(Arc::new(b.build().unwrap()), DeviceConfig::new(5)).unwrap()
}

fn booted() -> Harness {
    let mut h = Harness::with_device(device());
    h.power_up(ms(0));
    h.take();
    h
}

/// A COB-ID entry and how its object's table reads bits 30 and 31.
#[derive(Debug, Clone, Copy)]
struct Case {
    index: u16,
    sub: u8,
    /// Whether the identifier is used whatever bit 31 says (SYNC, TIME, EMCY), so a
    /// restricted one is refused with bit 31 set too.
    always_in_use: bool,
    /// The flags a value keeps the entry out of use (and its identifier free to change)
    /// with.
    free: u32,
}

const CASES: [Case; 10] = [
    Case {
        index: 0x1005,
        sub: 0,
        always_in_use: true,
        free: 0,
    },
    Case {
        index: 0x1012,
        sub: 0,
        always_in_use: true,
        free: 0,
    },
    Case {
        index: 0x1014,
        sub: 0,
        always_in_use: true,
        free: BIT31,
    },
    Case {
        index: 0x1028,
        sub: 1,
        always_in_use: false,
        free: BIT31,
    },
    Case {
        index: 0x1201,
        sub: 1,
        always_in_use: false,
        free: BIT31,
    },
    Case {
        index: 0x1201,
        sub: 2,
        always_in_use: false,
        free: BIT31,
    },
    Case {
        index: 0x1280,
        sub: 1,
        always_in_use: false,
        free: BIT31,
    },
    Case {
        index: 0x1280,
        sub: 2,
        always_in_use: false,
        free: BIT31,
    },
    Case {
        index: 0x1400,
        sub: 1,
        always_in_use: false,
        free: BIT31,
    },
    Case {
        index: 0x1800,
        sub: 1,
        always_in_use: false,
        free: BIT31,
    },
];

fn write(dev: &mut Device, c: &Case, v: u32) -> Result<(), AbortCode> {
    dev.write(c.index, c.sub, &v.to_le_bytes())
}

fn value(dev: &mut Device, c: &Case) -> u32 {
    let mut b = [0u8; 4];
    dev.read(c.index, c.sub, 0, &mut b).unwrap();
    u32::from_le_bytes(b)
}

/// Takes the entry out of use on a free identifier, so that only the value written next
/// decides.
fn release(dev: &mut Device, c: &Case) {
    write(dev, c, c.free | 0x1E5).unwrap();
}

#[test]
fn cia301_7_3_5_every_restricted_can_id_is_refused_by_every_cob_id_entry() {
    let mut dev = device();
    for c in &CASES {
        release(&mut dev, c);
        let mut refused = 0;
        for id in (0..0x800u16).filter(|&i| is_restricted(i)) {
            let before = value(&mut dev, c);
            let id = u32::from(id);
            assert_eq!(
                write(&mut dev, c, id),
                Err(AbortCode::INVALID_VALUE),
                "{:04X}sub{} = {id:#X}",
                c.index,
                c.sub
            );
            let flagged = write(&mut dev, c, BIT31 | id);
            if c.always_in_use {
                assert_eq!(flagged, Err(AbortCode::INVALID_VALUE), "{c:?} {id:#X}");
                assert_eq!(
                    value(&mut dev, c),
                    before,
                    "a refused write changes nothing"
                );
            } else {
                // Not valid: the identifier is not on the bus.
                assert_eq!(flagged, Ok(()), "{c:?} {id:#X}");
            }
            release(&mut dev, c);
            refused += 1;
        }
        assert_eq!(refused, 797);
    }
}

#[test]
fn cia301_7_3_5_every_other_11_bit_can_id_is_accepted_by_every_cob_id_entry() {
    let mut dev = device();
    for c in &CASES {
        for id in (0..0x800u16).filter(|&i| !is_restricted(i)) {
            release(&mut dev, c);
            let v = c.free & !BIT31 | u32::from(id);
            assert_eq!(write(&mut dev, c, v), Ok(()), "{c:?} {id:#X}");
            assert_eq!(value(&mut dev, c), v);
        }
    }
}

#[test]
fn cia301_7_5_2_5_sync_on_the_own_sdo_request_identifier_is_refused_and_sdo_keeps_working() {
    // The deviation found by a conformance sequence: 0x1005 = 0x605 was accepted and the
    // device then took its SDO requests for SYNC.
    let mut h = booted();
    let t = ms(1);
    h.rx(t, "605#2305100005060000");
    assert_eq!(
        h.take(),
        [(t.as_nanos(), "585#8005100030000906".to_string())]
    );
    let t = ms(2);
    h.rx(t, "605#4005100000000000");
    assert_eq!(
        h.take(),
        [(t.as_nanos(), "585#4305100080000000".to_string())]
    );
    // Above 0x7FF without bit 29: refused as well.
    for v in [0x18BEu32, 0x3D6C] {
        assert_eq!(
            h.write(ms(3), 0x1005, 0, &v.to_le_bytes()),
            Err(AbortCode::INVALID_VALUE)
        );
        assert_eq!(
            h.write(ms(3), 0x1012, 0, &v.to_le_bytes()),
            Err(AbortCode::INVALID_VALUE)
        );
    }
}

#[test]
fn cia301_7_5_2_5_sync_bit31_is_dont_care_bit30_generates() {
    let mut dev = device();
    let sync = CASES[0];
    assert_eq!(write(&mut dev, &sync, BIT31 | 0x81), Ok(()));
    assert_eq!(write(&mut dev, &sync, BIT30 | 0x81), Ok(()));
    // The identifier is fixed while the device generates SYNC.
    assert_eq!(
        write(&mut dev, &sync, BIT30 | 0x82),
        Err(AbortCode::INVALID_VALUE)
    );
    assert_eq!(write(&mut dev, &sync, 0x81), Ok(()));
    assert_eq!(write(&mut dev, &sync, 0x82), Ok(()));
    // A device that cannot generate SYNC refuses bit 30.
    let desc = Arc::clone(dev.od().description());
    let mut consumer = Device::new(
        desc,
        DeviceConfig {
            sync_producer: false,
            time_producer: false,
            ..DeviceConfig::new(5)
        },
    )
    .unwrap();
    assert_eq!(
        write(&mut consumer, &sync, BIT30 | 0x80),
        Err(AbortCode::INVALID_VALUE)
    );
    assert_eq!(
        write(&mut consumer, &CASES[1], BIT30 | 0x100),
        Err(AbortCode::INVALID_VALUE)
    );
    assert_eq!(write(&mut consumer, &CASES[1], BIT31 | 0x100), Ok(()));
}

#[test]
fn cia301_7_5_2_emcy_bit30_is_reserved() {
    let mut dev = device();
    for c in [CASES[2], CASES[3]] {
        release(&mut dev, &c);
        assert_eq!(
            write(&mut dev, &c, BIT31 | BIT30 | 0x85),
            Err(AbortCode::INVALID_VALUE),
            "{c:?}"
        );
    }
    // Bit 30 means something to SDO (dynamic) and TPDO (no RTR) entries.
    for c in [CASES[4], CASES[6], CASES[9]] {
        release(&mut dev, &c);
        assert_eq!(write(&mut dev, &c, BIT30 | 0x1E6), Ok(()), "{c:?}");
    }
}

#[test]
fn cia301_7_5_2_the_identifier_of_an_entry_in_use_changes_only_after_it_is_released() {
    let mut dev = device();
    // EMCY, EMCY consumer, SDO server and client, PDOs: fixed while valid (bit 31 = 0).
    for c in &CASES[2..] {
        release(&mut dev, c);
        assert_eq!(write(&mut dev, c, 0x1E5), Ok(()), "{c:?}");
        assert_eq!(
            write(&mut dev, c, 0x1E6),
            Err(AbortCode::INVALID_VALUE),
            "{c:?}"
        );
        assert_eq!(
            write(&mut dev, c, FRAME | 0x1E5),
            Err(AbortCode::INVALID_VALUE),
            "{c:?}: the frame format is part of the identifier"
        );
        assert_eq!(value(&mut dev, c), 0x1E5);
        assert_eq!(write(&mut dev, c, BIT31 | 0x1E5), Ok(()), "{c:?}");
        assert_eq!(write(&mut dev, c, 0x1E6), Ok(()), "{c:?}");
    }
    // TIME: fixed while consumed or produced.
    let time = CASES[1];
    assert_eq!(write(&mut dev, &time, BIT31 | 0x1E5), Ok(()));
    assert_eq!(
        write(&mut dev, &time, BIT31 | 0x1E6),
        Err(AbortCode::INVALID_VALUE)
    );
    assert_eq!(write(&mut dev, &time, 0x1E5), Ok(()));
    assert_eq!(write(&mut dev, &time, BIT30 | 0x1E6), Ok(()));
}

fn case() -> impl Strategy<Value = Case> {
    proptest::sample::select(CASES.to_vec())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// §7.3.5: with bit 29 = 0 the CAN-ID has 11 bits; any of bits 11..=28 set is refused,
    /// whatever bits 30 and 31 say.
    #[test]
    fn cia301_7_3_5_bits_11_to_28_need_bit_29(
        c in case(),
        high in 1u32..(1 << 18),
        low in 0u32..0x800,
        flags in proptest::sample::select(vec![0, BIT31]),
    ) {
        let mut dev = device();
        release(&mut dev, &c);
        let before = value(&mut dev, &c);
        let v = flags | high << 11 | low;
        prop_assert_eq!(write(&mut dev, &c, v), Err(AbortCode::INVALID_VALUE));
        prop_assert_eq!(value(&mut dev, &c), before);
    }

    /// §7.3.5: the restricted CAN-IDs are 11-bit ones; every 29-bit CAN-ID is accepted by
    /// an entry whose identifier is free to change.
    #[test]
    fn cia301_7_3_5_29_bit_can_ids_are_accepted(c in case(), id in 0u32..(1 << 29)) {
        let mut dev = device();
        release(&mut dev, &c);
        let v = c.free & !BIT31 | FRAME | id;
        prop_assert_eq!(write(&mut dev, &c, v), Ok(()));
        prop_assert_eq!(value(&mut dev, &c), v);
    }
}

#[test]
fn cia301_7_3_5_a_29_bit_sync_is_received_on_its_extended_identifier() {
    let mut h = booted();
    h.write(ms(1), 0x1005, 0, &(FRAME | 0x605).to_le_bytes())
        .unwrap();
    assert!(h.dev.accepts(Id::extended(0x605).unwrap()));
    let t = ms(2) + Duration::from_micros(1);
    h.rx_frame(t, &Frame::data(Id::extended(0x605).unwrap(), &[]).unwrap());
    // Still an SDO server on the 11-bit 0x605.
    h.rx(ms(3), "605#4000100000000000");
    let sent = h.take();
    assert_eq!(sent.len(), 1, "{sent:?}");
    assert!(sent[0].1.starts_with("585#43001000"), "{sent:?}");
}
