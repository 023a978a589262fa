//! The slcan (Lawicel CANUSB ASCII) wire format, without any I/O.
//!
//! Each command and each frame record is ASCII text ended by a carriage return (`\r`). The
//! adapter answers `\r` for success and BEL (`\x07`) for an error; a queued transmission is
//! answered `z\r` (standard) or `Z\r` (extended). Frame records, both directions:
//!
//! | record | meaning |
//! |---|---|
//! | `tIIIL` + 2·L hex digits | standard data frame, 3 hex digits of identifier, DLC digit |
//! | `TIIIIIIIIL` + 2·L hex digits | extended data frame, 8 hex digits of identifier |
//! | `rIIIL` | standard remote frame of DLC L |
//! | `RIIIIIIIIL` | extended remote frame of DLC L |
//!
//! Identifiers and data are written in upper-case hex; either case is read. CAN FD records
//! (`d`, `D`, `b`, `B`) are refused: the bus is classic CAN.

use cantwin_can::{Frame, FrameError, Id, IdError};

/// The success reply.
pub const OK: &[u8] = b"\r";
/// The error reply (BEL).
pub const ERROR: &[u8] = b"\x07";
/// The reply to a queued standard frame (`t`, `r`).
pub const SENT_STANDARD: &[u8] = b"z\r";
/// The reply to a queued extended frame (`T`, `R`).
pub const SENT_EXTENDED: &[u8] = b"Z\r";

/// A line that does not parse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    /// An unknown command letter.
    #[error("unknown command")]
    Unknown,
    /// A known command with a malformed argument.
    #[error("malformed command")]
    Syntax,
    /// A CAN FD record on a classic bus.
    #[error("CAN FD is not supported")]
    Fd,
    /// An identifier out of range.
    #[error(transparent)]
    Id(#[from] IdError),
    /// A frame that cannot exist.
    #[error(transparent)]
    Frame(#[from] FrameError),
}

/// A command from the host to the adapter.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// An empty line (python-can sends one as the data bit rate of a classic bus).
    Empty,
    /// `O`: open the channel.
    Open,
    /// `L`: open the channel listen-only.
    ListenOnly,
    /// `C`: close the channel.
    Close,
    /// `Sn`: one of the standard bit rates, `S0` = 10 kbit/s … `S8` = 1 Mbit/s, `S9` =
    /// 83.3 kbit/s.
    Bitrate(u8),
    /// `sxxyy`: SJA1000 bus timing registers BTR0, BTR1.
    Btr(u8, u8),
    /// `V`: hardware and software version.
    Version,
    /// `N`: serial number.
    Serial,
    /// `F`: status flags.
    Status,
    /// `Zn`: timestamps on received frames off (0) or on (1).
    Timestamps(bool),
    /// `t`, `T`, `r`, `R`: transmit a frame.
    Transmit(Frame),
}

fn hex(bytes: &[u8]) -> Result<u32, WireError> {
    if bytes.is_empty() || bytes.len() > 8 || !bytes.iter().all(u8::is_ascii_hexdigit) {
        return Err(WireError::Syntax);
    }
    let text = core::str::from_utf8(bytes).map_err(|_| WireError::Syntax)?;
    u32::from_str_radix(text, 16).map_err(|_| WireError::Syntax)
}

/// Parse one command line, without its `\r`.
pub fn parse_command(line: &[u8]) -> Result<Command, WireError> {
    let Some((&first, rest)) = line.split_first() else {
        return Ok(Command::Empty);
    };
    let bare = |c: Command| {
        if rest.is_empty() {
            Ok(c)
        } else {
            Err(WireError::Syntax)
        }
    };
    match first {
        b'O' => bare(Command::Open),
        b'L' => bare(Command::ListenOnly),
        b'C' => bare(Command::Close),
        b'V' => bare(Command::Version),
        b'N' => bare(Command::Serial),
        b'F' => bare(Command::Status),
        b'S' => match rest {
            [d @ b'0'..=b'9'] => Ok(Command::Bitrate(d - b'0')),
            _ => Err(WireError::Syntax),
        },
        b's' if rest.len() == 4 => {
            let v = hex(rest)?;
            Ok(Command::Btr((v >> 8) as u8, v as u8))
        }
        b's' => Err(WireError::Syntax),
        b'Z' => match rest {
            b"0" => Ok(Command::Timestamps(false)),
            b"1" => Ok(Command::Timestamps(true)),
            _ => Err(WireError::Syntax),
        },
        b't' | b'T' | b'r' | b'R' => parse_frame(line).map(Command::Transmit),
        b'd' | b'D' | b'b' | b'B' => Err(WireError::Fd),
        _ => Err(WireError::Unknown),
    }
}

