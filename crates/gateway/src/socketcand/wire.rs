//! The socketcand wire format, without any I/O: splitting a byte stream into `< … >` elements,
//! parsing commands and server messages into typed values, and formatting them back.
//!
//! Facts from linux-can/socketcand `doc/protocol.md` and its raw-mode state machine:
//!
//! * every element is `< … >`; a receiver scans for `<`, then for the first `>`, and drops the
//!   bytes in between elements;
//! * `< send ID DLC B0 B1 … >`: `ID` in hex, eight hex digits meaning an extended identifier;
//!   `DLC` a number 0–8; the bytes in hex, space separated, leading zeros optional;
//! * `< frame ID SECS.USECS DATA >` in raw mode: `ID` as three (standard) or eight (extended)
//!   upper-case hex digits, the timestamp as seconds and six digits of microseconds, `DATA` as
//!   upper-case hex without spaces. The daemon writes the text before and after `DATA` with a
//!   space each, so a frame without data has two spaces before `>`; python-can fails on a
//!   zero-length frame written with one space.
//!
//! Extension: python-can writes a remote frame as a `send` with its DLC and no data bytes
//! (`< send 705 1  >`), which the daemon rejects as a syntax error. Here a `send` whose DLC is
//! above zero and which carries no data bytes is a remote frame of that DLC. A remote frame
//! with DLC 0 cannot be told apart from an empty data frame and is read as the latter.
//! Remote frames are not sent to clients in raw mode, as the daemon does not either
//! (python-can could not tell them from data frames).

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use cantwin_can::{Frame, FrameError, Id, IdError};

/// The greeting a server sends on accept.
pub const HI: &[u8] = b"< hi >";
/// The positive reply to `open`, `rawmode` and the other mode changes.
pub const OK: &[u8] = b"< ok >";
/// socketcand's limit on one element, in bytes.
pub const MAX_ELEMENT: usize = 8290;

/// An element that does not parse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    /// Not text, or not framed by `<` and `>`.
    #[error("not a socketcand element")]
    Malformed,
    /// An empty element `< >`.
    #[error("empty element")]
    Empty,
    /// A command this protocol does not know.
    #[error("unknown command")]
    UnknownCommand,
    /// A known command with wrong arguments.
    #[error("syntax error in {0} command")]
    Syntax(&'static str),
    /// An identifier out of range.
    #[error(transparent)]
    Id(#[from] IdError),
    /// A frame that cannot exist.
    #[error(transparent)]
    Frame(#[from] FrameError),
}

/// A command from a client to the server.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// `< open NAME >`: attach to bus `NAME`.
    Open(String),
    /// `< rawmode >`: receive every frame on the bus.
    RawMode,
    /// `< bcmmode >`: back to the default broadcast-manager mode.
    BcmMode,
    /// `< controlmode >`.
    ControlMode,
    /// `< isotpmode >`.
    IsoTpMode,
    /// `< echo >`: the server echoes it back.
    Echo,
    /// `< send ID DLC DATA… >`: transmit a frame.
    Send(Frame),
    /// `< add SECS USECS ID DLC DATA… >`: send a frame every interval (broadcast manager).
    Add {
        /// The interval; zero sets up a job that never sends.
        interval: Duration,
        /// The frame.
        frame: Frame,
    },
    /// `< update ID DLC DATA… >`: change the frame of a job, its timer untouched.
    Update(Frame),
    /// `< delete ID >`: remove a job.
    Delete(Id),
    /// `< subscribe SECS USECS ID >`: receive every frame of an identifier, at most one per
    /// throttle time.
    Subscribe {
        /// The throttle time (zero: every frame).
        throttle: Duration,
        /// The identifier.
        id: Id,
    },
    /// `< filter SECS USECS ID DLC MASK… >`: receive frames whose data changed under a mask.
    Filter {
        /// The throttle time (zero: every change).
        throttle: Duration,
        /// The identifier.
        id: Id,
        /// The mask's bytes (zero beyond them).
        mask: Vec<u8>,
    },
    /// `< muxfilter SECS USECS ID N MASKS… >`: a multiplexer mask and N − 1 filters, each for
    /// the multiplexer value it carries under the multiplexer mask.
    MuxFilter {
        /// The throttle time.
        throttle: Duration,
        /// The identifier.
        id: Id,
        /// The multiplexer mask first, then the filters (2 to 257 in all).
        masks: Vec<[u8; 8]>,
    },
    /// `< unsubscribe ID >`: remove a subscription or filter.
    Unsubscribe(Id),
    /// A control or ISO-TP command (`statistics`, `isotpconf`, `sendpdu`, `fdsend`, `sendfd`)
    /// or a bus configuration command, named here by its first word.
    Other(String),
}

impl Command {
    /// Whether this is a broadcast-manager command (`add`, `update`, `delete`, `subscribe`,
    /// `filter`, `muxfilter`, `unsubscribe`).
    pub fn is_broadcast_manager(&self) -> bool {
        matches!(
            self,
            Command::Add { .. }
                | Command::Update(_)
                | Command::Delete(_)
                | Command::Subscribe { .. }
                | Command::Filter { .. }
                | Command::MuxFilter { .. }
                | Command::Unsubscribe(_)
        )
    }
}

/// A message from the server to a client.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ServerMessage {
    /// `< hi >`.
    Hi,
    /// `< ok >`.
    Ok,
    /// `< echo >`.
    Echo,
    /// `< frame ID SECS.USECS DATA >`.
    Frame {
        /// The frame.
        frame: Frame,
        /// Its timestamp.
        timestamp: SystemTime,
    },
    /// `< error TEXT >`.
    Error(String),
    /// Any other element, verbatim without the brackets.
    Other(String),
}

