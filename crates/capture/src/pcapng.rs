//! pcapng files (draft-ietf-opsawg-pcapng) with LINKTYPE_CAN_SOCKETCAN interfaces.
//!
//! Every block is `type, total length, body, total length` (32-bit words, padded to 4 bytes).
//! [`PcapngWriter`] writes a Section Header Block, then for each new channel an Interface
//! Description Block (`if_name` = channel, `if_tsresol` = 9, i.e. nanoseconds) just before
//! the channel's first Enhanced Packet Block. [`PcapngReader`] reads Section Header,
//! Interface Description, Enhanced Packet and Simple Packet Blocks in either byte order (each
//! section has its own) and skips every other block without buffering it.
//!
//! A Simple Packet Block has no timestamp: its records get timestamp 0. An interface with no
//! `if_name` is named `if<N>` after its index in the section. An interface with another link
//! type is an error ([`Error::LinkType`]). CAN FD / CAN XL packets are skipped and counted.

use crate::error::{Error, Format, Result};
use crate::io_util::{Endian, next_record, read_body, read_up_to, skip, writer_plumbing};
use crate::record::Record;
use crate::socketcan::{self, CAN_MTU, Decoded, LINKTYPE_CAN_SOCKETCAN};
use std::io::{Read, Write};

/// Section Header Block type (a palindrome: the same in both byte orders).
pub(crate) const SHB: u32 = 0x0A0D_0D0A;
const IDB: u32 = 0x0000_0001;
const SPB: u32 = 0x0000_0003;
const EPB: u32 = 0x0000_0006;
const BYTE_ORDER_MAGIC: u32 = 0x1A2B_3C4D;
const OPT_END: u16 = 0;
const IF_NAME: u16 = 2;
const IF_TSRESOL: u16 = 9;
const IF_TSOFFSET: u16 = 14;
/// Blocks the reader parses (section headers, interfaces, packets) larger than this are
/// rejected: it bounds what a corrupt length can make the reader allocate. Other blocks are
/// skipped by streaming, whatever their size.
pub const MAX_BLOCK_LEN: u32 = 1 << 20;

fn pad4(n: usize) -> usize {
    (4 - n % 4) % 4
}

/// Writes a pcapng file, little-endian, one interface per channel.
#[derive(Debug)]
pub struct PcapngWriter<W: Write> {
    out: W,
    interfaces: Vec<String>,
}

impl<W: Write> PcapngWriter<W> {
    /// Writes the Section Header Block (version 1.0, section length unknown).
    pub fn new(mut out: W) -> Result<Self> {
        let mut b = Vec::with_capacity(28);
        b.extend_from_slice(&SHB.to_le_bytes());
        b.extend_from_slice(&28u32.to_le_bytes());
        b.extend_from_slice(&BYTE_ORDER_MAGIC.to_le_bytes());
        b.extend_from_slice(&1u16.to_le_bytes());
        b.extend_from_slice(&0u16.to_le_bytes());
        b.extend_from_slice(&(-1i64).to_le_bytes());
        b.extend_from_slice(&28u32.to_le_bytes());
        out.write_all(&b)?;
        Ok(PcapngWriter {
            out,
            interfaces: Vec::new(),
        })
    }

    /// The channels written so far, in interface-index order.
    pub fn channels(&self) -> &[String] {
        &self.interfaces
    }

    fn interface(&mut self, channel: &str) -> Result<u32> {
        if let Some(i) = self.interfaces.iter().position(|c| c == channel) {
            return Ok(i as u32);
        }
        if channel.len() > usize::from(u16::MAX) {
            return Err(Error::BadChannel(
                channel.to_owned(),
                "longer than a pcapng option can hold",
            ));
        }
        let index = u32::try_from(self.interfaces.len()).map_err(|_| {
            Error::BadChannel(channel.to_owned(), "too many interfaces in one section")
        })?;
        let name = channel.as_bytes();
        let len = 16 + 4 + name.len() + pad4(name.len()) + 8 + 4 + 4;
        let mut b = Vec::with_capacity(len);
        b.extend_from_slice(&IDB.to_le_bytes());
        b.extend_from_slice(&(len as u32).to_le_bytes());
        b.extend_from_slice(&(LINKTYPE_CAN_SOCKETCAN as u16).to_le_bytes());
        b.extend_from_slice(&0u16.to_le_bytes());
        b.extend_from_slice(&0u32.to_le_bytes()); // snaplen 0: no limit
        b.extend_from_slice(&IF_NAME.to_le_bytes());
        b.extend_from_slice(&(name.len() as u16).to_le_bytes());
        b.extend_from_slice(name);
        b.resize(b.len() + pad4(name.len()), 0);
        b.extend_from_slice(&IF_TSRESOL.to_le_bytes());
        b.extend_from_slice(&1u16.to_le_bytes());
        b.extend_from_slice(&[9, 0, 0, 0]);
        b.extend_from_slice(&OPT_END.to_le_bytes());
        b.extend_from_slice(&0u16.to_le_bytes());
        b.extend_from_slice(&(len as u32).to_le_bytes());
        self.out.write_all(&b)?;
        self.interfaces.push(channel.to_owned());
        Ok(index)
    }

