//! can-utils `candump -l` log files.
//!
//! One line per frame (can-utils `candump.c` and `lib.c`):
//!
//! ```text
//! (1700000000.000123) can0 123#DEADBEEF
//! (1700000000.000124) can0 12345678#R4
//! (1700000000.000125) can0 20000004#0004000000000000
//! ```
//!
//! The timestamp is `seconds.microseconds` (10 and 6 digits). The frame is `ID#DATA`: a
//! standard identifier as 3 hex digits, an extended one as 8; data as upper-case hex pairs;
//! a remote frame as `R` followed by its DLC when not 0. An error frame is an 8-digit
//! identifier with `CAN_ERR_FLAG` (0x20000000) set, its class in the low bits, and 8 data
//! bytes.
//!
//! The writer writes exactly that, with no trailing direction flag (Wireshark 4.0 refuses
//! lines ending in ` T` / ` R`). The reader also accepts lower-case hex, `.` between data
//! bytes, a `_<dlc>` suffix (len8_dlc, ignored), a trailing ` T` or ` R`, a timestamp with
//! up to 9 fractional digits, blank lines, and `\r\n` line ends. CAN FD (`ID##...`) and CAN
//! XL (`...#...#...`) lines are skipped and counted ([`CandumpReader::skipped`]).

use crate::error::{Error, Result};
use crate::io_util::{next_record, writer_plumbing};
use crate::record::{ErrorFrame, Event, Record};
use crate::socketcan::{EFF_FLAG, ERR_FLAG, ID_MASK, RTR_FLAG};
use cantwin_can::{Frame, Id};
use core::fmt::Write as _;
use std::io::{BufRead, Read, Write};

/// Longest line the reader accepts; a longer one (no newline in a binary file, say) is an
/// error rather than an unbounded allocation.
pub const MAX_LINE_LEN: usize = 4096;

/// Formats one record as a candump log line, without the line end.
///
/// Fails with [`Error::BadChannel`] if the channel is empty or contains white space, which
/// the line format cannot carry.
pub fn format_line(record: &Record) -> Result<String> {
    check_channel(&record.channel)?;
    let secs = record.timestamp_ns / 1_000_000_000;
    let micros = record.timestamp_ns % 1_000_000_000 / 1_000;
    let mut s = String::with_capacity(48);
    // Writing into a String cannot fail.
    let _ = write!(s, "({secs:010}.{micros:06}) {} ", record.channel);
    push_frame(&mut s, &record.event);
    Ok(s)
}

fn check_channel(channel: &str) -> Result<()> {
    if channel.is_empty() {
        return Err(Error::BadChannel(channel.to_owned(), "empty"));
    }
    if channel.chars().any(char::is_whitespace) {
        return Err(Error::BadChannel(
            channel.to_owned(),
            "white space separates the fields of a candump line",
        ));
    }
    Ok(())
}

/// Appends the compact `ID#DATA` form of an event.
pub(crate) fn push_frame(s: &mut String, event: &Event) {
    match event {
        Event::Frame(frame) => {
            let _ = match frame.id() {
                Id::Standard(id) => write!(s, "{:03X}#", id.as_raw()),
                Id::Extended(id) => write!(s, "{:08X}#", id.as_raw()),
            };
            if frame.is_remote() {
                s.push('R');
                if frame.dlc() > 0 {
                    let _ = write!(s, "{}", frame.dlc());
                }
            } else {
                for b in frame.data_bytes() {
                    let _ = write!(s, "{b:02X}");
                }
            }
        }
        Event::Error(err) => {
            let _ = write!(s, "{:08X}#", ERR_FLAG | err.class());
            for b in err.data() {
                let _ = write!(s, "{b:02X}");
            }
        }
    }
}

/// Writes a candump log, one line per record.
#[derive(Debug)]
pub struct CandumpWriter<W: Write> {
    out: W,
}

impl<W: Write> CandumpWriter<W> {
    /// A writer; the format has no header.
    pub fn new(out: W) -> Self {
        CandumpWriter { out }
    }

    /// Appends one line. Timestamps are truncated to microseconds.
    pub fn write_record(&mut self, record: &Record) -> Result<()> {
        let mut line = format_line(record)?;
        line.push('\n');
        self.out.write_all(line.as_bytes())?;
        Ok(())
    }
}

