//! Every writer hands each record (and each header or interface block) to its output in one
//! `write`, so a buffered capture that is flushed, or a process killed between two writes,
//! leaves a file that ends on a whole record: any prefix of the writes reads back as a prefix
//! of the records. `cantwin sim` relies on this to lose at most its last second on SIGKILL.
#![allow(clippy::unwrap_used)]

use std::io::Write;
use std::sync::{Arc, Mutex};

use cantwin_can::Frame;
use cantwin_capture::{CaptureReader, Format, Record};

/// An output that keeps each `write` call's bytes apart.
#[derive(Clone, Default)]
struct Calls(Arc<Mutex<Vec<Vec<u8>>>>);

impl Write for Calls {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().push(buf.to_vec());
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

fn records(channels: &[&str]) -> Vec<Record> {
    (0..12u16)
        .map(|i| {
            let frame = Frame::std(0x180 + i, &[i as u8; 5][..usize::from(i % 6)]).unwrap();
            let channel = channels[usize::from(i) % channels.len()];
            Record::new(
                1_700_000_000_000_000_000 + u64::from(i) * 1_000_123_000,
                channel,
                frame,
            )
        })
        .collect()
}

#[test]
fn any_prefix_of_the_writes_reads_back_as_a_prefix_of_the_records() {
    for (format, channels) in [
        (Format::Pcap, &["can0"][..]),
        (Format::Pcapng, &["can0", "can1"][..]),
        (Format::Candump, &["can0", "can1"][..]),
    ] {
        let written = records(channels);
        let calls = Calls::default();
        let mut w = cantwin_capture::writer(format, calls.clone()).unwrap();
        for r in &written {
            w.write_record(r).unwrap();
        }
        w.flush().unwrap();
        drop(w);
        let calls = calls.0.lock().unwrap().clone();
        // One write per record, and the file header or interface blocks in writes of their own.
        assert!(
            calls.len() >= written.len(),
            "{format:?}: {} writes",
            calls.len()
        );
        let mut file = Vec::new();
        for (k, call) in calls.iter().enumerate() {
            file.extend_from_slice(call);
            let read: Vec<Record> = CaptureReader::new(file.as_slice())
                .unwrap_or_else(|e| panic!("{format:?} cut after write {k}: {e}"))
                .collect::<Result<_, _>>()
                .unwrap_or_else(|e| panic!("{format:?} cut after write {k}: {e}"));
            assert_eq!(
                read,
                written[..read.len()],
                "{format:?} cut after write {k}"
            );
        }
        let all: Vec<Record> = CaptureReader::new(file.as_slice())
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(all, written, "{format:?}");
    }
}