    /// Appends one record as an Enhanced Packet Block, preceded by an Interface Description
    /// Block the first time its channel appears.
    pub fn write_record(&mut self, record: &Record) -> Result<()> {
        let iface = self.interface(&record.channel)?;
        const LEN: u32 = 28 + CAN_MTU as u32 + 4;
        let ts = record.timestamp_ns;
        let mut b = [0u8; LEN as usize];
        b[0..4].copy_from_slice(&EPB.to_le_bytes());
        b[4..8].copy_from_slice(&LEN.to_le_bytes());
        b[8..12].copy_from_slice(&iface.to_le_bytes());
        b[12..16].copy_from_slice(&((ts >> 32) as u32).to_le_bytes());
        b[16..20].copy_from_slice(&(ts as u32).to_le_bytes());
        b[20..24].copy_from_slice(&(CAN_MTU as u32).to_le_bytes());
        b[24..28].copy_from_slice(&(CAN_MTU as u32).to_le_bytes());
        b[28..28 + CAN_MTU].copy_from_slice(&socketcan::encode(&record.event));
        b[28 + CAN_MTU..].copy_from_slice(&LEN.to_le_bytes());
        self.out.write_all(&b)?;
        Ok(())
    }
}

writer_plumbing!(PcapngWriter);

#[derive(Debug)]
struct Interface {
    name: String,
    tsresol: u8,
    tsoffset_s: i64,
    snaplen: u32,
}

/// Converts a timestamp in `if_tsresol` units plus `if_tsoffset` seconds to nanoseconds.
fn to_nanos(ts: u64, tsresol: u8, offset_s: i64) -> Option<u64> {
    let ts = u128::from(ts);
    let ns = if tsresol & 0x80 == 0 {
        // 10^-n seconds per unit.
        let n = u32::from(tsresol);
        if n <= 9 {
            ts * 10u128.pow(9 - n)
        } else if n <= 38 {
            ts / 10u128.pow(n - 9)
        } else {
            0
        }
    } else {
        // 2^-n seconds per unit; n <= 127 so the shift is defined.
        (ts * 1_000_000_000) >> u32::from(tsresol & 0x7F)
    };
    let total = i128::try_from(ns).ok()? + i128::from(offset_s) * 1_000_000_000;
    u64::try_from(total).ok()
}

/// Reads a pcapng file.
#[derive(Debug)]
pub struct PcapngReader<R: Read> {
    input: R,
    endian: Endian,
    interfaces: Vec<Interface>,
    offset: u64,
    skipped: u64,
    buf: Vec<u8>,
    done: bool,
}

impl<R: Read> PcapngReader<R> {
    /// Reads the first Section Header Block.
    pub fn new(input: R) -> Result<Self> {
        let mut r = PcapngReader {
            input,
            endian: Endian::Little,
            interfaces: Vec::new(),
            offset: 0,
            skipped: 0,
            buf: Vec::new(),
            done: false,
        };
        let mut head = [0u8; 8];
        let n = read_up_to(&mut r.input, &mut head)?;
        if n >= 4 && u32::from_le_bytes([head[0], head[1], head[2], head[3]]) != SHB {
            return Err(r.malformed(0, "file does not start with a Section Header Block".into()));
        }
        if n < 8 {
            return Err(r.truncated(0, "section header block"));
        }
        r.section_header(head)?;
        Ok(r)
    }

    /// How many CAN FD / CAN XL packets were skipped so far.
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    fn malformed(&self, offset: u64, reason: String) -> Error {
        Error::Malformed {
            format: Format::Pcapng,
            offset,
            reason,
        }
    }

