//! Classic libpcap files with LINKTYPE_CAN_SOCKETCAN (227).
//!
//! Layout (tcpdump.org, "pcap-savefile" / draft-ietf-opsawg-pcap): a 24-byte file header
//! (magic, version 2.4, thiszone, sigfigs, snaplen, link type) in the writer's byte order, then
//! per packet a 16-byte record header (seconds, micro- or nanoseconds, captured length,
//! original length) and the packet. The magic `0xA1B2C3D4` means microsecond timestamps,
//! `0xA1B23C4D` nanosecond ones; read in the wrong byte order it tells the reader to swap.
//!
//! The format has no channel field, so a file holds one bus: [`PcapWriter`] takes the channel
//! of its first record and refuses others ([`Error::Channel`]); [`PcapReader`] names every
//! record's channel after [`PcapReader::with_channel`] (default `can0`).
//!
//! CAN FD and CAN XL packets, which [`cantwin_can::Frame`] cannot hold, are skipped and counted
//! ([`PcapReader::skipped`]).

use crate::error::{Error, Format, Result};
use crate::io_util::{Endian, next_record, read_body, read_up_to, writer_plumbing};
use crate::record::Record;
use crate::socketcan::{self, CAN_MTU, Decoded, LINKTYPE_CAN_SOCKETCAN};
use std::io::{Read, Write};

/// Microsecond-resolution magic number.
pub(crate) const MAGIC_MICROS: u32 = 0xA1B2_C3D4;
/// Nanosecond-resolution magic number.
pub(crate) const MAGIC_NANOS: u32 = 0xA1B2_3C4D;
/// The snaplen cantwin writes: larger than any CAN, CAN FD or CAN XL packet.
const SNAPLEN: u32 = 65_535;
/// Records claiming more captured bytes than this are rejected: no CAN packet comes close,
/// and it bounds what a corrupt length field can make the reader allocate.
pub const MAX_RECORD_LEN: u32 = 262_144;
/// Channel name given to records of a pcap file unless told otherwise.
pub const DEFAULT_CHANNEL: &str = "can0";

/// Timestamp resolution of a pcap file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Resolution {
    /// Microseconds (magic `0xA1B2C3D4`): the original format, read by every tool.
    Micro,
    /// Nanoseconds (magic `0xA1B23C4D`): no loss of cantwin's bus time; the default.
    #[default]
    Nano,
}

impl Resolution {
    const fn magic(self) -> u32 {
        match self {
            Resolution::Micro => MAGIC_MICROS,
            Resolution::Nano => MAGIC_NANOS,
        }
    }

    const fn units_per_sec(self) -> u64 {
        match self {
            Resolution::Micro => 1_000_000,
            Resolution::Nano => 1_000_000_000,
        }
    }
}

/// Writes a pcap file, little-endian, one 16-byte `struct can_frame` per record.
#[derive(Debug)]
pub struct PcapWriter<W: Write> {
    out: W,
    resolution: Resolution,
    channel: Option<String>,
}

impl<W: Write> PcapWriter<W> {
    /// Writes the file header for nanosecond timestamps.
    pub fn new(out: W) -> Result<Self> {
        Self::with_resolution(out, Resolution::Nano)
    }

    /// Writes the file header for the given timestamp resolution.
    pub fn with_resolution(mut out: W, resolution: Resolution) -> Result<Self> {
        let mut h = [0u8; 24];
        h[0..4].copy_from_slice(&resolution.magic().to_le_bytes());
        h[4..6].copy_from_slice(&2u16.to_le_bytes());
        h[6..8].copy_from_slice(&4u16.to_le_bytes());
        // thiszone and sigfigs stay 0, as the format asks.
        h[16..20].copy_from_slice(&SNAPLEN.to_le_bytes());
        h[20..24].copy_from_slice(&LINKTYPE_CAN_SOCKETCAN.to_le_bytes());
        out.write_all(&h)?;
        Ok(PcapWriter {
            out,
            resolution,
            channel: None,
        })
    }

    /// The channel this file holds, once a record was written.
    pub fn channel(&self) -> Option<&str> {
        self.channel.as_deref()
    }

    /// Appends one record. The first record fixes the file's channel; a record on another
    /// channel is refused with [`Error::Channel`] and nothing is written.
    ///
    /// Timestamps are truncated to the file's resolution; seconds beyond `u32::MAX` (the year
    /// 2106) give [`Error::Timestamp`].
    pub fn write_record(&mut self, record: &Record) -> Result<()> {
        match &self.channel {
            Some(c) if *c != record.channel => {
                return Err(Error::Channel {
                    expected: c.clone(),
                    found: record.channel.clone(),
                });
            }
            _ => {}
        }
        let secs =
            u32::try_from(record.timestamp_ns / 1_000_000_000).map_err(|_| Error::Timestamp {
                format: Format::Pcap,
                timestamp_ns: record.timestamp_ns,
            })?;
        let sub_ns = record.timestamp_ns % 1_000_000_000;
        let frac = match self.resolution {
            Resolution::Micro => sub_ns / 1_000,
            Resolution::Nano => sub_ns,
        } as u32;
        let packet = socketcan::encode(&record.event);
        let mut rec = [0u8; 16 + CAN_MTU];
        rec[0..4].copy_from_slice(&secs.to_le_bytes());
        rec[4..8].copy_from_slice(&frac.to_le_bytes());
        rec[8..12].copy_from_slice(&(CAN_MTU as u32).to_le_bytes());
        rec[12..16].copy_from_slice(&(CAN_MTU as u32).to_le_bytes());
        rec[16..].copy_from_slice(&packet);
        self.out.write_all(&rec)?;
        if self.channel.is_none() {
            self.channel = Some(record.channel.clone());
        }
        Ok(())
    }
}

