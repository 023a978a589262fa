//! Request lines: `[<seq>] [[<net>] <node>] <command>`, parsed into an answer now or a bus
//! operation whose result [`Pending::finish`] turns into the answer line.

use cantwin_canopen::sdo::wire::Mux;
use cantwin_canopen::wire::NmtCs;

use crate::error::GwError;
use crate::value::{Ty, encode, show, ty};

/// The only network the gateway serves.
pub const NET: u32 = 1;

/// What a request asks of the bus.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BusOp {
    /// An SDO upload (read) from `node`.
    Upload {
        /// The SDO server's node-ID.
        node: u8,
        /// The object read.
        mux: Mux,
    },
    /// An SDO download (write) of `data` to `node`.
    Download {
        /// The SDO server's node-ID.
        node: u8,
        /// The object written.
        mux: Mux,
        /// The bytes written.
        data: Vec<u8>,
    },
    /// An NMT command to `node` (0: all nodes).
    Nmt {
        /// The node addressed, 0 for all.
        node: u8,
        /// The command specifier.
        cs: NmtCs,
    },
}

/// One client's settings, which `set` requests change.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Session {
    /// The default node (`set node`), for requests without a node.
    pub node: Option<u8>,
    /// The SDO timeout in milliseconds (`set sdo_timeout`).
    pub sdo_timeout_ms: u32,
    /// Whether SDO transfers use block transfer (`set sdo_block 1`).
    pub block: bool,
}

impl Session {
    /// A client with no default node, the given SDO timeout and no block transfer.
    pub fn new(sdo_timeout_ms: u32) -> Session {
        Session {
            node: None,
            sdo_timeout_ms,
            block: false,
        }
    }
}

/// What a request line needs: an answer now, or a bus operation first.
#[derive(Debug)]
pub enum Step {
    /// The answer, ready to send (one or more lines, the sequence number on the last).
    Answer(String),
    /// A bus operation to run; its result gives the answer.
    Bus(Pending),
}

/// A bus operation a request waits for, and how its result is answered.
#[derive(Debug)]
pub struct Pending {
    seq: Option<u32>,
    op: BusOp,
    show: Option<Option<Ty>>,
}

impl Pending {
    /// The operation to run on the bus.
    pub fn op(&self) -> &BusOp {
        &self.op
    }

    /// The answer line for the operation's result: the uploaded bytes (shown in the
    /// request's type), or why it failed. Downloads and NMT commands answer `OK`.
    pub fn finish(self, result: Result<Vec<u8>, GwError>) -> String {
        let text = result.and_then(|data| match self.show {
            Some(t) => show(t, &data),
            None => Ok("OK".into()),
        });
        sequenced(self.seq, text)
    }
}

/// What a parsed request needs: a bus operation (answered by `show`), or an answer now.
#[derive(Debug)]
enum Action {
    Bus { op: BusOp, show: Option<Option<Ty>> },
    Answer(String),
}

/// The answer text with its sequence number: a multi-line answer (help) carries it on its
/// last line.
fn sequenced(seq: Option<u32>, result: Result<String, GwError>) -> String {
    let text = match result {
        Ok(t) => t,
        Err(e) => format!("ERROR: {e}"),
    };
    match seq {
        Some(n) => match text.rsplit_once('\n') {
            Some((head, last)) => format!("{head}\n[{n}] {last}"),
            None => format!("[{n}] {text}"),
        },
        None => text,
    }
}

/// Handles one request line for a client with settings `s`: `set` requests change them.
pub fn request(line: &str, s: &mut Session) -> Step {
    let line = line.trim();
    let (seq, rest) = match line.strip_prefix('[') {
        Some(r) => match r.split_once(']') {
            Some((n, rest)) => match n.trim().parse::<u32>() {
                Ok(n) => (Some(n), rest),
                Err(_) => return Step::Answer(format!("ERROR: {}", GwError::SYNTAX)),
            },
            None => return Step::Answer(format!("ERROR: {}", GwError::SYNTAX)),
        },
        None => (None, line),
    };
    match parse(rest, s) {
        Ok(Action::Answer(a)) => Step::Answer(sequenced(seq, Ok(a))),
        Ok(Action::Bus { op, show }) => Step::Bus(Pending { seq, op, show }),
        Err(e) => Step::Answer(sequenced(seq, Err(e))),
    }
}