    fn truncated(&self, offset: u64, what: &'static str) -> Error {
        Error::Truncated {
            format: Format::Pcapng,
            offset,
            what,
        }
    }

    /// Checks a block's total length and reads the rest of its body (after `consumed` bytes)
    /// into `self.buf`, trailing length included.
    fn body(&mut self, at: u64, len: u32, consumed: u32, what: &'static str) -> Result<()> {
        if len % 4 != 0 || len < consumed + 4 {
            return Err(self.malformed(at, format!("{what} with total length {len}")));
        }
        if len > MAX_BLOCK_LEN {
            return Err(self.malformed(
                at,
                format!("{what} of {len} bytes exceeds the limit of {MAX_BLOCK_LEN}"),
            ));
        }
        let want = u64::from(len - consumed);
        let got = read_body(&mut self.input, want, &mut self.buf)?;
        if (got as u64) < want {
            return Err(self.truncated(at, what));
        }
        let trailer = self.endian.u32_at(&self.buf, self.buf.len() - 4);
        if trailer != Some(len) {
            return Err(self.malformed(
                at,
                format!("{what}: trailing length {trailer:?} differs from {len}"),
            ));
        }
        self.buf.truncate(self.buf.len() - 4);
        self.offset = at + u64::from(len);
        Ok(())
    }

    /// Reads a Section Header Block whose first 8 bytes are `head`; a new section starts with
    /// its own byte order and no interfaces.
    fn section_header(&mut self, head: [u8; 8]) -> Result<()> {
        let at = self.offset;
        let mut bom = [0u8; 4];
        if read_up_to(&mut self.input, &mut bom)? < 4 {
            return Err(self.truncated(at, "section header block"));
        }
        self.endian = match u32::from_le_bytes(bom) {
            BYTE_ORDER_MAGIC => Endian::Little,
            m if m.swap_bytes() == BYTE_ORDER_MAGIC => Endian::Big,
            m => {
                return Err(self.malformed(at, format!("byte-order magic {m:#010x}")));
            }
        };
        let len = self.endian.u32([head[4], head[5], head[6], head[7]]);
        if len < 28 {
            return Err(self.malformed(at, format!("section header block of {len} bytes")));
        }
        self.body(at, len, 12, "section header block")?;
        let major = self.endian.u16_at(&self.buf, 0);
        if major != Some(1) {
            return Err(self.malformed(at, format!("unsupported pcapng major version {major:?}")));
        }
        self.interfaces.clear();
        Ok(())
    }

    fn interface_description(&mut self, at: u64) -> Result<()> {
        let e = self.endian;
        let b = &self.buf;
        let (Some(link_type), Some(snaplen)) = (e.u16_at(b, 0), e.u32_at(b, 4)) else {
            return Err(self.malformed(at, "interface description block too short".into()));
        };
        if u32::from(link_type) != LINKTYPE_CAN_SOCKETCAN {
            return Err(Error::LinkType {
                format: Format::Pcapng,
                offset: at,
                link_type: u32::from(link_type),
            });
        }
        let mut iface = Interface {
            name: format!("if{}", self.interfaces.len()),
            tsresol: 6,
            tsoffset_s: 0,
            snaplen,
        };
        let mut pos = 8;
        while let (Some(code), Some(olen)) = (e.u16_at(b, pos), e.u16_at(b, pos + 2)) {
            if code == OPT_END {
                break;
            }
            let start = pos + 4;
            let end = start + usize::from(olen);
            let Some(value) = b.get(start..end) else {
                return Err(self.malformed(at, format!("option {code} overruns its block")));
            };
            match code {
                IF_NAME => iface.name = String::from_utf8_lossy(value).into_owned(),
                IF_TSRESOL if olen == 1 => iface.tsresol = value[0],
                IF_TSOFFSET if olen == 8 => {
                    let mut v = [0u8; 8];
                    v.copy_from_slice(value);
                    iface.tsoffset_s = match e {
                        Endian::Little => i64::from_le_bytes(v),
                        Endian::Big => i64::from_be_bytes(v),
                    };
                }
                _ => {}
            }
            pos = end + pad4(usize::from(olen));
        }
        self.interfaces.push(iface);
        Ok(())
    }

