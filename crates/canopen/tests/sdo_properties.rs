//! Property tests of the SDO server and the object dictionary.
#![allow(clippy::unwrap_used)]

mod sdo_harness;

use cantwin_can::Duration;
use cantwin_canopen::od::{DataType, ObjectDictionary, TimeOfDay, Value};
use cantwin_canopen::sdo::wire::Response;
use proptest::prelude::*;
use sdo_harness::*;
use std::sync::Arc;

/// Request frames biased towards the interesting ones: real command bytes, real indices.
fn request() -> impl Strategy<Value = [u8; 8]> {
    let cmd = prop_oneof![
        Just(0x40u8),
        Just(0x60),
        Just(0x70),
        Just(0x21),
        Just(0x20),
        Just(0x23),
        Just(0x2B),
        Just(0x2F),
        Just(0x22),
        Just(0x00),
        Just(0x10),
        Just(0x01),
        Just(0x11),
        Just(0x0D),
        Just(0xC6),
        Just(0xC2),
        Just(0xC1),
        Just(0xD9),
        Just(0xA4),
        Just(0xA0),
        Just(0xA3),
        Just(0xA2),
        Just(0xA1),
        Just(0x80),
        Just(0x81),
        Just(0x82),
        Just(0xFF),
        any::<u8>(),
    ];
    let index = prop_oneof![
        Just(0x1000u16),
        Just(0x1008),
        Just(0x1017),
        Just(0x1018),
        Just(0x2000),
        Just(0x2002),
        Just(0x2003),
        Just(0x2004),
        Just(0x2006),
        Just(0x2009),
        Just(0x5000),
        any::<u16>(),
    ];
    (cmd, index, 0u8..4, any::<[u8; 4]>()).prop_map(|(c, i, s, d)| {
        let i = i.to_le_bytes();
        [c, i[0], i[1], s, d[0], d[1], d[2], d[3]]
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Random frame sequences never panic the server; while no transfer is in progress
    /// every request except a client abort gets exactly one well-formed answer; every
    /// abort the server sends is a code of CiA 301 table 22 and leaves it idle.
    #[test]
    fn random_frame_sequences_get_an_answer_or_an_abort(
        steps in proptest::collection::vec((request(), 0u64..1_500), 1..60),
    ) {
        let mut h = Harness::new();
        h.server.set_block_size(4);
        for (b, ms) in steps {
            h.advance(Duration::from_millis(ms));
            let timed_out = h.tick();
            prop_assert!(timed_out.len() <= 1);
            let was_idle = h.server.is_idle();
            let answers = h.req(b);
            if was_idle {
                if b[0] >> 5 == 4 {
                    prop_assert!(answers.is_empty());
                } else {
                    prop_assert_eq!(answers.len(), 1);
                    prop_assert!(Response::decode(&answers[0]).is_ok());
                }
            }
            prop_assert!(answers.len() <= 4);
            if let Some(last) = answers.last()
                && let Ok(Response::Abort { code, .. }) = Response::decode(last)
                && last[0] == 0x80
            {
                prop_assert!(code.is_known());
                prop_assert!(h.server.is_idle());
                prop_assert_eq!(h.server.next_deadline(), None);
            }
        }
    }
}

fn value() -> impl Strategy<Value = Value> {
    prop_oneof![
        any::<bool>().prop_map(Value::Boolean),
        any::<i8>().prop_map(Value::Integer8),
        any::<i16>().prop_map(Value::Integer16),
        (-(1i32 << 23)..(1i32 << 23)).prop_map(Value::Integer24),
        any::<i32>().prop_map(Value::Integer32),
        (-(1i64 << 39)..(1i64 << 39)).prop_map(Value::Integer40),
        (-(1i64 << 47)..(1i64 << 47)).prop_map(Value::Integer48),
        (-(1i64 << 55)..(1i64 << 55)).prop_map(Value::Integer56),
        any::<i64>().prop_map(Value::Integer64),
        any::<u8>().prop_map(Value::Unsigned8),
        any::<u16>().prop_map(Value::Unsigned16),
        (0u32..(1 << 24)).prop_map(Value::Unsigned24),
        any::<u32>().prop_map(Value::Unsigned32),
        (0u64..(1 << 40)).prop_map(Value::Unsigned40),
        (0u64..(1 << 48)).prop_map(Value::Unsigned48),
        (0u64..(1 << 56)).prop_map(Value::Unsigned56),
        any::<u64>().prop_map(Value::Unsigned64),
        any::<f32>().prop_map(Value::Real32),
        any::<f64>().prop_map(Value::Real64),
        "[ -~]{0,30}".prop_map(Value::VisibleString),
        proptest::collection::vec(any::<u8>(), 0..40).prop_map(Value::OctetString),
        proptest::collection::vec(any::<u16>(), 0..20).prop_map(Value::UnicodeString),
        proptest::collection::vec(any::<u8>(), 0..100).prop_map(Value::Domain),
        (0..=TimeOfDay::MS_MAX, any::<u16>())
            .prop_map(|(ms, days)| Value::TimeOfDay(TimeOfDay { ms, days })),
        (0..=TimeOfDay::MS_MAX, any::<u16>())
            .prop_map(|(ms, days)| Value::TimeDifference(TimeOfDay { ms, days })),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// CiA 301 §7.1.6: a value of any basic type written by SDO reads back with the same
    /// bytes, and decodes to the same typed value.
    #[test]
    fn od_reads_after_writes_round_trip_every_data_type(v in value()) {
        let ty = v.data_type();
        let od = ObjectDictionary::new(Arc::new(every_type_description()), NODE);
        let mut h = Harness::with(od);
        let index = 0x4000 + ty.index();
        let bytes = v.to_le_bytes();
        h.download(index, 0, &bytes).unwrap();
        let back = h.upload(index, 0).unwrap();
        prop_assert_eq!(&back, &bytes);
        let decoded = Value::from_le_bytes(ty, &back).unwrap();
        prop_assert_eq!(decoded.to_le_bytes(), bytes);
        if !matches!(ty, DataType::Real32 | DataType::Real64) {
            prop_assert_eq!(h.access.get(index, 0).unwrap(), v.clone());
            // Display and parse round-trip too (the CLI form).
            if ty != DataType::UnicodeString {
                prop_assert_eq!(Value::parse(ty, &v.to_string()).unwrap(), v);
            }
        }
    }

    /// Block download then block upload, any length, block size and CRC use.
    #[test]
    fn block_transfers_round_trip(len in 0usize..1200, blksize in 1u8..=127, server_blksize in 1u8..=127, crc: bool) {
        let mut h = Harness::new();
        h.server.set_block_size(server_blksize);
        let data = pattern(len);
        h.block_download(0x2003, 0, &data, crc).unwrap();
        let (back, _) = h.block_upload(0x2003, 0, blksize, crc).unwrap();
        prop_assert_eq!(back, data);
    }
}