/// A whitespace-separated word of `line` and where the rest of the line starts after it.
fn words(line: &str) -> Vec<(&str, usize)> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, c) in line.char_indices() {
        match (c.is_whitespace(), start) {
            (true, Some(s)) => {
                out.push((&line[s..i], i));
                start = None;
            }
            (false, None) => start = Some(i),
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push((&line[s..], line.len()));
    }
    out
}

/// A number, decimal or hex with `0x`.
fn number(text: &str) -> Option<u32> {
    let t = text.trim();
    match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(h) => u32::from_str_radix(h, 16).ok(),
        None => t.parse().ok(),
    }
}

/// An index and sub-index.
fn mux(index: &str, sub: &str) -> Option<Mux> {
    let i = u16::try_from(number(index)?).ok()?;
    let s = u8::try_from(number(sub)?).ok()?;
    Some(Mux::new(i, s))
}

fn net_or_node(text: &str, max: u32) -> Option<u32> {
    number(text).filter(|n| *n <= max)
}

/// Parses a request (without its `[seq]`) for a client with settings `s`.
fn parse(line: &str, s: &mut Session) -> Result<Action, GwError> {
    let w = words(line);
    if w.is_empty() {
        return Err(GwError::SYNTAX);
    }
    // `[[<net>] <node>]`: up to two leading numbers.
    let numeric = w
        .iter()
        .take_while(|(t, _)| t.starts_with(|c: char| c.is_ascii_digit()))
        .count();
    let (net, node, at) = match numeric {
        0 => (None, None, 0),
        1 => (None, Some(w[0].0), 1),
        2 => (Some(w[0].0), Some(w[1].0), 2),
        _ => return Err(GwError::SYNTAX),
    };
    if let Some(n) = net {
        let n = net_or_node(n, u32::from(u16::MAX)).ok_or(GwError::SYNTAX)?;
        if n != NET {
            return Err(GwError::NET);
        }
    }
    let node = match node {
        Some(n) => Some(
            net_or_node(n, u32::from(u8::MAX))
                .ok_or(GwError::SYNTAX)
                .and_then(|n| {
                    u8::try_from(n)
                        .ok()
                        .filter(|n| *n <= 127)
                        .ok_or(GwError::NODE)
                })?,
        ),
        None => None,
    };
    let Some(&(cmd, _)) = w.get(at) else {
        return Err(GwError::SYNTAX);
    };
    let args = &w[at + 1..];
    let sdo_node = || -> Result<u8, GwError> {
        match node.or(s.node) {
            None => Err(GwError::NO_NODE),
            Some(0) => Err(GwError::NODE),
            Some(n) => Ok(n),
        }
    };
    let cmd = cmd.to_ascii_lowercase();
    let nmt = |cs| -> Result<Action, GwError> {
        let node = node.or(s.node).ok_or(GwError::NO_NODE)?;
        Ok(Action::Bus {
            op: BusOp::Nmt { node, cs },
            show: None,
        })
    };
    match (cmd.as_str(), args) {
        ("read" | "r", [(index, _), (sub, _), rest @ ..]) if rest.len() <= 1 => {
            let node = sdo_node()?;
            let mux = mux(index, sub).ok_or(GwError::SYNTAX)?;
            let t = rest.first().map(|(m, _)| ty(m)).transpose()?;
            Ok(Action::Bus {
                op: BusOp::Upload { node, mux },
                show: Some(t),
            })
        }
        ("write" | "w", [(index, _), (sub, _), (t, end), _, ..]) => {
            let node = sdo_node()?;
            let mux = mux(index, sub).ok_or(GwError::SYNTAX)?;
            let t = ty(t)?;
            let data = encode(t, &line[*end..])?;
            Ok(Action::Bus {
                op: BusOp::Download { node, mux, data },
                show: None,
            })
        }
        ("start", []) => nmt(NmtCs::Start),
        ("stop", []) => nmt(NmtCs::Stop),
        ("preop" | "preoperational", []) => nmt(NmtCs::EnterPreOperational),
        ("reset", [(what, _)]) => match what.to_ascii_lowercase().as_str() {
            "node" => nmt(NmtCs::ResetNode),
            "comm" | "communication" => nmt(NmtCs::ResetCommunication),
            _ => Err(GwError::SYNTAX),
        },
        ("set", [(what, _), (value, _)]) if node.is_none() => {
            match what.to_ascii_lowercase().as_str() {
                "network" => {
                    let n = net_or_node(value, u32::from(u16::MAX)).ok_or(GwError::SYNTAX)?;
                    if n != NET {
                        return Err(GwError::NET);
                    }
                }
                "node" => {
                    let n = net_or_node(value, u32::from(u8::MAX)).ok_or(GwError::SYNTAX)?;
                    let n = u8::try_from(n)
                        .ok()
                        .filter(|n| (1..=127).contains(n))
                        .ok_or(GwError::NODE)?;
                    s.node = Some(n);
                }
                "sdo_timeout" => {
                    let ms = number(value).ok_or(GwError::SYNTAX)?;
                    if ms == 0 {
                        return Err(GwError::SYNTAX);
                    }
                    s.sdo_timeout_ms = ms;
                }
                "sdo_block" => match *value {
                    "0" => s.block = false,
                    "1" => s.block = true,
                    _ => return Err(GwError::SYNTAX),
                },
                _ => return Err(GwError::NOT_SUPPORTED),
            }
            Ok(Action::Answer("OK".into()))
        }
        ("info", []) => Ok(Action::Answer(format!(
            "cantwin {} CiA 309-3 ASCII gateway: net {NET}, node {}, sdo_timeout {} ms, sdo_block {}",
            env!("CARGO_PKG_VERSION"),
            s.node.map_or_else(|| "none".to_string(), |n| n.to_string()),
            s.sdo_timeout_ms,
            u8::from(s.block),
        ))),
        ("help", []) => Ok(Action::Answer(format!("{HELP}OK"))),
        (
            "read" | "r" | "write" | "w" | "start" | "stop" | "preop" | "preoperational" | "reset"
            | "set" | "info" | "help",
            _,
        ) => Err(GwError::SYNTAX),
        _ => Err(GwError::NOT_SUPPORTED),
    }
}