writer_plumbing!(CandumpWriter);

/// What one line holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Line {
    /// A classic CAN frame or an error frame.
    Record(Record),
    /// A CAN FD or CAN XL frame, which [`Frame`] cannot hold.
    NotClassic,
    /// Nothing (a blank line).
    Blank,
}

/// Parses one line (without its line end); the error is the reason, without line number.
pub fn parse_line(line: &str) -> Result<Line, String> {
    let line = line.trim();
    if line.is_empty() {
        return Ok(Line::Blank);
    }
    let rest = line
        .strip_prefix('(')
        .ok_or("expected `(` opening the timestamp")?;
    let (ts, rest) = rest
        .split_once(')')
        .ok_or("expected `)` closing the timestamp")?;
    let timestamp_ns = parse_timestamp(ts)?;
    let mut fields = rest.split_whitespace();
    let channel = fields.next().ok_or("missing channel name")?;
    let frame = fields.next().ok_or("missing frame")?;
    match (fields.next(), fields.next()) {
        (None, _) | (Some("T" | "R"), None) => {}
        (Some(extra), _) => return Err(format!("unexpected text after the frame: {extra:?}")),
    }
    let (id, data) = frame
        .split_once('#')
        .ok_or_else(|| format!("frame {frame:?} has no `#`"))?;
    if data.contains('#') {
        // `ID##...` is CAN FD, `...#...#...` CAN XL.
        return Ok(Line::NotClassic);
    }
    let event = parse_frame(id, data).map_err(|e| format!("frame {frame:?}: {e}"))?;
    Ok(Line::Record(Record {
        timestamp_ns,
        channel: channel.to_owned(),
        event,
    }))
}

fn parse_timestamp(ts: &str) -> Result<u64, String> {
    let bad = || format!("bad timestamp {ts:?}");
    let (secs, frac) = ts.split_once('.').ok_or_else(bad)?;
    if secs.is_empty()
        || frac.is_empty()
        || frac.len() > 9
        || !secs.bytes().all(|b| b.is_ascii_digit())
        || !frac.bytes().all(|b| b.is_ascii_digit())
    {
        return Err(bad());
    }
    let scale = 10u64.pow(9 - frac.len() as u32);
    let secs: u64 = secs.parse().map_err(|_| bad())?;
    let frac_ns = frac.parse::<u64>().map_err(|_| bad())? * scale;
    secs.checked_mul(1_000_000_000)
        .and_then(|ns| ns.checked_add(frac_ns))
        .ok_or_else(|| format!("timestamp {ts:?} beyond the year 2554"))
}

fn parse_hex_u32(s: &str) -> Result<u32, String> {
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(format!("{s:?} is not hexadecimal"));
    }
    u32::from_str_radix(s, 16).map_err(|e| e.to_string())
}

fn parse_frame(id: &str, data: &str) -> Result<Event, String> {
    enum Kind {
        Standard(u16),
        Extended(u32),
        Error(u32),
    }
    let raw = parse_hex_u32(id)?;
    let kind = match id.len() {
        3 => Kind::Standard(u16::try_from(raw).map_err(|e| e.to_string())?),
        8 if raw & ERR_FLAG != 0 && raw & (EFF_FLAG | RTR_FLAG) == 0 => Kind::Error(raw & ID_MASK),
        8 if raw & !ID_MASK == 0 => Kind::Extended(raw),
        8 => {
            return Err(format!(
                "identifier {id} has flag bits other than CAN_ERR_FLAG"
            ));
        }
        n => return Err(format!("identifier of {n} digits (3 or 8 expected)")),
    };
    let frame_id = match kind {
        Kind::Standard(raw) => Id::standard(raw).map_err(|e| e.to_string())?,
        Kind::Extended(raw) => Id::extended(raw).map_err(|e| e.to_string())?,
        Kind::Error(class) => {
            let bytes = parse_data(data)?;
            let mut d = [0u8; 8];
            d[..bytes.len()].copy_from_slice(&bytes);
            let err = ErrorFrame::new(class, d).map_err(|e| e.to_string())?;
            return Ok(Event::Error(err));
        }
    };
    if let Some(dlc) = data.strip_prefix(['R', 'r']) {
        // `R`, `R<dlc>`, optionally with a `_<len8_dlc>` suffix, which Frame cannot keep.
        let dlc = dlc.split_once('_').map_or(dlc, |(d, _)| d);
        let dlc = match dlc {
            "" => 0,
            d if d.len() == 1 && d.as_bytes()[0].is_ascii_digit() => d.as_bytes()[0] - b'0',
            d => return Err(format!("bad remote frame length {d:?}")),
        };
        return Frame::remote(frame_id, dlc)
            .map(Event::Frame)
            .map_err(|e| e.to_string());
    }
    let bytes = parse_data(data)?;
    Frame::data(frame_id, &bytes)
        .map(Event::Frame)
        .map_err(|e| e.to_string())
}

