//! CANopen client commands: `cantwin sdo`, `nmt`, `scan` and `trace`, driving the sans-IO
//! master of `cantwin-canopen` over any bus a client command can reach.

use std::io::Write as _;
use std::path::PathBuf;
use std::time::Duration as WallDuration;

use anyhow::{Context, Result, bail};
use cantwin_can::Outbox;
use cantwin_canopen::master::pdo::PdoDecoder;
use cantwin_canopen::master::{Master, MasterEvent, Mode, SdoEvent, TransferId};
use cantwin_canopen::od::{DataType, Value};
use cantwin_canopen::sdo::wire::Mux;
use cantwin_canopen::wire::NmtCs;

use crate::connect::{Link, Target};
use crate::output;
use serde_json::json;

pub(crate) fn data_type(mnemonic: &str) -> Result<DataType> {
    cantwin_cia309::data_type(mnemonic).with_context(|| {
        let all: Vec<&str> = cantwin_cia309::MNEMONICS.iter().map(|(m, _)| *m).collect();
        format!(
            "unknown data type {mnemonic:?} (CiA 309-3 mnemonics: {})",
            all.join(" ")
        )
    })
}

pub(crate) fn number(text: &str, what: &str) -> Result<u32> {
    let t = text.trim();
    let v = match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(h) => u32::from_str_radix(h, 16),
        None => t.parse(),
    };
    v.with_context(|| format!("{what} {text:?} is not a number (decimal, or hex with 0x)"))
}

fn node_id(text: &str) -> Result<u8> {
    let n = number(text, "node-ID")?;
    u8::try_from(n)
        .ok()
        .filter(|n| (1..=127).contains(n))
        .with_context(|| format!("node-ID {text} is outside 1–127"))
}

pub(crate) fn mux(index: &str, sub: &str) -> Result<Mux> {
    let i = number(index, "index")?;
    let s = number(sub, "sub-index")?;
    Ok(Mux::new(
        u16::try_from(i).with_context(|| format!("index {index} is above 0xFFFF"))?,
        u8::try_from(s).with_context(|| format!("sub-index {sub} is above 255"))?,
    ))
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum ModeArg {
    Auto,
    Expedited,
    Segmented,
    Block,
}

impl ModeArg {
    fn mode(self, blksize: u8) -> Mode {
        match self {
            ModeArg::Auto => Mode::Auto,
            ModeArg::Expedited => Mode::Expedited,
            ModeArg::Segmented => Mode::Segmented,
            ModeArg::Block => Mode::Block { blksize },
        }
    }
}

#[derive(Debug, clap::Args)]
pub struct SdoArgs {
    #[command(flatten)]
    target: Target,
    /// SDO protocol: auto (by size), expedited, segmented or block.
    #[arg(long, value_enum, default_value_t = ModeArg::Auto, global = true)]
    mode: ModeArg,
    /// Segments per block for block transfers (1–127).
    #[arg(long, default_value_t = 127, value_parser = clap::value_parser!(u8).range(1..=127), global = true)]
    block_size: u8,
    /// SDO timeout in seconds (CiA 301's usual 1 s).
    #[arg(long, default_value_t = 1.0, global = true)]
    timeout: f64,
    #[command(subcommand)]
    command: SdoCommand,
}

#[derive(Debug, clap::Subcommand)]
enum SdoCommand {
    /// Read (upload) an object: NODE INDEX SUB [TYPE]. Without a type the bytes are shown
    /// in hex; `--output FILE` writes them to a file.
    #[command(
        after_help = "Examples:\n  cantwin sdo --socketcand 127.0.0.1:29536 read 5 0x1008 0 vs\n  \
                            cantwin sdo --socketcand 127.0.0.1:29536 read 5 0x1017 0 u16\n  \
                            cantwin sdo --socketcand 127.0.0.1:29536 --mode block read 5 0x2000 0 --output domain.bin\n\n\
                            Types (CiA 309-3): b i8 i16 i24 i32 i40 i48 i56 i64 u8 u16 u24 u32 u40 u48 u56 u64 r32 r64 t td vs os us d"
    )]
    Read {
        /// Node-ID (1–127).
        node: String,
        /// Object index (0x1017 or 4119).
        index: String,
        /// Sub-index.
        sub: String,
        /// CiA 309-3 data type mnemonic.
        r#type: Option<String>,
        /// Write the bytes read to this file.
        #[arg(long, short)]
        output: Option<PathBuf>,
    },
    /// Write (download) an object: NODE INDEX SUB TYPE VALUE, or `--input FILE` for the
    /// bytes of a DOMAIN.
    #[command(
        after_help = "Examples:\n  cantwin sdo --socketcand 127.0.0.1:29536 write 5 0x1017 0 u16 1000\n  \
                            cantwin sdo --socketcand 127.0.0.1:29536 write 5 0x1008 0 vs \"Pump 3\"\n  \
                            cantwin sdo --socketcand 127.0.0.1:29536 --mode block write 5 0x2000 0 d --input firmware.bin"
    )]
    Write {
        /// Node-ID (1–127).
        node: String,
        /// Object index.
        index: String,
        /// Sub-index.
        sub: String,
        /// CiA 309-3 data type mnemonic.
        r#type: String,
        /// The value (decimal, 0x hex, text, or hex bytes for os/d).
        value: Option<String>,
        /// Read the bytes to write from this file.
        #[arg(long, short)]
        input: Option<PathBuf>,
    },
}