/// The text `help` answers with (before its final `OK`).
pub const HELP: &str = "\
Request: [<seq>] [[<net>] <node>] <command>; answer: [<seq>] OK | <value> | ERROR: <code>
  read <index> <sub> [<type>]          SDO upload (r)
  write <index> <sub> <type> <value>   SDO download (w)
  start | stop | preop | reset node | reset comm     NMT (node 0: all nodes)
  set network <net> | set node <node> | set sdo_timeout <ms> | set sdo_block <0|1>
  info | help
Types: b i8 i16 i24 i32 i40 i48 i56 i64 u8 u16 u24 u32 u40 u48 u56 u64 x8 x16 x32 x64
       r32 r64 t td vs us (\"text\") os d (hex bytes)
Errors: SDO abort code (0x...), 100 not supported, 101 syntax, 102 internal state,
        103 time-out, 105 no default node, 106 unsupported net, 107 unsupported node
";

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_canopen::AbortCode;

    fn session() -> Session {
        Session {
            node: None,
            sdo_timeout_ms: 1000,
            block: false,
        }
    }

    fn bus_op(line: &str, s: &mut Session) -> BusOp {
        match parse(line, s).unwrap() {
            Action::Bus { op, .. } => op,
            Action::Answer(a) => panic!("{line}: answered {a}"),
        }
    }

    /// The answer line, a bus operation failing as it does when the bus is gone.
    fn answer(line: &str, s: &mut Session) -> String {
        match request(line, s) {
            Step::Answer(a) => a,
            Step::Bus(p) => p.finish(Err(GwError::STATE)),
        }
    }

    #[test]
    fn cia309_3_node_prefix_and_default_node() {
        let mut s = session();
        assert_eq!(
            bus_op("5 read 0x1008 0 vs", &mut s),
            BusOp::Upload {
                node: 5,
                mux: Mux::new(0x1008, 0)
            }
        );
        assert_eq!(
            bus_op("1 5 r 4119 0", &mut s),
            BusOp::Upload {
                node: 5,
                mux: Mux::new(0x1017, 0)
            }
        );
        assert_eq!(parse("read 0x1017 0", &mut s).err(), Some(GwError::NO_NODE));
        assert!(matches!(parse("set node 7", &mut s), Ok(Action::Answer(a)) if a == "OK"));
        assert_eq!(
            bus_op("reset comm", &mut s),
            BusOp::Nmt {
                node: 7,
                cs: NmtCs::ResetCommunication
            }
        );
        assert_eq!(
            bus_op("0 start", &mut s),
            BusOp::Nmt {
                node: 0,
                cs: NmtCs::Start
            }
        );
        assert_eq!(parse("2 5 start", &mut s).err(), Some(GwError::NET));
        assert_eq!(parse("200 start", &mut s).err(), Some(GwError::NODE));
        assert_eq!(parse("0 read 0x1000 0", &mut s).err(), Some(GwError::NODE));
        assert_eq!(
            parse("5 frobnicate", &mut s).err(),
            Some(GwError::NOT_SUPPORTED)
        );
        assert_eq!(parse("5 read 0x1000", &mut s).err(), Some(GwError::SYNTAX));
        assert_eq!(
            parse("5 read 0x1000 0 q7", &mut s).err(),
            Some(GwError::SYNTAX)
        );
    }

    #[test]
    fn cia309_3_write_values_by_type() {
        let mut s = session();
        let data = |line: &str, s: &mut Session| match bus_op(line, s) {
            BusOp::Download { data, .. } => data,
            other => panic!("{other:?}"),
        };
        assert_eq!(data("5 w 0x1017 0 u16 1000", &mut s), [0xE8, 0x03]);
        assert_eq!(data("5 w 0x2000 0 x16 0xBEEF", &mut s), [0xEF, 0xBE]);
        assert_eq!(data("5 w 0x2000 0 i8 -2", &mut s), [0xFE]);
        assert_eq!(data("5 w 0x2000 0 b 1", &mut s), [1]);
        assert_eq!(
            data("5 w 0x1008 0 vs \"say \"\"hi\"\" twice\"", &mut s),
            b"say \"hi\" twice"
        );
        assert_eq!(data("5 w 0x1008 0 vs plain", &mut s), b"plain");
        assert_eq!(data("5 w 0x2000 0 os 01 02 0A", &mut s), [1, 2, 10]);
        assert_eq!(
            parse("5 w 0x2000 0 u8 256", &mut s).err(),
            Some(GwError::SYNTAX)
        );
        assert_eq!(
            parse("5 w 0x2000 0 x8 0x100", &mut s).err(),
            Some(GwError::SYNTAX)
        );
        assert_eq!(
            parse("5 w 0x1008 0 vs \"open", &mut s).err(),
            Some(GwError::SYNTAX)
        );
    }

    #[test]
    fn sequence_numbers_and_errors_are_formatted() {
        let mut s = session();
        assert_eq!(answer("[3] set node 9", &mut s), "[3] OK");
        assert_eq!(answer("[4] 9 bogus", &mut s), "[4] ERROR: 100");
        assert_eq!(answer("[x] 9 start", &mut s), "ERROR: 101");
        assert_eq!(answer("set sdo_timeout 0", &mut s), "ERROR: 101");
        assert!(answer("[5] help", &mut s).ends_with("\n[5] OK"));
        assert_eq!(
            GwError::Abort(AbortCode::from(0x0602_0000)).to_string(),
            "0x06020000"
        );
    }

    #[test]
    fn bus_results_are_answered_in_the_requested_type() {
        let mut s = session();
        let Step::Bus(p) = request("[2] 5 read 0x1017 0 u16", &mut s) else {
            panic!("a read goes to the bus");
        };
        assert_eq!(p.finish(Ok(vec![0xE8, 0x03])), "[2] 1000");
        let Step::Bus(p) = request("5 w 0x1017 0 u16 1000", &mut s) else {
            panic!("a write goes to the bus");
        };
        assert_eq!(p.finish(Ok(Vec::new())), "OK");
        let Step::Bus(p) = request("[7] 5 read 0x1017 0", &mut s) else {
            panic!("a read goes to the bus");
        };
        assert_eq!(p.finish(Err(GwError::TIMEOUT)), "[7] ERROR: 103");
    }
}
