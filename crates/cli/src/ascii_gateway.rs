//! `cantwin gateway --ascii`: a CiA 309-3 ASCII gateway in the command syntax of
//! CANopenNode's gateway and its `cocomm` client, on stdin/stdout or TCP.
//!
//! A request is one line, `[<seq>] [[<net>] <node>] <command>`; the answer is one line
//! `[<seq>] OK`, `[<seq>] <value>` or `[<seq>] ERROR: <code>`, where the code is the SDO
//! abort code in hex (`0x06020000`, CiA 301 table 22) or one of the gateway's own error
//! codes in decimal (CiA 309-3): 100 request not supported, 101 syntax error, 102 request not
//! processed due to internal state, 103 time-out, 105 no default node set, 106 unsupported
//! net, 107 unsupported node. `help` answers with its text and then `[<seq>] OK`. Without
//! `[<seq>]` the answer has no prefix either.
//!
//! Commands:
//!
//! * `read <index> <sub> [<type>]` (or `r`): SDO upload; without a type the bytes in hex;
//! * `write <index> <sub> <type> <value>` (or `w`): SDO download;
//! * `start`, `stop`, `preop` (`preoperational`), `reset node`, `reset comm`
//!   (`reset communication`): NMT, node 0 addresses all nodes;
//! * `set network <net>`, `set node <node>`, `set sdo_timeout <ms>`, `set sdo_block <0|1>`;
//! * `info`, `help`.
//!
//! Types: `b`, `i8`…`i64`, `u8`…`u64` (decimal or `0x` hex), `x8`, `x16`, `x32`, `x64`
//! (unsigned, shown in hex), `r32`, `r64`, `t`, `td`, `vs`, `us` (text; in double quotes
//! when it has spaces, a quote inside doubled; shown quoted), `os`, `d` (hex bytes, spaces
//! allowed).
//!
//! One gateway serves one network, net 1. The bus is driven by one master on the gateway's
//! thread; each client has its own default node, SDO timeout and block setting.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver, Sender, TryRecvError};
use std::time::Duration as WallDuration;

use anyhow::{Context, Result, bail};
use cantwin_can::{Duration, Outbox};
use cantwin_canopen::AbortCode;
use cantwin_canopen::master::{Master, MasterEvent, Mode, SdoEvent, TransferId};
use cantwin_canopen::od::{DataType, Value};
use cantwin_canopen::sdo::wire::Mux;
use cantwin_canopen::wire::NmtCs;

use crate::canopen::{data_type, mux, number};
use crate::connect::{Link, Target};

/// The longest request line accepted, in bytes.
pub const MAX_LINE: usize = 1024;
/// The most TCP clients served at once.
pub const MAX_CLIENTS: usize = 4;
/// The only network the gateway serves.
const NET: u32 = 1;

/// Arguments of `cantwin gateway`.
#[derive(Debug, clap::Args)]
pub struct GatewayArgs {
    #[command(flatten)]
    target: Target,
    /// Speak the CiA 309-3 ASCII protocol (the only one offered).
    #[arg(long, required = true)]
    ascii: bool,
    /// Serve TCP clients on [ADDR:]PORT (ADDR defaults to 127.0.0.1; port 0 picks one)
    /// instead of reading stdin.
    #[arg(long, value_name = "[ADDR:]PORT")]
    listen: Option<String>,
    /// The SDO timeout each client starts with, in milliseconds.
    #[arg(long, default_value_t = 1000)]
    sdo_timeout: u32,
}

/// Why a request failed: the SDO abort code or one of the gateway's own codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GwError {
    /// The SDO transfer was aborted with this code.
    Abort(AbortCode),
    /// A CiA 309-3 gateway error code.
    Code(u16),
}

impl GwError {
    const NOT_SUPPORTED: GwError = GwError::Code(100);
    const SYNTAX: GwError = GwError::Code(101);
    const STATE: GwError = GwError::Code(102);
    const NO_NODE: GwError = GwError::Code(105);
    const NET: GwError = GwError::Code(106);
    const NODE: GwError = GwError::Code(107);
}