/// Run one transfer on `master` to its end.
fn transfer(link: &mut Link, master: &mut Master, id: TransferId, timeout: f64) -> Result<Vec<u8>> {
    let mut result = None;
    // Drawn only for transfers of 4 KiB or more, where it is worth watching.
    let mut bar: Option<indicatif::ProgressBar> = None;
    let finished = link.run(
        master,
        |m| {
            while let Some((_, ev)) = m.poll_event() {
                if let MasterEvent::Sdo { id: got, event, .. } = ev
                    && got == id
                {
                    match event {
                        SdoEvent::Progress { done, total } => {
                            if total.is_some_and(|t| t >= 4096) || done >= 4096 {
                                bar.get_or_insert_with(|| {
                                    output::bytes(total.map(u64::from), "SDO")
                                })
                                .set_position(u64::from(done));
                            }
                        }
                        SdoEvent::FellBack { code } => {
                            eprintln!("the server refused block transfer ({code}); falling back to segmented");
                        }
                        SdoEvent::Completed { data, .. } => result = Some(Ok(data)),
                        SdoEvent::Aborted { code, by_server, .. } => {
                            result = Some(Err((code, by_server)));
                        }
                    }
                }
            }
            result.is_some()
        },
        // The master's own SDO timeout decides; this is only a safety net.
        WallDuration::from_secs_f64(timeout * 2.0 + 600.0),
    )?;
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    match result {
        Some(Ok(data)) => Ok(data),
        Some(Err((code, true))) => bail!("SDO aborted by the server: {code}"),
        Some(Err((code, false))) => bail!("SDO aborted: {code}"),
        None if !finished => bail!("no answer"),
        None => bail!("the transfer ended without a result"),
    }
}

fn master(timeout: f64) -> Result<Master> {
    if !(timeout.is_finite() && timeout > 0.0) {
        bail!("--timeout must be a positive number of seconds");
    }
    let mut m = Master::new();
    m.config_mut().sdo.timeout = cantwin_can::Duration::from_secs_f64(timeout);
    // Progress every KiB feeds the progress bar of large transfers.
    m.config_mut().sdo.progress_step = Some(1024);
    Ok(m)
}