/// Hex byte pairs, optionally separated by `.`, optionally followed by `_<len8_dlc>`.
fn parse_data(data: &str) -> Result<Vec<u8>, String> {
    let data = match data.split_once('_') {
        Some((d, dlc)) if dlc.len() == 1 && dlc.as_bytes()[0].is_ascii_hexdigit() => d,
        Some((_, dlc)) => return Err(format!("bad len8_dlc suffix {dlc:?}")),
        None => data,
    };
    let digits: Vec<u8> = data.bytes().filter(|&b| b != b'.').collect();
    if digits.len() % 2 != 0 {
        return Err("odd number of hex digits in the data".into());
    }
    if digits.len() > 16 {
        return Err(format!("{} data bytes (at most 8)", digits.len() / 2));
    }
    digits
        .chunks(2)
        .map(|p| {
            let hi = (p[0] as char).to_digit(16);
            let lo = (p[1] as char).to_digit(16);
            match (hi, lo) {
                (Some(h), Some(l)) => Ok((h * 16 + l) as u8),
                _ => Err(format!(
                    "{:?} is not a hex byte",
                    String::from_utf8_lossy(p)
                )),
            }
        })
        .collect()
}

/// Reads a candump log line by line.
#[derive(Debug)]
pub struct CandumpReader<R: BufRead> {
    input: R,
    line: u64,
    skipped: u64,
    buf: Vec<u8>,
    done: bool,
}

impl<R: BufRead> CandumpReader<R> {
    /// A reader; the format has no header.
    pub fn new(input: R) -> Self {
        CandumpReader {
            input,
            line: 0,
            skipped: 0,
            buf: Vec::new(),
            done: false,
        }
    }

    /// How many CAN FD / CAN XL lines were skipped so far.
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    /// The number of lines read so far.
    pub fn line_number(&self) -> u64 {
        self.line
    }

    fn error(&self, reason: impl Into<String>) -> Error {
        Error::Line {
            line: self.line,
            reason: reason.into(),
        }
    }

    /// The next record, `None` at the end of the file.
    pub fn read_record(&mut self) -> Result<Option<Record>> {
        loop {
            self.buf.clear();
            let limit = MAX_LINE_LEN as u64 + 1;
            let n = Read::take(self.input.by_ref(), limit).read_until(b'\n', &mut self.buf)?;
            if n == 0 {
                return Ok(None);
            }
            self.line += 1;
            if self.buf.len() > MAX_LINE_LEN {
                return Err(self.error(format!("line longer than {MAX_LINE_LEN} bytes")));
            }
            let text = std::str::from_utf8(&self.buf).map_err(|_| self.error("not UTF-8 text"))?;
            match parse_line(text).map_err(|e| self.error(e))? {
                Line::Record(r) => return Ok(Some(r)),
                Line::NotClassic => self.skipped += 1,
                Line::Blank => {}
            }
        }
    }
}

impl<R: BufRead> Iterator for CandumpReader<R> {
    type Item = Result<Record>;

    /// Records until the end of the file or the first error (then nothing more).
    fn next(&mut self) -> Option<Self::Item> {
        next_record(self, |r| &mut r.done, Self::read_record)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamp_fraction_digits_scale() {
        assert_eq!(parse_timestamp("1.5"), Ok(1_500_000_000));
        assert_eq!(parse_timestamp("0.000000001"), Ok(1));
        assert!(parse_timestamp("1.0000000001").is_err());
        assert!(parse_timestamp("-1.0").is_err());
        assert!(parse_timestamp("99999999999999999999.0").is_err());
    }
}