/// Splits a byte stream into `< … >` elements, with a bound on an element's length.
#[derive(Debug, Clone)]
pub struct Framer {
    buf: Vec<u8>,
    max: usize,
    state: FramerState,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FramerState {
    /// Between elements: bytes are dropped until `<`.
    Outside,
    /// Inside an element.
    Inside,
    /// Inside an element that outgrew the limit: bytes are dropped until `>`.
    Skipping,
}

/// What [`Framer::push`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Framed<'a> {
    /// A complete element, `<` and `>` included.
    Element(&'a [u8]),
    /// An element grew past the limit; it is dropped up to its closing `>`.
    TooLong,
}

impl Framer {
    /// A framer that accepts elements of up to `max` bytes (at least 2).
    pub fn new(max: usize) -> Self {
        Framer {
            buf: Vec::new(),
            max: max.max(2),
            state: FramerState::Outside,
        }
    }

    /// Bytes of the element being received (0 between elements).
    pub fn pending(&self) -> usize {
        match self.state {
            FramerState::Inside => self.buf.len(),
            FramerState::Outside | FramerState::Skipping => 0,
        }
    }

    /// Feed one byte; returns an element when this byte completes one.
    pub fn push(&mut self, byte: u8) -> Option<Framed<'_>> {
        match self.state {
            FramerState::Outside => {
                if byte == b'<' {
                    self.buf.clear();
                    self.buf.push(byte);
                    self.state = FramerState::Inside;
                }
                None
            }
            FramerState::Inside => {
                self.buf.push(byte);
                if byte == b'>' {
                    self.state = FramerState::Outside;
                    Some(Framed::Element(&self.buf))
                } else if self.buf.len() >= self.max {
                    self.buf.clear();
                    self.state = FramerState::Skipping;
                    Some(Framed::TooLong)
                } else {
                    None
                }
            }
            FramerState::Skipping => {
                if byte == b'>' {
                    self.state = FramerState::Outside;
                }
                None
            }
        }
    }
}

/// The words of an element between `<` and `>`.
fn words(element: &[u8]) -> Result<Vec<&str>, WireError> {
    let text = core::str::from_utf8(element).map_err(|_| WireError::Malformed)?;
    let inner = text
        .strip_prefix('<')
        .and_then(|t| t.strip_suffix('>'))
        .ok_or(WireError::Malformed)?;
    let words: Vec<&str> = inner.split_ascii_whitespace().collect();
    if words.is_empty() {
        return Err(WireError::Empty);
    }
    Ok(words)
}