impl core::fmt::Display for GwError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            GwError::Abort(code) => write!(f, "{:#010X}", u32::from(*code)),
            GwError::Code(c) => write!(f, "{c}"),
        }
    }
}

/// A data type of a read or write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Ty {
    /// A CiA 301 data type.
    Data(DataType),
    /// `x8`…`x64`: an unsigned integer of this many bytes, shown in hex.
    Hex(usize),
}

fn ty(mnemonic: &str) -> Result<Ty, GwError> {
    match mnemonic.to_ascii_lowercase().as_str() {
        "x8" => Ok(Ty::Hex(1)),
        "x16" => Ok(Ty::Hex(2)),
        "x32" => Ok(Ty::Hex(4)),
        "x64" => Ok(Ty::Hex(8)),
        m => data_type(m).map(Ty::Data).map_err(|_| GwError::SYNTAX),
    }
}

/// What a request asks of the bus.
#[derive(Debug, Clone, PartialEq, Eq)]
enum BusOp {
    Upload { node: u8, mux: Mux },
    Download { node: u8, mux: Mux, data: Vec<u8> },
    Nmt { node: u8, cs: NmtCs },
}

/// One client's settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Session {
    node: Option<u8>,
    sdo_timeout_ms: u32,
    block: bool,
}

/// What a parsed request needs: a bus operation (answered by `show`), or an answer now.
#[derive(Debug)]
enum Action {
    Bus { op: BusOp, show: Option<Option<Ty>> },
    Answer(String),
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

/// A text value: `"…"` with `""` for a quote, or the text as it is.
fn text_value(rest: &str) -> Result<String, GwError> {
    let t = rest.trim();
    let Some(body) = t.strip_prefix('"') else {
        return Ok(t.to_owned());
    };
    let mut s = String::new();
    let mut chars = body.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '"' {
            if chars.peek() == Some(&'"') {
                chars.next();
                s.push('"');
            } else if chars.all(char::is_whitespace) {
                return Ok(s);
            } else {
                return Err(GwError::SYNTAX);
            }
        } else {
            s.push(c);
        }
    }
    Err(GwError::SYNTAX)
}

/// The bytes to write for `value` of type `t`.
fn encode(t: Ty, value: &str) -> Result<Vec<u8>, GwError> {
    match t {
        Ty::Hex(n) => {
            let v = number_u64(value.trim()).ok_or(GwError::SYNTAX)?;
            if n < 8 && v >> (8 * n) != 0 {
                return Err(GwError::SYNTAX);
            }
            Ok(v.to_le_bytes()[..n].to_vec())
        }
        Ty::Data(ty @ (DataType::VisibleString | DataType::UnicodeString)) => {
            let s = text_value(value)?;
            Value::parse(ty, &s)
                .map(|v| v.to_le_bytes())
                .map_err(|_| GwError::SYNTAX)
        }
        Ty::Data(DataType::Boolean) => match value.trim() {
            "0" | "false" => Ok(vec![0]),
            "1" | "true" => Ok(vec![1]),
            _ => Err(GwError::SYNTAX),
        },
        Ty::Data(ty) => {
            let v = value.trim();
            if v.is_empty() {
                return Err(GwError::SYNTAX);
            }
            Value::parse(ty, v)
                .map(|v| v.to_le_bytes())
                .map_err(|_| GwError::SYNTAX)
        }
    }
}

fn number_u64(t: &str) -> Option<u64> {
    match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(h) => u64::from_str_radix(h, 16).ok(),
        None => t.parse().ok(),
    }
}