pub fn run_sdo(args: &SdoArgs) -> Result<()> {
    let mode = args.mode.mode(args.block_size);
    let mut m = master(args.timeout)?;
    match &args.command {
        SdoCommand::Read {
            node,
            index,
            sub,
            r#type,
            output,
        } => {
            let node = node_id(node)?;
            let mux = mux(index, sub)?;
            let ty = r#type.as_deref().map(data_type).transpose()?;
            let mut link = Link::open(&args.target)?;
            let mut out = Outbox::new();
            let id = m
                .upload(node, mux, mode, link.now(), &mut out)
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            for f in out.drain() {
                link.send(f)?;
            }
            let data = transfer(&mut link, &mut m, id, args.timeout)?;
            if let Some(path) = output {
                std::fs::write(path, &data)
                    .with_context(|| format!("writing {}", path.display()))?;
                if output::json() {
                    output::emit(&json!({
                        "node": node, "index": mux.index, "sub": mux.sub,
                        "size": data.len(), "output": path.display().to_string(),
                    }))?;
                } else {
                    eprintln!("{} bytes written to {}", data.len(), path.display());
                }
                return Ok(());
            }
            if output::json() {
                let mut v = json!({
                    "node": node, "index": mux.index, "sub": mux.sub,
                    "size": data.len(), "data": output::hex(&data),
                });
                if let Some(ty) = ty {
                    let value = Value::from_le_bytes(ty, &data).map_err(|e| {
                        anyhow::anyhow!("the {} bytes read are not a {ty:?}: {e}", data.len())
                    })?;
                    v["type"] = json!(format!("{ty:?}"));
                    v["value"] = value_json(&value);
                }
                output::emit(&v)?;
                return Ok(());
            }
            match ty {
                Some(ty) => {
                    let v = Value::from_le_bytes(ty, &data).map_err(|e| {
                        anyhow::anyhow!("the {} bytes read are not a {ty:?}: {e}", data.len())
                    })?;
                    match v {
                        Value::Unsigned8(_)
                        | Value::Unsigned16(_)
                        | Value::Unsigned32(_)
                        | Value::Unsigned64(_) => {
                            println!("{v} (0x{})", hex_le(&data))
                        }
                        _ => println!("{v}"),
                    }
                }
                None => println!("{}", hex_bytes(&data)),
            }
            Ok(())
        }
        SdoCommand::Write {
            node,
            index,
            sub,
            r#type,
            value,
            input,
        } => {
            let node = node_id(node)?;
            let mux = mux(index, sub)?;
            let ty = data_type(r#type)?;
            let data = match (value, input) {
                (Some(_), Some(_)) => bail!("give either a VALUE or --input FILE, not both"),
                (None, None) => bail!("give the VALUE to write, or --input FILE"),
                (None, Some(path)) => {
                    std::fs::read(path).with_context(|| format!("reading {}", path.display()))?
                }
                (Some(text), None) => Value::parse(ty, text)
                    .map_err(|e| anyhow::anyhow!("{text:?}: {e}"))?
                    .to_le_bytes(),
            };
            let mut link = Link::open(&args.target)?;
            let mut out = Outbox::new();
            let id = m
                .download(node, mux, data.clone(), mode, link.now(), &mut out)
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            for f in out.drain() {
                link.send(f)?;
            }
            transfer(&mut link, &mut m, id, args.timeout)?;
            output::result(
                format_args!(
                    "written {} bytes to node {node} {:#06X}sub{}",
                    data.len(),
                    mux.index,
                    mux.sub
                ),
                || {
                    json!({
                        "node": node, "index": mux.index, "sub": mux.sub,
                        "written": data.len(),
                    })
                },
            )?;
            Ok(())
        }
    }
}

/// A value read by SDO as JSON: numbers as numbers, everything else as its text.
fn value_json(v: &Value) -> serde_json::Value {
    match v {
        Value::Boolean(b) => json!(b),
        Value::Real32(x) => json!(x),
        Value::Real64(x) => json!(x),
        Value::VisibleString(_)
        | Value::UnicodeString(_)
        | Value::OctetString(_)
        | Value::Domain(_)
        | Value::TimeOfDay(_)
        | Value::TimeDifference(_) => json!(v.to_string()),
        // The integer types: their text is a decimal number.
        _ => {
            let text = v.to_string();
            text.parse::<i64>()
                .map(|n| json!(n))
                .or_else(|_| text.parse::<u64>().map(|n| json!(n)))
                .unwrap_or_else(|_| json!(text))
        }
    }
}

fn hex_bytes(data: &[u8]) -> String {
    data.iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn hex_le(data: &[u8]) -> String {
    data.iter().rev().map(|b| format!("{b:02X}")).collect()
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum NmtCommand {
    Start,
    Stop,
    Preop,
    Reset,
    ResetComm,
}

#[derive(Debug, clap::Args)]
pub struct NmtArgs {
    #[command(flatten)]
    target: Target,
    /// The command.
    #[arg(value_enum)]
    command: NmtCommand,
    /// A node-ID (1–127) or `all`.
    node: String,
}

pub fn run_nmt(args: &NmtArgs) -> Result<()> {
    let node = if args.node.eq_ignore_ascii_case("all") {
        0
    } else {
        node_id(&args.node)?
    };
    let cs = match args.command {
        NmtCommand::Start => NmtCs::Start,
        NmtCommand::Stop => NmtCs::Stop,
        NmtCommand::Preop => NmtCs::EnterPreOperational,
        NmtCommand::Reset => NmtCs::ResetNode,
        NmtCommand::ResetComm => NmtCs::ResetCommunication,
    };
    let mut link = Link::open(&args.target)?;
    let mut m = Master::new();
    let mut out = Outbox::new();
    m.nmt(cs, node, &mut out)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    for f in out.drain() {
        link.send(f)?;
        output::result(
            format_args!("sent {f}"),
            || json!({"sent": f.to_string(), "command": format!("{:?}", args.command), "node": node}),
        )?;
    }
    // Let the frame leave before the link closes.
    link.run(&mut m, |_| false, WallDuration::from_millis(100))?;
    Ok(())
}

#[derive(Debug, clap::Args)]
pub struct ScanArgs {
    #[command(flatten)]
    target: Target,
    /// How long each node has to answer, in seconds.
    #[arg(long, default_value_t = 0.3)]
    timeout: f64,
}

pub fn run_scan(args: &ScanArgs) -> Result<()> {
    let mut m = master(args.timeout)?;
    let mut link = Link::open(&args.target)?;
    let mut out = Outbox::new();
    m.scan(link.now(), &mut out)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    for f in out.drain() {
        link.send(f)?;
    }
    let mut found = None;
    link.run(
        &mut m,
        |m| {
            while let Some((_, ev)) = m.poll_event() {
                if let MasterEvent::ScanFinished { found: f } = ev {
                    found = Some(f);
                }
            }
            found.is_some()
        },
        WallDuration::from_secs_f64(args.timeout * 4.0 + 10.0),
    )?;
    let found = found.context("the scan did not finish")?;
    if output::json() {
        let nodes: Vec<serde_json::Value> = found
            .iter()
            .map(|hit| match hit.device_type {
                Ok(t) => json!({"node": hit.node, "device_type": t, "profile": t & 0xFFFF, "additional": t >> 16}),
                Err(code) => json!({"node": hit.node, "abort": code.to_string()}),
            })
            .collect();
        output::emit(&json!({"nodes": nodes, "found": found.len()}))?;
        return Ok(());
    }
    for hit in &found {
        match hit.device_type {
            Ok(t) => println!(
                "node {:3}  device type 0x{t:08X} (profile {}, additional 0x{:04X})",
                hit.node,
                t & 0xFFFF,
                t >> 16
            ),
            Err(code) => println!("node {:3}  answered with abort {code}", hit.node),
        }
    }
    println!("{} nodes found", found.len());
    Ok(())
}

#[derive(Debug, clap::Args)]
pub struct TraceArgs {
    #[command(flatten)]
    target: Target,
    /// Name PDO values from a node's EDS or DCF: NODE=FILE (repeatable).
    #[arg(long = "eds", value_name = "NODE=FILE")]
    eds: Vec<String>,
    /// Stop after this many seconds (default: until Ctrl-C).
    #[arg(long)]
    seconds: Option<f64>,
    /// Stop after this many frames.
    #[arg(long)]
    count: Option<u64>,
}

pub use cantwin_report::canopen::{describe, emcy_meaning};

/// The PDOs an EDS declares for `node`, with their default COB-IDs and mappings.
fn pdo_decoder(specs: &[String]) -> Result<PdoDecoder> {
    let mut decoder = PdoDecoder::new();
    add_eds_pdos(&mut decoder, specs)?;
    Ok(decoder)
}

/// Adds to `decoder` the PDOs of `--eds NODE=FILE` specs (replacing any on the same COB-IDs).
pub(crate) fn add_eds_pdos(decoder: &mut PdoDecoder, specs: &[String]) -> Result<()> {
    for spec in specs {
        let (node, file) = spec
            .split_once('=')
            .with_context(|| format!("--eds {spec:?}: expected NODE=FILE"))?;
        let node = node_id(node)?;
        let bytes = std::fs::read(file).with_context(|| format!("reading {file}"))?;
        cantwin_report::canopen::add_eds_pdos(decoder, node, &bytes)
            .map_err(|e| anyhow::anyhow!("{file}: {e}"))?;
    }
    Ok(())
}

pub fn run_trace(args: &TraceArgs) -> Result<()> {
    // The listing decoder of `cantwin dump --decode`: it also names a node guarding answer
    // by the request before it (CiA 301 §7.2.8.3.2.1), which one frame alone cannot.
    let opts = cantwin_report::Options {
        pdos: pdo_decoder(&args.eds)?,
        ..cantwin_report::Options::default()
    };
    let mut decoder = cantwin_report::Decoder::new(&opts);
    let mut link = Link::open(&args.target)?;
    let limit = args.seconds.map(WallDuration::from_secs_f64);
    let mut seen = 0u64;
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let mut failed = None;
    link.watch(limit, |frame, at| {
        let t = at
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| format!("{}.{:06}", d.as_secs(), d.subsec_micros()))
            .unwrap_or_default();
        let text = decoder.describe("", frame);
        let written = if output::json() {
            let mut v = output::frame_json(frame);
            v["time"] = json!(t);
            v["frame"] = json!(frame.to_string());
            v["decoded"] = json!(text);
            writeln!(out, "{v}")
        } else {
            writeln!(out, "({t}) {:<20} {text}", frame.to_string())
        };
        if let Err(e) = written {
            failed = Some(e);
            return false;
        }
        seen += 1;
        args.count.is_none_or(|c| seen < c)
    })?;
    match failed {
        // A closed pipe (`| head`) ends the trace quietly.
        Some(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}