fn parse_hex_u32(s: &str) -> Option<u32> {
    if s.is_empty() || s.len() > 8 || !s.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    u32::from_str_radix(s, 16).ok()
}

/// An identifier token: eight hex digits mean extended format, fewer standard (the daemon
/// reads the value with `%x` and looks only at the token's length).
fn parse_id(s: &str, cmd: &'static str) -> Result<Id, WireError> {
    let raw = parse_hex_u32(s).ok_or(WireError::Syntax(cmd))?;
    if s.len() == 8 {
        Ok(Id::extended(raw)?)
    } else {
        let raw = u16::try_from(raw).map_err(|_| IdError::StandardOutOfRange(raw))?;
        Ok(Id::standard(raw)?)
    }
}

/// Parse a client command from one element (`<` and `>` included).
pub fn parse_command(element: &[u8]) -> Result<Command, WireError> {
    let words = words(element)?;
    let args = &words[1..];
    let bare = |c: Command, name: &'static str| {
        if args.is_empty() {
            Ok(c)
        } else {
            Err(WireError::Syntax(name))
        }
    };
    match words[0] {
        "open" => match args {
            [name] => Ok(Command::Open((*name).to_owned())),
            _ => Err(WireError::Syntax("open")),
        },
        "rawmode" => bare(Command::RawMode, "rawmode"),
        "bcmmode" => bare(Command::BcmMode, "bcmmode"),
        "controlmode" => bare(Command::ControlMode, "controlmode"),
        "isotpmode" => bare(Command::IsoTpMode, "isotpmode"),
        "echo" => bare(Command::Echo, "echo"),
        "send" => parse_send(args).map(Command::Send),
        "add" => match args {
            [secs, usecs, id, dlc, bytes @ ..] => Ok(Command::Add {
                interval: parse_interval(secs, usecs, "add")?,
                frame: parse_data_frame(id, dlc, bytes, "add")?,
            }),
            _ => Err(WireError::Syntax("add")),
        },
        "update" => match args {
            [id, dlc, bytes @ ..] => {
                parse_data_frame(id, dlc, bytes, "update").map(Command::Update)
            }
            _ => Err(WireError::Syntax("update")),
        },
        // The daemon reads the arguments it needs and ignores what follows them.
        "delete" => match args {
            [id, ..] => parse_id(id, "delete").map(Command::Delete),
            _ => Err(WireError::Syntax("delete")),
        },
        "subscribe" => match args {
            [secs, usecs, id, ..] => Ok(Command::Subscribe {
                throttle: parse_interval(secs, usecs, "subscribe")?,
                id: parse_id(id, "subscribe")?,
            }),
            _ => Err(WireError::Syntax("subscribe")),
        },
        "filter" => match args {
            [secs, usecs, id, dlc, bytes @ ..] => {
                let mask = parse_data_frame(id, dlc, bytes, "filter")?;
                Ok(Command::Filter {
                    throttle: parse_interval(secs, usecs, "filter")?,
                    id: mask.id(),
                    mask: mask.data_bytes().to_vec(),
                })
            }
            _ => Err(WireError::Syntax("filter")),
        },
        "muxfilter" => parse_muxfilter(args),
        "unsubscribe" => match args {
            [id, ..] => parse_id(id, "unsubscribe").map(Command::Unsubscribe),
            _ => Err(WireError::Syntax("unsubscribe")),
        },
        "statistics" | "isotpconf" | "sendpdu" | "fdsend" | "sendfd" => {
            Ok(Command::Other(words[0].to_owned()))
        }
        // Bus configuration: `< NAME B … >` and `< NAME C … >`.
        _ if matches!(args.first(), Some(&"B") | Some(&"C")) => {
            Ok(Command::Other(words[0].to_owned()))
        }
        _ => Err(WireError::UnknownCommand),
    }
}