    fn packet(
        &mut self,
        at: u64,
        iface: u32,
        ts: Option<u64>,
        data: (usize, usize),
    ) -> Result<Option<Record>> {
        let Some(i) = self.interfaces.get(iface as usize) else {
            return Err(self.malformed(at, format!("packet on undeclared interface {iface}")));
        };
        let timestamp_ns = match ts {
            Some(ts) => to_nanos(ts, i.tsresol, i.tsoffset_s).ok_or_else(|| {
                self.malformed(at, "timestamp outside the range of u64 nanoseconds".into())
            })?,
            None => 0,
        };
        let Some(packet) = self.buf.get(data.0..data.0.saturating_add(data.1)) else {
            return Err(self.malformed(at, "packet data overruns its block".into()));
        };
        match socketcan::decode(packet) {
            Ok(Decoded::Event(event)) => Ok(Some(Record {
                timestamp_ns,
                channel: i.name.clone(),
                event,
            })),
            Ok(Decoded::NotClassic) => {
                self.skipped += 1;
                Ok(None)
            }
            Err(reason) => Err(self.malformed(at, reason)),
        }
    }

    /// The next record, `None` at the end of the file.
    pub fn read_record(&mut self) -> Result<Option<Record>> {
        loop {
            let at = self.offset;
            let mut head = [0u8; 8];
            let n = read_up_to(&mut self.input, &mut head)?;
            if n == 0 {
                return Ok(None);
            }
            if n < 8 {
                return Err(self.truncated(at, "block header"));
            }
            let e = self.endian;
            let kind = e.u32([head[0], head[1], head[2], head[3]]);
            let len = e.u32([head[4], head[5], head[6], head[7]]);
            match kind {
                SHB => self.section_header(head)?,
                IDB => {
                    self.body(at, len, 8, "interface description block")?;
                    self.interface_description(at)?;
                }
                EPB => {
                    self.body(at, len, 8, "enhanced packet block")?;
                    let b = &self.buf;
                    let fields = (
                        e.u32_at(b, 0),
                        e.u32_at(b, 4),
                        e.u32_at(b, 8),
                        e.u32_at(b, 12),
                    );
                    let (Some(iface), Some(hi), Some(lo), Some(caplen)) = fields else {
                        return Err(self.malformed(at, "enhanced packet block too short".into()));
                    };
                    let ts = (u64::from(hi) << 32) | u64::from(lo);
                    if let Some(r) = self.packet(at, iface, Some(ts), (20, caplen as usize))? {
                        return Ok(Some(r));
                    }
                }
                SPB => {
                    self.body(at, len, 8, "simple packet block")?;
                    let Some(orig) = e.u32_at(&self.buf, 0) else {
                        return Err(self.malformed(at, "simple packet block too short".into()));
                    };
                    // The captured length is implied: the original length, cut by the
                    // interface's snaplen and by the block (padding included).
                    let mut caplen = (orig as usize).min(self.buf.len() - 4);
                    if let Some(i) = self.interfaces.first()
                        && i.snaplen != 0
                    {
                        caplen = caplen.min(i.snaplen as usize);
                    }
                    if let Some(r) = self.packet(at, 0, None, (4, caplen))? {
                        return Ok(Some(r));
                    }
                }
                _ => {
                    if len % 4 != 0 || len < 12 {
                        return Err(self.malformed(
                            at,
                            format!("block of type {kind:#x} with total length {len}"),
                        ));
                    }
                    let want = u64::from(len) - 8;
                    if skip(&mut self.input, want)? < want {
                        return Err(self.truncated(at, "block"));
                    }
                    self.offset = at + u64::from(len);
                }
            }
        }
    }
}

impl<R: Read> Iterator for PcapngReader<R> {
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
    fn timestamp_resolutions() {
        assert_eq!(to_nanos(1_500_000, 6, 0), Some(1_500_000_000));
        assert_eq!(to_nanos(7, 9, 0), Some(7));
        assert_eq!(to_nanos(12_345, 12, 0), Some(12));
        assert_eq!(to_nanos(3, 0x81, 0), Some(1_500_000_000));
        assert_eq!(to_nanos(1, 6, 10), Some(10_000_001_000));
        assert_eq!(to_nanos(0, 6, -1), None);
        assert_eq!(to_nanos(u64::MAX, 0, 0), None);
        assert_eq!(to_nanos(u64::MAX, 0x7F, 0), Some(0));
        assert_eq!(to_nanos(u64::MAX, 0xC8, 0), Some(3_906_249));
    }
}
