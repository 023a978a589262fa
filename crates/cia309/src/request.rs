//! Request lines: `[<seq>] [[<net>] <node>] <command>`, parsed into an answer now or a bus
//! operation whose result [`Pending::finish`] turns into the answer line.

use cantwin_canopen::lss::{Address, Mode, Outcome, Part, Scan, Service};
use cantwin_canopen::sdo::wire::Mux;
use cantwin_canopen::wire::NmtCs;

use crate::error::GwError;
use crate::value::{Ty, encode, show, ty};

/// The highest network number a request may give (CiA 309-3: a 16-bit net). The gateway
/// serves one network and, as CANopenNode's gateway built for one network
/// (`CO_CONFIG_GTW_MULTI_NET` off), accepts any net up to this and does not use it.
pub const NET_MAX: u32 = 0xFFFF;

/// What ends every answer, on stdin/stdout and TCP alike: CANopenNode's gateway writes each
/// response with CR LF (and `cocomm` waits for it); the lines inside a multi-line answer
/// (`help`, `lss_allnodes`) end with LF only.
pub const EOL: &str = "\r\n";

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
    /// An LSS master service (CiA 305); LSS addresses no node.
    Lss(LssOp),
}

/// What an LSS request asks of the LSS master.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LssOp {
    /// One service, each answer awaited `timeout_ms`.
    Service {
        /// The service.
        service: Service,
        /// How long each answer is awaited, in milliseconds.
        timeout_ms: u16,
    },
    /// `lss_allnodes`: fastscan, configure node-ID (`start`, `start + 1` …), store if asked,
    /// switch state global waiting, until no non-configured node answers or 127 is given.
    AllNodes {
        /// How long each fastscan step waits, in milliseconds.
        timeout_ms: u16,
        /// The first node-ID given.
        start: u8,
        /// Whether each node stores its node-ID.
        store: bool,
        /// How fastscan treats each part of the address (vendor, product, revision, serial).
        plan: [Scan; 4],
    },
}

/// The LSS master's result of an [`LssOp`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LssResult {
    /// How the service ended.
    Outcome(Outcome),
    /// `lss_allnodes`: the node-IDs given, in order, and how the search ended: `Ok(true)`
    /// no non-configured node is left, `Ok(false)` node-ID 127 was given, or the error of
    /// the step that failed.
    AllNodes {
        /// The node-IDs given and the address of each node.
        assigned: Vec<(u8, Address)>,
        /// How it ended.
        end: Result<bool, GwError>,
    },
}

/// The LSS master's default time for an answer (CANopenNode's gateway: 1000 ms).
pub const LSS_TIMEOUT_MS: u16 = 1000;
/// The default time of each fastscan step (`_lss_fastscan`, `lss_allnodes`: 100 ms).
pub const FASTSCAN_TIMEOUT_MS: u16 = 100;

/// One client's settings, which `set` requests change.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Session {
    /// The default net (`set network`): remembered, not used (one network).
    pub net: Option<u16>,
    /// The default node (`set node`), for requests without a node.
    pub node: Option<u8>,
    /// The SDO timeout in milliseconds (`set sdo_timeout`).
    pub sdo_timeout_ms: u32,
    /// Whether SDO transfers use block transfer (`set sdo_block 1`).
    pub block: bool,
    /// The sequence number of the last request: an answer to a line without one carries it,
    /// as CANopenNode's gateway does.
    pub sequence: u32,
}

impl Session {
    /// A client with no default node, the given SDO timeout and no block transfer.
    pub fn new(sdo_timeout_ms: u32) -> Session {
        Session {
            net: None,
            node: None,
            sdo_timeout_ms,
            block: false,
            sequence: 0,
        }
    }
}

/// What a request line needs: an answer now, or a bus operation first.
#[derive(Debug)]
pub enum Step {
    /// The answer, ready to send followed by [`EOL`] (one or more lines separated by LF, the
    /// sequence number on the last; `help`'s text has none).
    Answer(String),
    /// A bus operation to run; its result gives the answer.
    Bus(Pending),
}

/// A bus operation a request waits for, and how its result is answered.
#[derive(Debug)]
pub struct Pending {
    seq: u32,
    op: BusOp,
    show: Show,
}