fn parse_send(args: &[&str]) -> Result<Frame, WireError> {
    const CMD: &str = "send";
    let [id, dlc, bytes @ ..] = args else {
        return Err(WireError::Syntax(CMD));
    };
    if bytes.is_empty() && parse_dlc(dlc, CMD)? > 0 {
        // python-can's remote frame (see the module documentation).
        return Ok(Frame::remote(parse_id(id, CMD)?, parse_dlc(dlc, CMD)?)?);
    }
    parse_data_frame(id, dlc, bytes, CMD)
}

/// A DLC token: a decimal number 0–8 (leading zeros allowed, as `%hhu` reads it).
fn parse_dlc(dlc: &str, cmd: &'static str) -> Result<u8, WireError> {
    if dlc.is_empty() || dlc.len() > 3 || !dlc.bytes().all(|b| b.is_ascii_digit()) {
        return Err(WireError::Syntax(cmd));
    }
    match dlc.parse::<u8>() {
        Ok(n) if n <= 8 => Ok(n),
        _ => Err(WireError::Syntax(cmd)),
    }
}

/// One byte token: one or two hex digits.
fn parse_byte(b: &str, cmd: &'static str) -> Result<u8, WireError> {
    if b.is_empty() || b.len() > 2 {
        return Err(WireError::Syntax(cmd));
    }
    parse_hex_u32(b)
        .map(|v| v as u8)
        .ok_or(WireError::Syntax(cmd))
}

/// `ID DLC DATA…` with exactly DLC data bytes.
fn parse_data_frame(
    id: &str,
    dlc: &str,
    bytes: &[&str],
    cmd: &'static str,
) -> Result<Frame, WireError> {
    let id = parse_id(id, cmd)?;
    let dlc = parse_dlc(dlc, cmd)?;
    if bytes.len() != usize::from(dlc) {
        return Err(WireError::Syntax(cmd));
    }
    let mut data = [0u8; 8];
    for (slot, b) in data.iter_mut().zip(bytes) {
        *slot = parse_byte(b, cmd)?;
    }
    Ok(Frame::data(id, &data[..usize::from(dlc)])?)
}

/// The broadcast manager's longest timer, 400 days (`BCM_TIMER_SEC_MAX` in the kernel); a
/// longer one, or microseconds of a second or more, is refused as the kernel refuses it.
const MAX_INTERVAL_SECS: u64 = 400 * 24 * 60 * 60;

/// `SECS USECS`, both decimal.
fn parse_interval(secs: &str, usecs: &str, cmd: &'static str) -> Result<Duration, WireError> {
    let number = |s: &str| {
        if s.is_empty() || s.len() > 19 || !s.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        s.parse::<u64>().ok()
    };
    match (number(secs), number(usecs)) {
        (Some(s), Some(us)) if s <= MAX_INTERVAL_SECS && us < 1_000_000 => {
            Ok(Duration::from_secs(s) + Duration::from_micros(us))
        }
        _ => Err(WireError::Syntax(cmd)),
    }
}

/// `SECS USECS ID N` then N times eight bytes; bytes after them are ignored, as the daemon
/// ignores them.
fn parse_muxfilter(args: &[&str]) -> Result<Command, WireError> {
    const CMD: &str = "muxfilter";
    let [secs, usecs, id, n, bytes @ ..] = args else {
        return Err(WireError::Syntax(CMD));
    };
    let count: usize = match n.parse() {
        Ok(count) if (2..=257).contains(&count) && n.bytes().all(|b| b.is_ascii_digit()) => count,
        _ => return Err(WireError::Syntax(CMD)),
    };
    let n = count;
    if bytes.len() < n * 8 {
        return Err(WireError::Syntax(CMD));
    }
    let mut masks = Vec::with_capacity(n);
    for chunk in bytes[..n * 8].chunks(8) {
        let mut mask = [0u8; 8];
        for (slot, b) in mask.iter_mut().zip(chunk) {
            *slot = parse_byte(b, CMD)?;
        }
        masks.push(mask);
    }
    Ok(Command::MuxFilter {
        throttle: parse_interval(secs, usecs, CMD)?,
        id: parse_id(id, CMD)?,
        masks,
    })
}

