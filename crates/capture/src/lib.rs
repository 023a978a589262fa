//! CAN captures: pcap and pcapng with LINKTYPE_CAN_SOCKETCAN, and can-utils candump logs.
//!
//! A capture is a sequence of [`Record`]s: a wall-clock timestamp in nanoseconds since the
//! Unix epoch, a channel (bus) name and an [`Event`] — a classic CAN data or remote
//! [`Frame`](cantwin_can::Frame), or a SocketCAN [`ErrorFrame`].
//!
//! * [`pcap`]: classic pcap, link type 227, micro- or nanosecond timestamps, either byte
//!   order; one channel per file (the format has no channel field).
//! * [`pcapng`]: one interface per channel (`if_name`), nanosecond timestamps.
//! * [`candump`]: the `candump -l` text log, `(1700000000.000123) can0 123#DEADBEEF`.
//!
//! Writers write to any [`std::io::Write`] and share the [`CaptureWriter`] trait, so a bus tap
//! or a gateway can record into any format ([`create`] picks it from the file name);
//! [`bus_tap::record_of`] turns a bus event into the record a tap writes. Readers
//! stream from any [`std::io::Read`]; [`CaptureReader`] (and [`open`], [`read_all`]) tells the
//! format from the first bytes. Bad input is an [`Error`] with a byte offset or line number,
//! never a panic, and no length field makes a reader allocate more than a fixed bound.
//! CAN FD and CAN XL frames, which [`Frame`](cantwin_can::Frame) cannot hold, are skipped and
//! counted ([`CaptureReader::skipped`]).
//!
//! ```
//! use cantwin_can::{Frame, Id};
//! use cantwin_capture::{CaptureReader, CaptureWriter, Record, pcap::PcapWriter};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let frame = Frame::data(Id::standard(0x181)?, &[0x01, 0x02])?;
//! let record = Record::new(1_700_000_000_000_123_456, "can0", frame);
//!
//! let mut file = Vec::new();
//! let mut writer = PcapWriter::new(&mut file)?;
//! writer.write_record(&record)?;
//! writer.flush()?;
//!
//! let reader = CaptureReader::new(file.as_slice())?;
//! let records: Vec<Record> = reader.collect::<Result<_, _>>()?;
//! assert_eq!(records, [record.clone()]);
//! assert_eq!(
//!     cantwin_capture::format_record(&record),
//!     "1700000000.000123456  can0  181#0102               [2]"
//! );
//! # Ok(())
//! # }
//! ```
#![forbid(unsafe_code)]

pub mod bus_tap;
pub mod candump;
mod dump;
mod error;
#[doc(hidden)]
pub mod fuzz;
mod io_util;
pub mod pcap;
pub mod pcapng;
mod record;
mod socketcan;

pub use dump::{DumpSummary, dump, format_record};
pub use error::{Error, Format, Result};
pub use record::{ErrorClassError, ErrorFrame, Event, Record, error_class};

use candump::{CandumpReader, CandumpWriter};
use io_util::next_record;
use pcap::{PcapReader, PcapWriter};
use pcapng::{PcapngReader, PcapngWriter};
use std::fs::File;
use std::io::{self, BufRead, BufReader, BufWriter, Cursor, Read, Write};
use std::path::Path;

/// Something that records captures: implemented by the pcap, pcapng and candump writers.
pub trait CaptureWriter {
    /// Appends one record.
    fn write_record(&mut self, record: &Record) -> Result<()>;
    /// Pushes buffered output to the file.
    fn flush(&mut self) -> Result<()>;
}

impl<T: CaptureWriter + ?Sized> CaptureWriter for Box<T> {
    fn write_record(&mut self, record: &Record) -> Result<()> {
        (**self).write_record(record)
    }

    fn flush(&mut self) -> Result<()> {
        (**self).flush()
    }
}

impl<T: CaptureWriter + ?Sized> CaptureWriter for &mut T {
    fn write_record(&mut self, record: &Record) -> Result<()> {
        (**self).write_record(record)
    }

    fn flush(&mut self) -> Result<()> {
        (**self).flush()
    }
}

impl Format {
    /// The format a file name's extension names: `.pcap`, `.pcapng`, `.log` or `.candump`
    /// (any case).
    pub fn from_extension(path: impl AsRef<Path>) -> Option<Format> {
        let ext = path.as_ref().extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "pcap" => Some(Format::Pcap),
            "pcapng" => Some(Format::Pcapng),
            "log" | "candump" => Some(Format::Candump),
            _ => None,
        }
    }

    /// The format the first bytes of a file announce: a pcap magic number (either byte
    /// order, either resolution), the pcapng Section Header Block type, or text (printable
    /// ASCII and white space, as a candump log starts). An empty file counts as an empty
    /// candump log.
    pub fn detect(prefix: &[u8]) -> Option<Format> {
        if let Some(m) = prefix.first_chunk::<4>() {
            let le = u32::from_le_bytes(*m);
            if [le, le.swap_bytes()]
                .iter()
                .any(|&v| v == pcap::MAGIC_MICROS || v == pcap::MAGIC_NANOS)
            {
                return Some(Format::Pcap);
            }
            if le == pcapng::SHB {
                return Some(Format::Pcapng);
            }
        }
        prefix
            .iter()
            .all(|&b| b.is_ascii_graphic() || b.is_ascii_whitespace())
            .then_some(Format::Candump)
    }
}