/// The answer to a read: the value as CANopenNode's gateway shows it.
fn show(t: Option<Ty>, data: &[u8]) -> Result<String, GwError> {
    let hex_bytes = |d: &[u8]| {
        d.iter()
            .map(|b| format!("{b:02X}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    match t {
        None => Ok(hex_bytes(data)),
        Some(Ty::Hex(n)) => {
            if data.len() != n {
                return Err(GwError::Abort(AbortCode::TYPE_MISMATCH));
            }
            let mut b = [0u8; 8];
            b[..n].copy_from_slice(data);
            Ok(format!("0x{:0w$X}", u64::from_le_bytes(b), w = 2 * n))
        }
        Some(Ty::Data(ty)) => {
            let v = Value::from_le_bytes(ty, data)
                .map_err(|_| GwError::Abort(AbortCode::TYPE_MISMATCH))?;
            Ok(match v {
                Value::Boolean(b) => u8::from(b).to_string(),
                Value::VisibleString(_) | Value::UnicodeString(_) => {
                    format!("\"{}\"", v.to_string().replace('"', "\"\""))
                }
                other => other.to_string(),
            })
        }
    }
}

fn net_or_node(text: &str, max: u32) -> Option<u32> {
    number(text, "node").ok().filter(|n| *n <= max)
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
            let mux = mux(index, sub).map_err(|_| GwError::SYNTAX)?;
            let t = rest.first().map(|(m, _)| ty(m)).transpose()?;
            Ok(Action::Bus {
                op: BusOp::Upload { node, mux },
                show: Some(t),
            })
        }
        ("write" | "w", [(index, _), (sub, _), (t, end), _, ..]) => {
            let node = sdo_node()?;
            let mux = mux(index, sub).map_err(|_| GwError::SYNTAX)?;
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
                    let ms = number(value, "timeout").map_err(|_| GwError::SYNTAX)?;
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

const HELP: &str = "\
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

/// A bus operation sent to the gateway's thread, with the client's settings and where the
/// result goes.
struct Job {
    op: BusOp,
    timeout: Duration,
    mode: Mode,
    reply: Sender<Result<Vec<u8>, GwError>>,
}

/// Answers one request line; bus operations go to `jobs`.
fn answer(line: &str, s: &mut Session, jobs: &Sender<Job>) -> String {
    let line = line.trim();
    let (seq, rest) = match line.strip_prefix('[') {
        Some(r) => match r.split_once(']') {
            Some((n, rest)) => match n.trim().parse::<u32>() {
                Ok(n) => (Some(n), rest),
                Err(_) => return format!("ERROR: {}", GwError::SYNTAX),
            },
            None => return format!("ERROR: {}", GwError::SYNTAX),
        },
        None => (None, line),
    };
    let result = parse(rest, s).and_then(|action| match action {
        Action::Answer(a) => Ok(a),
        Action::Bus { op, show: how } => {
            let (tx, rx) = mpsc::channel();
            let job = Job {
                op,
                timeout: Duration::from_millis(u64::from(s.sdo_timeout_ms)),
                mode: if s.block {
                    Mode::Block { blksize: 127 }
                } else {
                    Mode::Auto
                },
                reply: tx,
            };
            jobs.send(job).map_err(|_| GwError::STATE)?;
            let data = rx.recv().map_err(|_| GwError::STATE)??;
            match how {
                Some(t) => show(t, &data),
                None => Ok("OK".into()),
            }
        }
    });
    let text = match result {
        Ok(t) => t,
        Err(e) => format!("ERROR: {e}"),
    };
    match seq {
        // A multi-line answer (help) carries the sequence number on its last line.
        Some(n) => match text.rsplit_once('\n') {
            Some((head, last)) => format!("{head}\n[{n}] {last}"),
            None => format!("[{n}] {text}"),
        },
        None => text,
    }
}

/// Runs `op` on the bus; the master's own SDO timeout ends a transfer that gets no answer.
fn execute(link: &mut Link, master: &mut Master, job: &Job) -> Result<Result<Vec<u8>, GwError>> {
    let mut out = Outbox::new();
    master.config_mut().sdo.timeout = job.timeout;
    let started = match &job.op {
        BusOp::Nmt { node, cs } => {
            let r = master.nmt(*cs, *node, &mut out);
            for f in out.drain() {
                link.send(f)?;
            }
            return Ok(r.map(|()| Vec::new()).map_err(|_| GwError::NODE));
        }
        BusOp::Upload { node, mux } => master.upload(*node, *mux, job.mode, link.now(), &mut out),
        BusOp::Download { node, mux, data } => {
            master.download(*node, *mux, data.clone(), job.mode, link.now(), &mut out)
        }
    };
    let id: TransferId = match started {
        Ok(id) => id,
        Err(_) => return Ok(Err(GwError::STATE)),
    };
    for f in out.drain() {
        link.send(f)?;
    }
    let mut result = None;
    let limit = WallDuration::from_nanos(job.timeout.as_nanos()) * 4 + WallDuration::from_secs(600);
    link.run(
        master,
        |m| {
            while let Some((_, ev)) = m.poll_event() {
                if let MasterEvent::Sdo { id: got, event, .. } = ev
                    && got == id
                {
                    match event {
                        SdoEvent::Completed { data, .. } => result = Some(Ok(data)),
                        SdoEvent::Aborted { code, .. } => result = Some(Err(GwError::Abort(code))),
                        _ => {}
                    }
                }
            }
            result.is_some()
        },
        limit,
    )?;
    Ok(result.unwrap_or(Err(GwError::Code(103))))
}

/// Drives the bus: runs jobs one at a time and keeps the master fed between them (so the
/// link's receive queue stays short and a job waits at most 10 ms), until every client is
/// gone.
fn serve_bus(link: &mut Link, jobs: &Receiver<Job>) -> Result<()> {
    let mut master = Master::new();
    loop {
        match jobs.try_recv() {
            Ok(job) => {
                let r = execute(link, &mut master, &job)?;
                // A client that left does not take an answer.
                let _ = job.reply.send(r);
            }
            Err(TryRecvError::Empty) => {
                link.run(
                    &mut master,
                    |m| {
                        while m.poll_event().is_some() {}
                        false
                    },
                    WallDuration::from_millis(10),
                )?;
            }
            Err(TryRecvError::Disconnected) => return Ok(()),
        }
    }
}

/// Reads one line of at most [`MAX_LINE`] bytes: `None` at the end of input, `Some(Err(()))`
/// for a longer line (whose rest is skipped).
fn read_line(r: &mut impl BufRead) -> std::io::Result<Option<Result<String, ()>>> {
    let mut buf = Vec::new();
    let n = r
        .by_ref()
        .take(MAX_LINE as u64 + 1)
        .read_until(b'\n', &mut buf)?;
    if n == 0 {
        return Ok(None);
    }
    if buf.last() != Some(&b'\n') && buf.len() > MAX_LINE {
        loop {
            let mut skip = Vec::new();
            let n = r.by_ref().take(4096).read_until(b'\n', &mut skip)?;
            if n == 0 || skip.last() == Some(&b'\n') {
                break;
            }
        }
        return Ok(Some(Err(())));
    }
    Ok(Some(
        String::from_utf8(buf)
            .map_err(|_| ())
            .map(|s| s.trim_end().to_owned()),
    ))
}

/// Serves one client: lines in, answers out, each answer ended by `eol`.
fn serve_client(
    input: &mut impl BufRead,
    output: &mut impl Write,
    jobs: &Sender<Job>,
    mut session: Session,
    eol: &str,
) -> std::io::Result<()> {
    while let Some(line) = read_line(input)? {
        let text = match line {
            Ok(l) if l.trim().is_empty() => continue,
            Ok(l) => answer(&l, &mut session, jobs),
            Err(()) => format!("ERROR: {}", GwError::SYNTAX),
        };
        output.write_all(text.replace('\n', eol).as_bytes())?;
        output.write_all(eol.as_bytes())?;
        output.flush()?;
    }
    Ok(())
}

fn listen_addr(spec: &str) -> String {
    if spec.contains(':') {
        spec.to_owned()
    } else {
        format!("127.0.0.1:{spec}")
    }
}

/// Runs `cantwin gateway`.
pub fn run(args: &GatewayArgs) -> Result<()> {
    if !args.ascii {
        bail!("give --ascii: the CiA 309-3 ASCII protocol is the only one offered");
    }
    if args.sdo_timeout == 0 {
        bail!("--sdo-timeout must be greater than 0");
    }
    let session = Session {
        node: None,
        sdo_timeout_ms: args.sdo_timeout,
        block: false,
    };
    let mut link = Link::open(&args.target)?;
    let (jobs, rx) = mpsc::channel::<Job>();
    match &args.listen {
        None => {
            std::thread::spawn(move || {
                let stdin = std::io::stdin();
                let mut input = stdin.lock();
                let mut output = std::io::stdout();
                if let Err(e) = serve_client(&mut input, &mut output, &jobs, session, "\n") {
                    eprintln!("gateway: {e}");
                }
            });
        }
        Some(spec) => {
            let addr = listen_addr(spec);
            let listener = TcpListener::bind(&addr)
                .with_context(|| format!("--listen {spec}: binding {addr}"))?;
            let local = listener.local_addr().context("the listening address")?;
            println!("gateway {local}");
            std::io::stdout().flush().context("writing to stdout")?;
            std::thread::spawn(move || accept(&listener, &jobs, session));
        }
    }
    serve_bus(&mut link, &rx)
}

/// Accepts TCP clients, at most [`MAX_CLIENTS`] at once.
fn accept(listener: &TcpListener, jobs: &Sender<Job>, session: Session) {
    let clients = Arc::new(AtomicUsize::new(0));
    for stream in listener.incoming() {
        let Ok(mut stream) = stream else {
            continue;
        };
        if clients.fetch_add(1, Ordering::SeqCst) >= MAX_CLIENTS {
            clients.fetch_sub(1, Ordering::SeqCst);
            let _ = writeln!(
                stream,
                "ERROR: {} (the gateway serves at most {MAX_CLIENTS} clients)\r",
                GwError::STATE
            );
            continue;
        }
        let jobs = jobs.clone();
        let clients = Arc::clone(&clients);
        std::thread::spawn(move || {
            if let Err(e) = serve_tcp(stream, &jobs, session) {
                eprintln!("gateway client: {e}");
            }
            clients.fetch_sub(1, Ordering::SeqCst);
        });
    }
}

fn serve_tcp(stream: TcpStream, jobs: &Sender<Job>, session: Session) -> std::io::Result<()> {
    let mut output = stream.try_clone()?;
    let mut input = BufReader::new(stream);
    serve_client(&mut input, &mut output, jobs, session, "\r\n")
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn cia309_3_read_values_shown_like_the_reference_gateway() {
        let d = |m: &str| Some(ty(m).unwrap());
        assert_eq!(show(d("u16"), &[0xE8, 0x03]).unwrap(), "1000");
        assert_eq!(show(d("x32"), &[0x91, 0x01, 0, 0]).unwrap(), "0x00000191");
        assert_eq!(show(d("i8"), &[0xFE]).unwrap(), "-2");
        assert_eq!(show(d("b"), &[1]).unwrap(), "1");
        assert_eq!(show(d("vs"), b"a \"b\"").unwrap(), "\"a \"\"b\"\"\"");
        assert_eq!(show(d("os"), &[1, 0xAB]).unwrap(), "01 AB");
        assert_eq!(show(None, &[1, 0xAB]).unwrap(), "01 AB");
        assert_eq!(
            show(d("u32"), &[1, 2]).err(),
            Some(GwError::Abort(AbortCode::TYPE_MISMATCH))
        );
    }

    #[test]
    fn sequence_numbers_and_errors_are_formatted() {
        let (jobs, _rx) = mpsc::channel();
        let mut s = session();
        assert_eq!(answer("[3] set node 9", &mut s, &jobs), "[3] OK");
        assert_eq!(answer("[4] 9 bogus", &mut s, &jobs), "[4] ERROR: 100");
        assert_eq!(answer("[x] 9 start", &mut s, &jobs), "ERROR: 101");
        assert_eq!(answer("set sdo_timeout 0", &mut s, &jobs), "ERROR: 101");
        assert!(answer("[5] help", &mut s, &jobs).ends_with("\n[5] OK"));
        assert_eq!(
            GwError::Abort(AbortCode::from(0x0602_0000)).to_string(),
            "0x06020000"
        );
    }

    #[test]
    fn long_lines_are_refused_and_skipped() {
        let text = format!("{}\n[1] help\n", "x".repeat(MAX_LINE + 10));
        let mut r = std::io::Cursor::new(text.into_bytes());
        assert_eq!(read_line(&mut r).unwrap(), Some(Err(())));
        assert_eq!(read_line(&mut r).unwrap(), Some(Ok("[1] help".into())));
        assert_eq!(read_line(&mut r).unwrap(), None);
    }
}
