//! The one error type of the crate.

use std::fmt;
use std::io;

/// The capture formats this crate reads and writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Format {
    /// Classic libpcap file with LINKTYPE_CAN_SOCKETCAN (227).
    Pcap,
    /// pcapng with one Interface Description Block per channel.
    Pcapng,
    /// can-utils `candump -l` log file.
    Candump,
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Format::Pcap => "pcap",
            Format::Pcapng => "pcapng",
            Format::Candump => "candump log",
        })
    }
}

/// Everything that can go wrong reading or writing a capture.
///
/// Binary formats report the byte offset of the offending record or block, the candump log
/// reader the 1-based line number.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The underlying reader or writer failed.
    #[error("I/O error: {0}")]
    Io(#[from] io::Error),
    /// The file starts with neither a pcap nor a pcapng magic number, nor text.
    #[error("not a pcap, pcapng or candump log file (starts with {prefix:02X?})")]
    UnknownFormat {
        /// The first bytes of the file (up to 4).
        prefix: Vec<u8>,
    },
    /// The file name has no extension that names a capture format.
    #[error(
        "cannot tell the capture format from the file name {0:?}: use .pcap, .pcapng, .log or .candump"
    )]
    UnknownExtension(String),
    /// The file ends in the middle of a header, record or block.
    #[error("{format}: truncated {what} at byte {offset}")]
    Truncated {
        /// Format being read.
        format: Format,
        /// Byte offset where the incomplete item starts.
        offset: u64,
        /// What was being read.
        what: &'static str,
    },
    /// A header, record or block is inconsistent.
    #[error("{format}: malformed data at byte {offset}: {reason}")]
    Malformed {
        /// Format being read.
        format: Format,
        /// Byte offset of the offending header, record or block.
        offset: u64,
        /// What is wrong.
        reason: String,
    },
    /// The file (or one of its pcapng interfaces) does not carry SocketCAN frames.
    #[error("{format}: link type {link_type} at byte {offset} is not LINKTYPE_CAN_SOCKETCAN (227)")]
    LinkType {
        /// Format being read.
        format: Format,
        /// Byte offset of the file header or Interface Description Block.
        offset: u64,
        /// The link type found.
        link_type: u32,
    },
    /// A candump log line cannot be parsed.
    #[error("candump log line {line}: {reason}")]
    Line {
        /// 1-based line number.
        line: u64,
        /// What is wrong.
        reason: String,
    },
    /// A record's timestamp cannot be represented in the format.
    #[error("{format}: timestamp {timestamp_ns} ns does not fit the format's timestamp field")]
    Timestamp {
        /// Format being written.
        format: Format,
        /// The timestamp, in nanoseconds since the Unix epoch.
        timestamp_ns: u64,
    },
    /// A classic pcap file holds one channel only.
    #[error(
        "a pcap file holds one channel ({expected}); a record on {found} needs its own file or pcapng"
    )]
    Channel {
        /// The channel of the first record written.
        expected: String,
        /// The channel of the rejected record.
        found: String,
    },
    /// A channel name the format cannot carry.
    #[error("channel name {0:?} cannot be written: {1}")]
    BadChannel(String, &'static str),
}

/// Shorthand for results of this crate.
pub type Result<T, E = Error> = core::result::Result<T, E>;