/// How the result of a bus operation is answered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Show {
    /// `OK`.
    Ok,
    /// The uploaded bytes in this type (`None`: `hex`).
    Value(Option<Ty>),
    /// An LSS service, answered as CANopenNode's gateway answers it.
    Lss(LssShow),
}

/// What an LSS request answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum LssShow {
    /// `OK`, or 103 when no slave answered.
    Ok,
    /// Configure node-ID: a refusal is 502.
    NodeId,
    /// Configure bit timing: a refusal is 503.
    BitRate,
    /// Store configuration: a refusal is 504.
    Store,
    /// An inquiry or fastscan: the value(s) in hex.
    Value,
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
            Show::Value(t) => show(t, &data),
            Show::Ok | Show::Lss(_) => Ok("OK".into()),
        });
        sequenced(self.seq, text)
    }

    /// The answer for the LSS master's result (CANopenNode's gateway: 103 when no slave
    /// answered, 501 for a manufacturer-specific error, 502/503/504 for a refused node-ID,
    /// bit rate or store; inquired values as `0x%08X`, a node-ID as `0x%02X`).
    pub fn finish_lss(self, result: Result<LssResult, GwError>) -> String {
        let kind = match self.show {
            Show::Lss(k) => k,
            Show::Ok | Show::Value(_) => LssShow::Ok,
        };
        let text = match result {
            Err(e) => Err(e),
            Ok(LssResult::Outcome(o)) => lss_outcome(kind, o),
            Ok(LssResult::AllNodes { assigned, end }) => {
                let mut lines = String::new();
                for (id, a) in &assigned {
                    lines.push_str(&format!("# Node-ID {id} assigned to: {}\n", address(a)));
                }
                let last = match end {
                    Ok(true) => Ok(format!(
                        "# Found {} nodes, search finished.\nOK",
                        assigned.len()
                    )),
                    Ok(false) => Ok("# Not all nodes scanned!\nOK".to_string()),
                    Err(e) => Err(e),
                };
                return match last {
                    Ok(t) => sequenced(self.seq, Ok(format!("{lines}{t}"))),
                    Err(e) => format!("{lines}{}", sequenced(self.seq, Err(e))),
                };
            }
        };
        sequenced(self.seq, text)
    }
}

/// The four parts of an address as the gateway shows them.
fn address(a: &Address) -> String {
    format!(
        "0x{:08X} 0x{:08X} 0x{:08X} 0x{:08X}",
        a.vendor, a.product, a.revision, a.serial
    )
}

fn lss_outcome(kind: LssShow, o: Outcome) -> Result<String, GwError> {
    match (kind, o) {
        (_, Outcome::Timeout) => Err(GwError::TIMEOUT),
        (_, Outcome::Refused { error: 0xFF, .. }) => Err(GwError::LSS_MANUFACTURER),
        (LssShow::NodeId, Outcome::Refused { .. }) => Err(GwError::LSS_NODE_ID),
        (LssShow::BitRate, Outcome::Refused { .. }) => Err(GwError::LSS_BIT_RATE),
        (LssShow::Store, Outcome::Refused { .. }) => Err(GwError::LSS_STORE),
        (_, Outcome::Value(v)) => Ok(format!("0x{v:08X}")),
        (_, Outcome::NodeId(n)) => Ok(format!("0x{n:02X}")),
        (_, Outcome::Address(a)) => Ok(address(&a)),
        (_, Outcome::Done | Outcome::Identified(_)) => Ok("OK".into()),
        (_, Outcome::Refused { .. }) => Err(GwError::STATE),
    }
}

/// What a parsed request needs: a bus operation (answered by `show`), or an answer now.
#[derive(Debug)]
enum Action {
    Bus {
        op: BusOp,
        show: Show,
    },
    /// An answer after the sequence number.
    Answer(String),
    /// An answer without the sequence number (`help`).
    Text(String),
}

/// The answer text with its sequence number: a multi-line answer (`lss_allnodes`) carries it
/// on its last line.
/// The sequence number is shown as a signed 32-bit number, as CANopenNode prints it
/// (`PRId32`): `[4294967295]` is answered `[-1]`.
fn sequenced(seq: u32, result: Result<String, GwError>) -> String {
    let text = match result {
        Ok(t) => t,
        Err(e) => format!("ERROR:{e}"),
    };
    let n = seq as i32;
    match text.rsplit_once('\n') {
        Some((head, last)) => format!("{head}\n[{n}] {last}"),
        None => format!("[{n}] {text}"),
    }
}

