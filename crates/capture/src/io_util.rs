//! Small helpers shared by the binary readers.

use std::io::{self, Read};

/// Reads until `buf` is full or the input ends; returns how many bytes were read.
pub(crate) fn read_up_to<R: Read + ?Sized>(r: &mut R, buf: &mut [u8]) -> io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

/// Reads at most `len` bytes into `buf` (cleared first) without reserving `len` up front,
/// so a length field that lies costs no more memory than the bytes actually present.
pub(crate) fn read_body<R: Read + ?Sized>(
    r: &mut R,
    len: u64,
    buf: &mut Vec<u8>,
) -> io::Result<usize> {
    buf.clear();
    r.take(len).read_to_end(buf)
}

/// Skips `len` bytes; returns how many were actually there.
pub(crate) fn skip<R: Read + ?Sized>(r: &mut R, len: u64) -> io::Result<u64> {
    io::copy(&mut r.take(len), &mut io::sink())
}

/// Byte order of a binary file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Endian {
    Little,
    Big,
}

impl Endian {
    pub(crate) fn u16(self, b: [u8; 2]) -> u16 {
        match self {
            Endian::Little => u16::from_le_bytes(b),
            Endian::Big => u16::from_be_bytes(b),
        }
    }

    pub(crate) fn u32(self, b: [u8; 4]) -> u32 {
        match self {
            Endian::Little => u32::from_le_bytes(b),
            Endian::Big => u32::from_be_bytes(b),
        }
    }

    /// A `u16` at `at`, or `None` past the end.
    pub(crate) fn u16_at(self, b: &[u8], at: usize) -> Option<u16> {
        let s = b.get(at..at.checked_add(2)?)?;
        Some(self.u16([s[0], s[1]]))
    }

    /// A `u32` at `at`, or `None` past the end.
    pub(crate) fn u32_at(self, b: &[u8], at: usize) -> Option<u32> {
        let s = b.get(at..at.checked_add(4)?)?;
        Some(self.u32([s[0], s[1], s[2], s[3]]))
    }
}
