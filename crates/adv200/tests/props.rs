//! Property tests: PDC placement, random SDO requests, the CiA 402 machine, parameter
//! encoding.
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_adv200::ds402::{Ds402, State};
use cantwin_adv200::params::{ParamDb, catalog};
use cantwin_adv200::pdc::{Dir, Format, PdcFault, place};
use cantwin_can::{Frame, Instant, Node, Outbox};
use proptest::prelude::*;

fn format() -> impl Strategy<Value = Format> {
    prop_oneof![
        Just(Format::NotAssigned),
        Just(Format::Count16),
        Just(Format::Count32),
        Just(Format::Eu),
        Just(Format::Fill16),
        Just(Format::Fill32),
        Just(Format::Mdplc16),
        Just(Format::Mdplc32),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn manual_1_3_placement_invariants(
        channels in proptest::collection::vec((format(), prop_oneof![Just(0u16), 1..5000u16]), 16),
        m2s in any::<bool>(),
    ) {
        let dir = if m2s { Dir::M2S } else { Dir::S2M };
        match place(dir, &channels) {
            Ok(layout) => {
                prop_assert!(layout.pdos.len() <= 4);
                let mut last = 0;
                for pdo in &layout.pdos {
                    let bits: u32 = pdo.iter().map(|i| u32::from(i.bits)).sum();
                    prop_assert!(bits <= 64, "a PDO holds at most 4 words");
                    prop_assert!(!pdo.is_empty());
                    for item in pdo {
                        prop_assert!(item.channel > last, "channel order");
                        last = item.channel;
                        let (f, _) = channels[usize::from(item.channel) - 1];
                        prop_assert_eq!(item.bits, f.bits());
                    }
                }
                let end = channels.iter().position(|c| c.0 == Format::NotAssigned);
                if let Some(end) = end {
                    prop_assert!(usize::from(last) <= end, "nothing after Not assigned");
                }
            }
            Err(e) => {
                let (n, straddle) = match e {
                    PdcFault::M2sSize(n) if m2s => (n, true),
                    PdcFault::S2mSize(n) if !m2s => (n, true),
                    PdcFault::M2sTooManyWords(n) if m2s => (n, false),
                    PdcFault::S2mTooManyWords(n) if !m2s => (n, false),
                    other => return Err(TestCaseError::fail(format!("placement gave {other:?}"))),
                };
                prop_assert!((1..=16).contains(&n));
                if straddle {
                    prop_assert_eq!(channels[usize::from(n) - 1].0.bits(), 32, "only 32-bit items straddle");
                }
            }
        }
    }

    #[test]
    fn manual_1_4_random_sdo_requests_get_at_most_one_answer(data in proptest::array::uniform8(any::<u8>()), len in 0usize..=8) {
        let mut h = common::H::canopen(|_| {});
        let mut out = Outbox::new();
        let frame = Frame::std(0x60C, &data[..len]).unwrap();
        h.d.on_frame(&frame, Instant::from_nanos(common::MS), &mut out);
        let answers: Vec<_> = out.frames().iter().filter(|f| f.id().as_raw() == 0x58C).collect();
        prop_assert!(answers.len() <= 1);
        for a in answers {
            prop_assert_eq!(a.len(), 8);
        }
    }

    #[test]
    fn cia402_status_word_always_names_the_state(
        words in proptest::collection::vec(any::<u16>(), 1..40),
        faults in proptest::collection::vec(any::<bool>(), 40),
    ) {
        let mut m = Ds402::new();
        for (i, cw) in words.iter().enumerate() {
            let fault = faults[i] && i % 7 == 3;
            m.update(*cw, fault, true);
            let sw = m.statusword(false);
            let want = match m.state() {
                State::NotReadyToSwitchOn => (0x4F, 0x00),
                State::SwitchOnDisabled => (0x4F, 0x40),
                State::ReadyToSwitchOn => (0x6F, 0x21),
                State::SwitchedOn => (0x6F, 0x23),
                State::OperationEnabled => (0x6F, 0x27),
                State::QuickStopActive => (0x6F, 0x07),
                State::FaultReactionActive => (0x4F, 0x0F),
                State::Fault => (0x4F, 0x08),
            };
            prop_assert_eq!(sw & want.0, want.1);
            prop_assert!(m.state() != State::NotReadyToSwitchOn);
            if fault {
                prop_assert_eq!(m.state(), State::Fault);
            }
        }
    }

    #[test]
    fn manual_1_4_parameter_values_round_trip(i in 0usize..1000, v in any::<i64>()) {
        let c = catalog();
        let d = &c[i % c.len()];
        let mut db = ParamDb::new();
        let v = d.min + (v.rem_euclid(d.max - d.min + 1));
        if db.force(d.par, v).is_ok() {
            let (bytes, len) = db.encode(d.par).unwrap();
            prop_assert_eq!(ParamDb::decode(d.par, &bytes[..len]).unwrap(), v);
        }
    }
}