/// The input of a [`CaptureReader`]: the bytes read to detect the format, then the rest.
type Prefixed<R> = io::Chain<Cursor<Vec<u8>>, R>;

#[derive(Debug)]
enum Inner<R: BufRead> {
    Pcap(PcapReader<Prefixed<R>>),
    Pcapng(PcapngReader<Prefixed<R>>),
    Candump(CandumpReader<Prefixed<R>>),
}

/// Reads a capture of any supported format, told from its first bytes.
#[derive(Debug)]
pub struct CaptureReader<R: BufRead> {
    inner: Inner<R>,
    done: bool,
}

impl<R: BufRead> CaptureReader<R> {
    /// Detects the format and reads the file header.
    pub fn new(mut input: R) -> Result<Self> {
        let mut prefix = [0u8; 4];
        let n = io_util::read_up_to(&mut input, &mut prefix)?;
        let prefix = prefix[..n].to_vec();
        let format = Format::detect(&prefix).ok_or_else(|| Error::UnknownFormat {
            prefix: prefix.clone(),
        })?;
        let input = Cursor::new(prefix).chain(input);
        let inner = match format {
            Format::Pcap => Inner::Pcap(PcapReader::new(input)?),
            Format::Pcapng => Inner::Pcapng(PcapngReader::new(input)?),
            Format::Candump => Inner::Candump(CandumpReader::new(input)),
        };
        Ok(CaptureReader { inner, done: false })
    }

    /// Names the channel of a pcap file's records (pcap has no channel field; the default is
    /// [`pcap::DEFAULT_CHANNEL`]). No effect on the other formats, which name their channels.
    pub fn with_pcap_channel(mut self, channel: impl Into<String>) -> Self {
        if let Inner::Pcap(r) = self.inner {
            self.inner = Inner::Pcap(r.with_channel(channel));
        }
        self
    }

    /// The detected format.
    pub fn format(&self) -> Format {
        match &self.inner {
            Inner::Pcap(_) => Format::Pcap,
            Inner::Pcapng(_) => Format::Pcapng,
            Inner::Candump(_) => Format::Candump,
        }
    }

    /// How many CAN FD / CAN XL frames were skipped so far.
    pub fn skipped(&self) -> u64 {
        match &self.inner {
            Inner::Pcap(r) => r.skipped(),
            Inner::Pcapng(r) => r.skipped(),
            Inner::Candump(r) => r.skipped(),
        }
    }

    /// The next record, `None` at the end of the file.
    pub fn read_record(&mut self) -> Result<Option<Record>> {
        match &mut self.inner {
            Inner::Pcap(r) => r.read_record(),
            Inner::Pcapng(r) => r.read_record(),
            Inner::Candump(r) => r.read_record(),
        }
    }
}

impl<R: BufRead> Iterator for CaptureReader<R> {
    type Item = Result<Record>;

    /// Records until the end of the file or the first error (then nothing more).
    fn next(&mut self) -> Option<Self::Item> {
        next_record(self, |r| &mut r.done, Self::read_record)
    }
}

/// Opens a capture file of any supported format.
pub fn open(path: impl AsRef<Path>) -> Result<CaptureReader<BufReader<File>>> {
    CaptureReader::new(BufReader::new(File::open(path)?))
}

/// Reads every record of a capture file.
pub fn read_all(path: impl AsRef<Path>) -> Result<Vec<Record>> {
    open(path)?.collect()
}

/// Lists a capture file with [`dump`]: what `cantwin dump FILE` prints.
pub fn dump_file(path: impl AsRef<Path>, out: &mut impl Write) -> Result<DumpSummary> {
    dump(&mut open(path)?, out)
}

/// A writer of the given format on `out` (pcap with nanosecond timestamps).
pub fn writer<W: Write + Send + 'static>(
    format: Format,
    out: W,
) -> Result<Box<dyn CaptureWriter + Send>> {
    Ok(match format {
        Format::Pcap => Box::new(PcapWriter::new(out)?),
        Format::Pcapng => Box::new(PcapngWriter::new(out)?),
        Format::Candump => Box::new(CandumpWriter::new(out)),
    })
}

/// Creates (or truncates) a capture file, its format chosen by [`Format::from_extension`].
/// Call [`CaptureWriter::flush`] when done: errors of the final write surface there.
pub fn create(path: impl AsRef<Path>) -> Result<Box<dyn CaptureWriter + Send>> {
    let path = path.as_ref();
    let format = Format::from_extension(path)
        .ok_or_else(|| Error::UnknownExtension(path.display().to_string()))?;
    writer(format, BufWriter::new(File::create(path)?))
}
