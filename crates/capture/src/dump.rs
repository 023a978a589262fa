//! Plain one-line-per-record listing of a capture, for `cantwin dump FILE`.

use crate::CaptureReader;
use crate::candump::push_frame;
use crate::error::Result;
use crate::record::{Event, Record};
use core::fmt::Write as _;
use std::io::{BufRead, Write};

/// Formats one record:
///
/// ```text
/// 1700000000.000123000  can0  123#DEADBEEF           [4]
/// 1700000000.000124000  can0  12345678#R4            [4]  remote
/// 1700000000.000125000  can0  20000044#0004000000000000 [8]  error: controller-problem|bus-off
/// ```
///
/// Seconds and nanoseconds since the Unix epoch, the channel, the frame in candump notation,
/// the DLC in brackets, and what kind of frame it is when not a data frame.
pub fn format_record(record: &Record) -> String {
    let secs = record.timestamp_ns / 1_000_000_000;
    let nanos = record.timestamp_ns % 1_000_000_000;
    let mut frame = String::with_capacity(32);
    push_frame(&mut frame, &record.event);
    let mut s = String::with_capacity(80);
    let _ = write!(s, "{secs}.{nanos:09}  {}  {frame:<22} ", record.channel);
    match &record.event {
        Event::Frame(f) => {
            let _ = write!(s, "[{}]", f.dlc());
            if f.is_remote() {
                s.push_str("  remote");
            }
        }
        Event::Error(e) => {
            let _ = write!(s, "[8]  error: {e}");
        }
    }
    s
}

/// What [`dump`] went through.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DumpSummary {
    /// Records listed.
    pub records: u64,
    /// CAN FD / CAN XL frames skipped.
    pub skipped: u64,
}

/// Lists every record of `reader` on `out`, one per line, then a line counting skipped CAN FD
/// frames if there were any. Stops at the first error, after listing what came before it.
pub fn dump<R: BufRead, W: Write>(
    reader: &mut CaptureReader<R>,
    out: &mut W,
) -> Result<DumpSummary> {
    let mut summary = DumpSummary::default();
    while let Some(record) = reader.read_record()? {
        writeln!(out, "{}", format_record(&record))?;
        summary.records += 1;
    }
    summary.skipped = reader.skipped();
    if summary.skipped > 0 {
        writeln!(out, "# {} CAN FD / CAN XL frames skipped", summary.skipped)?;
    }
    Ok(summary)
}