writer_plumbing!(PcapWriter);

/// Reads a pcap file of either byte order and either resolution.
#[derive(Debug)]
pub struct PcapReader<R: Read> {
    input: R,
    endian: Endian,
    resolution: Resolution,
    channel: String,
    offset: u64,
    skipped: u64,
    buf: Vec<u8>,
    done: bool,
}

impl<R: Read> PcapReader<R> {
    /// Reads and checks the file header: a pcap magic number and link type 227.
    pub fn new(mut input: R) -> Result<Self> {
        let mut h = [0u8; 24];
        let n = read_up_to(&mut input, &mut h)?;
        if n >= 4 {
            let le = u32::from_le_bytes([h[0], h[1], h[2], h[3]]);
            let be = u32::from_be_bytes([h[0], h[1], h[2], h[3]]);
            let (endian, resolution) = match (le, be) {
                (MAGIC_MICROS, _) => (Endian::Little, Resolution::Micro),
                (MAGIC_NANOS, _) => (Endian::Little, Resolution::Nano),
                (_, MAGIC_MICROS) => (Endian::Big, Resolution::Micro),
                (_, MAGIC_NANOS) => (Endian::Big, Resolution::Nano),
                _ => {
                    return Err(Error::Malformed {
                        format: Format::Pcap,
                        offset: 0,
                        reason: format!("magic number {le:#010x} is not a pcap magic"),
                    });
                }
            };
            if n < 24 {
                return Err(Error::Truncated {
                    format: Format::Pcap,
                    offset: 0,
                    what: "file header",
                });
            }
            let major = endian.u16([h[4], h[5]]);
            if major != 2 {
                return Err(Error::Malformed {
                    format: Format::Pcap,
                    offset: 4,
                    reason: format!("unsupported pcap version {major}"),
                });
            }
            // The link type is the low 16 bits; the upper bits may carry FCS information.
            let link_type = endian.u32([h[20], h[21], h[22], h[23]]) & 0xFFFF;
            if link_type != LINKTYPE_CAN_SOCKETCAN {
                return Err(Error::LinkType {
                    format: Format::Pcap,
                    offset: 20,
                    link_type,
                });
            }
            return Ok(PcapReader {
                input,
                endian,
                resolution,
                channel: DEFAULT_CHANNEL.to_owned(),
                offset: 24,
                skipped: 0,
                buf: Vec::new(),
                done: false,
            });
        }
        Err(Error::Truncated {
            format: Format::Pcap,
            offset: 0,
            what: "file header",
        })
    }

    /// Names the channel of every record read (pcap has no channel field).
    pub fn with_channel(mut self, channel: impl Into<String>) -> Self {
        self.channel = channel.into();
        self
    }

    /// The file's timestamp resolution.
    pub fn resolution(&self) -> Resolution {
        self.resolution
    }

    /// How many CAN FD / CAN XL packets were skipped so far.
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    /// The next record, `None` at the end of the file.
    pub fn read_record(&mut self) -> Result<Option<Record>> {
        loop {
            let at = self.offset;
            let mut h = [0u8; 16];
            let n = read_up_to(&mut self.input, &mut h)?;
            if n == 0 {
                return Ok(None);
            }
            if n < 16 {
                return Err(Error::Truncated {
                    format: Format::Pcap,
                    offset: at,
                    what: "record header",
                });
            }
            let e = self.endian;
            let secs = u64::from(e.u32([h[0], h[1], h[2], h[3]]));
            let frac = u64::from(e.u32([h[4], h[5], h[6], h[7]]));
            let incl = e.u32([h[8], h[9], h[10], h[11]]);
            if incl > MAX_RECORD_LEN {
                return Err(Error::Malformed {
                    format: Format::Pcap,
                    offset: at,
                    reason: format!("record claims {incl} captured bytes (limit {MAX_RECORD_LEN})"),
                });
            }
            let got = read_body(&mut self.input, u64::from(incl), &mut self.buf)?;
            if got < incl as usize {
                return Err(Error::Truncated {
                    format: Format::Pcap,
                    offset: at,
                    what: "record",
                });
            }
            self.offset = at + 16 + u64::from(incl);
            // Both factors are below 2^32 and 10^9 < 2^30: no overflow in u64.
            let timestamp_ns =
                secs * 1_000_000_000 + frac * (1_000_000_000 / self.resolution.units_per_sec());
            match socketcan::decode(&self.buf) {
                Ok(Decoded::Event(event)) => {
                    return Ok(Some(Record {
                        timestamp_ns,
                        channel: self.channel.clone(),
                        event,
                    }));
                }
                Ok(Decoded::NotClassic) => self.skipped += 1,
                Err(reason) => {
                    return Err(Error::Malformed {
                        format: Format::Pcap,
                        offset: at,
                        reason,
                    });
                }
            }
        }
    }
}

impl<R: Read> Iterator for PcapReader<R> {
    type Item = Result<Record>;

    /// Records until the end of the file or the first error (then nothing more).
    fn next(&mut self) -> Option<Self::Item> {
        next_record(self, |r| &mut r.done, Self::read_record)
    }
}
