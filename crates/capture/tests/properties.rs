//! Property tests: every record survives a round trip through each format, and no input,
//! however broken, makes a reader panic.
#![allow(clippy::unwrap_used)]

use cantwin_can::{Frame, Id};
use cantwin_capture::candump::{CandumpReader, CandumpWriter};
use cantwin_capture::pcap::{PcapReader, PcapWriter, Resolution};
use cantwin_capture::pcapng::{PcapngReader, PcapngWriter};
use cantwin_capture::{CaptureReader, ErrorFrame, Event, Record};
use proptest::prelude::*;

fn event() -> impl Strategy<Value = Event> {
    let id = prop_oneof![
        (0u16..=0x7FF).prop_map(|i| Id::standard(i).unwrap()),
        (0u32..=0x1FFF_FFFF).prop_map(|i| Id::extended(i).unwrap()),
    ];
    prop_oneof![
        4 => (id.clone(), proptest::collection::vec(any::<u8>(), 0..=8))
            .prop_map(|(id, d)| Event::Frame(Frame::data(id, &d).unwrap())),
        1 => (id, 0u8..=8).prop_map(|(id, dlc)| Event::Frame(Frame::remote(id, dlc).unwrap())),
        1 => (0u32..=ErrorFrame::CLASS_MASK, any::<[u8; 8]>())
            .prop_map(|(c, d)| Event::Error(ErrorFrame::new(c, d).unwrap())),
    ]
}

/// Records with timestamps in the pcap range (seconds fit in u32) and `unit`-aligned.
fn records(channels: &'static [&'static str], unit: u64) -> impl Strategy<Value = Vec<Record>> {
    let max = u64::from(u32::MAX) * 1_000_000_000 / unit;
    proptest::collection::vec(
        (0..=max, proptest::sample::select(channels), event())
            .prop_map(move |(t, c, e)| Record::new(t * unit, c, e)),
        0..40,
    )
}

fn pcap_bytes(records: &[Record], res: Resolution) -> Vec<u8> {
    let mut w = PcapWriter::with_resolution(Vec::new(), res).unwrap();
    for r in records {
        w.write_record(r).unwrap();
    }
    w.into_inner()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn pcap_nanosecond_round_trip(recs in records(&["can0"], 1)) {
        let back: Vec<Record> = PcapReader::new(pcap_bytes(&recs, Resolution::Nano).as_slice())
            .unwrap().collect::<Result<_, _>>().unwrap();
        prop_assert_eq!(back, recs);
    }

    #[test]
    fn pcap_microsecond_round_trip(recs in records(&["can0"], 1_000)) {
        let back: Vec<Record> = PcapReader::new(pcap_bytes(&recs, Resolution::Micro).as_slice())
            .unwrap().collect::<Result<_, _>>().unwrap();
        prop_assert_eq!(back, recs);
    }

    #[test]
    fn pcapng_round_trip(recs in records(&["can0", "can1", "vcan2", "bus name"], 1), late in any::<u64>()) {
        let mut recs = recs;
        recs.push(Record::new(late, "can1", Frame::std(1, &[]).unwrap()));
        let mut w = PcapngWriter::new(Vec::new()).unwrap();
        for r in &recs {
            w.write_record(r).unwrap();
        }
        let back: Vec<Record> = PcapngReader::new(w.into_inner().as_slice())
            .unwrap().collect::<Result<_, _>>().unwrap();
        prop_assert_eq!(back, recs);
    }

    #[test]
    fn candump_round_trip(recs in records(&["can0", "can1", "vcan-2"], 1_000)) {
        let mut w = CandumpWriter::new(Vec::new());
        for r in &recs {
            w.write_record(r).unwrap();
        }
        let back: Vec<Record> = CandumpReader::new(w.into_inner().as_slice())
            .collect::<Result<_, _>>().unwrap();
        prop_assert_eq!(back, recs);
    }

    /// Any bytes: detection, then reading to the end or to the first error, never panics.
    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        if let Ok(r) = CaptureReader::new(bytes.as_slice()) {
            for item in r {
                if item.is_err() {
                    break;
                }
            }
        }
    }

    /// A valid file with bytes flipped or cut: each reader errors or reads on, never panics.
    #[test]
    fn corrupted_files_never_panic(
        recs in records(&["can0", "can1"], 1_000),
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
        cut in any::<prop::sample::Index>(),
        which in 0usize..3,
    ) {
        let mut bytes = match which {
            0 => pcap_bytes(&recs.iter().map(|r| Record { channel: "can0".into(), ..r.clone() }).collect::<Vec<_>>(), Resolution::Nano),
            1 => {
                let mut w = PcapngWriter::new(Vec::new()).unwrap();
                for r in &recs {
                    w.write_record(r).unwrap();
                }
                w.into_inner()
            }
            _ => {
                let mut w = CandumpWriter::new(Vec::new());
                for r in &recs {
                    w.write_record(r).unwrap();
                }
                w.into_inner()
            }
        };
        for (at, v) in flips {
            if bytes.is_empty() {
                break;
            }
            let i = at.index(bytes.len());
            bytes[i] = v;
        }
        bytes.truncate(cut.index(bytes.len() + 1));
        if let Ok(r) = CaptureReader::new(bytes.as_slice()) {
            for item in r {
                if item.is_err() {
                    break;
                }
            }
        }
    }

    /// Random text lines into the candump reader never panic.
    #[test]
    fn random_candump_lines_never_panic(line in "\\(?[0-9.]{0,22}\\)? ?[a-z0-9]{0,5} ?[0-9A-Fa-f#Rr_.]{0,24}( [TR])?") {
        let _ = cantwin_capture::candump::parse_line(&line);
    }
}
