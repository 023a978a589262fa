//! Small helpers shared by the readers.

use std::io::{self, Read};

use crate::error::Result;
use crate::record::Record;

/// One step of a reader's record iterator: the next record from `read`, ending for good at
/// the end of the input or after the first error (yielded once), so a damaged file cannot
/// make a caller loop on the same error.
pub(crate) fn next_record<S>(
    reader: &mut S,
    done: impl Fn(&mut S) -> &mut bool,
    read: impl FnOnce(&mut S) -> Result<Option<Record>>,
) -> Option<Result<Record>> {
    if *done(reader) {
        return None;
    }
    let r = read(reader).transpose();
    if !matches!(r, Some(Ok(_))) {
        *done(reader) = true;
    }
    r
}

/// What every capture writer has besides its own `write_record`: `flush`, `into_inner` and
/// the [`CaptureWriter`](crate::CaptureWriter) impl forwarding to the inherent methods. The
/// writer keeps its output in a field `out`.
macro_rules! writer_plumbing {
    ($writer:ident) => {
        impl<W: std::io::Write> $writer<W> {
            /// Flushes the underlying writer.
            pub fn flush(&mut self) -> $crate::error::Result<()> {
                std::io::Write::flush(&mut self.out)?;
                Ok(())
            }

            /// The underlying writer.
            pub fn into_inner(self) -> W {
                self.out
            }
        }

        impl<W: std::io::Write> $crate::CaptureWriter for $writer<W> {
            fn write_record(&mut self, record: &$crate::Record) -> $crate::error::Result<()> {
                $writer::write_record(self, record)
            }

            fn flush(&mut self) -> $crate::error::Result<()> {
                $writer::flush(self)
            }
        }
    };
}
pub(crate) use writer_plumbing;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Error;
    use cantwin_can::Frame;

    /// Answers a record, then an error, then a record again: a reader that could resume.
    struct Script {
        step: u32,
        done: bool,
    }

    impl Script {
        fn read(&mut self) -> Result<Option<Record>> {
            self.step += 1;
            match self.step {
                2 => Err(Error::Io(io::Error::other("damaged"))),
                _ => Ok(Some(Record::new(
                    u64::from(self.step),
                    "can0",
                    Frame::std(0x123, &[]).unwrap(),
                ))),
            }
        }
    }

    #[test]
    fn the_record_iterator_ends_after_its_first_error() {
        let mut s = Script {
            step: 0,
            done: false,
        };
        let next = |s: &mut Script| next_record(s, |s| &mut s.done, Script::read);
        assert!(matches!(next(&mut s), Some(Ok(r)) if r.timestamp_ns == 1));
        assert!(matches!(next(&mut s), Some(Err(Error::Io(_)))));
        assert!(next(&mut s).is_none());
        assert!(next(&mut s).is_none());
        assert_eq!(s.step, 2, "nothing is read after the error");
    }

    #[test]
    fn the_record_iterator_ends_at_the_end_of_the_input() {
        let mut done = false;
        let mut reads = 0;
        let mut read_nothing = |_: &mut bool| -> Result<Option<Record>> {
            reads += 1;
            Ok(None)
        };
        assert!(next_record(&mut done, |d| d, &mut read_nothing).is_none());
        assert!(next_record(&mut done, |d| d, &mut read_nothing).is_none());
        assert_eq!(reads, 1);
    }
}