/// Parse a frame record (`t`, `T`, `r`, `R`), without its `\r`.
pub fn parse_frame(line: &[u8]) -> Result<Frame, WireError> {
    let (&kind, rest) = line.split_first().ok_or(WireError::Syntax)?;
    let (extended, remote) = match kind {
        b't' => (false, false),
        b'T' => (true, false),
        b'r' => (false, true),
        b'R' => (true, true),
        _ => return Err(WireError::Unknown),
    };
    let id_len = if extended { 8 } else { 3 };
    if rest.len() < id_len + 1 {
        return Err(WireError::Syntax);
    }
    let (id_text, rest) = rest.split_at(id_len);
    let raw = hex(id_text)?;
    let id = if extended {
        Id::extended(raw)?
    } else {
        Id::standard(raw as u16)?
    };
    let (dlc, data) = match rest.split_first() {
        Some((&d @ b'0'..=b'8', data)) => (d - b'0', data),
        _ => return Err(WireError::Syntax),
    };
    if remote {
        if !data.is_empty() {
            return Err(WireError::Syntax);
        }
        return Ok(Frame::remote(id, dlc)?);
    }
    if data.len() != usize::from(dlc) * 2 {
        return Err(WireError::Syntax);
    }
    let mut bytes = [0u8; 8];
    for (slot, pair) in bytes.iter_mut().zip(data.chunks(2)) {
        *slot = hex(pair)? as u8;
    }
    Ok(Frame::data(id, &bytes[..usize::from(dlc)])?)
}

fn push_hex(out: &mut Vec<u8>, b: u8) {
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    out.push(HEX[usize::from(b >> 4)]);
    out.push(HEX[usize::from(b & 0xF)]);
}

/// Append `frame` as a record, `\r` included.
pub fn write_frame(out: &mut Vec<u8>, frame: &Frame) {
    let kind = match (frame.is_extended(), frame.is_remote()) {
        (false, false) => b't',
        (true, false) => b'T',
        (false, true) => b'r',
        (true, true) => b'R',
    };
    out.push(kind);
    // `Id`'s display is three or eight upper-case hex digits, as the records need.
    out.extend_from_slice(frame.id().to_string().as_bytes());
    out.push(b'0' + frame.dlc());
    for &b in frame.data_bytes() {
        push_hex(out, b);
    }
    out.push(b'\r');
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(f: &Frame) -> Vec<u8> {
        let mut out = Vec::new();
        write_frame(&mut out, f);
        out
    }

    #[test]
    fn records_as_python_can_writes_them() {
        assert_eq!(
            parse_command(b"t60584000100000000000"),
            Ok(Command::Transmit(
                Frame::std(0x605, &[0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]).unwrap()
            ))
        );
        assert_eq!(
            parse_command(b"r7051"),
            Ok(Command::Transmit(
                Frame::remote(Id::standard(0x705).unwrap(), 1).unwrap()
            ))
        );
        assert_eq!(
            parse_command(b"R01ABCDEF8"),
            Ok(Command::Transmit(
                Frame::remote(Id::extended(0x1AB_CDEF).unwrap(), 8).unwrap()
            ))
        );
        assert_eq!(
            parse_command(b"T000001232abcd"),
            Ok(Command::Transmit(
                Frame::data(Id::extended(0x123).unwrap(), &[0xAB, 0xCD]).unwrap()
            ))
        );
    }

    #[test]
    fn records_written() {
        assert_eq!(line(&Frame::std(0x80, &[]).unwrap()), b"t0800\r");
        assert_eq!(
            line(&Frame::remote(Id::standard(0x705).unwrap(), 1).unwrap()),
            b"r7051\r"
        );
        assert_eq!(
            line(&Frame::data(Id::extended(0x1FFF_FFFF).unwrap(), &[0xDE, 0xAD]).unwrap()),
            b"T1FFFFFFF2DEAD\r"
        );
        assert_eq!(
            line(&Frame::remote(Id::extended(5).unwrap(), 0).unwrap()),
            b"R000000050\r"
        );
    }

    #[test]
    fn commands() {
        assert_eq!(parse_command(b""), Ok(Command::Empty));
        assert_eq!(parse_command(b"O"), Ok(Command::Open));
        assert_eq!(parse_command(b"C"), Ok(Command::Close));
        assert_eq!(parse_command(b"S6"), Ok(Command::Bitrate(6)));
        assert_eq!(parse_command(b"s031C"), Ok(Command::Btr(0x03, 0x1C)));
        assert_eq!(parse_command(b"Z0"), Ok(Command::Timestamps(false)));
        assert_eq!(parse_command(b"V"), Ok(Command::Version));
        assert_eq!(parse_command(b"X"), Err(WireError::Unknown));
        assert_eq!(parse_command(b"O1"), Err(WireError::Syntax));
        assert_eq!(parse_command(b"SA"), Err(WireError::Syntax));
        assert_eq!(parse_command(b"d1231AA"), Err(WireError::Fd));
    }

    #[test]
    fn malformed_records() {
        for bad in [
            &b"t"[..],
            b"t123",
            b"t1239",
            b"t1231A",
            b"t1231AAA",
            b"t12G0",
            b"r12310",
            b"T1230",
        ] {
            assert_eq!(
                parse_command(bad),
                Err(WireError::Syntax),
                "{}",
                String::from_utf8_lossy(bad)
            );
        }
        assert!(matches!(parse_command(b"t8000"), Err(WireError::Id(_))));
        assert!(matches!(
            parse_command(b"T200000000"),
            Err(WireError::Id(_))
        ));
    }
}