/// Parse a server message from one element (`<` and `>` included).
pub fn parse_server_message(element: &[u8]) -> Result<ServerMessage, WireError> {
    let words = words(element)?;
    match (words[0], &words[1..]) {
        ("hi", []) => Ok(ServerMessage::Hi),
        ("ok", []) => Ok(ServerMessage::Ok),
        ("echo", []) => Ok(ServerMessage::Echo),
        ("error", rest) => Ok(ServerMessage::Error(rest.join(" "))),
        ("frame", [id, ts, data @ ..]) => {
            let id = parse_id(id, "frame")?;
            let timestamp = parse_timestamp(ts).ok_or(WireError::Syntax("frame"))?;
            // Raw mode writes the data as one run of hex digits, broadcast-manager mode
            // byte by byte; both are accepted.
            let mut bytes = [0u8; 8];
            let mut n = 0usize;
            for word in data {
                if word.len() % 2 != 0 {
                    return Err(WireError::Syntax("frame"));
                }
                for pair in word.as_bytes().chunks(2) {
                    let pair = core::str::from_utf8(pair).map_err(|_| WireError::Malformed)?;
                    let v = parse_hex_u32(pair).ok_or(WireError::Syntax("frame"))?;
                    *bytes.get_mut(n).ok_or(FrameError::TooLong(n + 1))? = v as u8;
                    n += 1;
                }
            }
            Ok(ServerMessage::Frame {
                frame: Frame::data(id, &bytes[..n])?,
                timestamp,
            })
        }
        _ => Ok(ServerMessage::Other(words.join(" "))),
    }
}

fn parse_timestamp(s: &str) -> Option<SystemTime> {
    let (secs, usecs) = s.split_once('.')?;
    if secs.is_empty()
        || usecs.is_empty()
        || usecs.len() > 6
        || !secs.bytes().all(|b| b.is_ascii_digit())
        || !usecs.bytes().all(|b| b.is_ascii_digit())
    {
        return None;
    }
    let secs: u64 = secs.parse().ok()?;
    let mut micros: u32 = usecs.parse().ok()?;
    for _ in usecs.len()..6 {
        micros *= 10;
    }
    UNIX_EPOCH.checked_add(Duration::new(secs, micros * 1_000))
}

fn push_hex(out: &mut Vec<u8>, b: u8) {
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    out.push(HEX[usize::from(b >> 4)]);
    out.push(HEX[usize::from(b & 0xF)]);
}

fn push_id(out: &mut Vec<u8>, id: Id) {
    // `Id`'s display is exactly the daemon's `%03X` / `%08X`.
    out.extend_from_slice(id.to_string().as_bytes());
}

/// Append a raw-mode `< frame … >` element for a data frame received at `timestamp`.
///
/// Remote frames are not carried to clients (see the module documentation): for one, nothing
/// is appended and `false` is returned.
pub fn write_frame(out: &mut Vec<u8>, frame: &Frame, timestamp: SystemTime) -> bool {
    write_frame_element(out, frame, timestamp, b"")
}

fn write_frame_element(
    out: &mut Vec<u8>,
    frame: &Frame,
    timestamp: SystemTime,
    after_byte: &[u8],
) -> bool {
    if frame.is_remote() {
        return false;
    }
    let since = timestamp.duration_since(UNIX_EPOCH).unwrap_or_default();
    out.extend_from_slice(b"< frame ");
    push_id(out, frame.id());
    out.extend_from_slice(format!(" {}.{:06} ", since.as_secs(), since.subsec_micros()).as_bytes());
    for &b in frame.data_bytes() {
        push_hex(out, b);
        out.extend_from_slice(after_byte);
    }
    out.extend_from_slice(b" >");
    true
}

/// Append a broadcast-manager-mode `< frame … >` element: as [`write_frame`], but each data
/// byte followed by a space (the daemon's BCM mode writes `%02X ` per byte, then ` >`).
pub fn write_bcm_frame(out: &mut Vec<u8>, frame: &Frame, timestamp: SystemTime) -> bool {
    write_frame_element(out, frame, timestamp, b" ")
}

