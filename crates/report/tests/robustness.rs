//! Any capture, however malformed, gives a report and a page, never a panic.
#![allow(clippy::unwrap_used)]

use cantwin_can::{Frame, Id};
use cantwin_capture::Record;
use cantwin_report::{Options, Protocol, analyse, render_html};
use proptest::prelude::*;

fn record() -> impl Strategy<Value = Record> {
    (
        0u64..5_000_000_000,
        // Concentrate on the CANopen SDO, NMT and error-control identifiers of a few nodes.
        prop_oneof![
            (0u16..0x800),
            (0x580u16..0x588),
            (0x600u16..0x608),
            (0x700u16..0x708),
        ],
        proptest::collection::vec(any::<u8>(), 0..=8),
        0usize..3,
    )
        .prop_map(|(t, id, data, ch)| {
            let frame = Frame::data(Id::standard(id).unwrap(), &data).unwrap();
            Record::new(t, ["can0", "dnet", "cal"][ch], frame)
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_traffic_never_panics(records in proptest::collection::vec(record(), 0..200)) {
        let mut opts = Options { max_timeline: 50, ..Options::default() };
        opts.protocols.insert("dnet".into(), Protocol::DeviceNet);
        opts.protocols.insert("cal".into(), Protocol::Cal);
        let report = analyse(&records, &opts);
        let frames: u64 = report.channels.iter().map(|c| c.frames).sum();
        prop_assert_eq!(frames, records.len() as u64);
        prop_assert!(report.timeline.len() <= 50);
        prop_assert!(report.timeline.windows(2).all(|w| w[0].t_ns <= w[1].t_ns));
        let html = render_html(&report);
        prop_assert!(html.ends_with("</html>\n"));
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// CiA 305 §4.2: every frame on the LSS identifiers gets a line (a message, or why it is
    /// none), and the listing decoder takes any frame of any protocol without panicking.
    #[test]
    fn lss_identifiers_always_get_a_line_and_the_decoder_never_panics(
        frames in proptest::collection::vec(
            (prop_oneof![Just(0x7E4u16), Just(0x7E5u16), 0u16..0x800],
             proptest::collection::vec(any::<u8>(), 0..=8), 0usize..3),
            0..100,
        )
    ) {
        let mut opts = Options::default();
        opts.protocols.insert("dnet".into(), Protocol::DeviceNet);
        opts.protocols.insert("cal".into(), Protocol::Cal);
        let mut decoder = cantwin_report::Decoder::new(&opts);
        for (id, data, ch) in frames {
            let frame = Frame::data(Id::standard(id).unwrap(), &data).unwrap();
            if id == 0x7E4 || id == 0x7E5 {
                let line = cantwin_report::lss::describe(&frame).unwrap();
                prop_assert!(line.starts_with("LSS "), "{}", line);
            }
            let _ = decoder.describe(["can0", "dnet", "cal"][ch], &frame);
        }
    }
}