/// Handles one request line for a client with settings `s`: `set` requests change them.
///
/// A line is `[<seq>]` and the request; `#` starts a comment. An empty line (or one that
/// is only a comment) is answered with an empty line; a line without `[<seq>]` with
/// `ERROR:101` under the previous sequence number (CANopenNode's gateway).
pub fn request(line: &str, s: &mut Session) -> Step {
    let line = match line.split_once('#') {
        Some((before, _)) => before,
        None => line,
    }
    .trim();
    if line.is_empty() {
        return Step::Answer(String::new());
    }
    let (first, rest) = match line.split_once(char::is_whitespace) {
        Some((f, r)) => (f, r),
        None => (line, ""),
    };
    let seq = first
        .strip_prefix('[')
        .and_then(|t| t.strip_suffix(']'))
        .and_then(number);
    let Some(seq) = seq else {
        return Step::Answer(sequenced(s.sequence, Err(GwError::SYNTAX)));
    };
    s.sequence = seq;
    match parse(rest, s) {
        Ok(Action::Answer(a)) => Step::Answer(sequenced(seq, Ok(a))),
        Ok(Action::Text(t)) => Step::Answer(t),
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

/// A number as C's `strtoul` with base 0 reads it: decimal, hex with `0x`, octal with a
/// leading 0.
fn number(text: &str) -> Option<u32> {
    let t = text.trim();
    if let Some(h) = t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        return u32::from_str_radix(h, 16).ok();
    }
    if t.len() > 1
        && let Some(o) = t.strip_prefix('0')
    {
        return u32::from_str_radix(o, 8).ok();
    }
    if !t.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    t.parse().ok()
}

/// A number in `min..=max`.
fn ranged(text: &str, min: u32, max: u32) -> Result<u32, GwError> {
    number(text)
        .filter(|n| (min..=max).contains(n))
        .ok_or(GwError::SYNTAX)
}

/// An LSS request (`lss_…`, `_lss_fastscan`), with the arguments after the command.
fn lss(cmd: &str, args: &[&str]) -> Result<Action, GwError> {
    let service = |service, show| Action::Bus {
        op: BusOp::Lss(LssOp::Service {
            service,
            timeout_ms: LSS_TIMEOUT_MS,
        }),
        show: Show::Lss(show),
    };
    Ok(match (cmd, args) {
        ("lss_switch_glob", [mode]) => {
            let mode = match ranged(mode, 0, 1)? {
                0 => Mode::Waiting,
                _ => Mode::Configuration,
            };
            service(Service::SwitchGlobal(mode), LssShow::Ok)
        }
        ("lss_switch_sel", [v, p, r, sn]) => {
            let part = |t: &str| ranged(t, 0, u32::MAX);
            let a = Address {
                vendor: part(v)?,
                product: part(p)?,
                revision: part(r)?,
                serial: part(sn)?,
            };
            service(Service::SwitchSelective(a), LssShow::Ok)
        }
        ("lss_set_node", [n]) => {
            let n = ranged(n, 0, 0xFF)?;
            if (0x80..0xFF).contains(&n) {
                return Err(GwError::SYNTAX);
            }
            service(Service::ConfigureNodeId(n as u8), LssShow::NodeId)
        }
        ("lss_conf_bitrate", [table, index]) => {
            // Only the CiA 301 table (selector 0); entry 5 is reserved.
            ranged(table, 0, 0)?;
            let index = ranged(index, 0, 9)?;
            if index == 5 {
                return Err(GwError::SYNTAX);
            }
            let bit_timing = Service::ConfigureBitTiming {
                table: 0,
                index: index as u8,
            };
            service(bit_timing, LssShow::BitRate)
        }
        ("lss_activate_bitrate", [delay]) => {
            let delay = ranged(delay, 0, 0xFFFF)? as u16;
            service(Service::ActivateBitTiming(delay), LssShow::Ok)
        }
        ("lss_store", []) => service(Service::StoreConfiguration, LssShow::Store),
        ("lss_inquire_addr", []) => service(Service::InquireAddress, LssShow::Value),
        ("lss_inquire_addr", [sub]) => {
            let part = Part::at(ranged(sub, 0, 3)? as u8).ok_or(GwError::SYNTAX)?;
            service(Service::Inquire(part), LssShow::Value)
        }
        ("lss_get_node", []) => service(Service::InquireNodeId, LssShow::Value),
        ("_lss_fastscan", rest) if rest.len() <= 1 => {
            let ms = match rest.first() {
                Some(t) => ranged(t, 0, 0xFFFF)? as u16,
                None => 0,
            };
            Action::Bus {
                op: BusOp::Lss(LssOp::Service {
                    service: Service::Fastscan,
                    timeout_ms: if ms == 0 { FASTSCAN_TIMEOUT_MS } else { ms },
                }),
                show: Show::Lss(LssShow::Value),
            }
        }
        ("lss_allnodes", rest) if matches!(rest.len(), 0 | 1 | 3 | 11) => {
            let ms = match rest.first() {
                Some(t) => ranged(t, 0, 0xFFFF)? as u16,
                None => 0,
            };
            // Without more arguments: node-IDs from 2, stored (CANopenNode's defaults).
            let (start, store) = match rest {
                [_, start, store, ..] => (ranged(start, 1, 127)? as u8, ranged(store, 0, 1)? == 1),
                _ => (2, true),
            };
            let mut plan = [Scan::Search; 4];
            if rest.len() == 11 {
                for (part, pair) in plan.iter_mut().zip(rest[3..].chunks(2)) {
                    // Scan types: 0 search, 1 skip, 2 match the value given.
                    let value = ranged(pair[1], 0, u32::MAX)?;
                    *part = match ranged(pair[0], 0, 2)? {
                        0 => Scan::Search,
                        1 => Scan::Skip,
                        _ => Scan::Match(value),
                    };
                }
                if plan.iter().all(|p| *p == Scan::Skip) {
                    return Err(GwError::SYNTAX);
                }
            }
            Action::Bus {
                op: BusOp::Lss(LssOp::AllNodes {
                    timeout_ms: if ms == 0 { FASTSCAN_TIMEOUT_MS } else { ms },
                    start,
                    store,
                    plan,
                }),
                show: Show::Lss(LssShow::Ok),
            }
        }
        _ => return Err(GwError::SYNTAX),
    })
}

/// An index and sub-index.
fn mux(index: &str, sub: &str) -> Option<Mux> {
    let i = u16::try_from(number(index)?).ok()?;
    let s = u8::try_from(number(sub)?).ok()?;
    Some(Mux::new(i, s))
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
    // CANopenNode's gateway: a net above 16 bits is 106, a node above 127 is 107; any other
    // net is taken and not used (one network).
    if let Some(n) = net {
        let n = number(n).ok_or(GwError::SYNTAX)?;
        if n > NET_MAX {
            return Err(GwError::NET);
        }
    }
    let node = match node {
        Some(n) => Some(number(n).ok_or(GwError::SYNTAX).and_then(|n| {
            u8::try_from(n)
                .ok()
                .filter(|n| *n <= 127)
                .ok_or(GwError::NODE)
        })?),
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
    if cmd.starts_with("lss_") || cmd == "_lss_fastscan" {
        let known = [
            "lss_switch_glob",
            "lss_switch_sel",
            "lss_set_node",
            "lss_conf_bitrate",
            "lss_activate_bitrate",
            "lss_store",
            "lss_inquire_addr",
            "lss_get_node",
            "_lss_fastscan",
            "lss_allnodes",
        ];
        if !known.contains(&cmd.as_str()) {
            return Err(GwError::NOT_SUPPORTED);
        }
        let words: Vec<&str> = args.iter().map(|(w, _)| *w).collect();
        return lss(&cmd, &words);
    }
    let nmt = |cs| -> Result<Action, GwError> {
        let node = node.or(s.node).ok_or(GwError::NO_NODE)?;
        Ok(Action::Bus {
            op: BusOp::Nmt { node, cs },
            show: Show::Ok,
        })
    };
    match (cmd.as_str(), args) {
        ("read" | "r", [(index, _), (sub, _), rest @ ..]) if rest.len() <= 1 => {
            let node = sdo_node()?;
            let mux = mux(index, sub).ok_or(GwError::SYNTAX)?;
            let t = rest.first().map(|(m, _)| ty(m)).transpose()?;
            Ok(Action::Bus {
                op: BusOp::Upload { node, mux },
                show: Show::Value(t),
            })
        }
        ("write" | "w", [(index, _), (sub, _), (t, end), _, ..]) => {
            let node = sdo_node()?;
            let mux = mux(index, sub).ok_or(GwError::SYNTAX)?;
            let t = ty(t)?;
            let data = encode(t, &line[*end..])?;
            Ok(Action::Bus {
                op: BusOp::Download { node, mux, data },
                show: Show::Ok,
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
        // `[<net>] set …`: CANopenNode's gateway takes the numbers before `set` and does not
        // use them.
        ("set", [(what, _), (value, _)]) => {
            match what.to_ascii_lowercase().as_str() {
                "network" => {
                    let n = ranged(value, 0, NET_MAX)?;
                    s.net = u16::try_from(n).ok();
                }
                // CANopenNode's gateway: a value out of its range is a syntax error (101).
                "node" => s.node = Some(ranged(value, 1, 127)? as u8),
                "sdo_timeout" => s.sdo_timeout_ms = ranged(value, 1, 0xFFFF)?,
                "sdo_block" => s.block = ranged(value, 0, 1)? == 1,
                _ => return Err(GwError::NOT_SUPPORTED),
            }
            Ok(Action::Answer("OK".into()))
        }
        ("info", []) => Ok(Action::Answer(format!(
            "cantwin {} CiA 309-3 ASCII gateway: net {}, node {}, sdo_timeout {} ms, sdo_block {}",
            env!("CARGO_PKG_VERSION"),
            s.net.map_or_else(|| "none".to_string(), |n| n.to_string()),
            s.node.map_or_else(|| "none".to_string(), |n| n.to_string()),
            s.sdo_timeout_ms,
            u8::from(s.block),
        ))),
        // CANopenNode's gateway answers `help` with its text alone (no sequence number, no
        // OK), an LF before it, LF between its lines, the answer's EOL after it.
        ("help", []) => Ok(Action::Text(help_text(HELP.lines()))),
        // CANopenNode's `help datatype` and `help lss`: the parts of the help on types and
        // on the LSS commands.
        ("help", [(what, _)]) => {
            let start: fn(&str) -> bool = match what.to_ascii_lowercase().as_str() {
                "datatype" => |l| l.starts_with("Types:"),
                "lss" => |l| l.contains("lss_"),
                _ => return Err(GwError::SYNTAX),
            };
            // A kept line and the indented lines that continue it.
            let mut keep = false;
            let lines = HELP.lines().filter(|l| {
                keep = start(l) || (keep && l.starts_with("      "));
                keep
            });
            Ok(Action::Text(help_text(lines)))
        }
        (
            "read" | "r" | "write" | "w" | "start" | "stop" | "preop" | "preoperational" | "reset"
            | "set" | "info" | "help",
            _,
        ) => Err(GwError::SYNTAX),
        _ => Err(GwError::NOT_SUPPORTED),
    }
}

/// `help`'s answer of `lines`: each after an LF (so the text starts on a line of its own).
fn help_text<'a>(lines: impl Iterator<Item = &'a str>) -> String {
    lines.fold(String::new(), |mut text, l| {
        text.push('\n');
        text.push_str(l);
        text
    })
}

/// The text `help` answers with.
pub const HELP: &str = "\
Request: [<seq>] [[<net>] <node>] <command>; answer: [<seq>] OK | <value> | ERROR:<code>
  read <index> <sub> [<type>]          SDO upload (r)
  write <index> <sub> <type> <value>   SDO download (w)
  start | stop | preop | reset node | reset comm     NMT (node 0: all nodes)
  set network <net> | set node <node> | set sdo_timeout <ms> | set sdo_block <0|1>
  lss_switch_glob <0|1>                LSS switch state global (0 waiting, 1 configuration)
  lss_switch_sel <vendor> <product> <revision> <serial>   LSS switch state selective
  lss_set_node <node>                  LSS configure node-ID (1-127, 0xFF: unconfigured)
  lss_conf_bitrate 0 <index>           LSS configure bit timing (0 1M, 1 800k, 2 500k,
                                       3 250k, 4 125k, 6 50k, 7 20k, 8 10k, 9 auto)
  lss_activate_bitrate <delay_ms>      LSS activate bit timing
  lss_store                            LSS store configuration
  lss_inquire_addr [<0..3>]            LSS inquire address (or one part)
  lss_get_node                         LSS inquire node-ID
  _lss_fastscan [<timeout_ms>]         LSS fastscan (default 100 ms per step)
  lss_allnodes [<timeout_ms> [<first node-ID> <store 0|1> [<scan> <vendor> <scan>
      <product> <scan> <revision> <scan> <serial>]]]   fastscan every node, give
                                       node-IDs from 2 and store them (scan: 0 search,
                                       1 skip, 2 match the value)
  info | help
Types: b i8 i16 i24 i32 i40 i48 i56 i64 u8 u16 u24 u32 u40 u48 u56 u64 x8 x16 x32 x64
       r32 r64 vs (\"text\") os us d (base64, RFC 2045) hex (bytes: C8 3D BB 00)
Errors: SDO abort code (0x...), 100 not supported, 101 syntax, 102 internal state,
        103 time-out, 105 no default node, 106 unsupported net, 107 unsupported node,
        501 LSS manufacturer error, 502 LSS node-ID not supported,
        503 LSS bit rate not supported, 504 LSS storing failed
";

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_canopen::AbortCode;

    fn session() -> Session {
        Session::new(1000)
    }

    fn bus_op(line: &str, s: &mut Session) -> BusOp {
        match parse(line, s).unwrap() {
            Action::Bus { op, .. } => op,
            Action::Answer(a) | Action::Text(a) => panic!("{line}: answered {a}"),
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
        assert_eq!(parse("200 start", &mut s).err(), Some(GwError::NODE));
        assert_eq!(parse("0x10000 5 start", &mut s).err(), Some(GwError::NET));
        assert_eq!(parse("1 128 start", &mut s).err(), Some(GwError::NODE));
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

    /// CANopenNode's gateway built for one network takes any net of 16 bits (0 too) and
    /// does not use it.
    #[test]
    fn cia309_3_any_16_bit_net_is_taken_and_not_used() {
        let mut s = session();
        for net in ["0", "1", "2", "0xFFFF"] {
            assert_eq!(
                bus_op(&format!("{net} 5 read 0x1017 0 u16"), &mut s),
                BusOp::Upload {
                    node: 5,
                    mux: Mux::new(0x1017, 0)
                },
                "net {net}"
            );
            assert_eq!(
                bus_op(&format!("{net} 0 start"), &mut s),
                BusOp::Nmt {
                    node: 0,
                    cs: NmtCs::Start
                },
                "net {net}"
            );
        }
        assert_eq!(
            parse("65536 5 read 0x1017 0", &mut s).err(),
            Some(GwError::NET)
        );
        assert_eq!(
            parse("1 0 read 0x1017 0", &mut s).err(),
            Some(GwError::NODE)
        );
        // `set network` remembers any 16-bit net; more is a syntax error.
        assert_eq!(answer("[1] set network 0", &mut s), "[1] OK");
        assert_eq!(s.net, Some(0));
        assert_eq!(answer("[2] set network 7", &mut s), "[2] OK");
        assert_eq!(answer("[3] set network 65536", &mut s), "[3] ERROR:101");
        assert_eq!(s.net, Some(7));
        // Numbers before `set` are taken and not used.
        assert_eq!(answer("[4] 3 set node 9", &mut s), "[4] OK");
        assert_eq!(s.node, Some(9));
        assert_eq!(answer("[5] 2 3 set sdo_timeout 300", &mut s), "[5] OK");
        assert_eq!(s.sdo_timeout_ms, 300);
        // Values out of range are syntax errors, as CANopenNode's gateway answers them.
        assert_eq!(answer("[6] set node 0", &mut s), "[6] ERROR:101");
        assert_eq!(answer("[7] set node 128", &mut s), "[7] ERROR:101");
        assert_eq!(answer("[8] set sdo_timeout 65536", &mut s), "[8] ERROR:101");
        assert_eq!(answer("[9] set sdo_block 2", &mut s), "[9] ERROR:101");
        assert_eq!(answer("[10] set sdo_block 0x1", &mut s), "[10] OK");
        assert!(s.block);
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
        assert_eq!(data("5 w 0x2000 0 os AQIK", &mut s), [1, 2, 10]);
        assert_eq!(data("5 w 0x2000 0 hex 01 02 0A", &mut s), [1, 2, 10]);
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
        assert_eq!(answer("[4] 9 bogus", &mut s), "[4] ERROR:100");
        // Without a sequence number: 101 under the previous one.
        assert_eq!(answer("[x] 9 start", &mut s), "[4] ERROR:101");
        assert_eq!(answer("set node 3", &mut s), "[4] ERROR:101");
        assert_eq!(answer("[6] set sdo_timeout 0", &mut s), "[6] ERROR:101");
        // help: the text alone, starting on a line of its own, no sequence number, no OK.
        let help = answer("[5] help", &mut s);
        assert!(help.starts_with("\nRequest: [<seq>]"), "{help}");
        assert!(!help.contains("[5]") && !help.contains("OK\n") && !help.ends_with('\n'));
        assert!(!help.contains('\r'), "{help}");
        let lss = answer("[5] help lss", &mut s);
        assert!(
            lss.starts_with("\n  lss_switch_glob <0|1>") && !lss.contains("[5]"),
            "{lss}"
        );
        assert!(
            lss.contains("9 auto") && !lss.contains("read <index>"),
            "{lss}"
        );
        let types = answer("[5] help datatype", &mut s);
        assert!(
            types.starts_with("\nTypes: b i8") && types.contains("hex (bytes"),
            "{types}"
        );
        assert_eq!(answer("[5] help me", &mut s), "[5] ERROR:101");
        assert_eq!(answer("[4294967295] set node 9", &mut s), "[-1] OK");
        assert_eq!(answer("[010] set node 9", &mut s), "[8] OK");
        assert_eq!(answer("", &mut s), "");
        assert_eq!(answer("  # a comment", &mut s), "");
        assert_eq!(answer("[7] set node 9 # trailing", &mut s), "[7] OK");
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
        let Step::Bus(p) = request("[0] 5 w 0x1017 0 u16 1000", &mut s) else {
            panic!("a write goes to the bus");
        };
        assert_eq!(p.finish(Ok(Vec::new())), "[0] OK");
        let Step::Bus(p) = request("[7] 5 read 0x1017 0", &mut s) else {
            panic!("a read goes to the bus");
        };
        assert_eq!(p.finish(Err(GwError::TIMEOUT)), "[7] ERROR:103");
        let Step::Bus(p) = request("[8] 5 read 0x1234 0", &mut s) else {
            panic!("a read goes to the bus");
        };
        assert_eq!(
            p.finish(Err(GwError::Abort(AbortCode::from(0x0602_0000)))),
            "[8] ERROR:0x06020000"
        );
    }

    fn lss_op(line: &str) -> Result<LssOp, GwError> {
        match parse(line, &mut session())? {
            Action::Bus {
                op: BusOp::Lss(op), ..
            } => Ok(op),
            _ => panic!("{line}: not an LSS request"),
        }
    }

    fn service(op: Result<LssOp, GwError>) -> Service {
        match op {
            Ok(LssOp::Service { service, .. }) => service,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn cia309_3_lss_commands_and_their_arguments() {
        assert_eq!(
            service(lss_op("lss_switch_glob 1")),
            Service::SwitchGlobal(Mode::Configuration)
        );
        assert_eq!(
            service(lss_op("lss_switch_sel 0xCA7 301 0x10000 5")),
            Service::SwitchSelective(Address {
                vendor: 0xCA7,
                product: 301,
                revision: 0x10000,
                serial: 5
            })
        );
        assert_eq!(
            service(lss_op("lss_set_node 0xFF")),
            Service::ConfigureNodeId(0xFF)
        );
        assert_eq!(lss_op("lss_set_node 128").err(), Some(GwError::SYNTAX));
        assert_eq!(
            service(lss_op("lss_conf_bitrate 0 2")),
            Service::ConfigureBitTiming { table: 0, index: 2 }
        );
        assert_eq!(lss_op("lss_conf_bitrate 0 5").err(), Some(GwError::SYNTAX));
        assert_eq!(lss_op("lss_conf_bitrate 1 2").err(), Some(GwError::SYNTAX));
        assert_eq!(
            service(lss_op("lss_activate_bitrate 100")),
            Service::ActivateBitTiming(100)
        );
        assert_eq!(service(lss_op("lss_store")), Service::StoreConfiguration);
        assert_eq!(service(lss_op("lss_inquire_addr")), Service::InquireAddress);
        assert_eq!(
            service(lss_op("lss_inquire_addr 3")),
            Service::Inquire(Part::Serial)
        );
        assert_eq!(service(lss_op("lss_get_node")), Service::InquireNodeId);
        assert_eq!(
            lss_op("_lss_fastscan"),
            Ok(LssOp::Service {
                service: Service::Fastscan,
                timeout_ms: 100
            })
        );
        assert_eq!(
            lss_op("lss_allnodes"),
            Ok(LssOp::AllNodes {
                timeout_ms: 100,
                start: 2,
                store: true,
                plan: [Scan::Search; 4]
            })
        );
        assert_eq!(
            lss_op("lss_allnodes 50 10 0"),
            Ok(LssOp::AllNodes {
                timeout_ms: 50,
                start: 10,
                store: false,
                plan: [Scan::Search; 4]
            })
        );
        assert_eq!(
            lss_op("lss_allnodes 50 10 1 2 0xCA7 1 0 0 0 0 0"),
            Ok(LssOp::AllNodes {
                timeout_ms: 50,
                start: 10,
                store: true,
                plan: [Scan::Match(0xCA7), Scan::Skip, Scan::Search, Scan::Search]
            })
        );
        assert_eq!(
            lss_op("lss_allnodes 50 10 1 1 0 1 0 1 0 1 0").err(),
            Some(GwError::SYNTAX)
        );
        assert_eq!(
            lss_op("lss_allnodes 50 10 1 3 0 0 0 0 0 0 0").err(),
            Some(GwError::SYNTAX)
        );
        assert_eq!(lss_op("lss_allnodes 50 10").err(), Some(GwError::SYNTAX));
        assert_eq!(
            parse("lss_frobnicate", &mut session()).err(),
            Some(GwError::NOT_SUPPORTED)
        );
    }

    /// The answers byte for byte as CANopenNode's gateway gives them.
    #[test]
    fn cia309_3_lss_answers_byte_for_byte() {
        let mut s = session();
        let lss =
            |line: &str, s: &mut Session, r: Result<LssResult, GwError>| match request(line, s) {
                Step::Bus(p) => p.finish_lss(r),
                Step::Answer(a) => panic!("{line}: answered {a}"),
            };
        let o = |o| Ok(LssResult::Outcome(o));
        let refused = |error| o(Outcome::Refused { error, spec: 0 });
        assert_eq!(
            lss("[1] lss_switch_glob 1", &mut s, o(Outcome::Done)),
            "[1] OK"
        );
        assert_eq!(
            lss("[2] lss_switch_sel 1 2 3 4", &mut s, o(Outcome::Timeout)),
            "[2] ERROR:103"
        );
        assert_eq!(
            lss("[3] lss_set_node 0", &mut s, refused(1)),
            "[3] ERROR:502"
        );
        assert_eq!(
            lss("[4] lss_set_node 7", &mut s, refused(0xFF)),
            "[4] ERROR:501"
        );
        assert_eq!(
            lss("[5] lss_conf_bitrate 0 9", &mut s, refused(1)),
            "[5] ERROR:503"
        );
        assert_eq!(lss("[6] lss_store", &mut s, refused(2)), "[6] ERROR:504");
        assert_eq!(
            lss("[7] lss_inquire_addr 0", &mut s, o(Outcome::Value(0xCA7))),
            "[7] 0x00000CA7"
        );
        assert_eq!(
            lss("[8] lss_get_node", &mut s, o(Outcome::NodeId(5))),
            "[8] 0x05"
        );
        let a = Address {
            vendor: 0xCA7,
            product: 301,
            revision: 0x10000,
            serial: 0xAB,
        };
        assert_eq!(
            lss("[9] _lss_fastscan", &mut s, o(Outcome::Address(a))),
            "[9] 0x00000CA7 0x0000012D 0x00010000 0x000000AB"
        );
        let all = Ok(LssResult::AllNodes {
            assigned: vec![(2, a)],
            end: Ok(true),
        });
        assert_eq!(
            lss("[10] lss_allnodes", &mut s, all),
            "# Node-ID 2 assigned to: 0x00000CA7 0x0000012D 0x00010000 0x000000AB\n\
             # Found 1 nodes, search finished.\n[10] OK"
        );
        let failed = Ok(LssResult::AllNodes {
            assigned: vec![(2, a)],
            end: Err(GwError::LSS_STORE),
        });
        assert_eq!(
            lss("[11] lss_allnodes", &mut s, failed),
            "# Node-ID 2 assigned to: 0x00000CA7 0x0000012D 0x00010000 0x000000AB\n[11] ERROR:504"
        );
    }
}
