//! Property tests of the wire codecs: random input never panics, and what is formatted parses
//! back to the same frame.
#![allow(clippy::unwrap_used)]

use std::time::{Duration, UNIX_EPOCH};

use cantwin_can::{Frame, Id};
use cantwin_gateway::{slcan, socketcand};
use proptest::prelude::*;

fn any_id() -> impl Strategy<Value = Id> {
    prop_oneof![
        (0u16..=0x7FF).prop_map(|r| Id::standard(r).unwrap()),
        (0u32..=0x1FFF_FFFF).prop_map(|r| Id::extended(r).unwrap()),
    ]
}

fn any_frame() -> impl Strategy<Value = Frame> {
    prop_oneof![
        (any_id(), proptest::collection::vec(any::<u8>(), 0..=8))
            .prop_map(|(id, d)| Frame::data(id, &d).unwrap()),
        (any_id(), 0u8..=8).prop_map(|(id, dlc)| Frame::remote(id, dlc).unwrap()),
    ]
}

/// Bytes biased towards the protocols' own alphabet, so parsers get past the first check.
fn protocol_bytes() -> impl Strategy<Value = Vec<u8>> {
    let alphabet = prop_oneof![
        Just(b'<'),
        Just(b'>'),
        Just(b' '),
        Just(b'\r'),
        prop::sample::select(b"0123456789abcdefABCDEFtTrRsendopframeOCSLVNFZ".to_vec()),
        any::<u8>(),
    ];
    proptest::collection::vec(alphabet, 0..300)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn socketcand_random_input_never_panics(bytes in protocol_bytes()) {
        let _ = socketcand::wire::parse_command(&bytes);
        let _ = socketcand::wire::parse_server_message(&bytes);
        let mut framer = socketcand::wire::Framer::new(64);
        for b in bytes {
            if let Some(socketcand::wire::Framed::Element(e)) = framer.push(b) {
                prop_assert!(e.len() <= 64);
                let _ = socketcand::wire::parse_command(e);
            }
            prop_assert!(framer.pending() < 64);
        }
    }

    #[test]
    fn slcan_random_input_never_panics(bytes in protocol_bytes()) {
        let _ = slcan::wire::parse_command(&bytes);
        let _ = slcan::wire::parse_frame(&bytes);
    }

    #[test]
    fn socketcand_send_round_trips(frame in any_frame()) {
        let mut out = Vec::new();
        socketcand::wire::write_send(&mut out, &frame);
        let parsed = socketcand::wire::parse_command(&out).unwrap();
        // A remote frame of DLC 0 reads back as an empty data frame (see the wire module).
        let want = if frame.is_remote() && frame.dlc() == 0 {
            Frame::data(frame.id(), &[]).unwrap()
        } else {
            frame
        };
        prop_assert_eq!(parsed, socketcand::wire::Command::Send(want));
    }

    #[test]
    fn socketcand_frame_round_trips(frame in any_frame(), secs in 0u64..4_000_000_000, micros in 0u32..1_000_000) {
        let t = UNIX_EPOCH + Duration::new(secs, micros * 1000);
        let mut out = Vec::new();
        let written = socketcand::wire::write_frame(&mut out, &frame, t);
        prop_assert_eq!(written, !frame.is_remote());
        if written {
            prop_assert_eq!(
                socketcand::wire::parse_server_message(&out).unwrap(),
                socketcand::wire::ServerMessage::Frame { frame, timestamp: t }
            );
        }
    }

    #[test]
    fn slcan_frame_round_trips(frame in any_frame()) {
        let mut out = Vec::new();
        slcan::wire::write_frame(&mut out, &frame);
        prop_assert_eq!(out.pop(), Some(b'\r'));
        prop_assert_eq!(slcan::wire::parse_frame(&out).unwrap(), frame);
        prop_assert_eq!(
            slcan::wire::parse_command(&out).unwrap(),
            slcan::wire::Command::Transmit(frame)
        );
    }
}