/// Append a `< send … >` element for `frame`; a remote frame is written with its DLC and no
/// data bytes (see the module documentation).
pub fn write_send(out: &mut Vec<u8>, frame: &Frame) {
    out.extend_from_slice(b"< send ");
    push_id(out, frame.id());
    out.extend_from_slice(format!(" {}", frame.dlc()).as_bytes());
    for &b in frame.data_bytes() {
        out.push(b' ');
        push_hex(out, b);
    }
    out.extend_from_slice(b" >");
}

/// Append an `< error TEXT >` element.
pub fn write_error(out: &mut Vec<u8>, text: &str) {
    out.extend_from_slice(b"< error ");
    out.extend_from_slice(text.as_bytes());
    out.extend_from_slice(b" >");
}

/// Append an `< open NAME >` element.
pub fn write_open(out: &mut Vec<u8>, channel: &str) {
    out.extend_from_slice(b"< open ");
    out.extend_from_slice(channel.as_bytes());
    out.extend_from_slice(b" >");
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ts(secs: u64, micros: u32) -> SystemTime {
        UNIX_EPOCH + Duration::new(secs, micros * 1000)
    }

    #[test]
    fn frame_zero_length_has_two_spaces() {
        let mut out = Vec::new();
        assert!(write_frame(
            &mut out,
            &Frame::std(0x80, &[]).unwrap(),
            ts(1_700_000_000, 0)
        ));
        assert_eq!(out, b"< frame 080 1700000000.000000  >");
    }

    #[test]
    fn frame_standard_and_extended_ids() {
        let mut out = Vec::new();
        write_frame(
            &mut out,
            &Frame::std(0x1A, &[0x1A, 0x22, 0x03, 0x44]).unwrap(),
            ts(12, 345),
        );
        assert_eq!(out, b"< frame 01A 12.000345 1A220344 >");
        out.clear();
        write_frame(
            &mut out,
            &Frame::data(Id::extended(0x1AAA_AAAA).unwrap(), &[0xF1]).unwrap(),
            ts(1, 999_999),
        );
        assert_eq!(out, b"< frame 1AAAAAAA 1.999999 F1 >");
    }

    #[test]
    fn remote_frames_are_not_written() {
        let mut out = Vec::new();
        let f = Frame::remote(Id::standard(0x705).unwrap(), 1).unwrap();
        assert!(!write_frame(&mut out, &f, ts(1, 0)));
        assert!(out.is_empty());
    }

    #[test]
    fn send_as_python_can_writes_it() {
        let p = |s: &[u8]| parse_command(s).unwrap();
        assert_eq!(
            p(b"< send 123 0  >"),
            Command::Send(Frame::std(0x123, &[]).unwrap())
        );
        assert_eq!(
            p(b"< send 123 2 1 f1 >"),
            Command::Send(Frame::std(0x123, &[1, 0xF1]).unwrap())
        );
        assert_eq!(
            p(b"< send 1AAAAAAA 1 a >"),
            Command::Send(Frame::data(Id::extended(0x1AAA_AAAA).unwrap(), &[0xA]).unwrap())
        );
        assert_eq!(
            p(b"< send 605 8 40 0 10 0 0 0 0 0 >"),
            Command::Send(Frame::std(0x605, &[0x40, 0, 0x10, 0, 0, 0, 0, 0]).unwrap())
        );
        assert_eq!(
            p(b"< send 705 1  >"),
            Command::Send(Frame::remote(Id::standard(0x705).unwrap(), 1).unwrap())
        );
        // Eight digits mean extended even for a small value.
        assert_eq!(
            p(b"< send 00000001 0 >"),
            Command::Send(Frame::data(Id::extended(1).unwrap(), &[]).unwrap())
        );
    }

    #[test]
    fn send_syntax_errors() {
        for bad in [
            &b"< send >"[..],
            b"< send 123 >",
            b"< send 123 9 >",
            b"< send 123 2 1 >",
            b"< send 123 1 1 2 >",
            b"< send 123 1 100 >",
            b"< send 123456789 0 >",
            b"< send xyz 0 >",
            b"< send 123 -1 >",
            b"< send 123 1 g >",
        ] {
            assert_eq!(
                parse_command(bad),
                Err(WireError::Syntax("send")),
                "{}",
                String::from_utf8_lossy(bad)
            );
        }
        assert!(matches!(
            parse_command(b"< send 800 0 >"),
            Err(WireError::Id(_))
        ));
        // Four digits are a standard identifier, as the daemon reads them: too large here.
        assert!(matches!(
            parse_command(b"< send 1234 0 >"),
            Err(WireError::Id(_))
        ));
        assert!(matches!(
            parse_command(b"< send 20000000 0 >"),
            Err(WireError::Id(_))
        ));
    }

    #[test]
    fn commands() {
        assert_eq!(
            parse_command(b"< open vcan0 >"),
            Ok(Command::Open("vcan0".into()))
        );
        assert_eq!(parse_command(b"<rawmode>"), Ok(Command::RawMode));
        assert_eq!(parse_command(b"< echo >"), Ok(Command::Echo));
        assert_eq!(
            parse_command(b"< statistics 1000 >"),
            Ok(Command::Other("statistics".into()))
        );
        assert_eq!(
            parse_command(b"< vcan0 C 0 0 0 >"),
            Ok(Command::Other("vcan0".into()))
        );
        assert_eq!(parse_command(b"< bogus >"), Err(WireError::UnknownCommand));
        assert_eq!(parse_command(b"< >"), Err(WireError::Empty));
        assert_eq!(
            parse_command(b"< rawmode x >"),
            Err(WireError::Syntax("rawmode"))
        );
        assert_eq!(parse_command(b"< \xff >"), Err(WireError::Malformed));
    }

    #[test]
    fn broadcast_manager_commands_from_the_daemons_documentation() {
        let std = |id| Id::standard(id).unwrap();
        assert_eq!(
            parse_command(b"< add 1 0 123 8 11 22 33 44 55 66 77 88 >"),
            Ok(Command::Add {
                interval: Duration::from_secs(1),
                frame: Frame::std(0x123, &[0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88])
                    .unwrap()
            })
        );
        assert_eq!(
            parse_command(b"< add 0 20000 123 4 42 42 42 42 >"),
            Ok(Command::Add {
                interval: Duration::from_millis(20),
                frame: Frame::std(0x123, &[0x42; 4]).unwrap()
            })
        );
        assert_eq!(
            parse_command(b"< update 123 3 11 22 33 >"),
            Ok(Command::Update(
                Frame::std(0x123, &[0x11, 0x22, 0x33]).unwrap()
            ))
        );
        assert_eq!(
            parse_command(b"< delete 123 >"),
            Ok(Command::Delete(std(0x123)))
        );
        assert_eq!(
            parse_command(b"< filter 1 500000 123 8 FF 00 F8 00 00 00 00 00 >"),
            Ok(Command::Filter {
                throttle: Duration::from_millis(1500),
                id: std(0x123),
                mask: vec![0xFF, 0, 0xF8, 0, 0, 0, 0, 0]
            })
        );
        assert_eq!(
            parse_command(
                b"< muxfilter 0 0 123 2 FF 00 00 00 00 00 00 00 33 FF FF FF FF FF FF FF >"
            ),
            Ok(Command::MuxFilter {
                throttle: Duration::ZERO,
                id: std(0x123),
                masks: vec![
                    [0xFF, 0, 0, 0, 0, 0, 0, 0],
                    [0x33, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF]
                ]
            })
        );
        assert_eq!(
            parse_command(b"< subscribe 0 0 123 >"),
            Ok(Command::Subscribe {
                throttle: Duration::ZERO,
                id: std(0x123)
            })
        );
        assert_eq!(
            parse_command(b"< subscribe 0 0 1AAAAAAA >"),
            Ok(Command::Subscribe {
                throttle: Duration::ZERO,
                id: Id::extended(0x1AAA_AAAA).unwrap()
            })
        );
        assert_eq!(
            parse_command(b"< unsubscribe 123 >"),
            Ok(Command::Unsubscribe(std(0x123)))
        );
        // As the daemon reads them: what follows the arguments is ignored, an identifier of
        // four to seven digits is a standard one, a DLC may have leading zeros.
        assert_eq!(
            parse_command(b"< unsubscribe 123 456 >"),
            Ok(Command::Unsubscribe(std(0x123)))
        );
        assert_eq!(
            parse_command(b"< update 0000123 08 1 2 3 4 5 6 7 8 >"),
            Ok(Command::Update(
                Frame::std(0x123, &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap()
            ))
        );
        assert!(matches!(
            parse_command(b"< delete 1234 >"),
            Err(WireError::Id(_))
        ));
        for bad in [
            &b"< add 1 0 123 2 11 >"[..],
            b"< add 1 1000000 123 0 >",
            b"< add 34560001 0 123 0 >",
            b"< add -1 0 123 0 >",
            b"< update 123 >",
            b"< delete >",
            b"< subscribe 0 123 >",
            b"< filter 0 0 123 9 >",
            b"< muxfilter 0 0 123 1 FF 00 00 00 00 00 00 00 >",
            b"< muxfilter 0 0 123 2 FF 00 00 00 00 00 00 00 33 >",
        ] {
            assert!(
                matches!(parse_command(bad), Err(WireError::Syntax(_))),
                "{}",
                String::from_utf8_lossy(bad)
            );
        }
    }

    #[test]
    fn broadcast_manager_frames_have_a_space_after_each_byte() {
        let mut out = Vec::new();
        let frame = Frame::std(0x123, &[0x11, 0x22, 0x33]).unwrap();
        assert!(write_bcm_frame(&mut out, &frame, ts(1_700_000_000, 250)));
        assert_eq!(out, b"< frame 123 1700000000.000250 11 22 33  >");
        out.clear();
        write_bcm_frame(&mut out, &Frame::std(0x80, &[]).unwrap(), ts(1, 0));
        assert_eq!(out, b"< frame 080 1.000000  >");
        let remote = Frame::remote(Id::standard(0x123).unwrap(), 1).unwrap();
        assert!(!write_bcm_frame(&mut out, &remote, ts(1, 0)));
    }

    #[test]
    fn server_messages() {
        assert_eq!(parse_server_message(HI), Ok(ServerMessage::Hi));
        assert_eq!(parse_server_message(OK), Ok(ServerMessage::Ok));
        assert_eq!(
            parse_server_message(b"< error could not open bus >"),
            Ok(ServerMessage::Error("could not open bus".into()))
        );
        assert_eq!(
            parse_server_message(b"< frame 080 1700000000.000000  >"),
            Ok(ServerMessage::Frame {
                frame: Frame::std(0x80, &[]).unwrap(),
                timestamp: ts(1_700_000_000, 0)
            })
        );
        // Broadcast-manager style, bytes spaced.
        assert_eq!(
            parse_server_message(b"< frame 123 5.5 11 22 >"),
            Ok(ServerMessage::Frame {
                frame: Frame::std(0x123, &[0x11, 0x22]).unwrap(),
                timestamp: ts(5, 500_000)
            })
        );
        assert!(parse_server_message(b"< frame 123 5.5 112 >").is_err());
        assert!(parse_server_message(b"< frame 123 5.5 112233445566778899 >").is_err());
    }

    #[test]
    fn framer_drops_bytes_outside_and_bounds_elements() {
        let mut f = Framer::new(10);
        let mut got = Vec::new();
        for &b in b"junk< hi >more<   long element here > < ok >" {
            match f.push(b) {
                Some(Framed::Element(e)) => got.push(String::from_utf8_lossy(e).into_owned()),
                Some(Framed::TooLong) => got.push("TOO LONG".into()),
                None => {}
            }
        }
        assert_eq!(got, ["< hi >", "TOO LONG", "< ok >"]);
        assert_eq!(f.pending(), 0);
    }
}
