//! `cantwin dump FILE`: print a capture (pcap, pcapng or candump log), one record a line,
//! with `--decode` each frame decoded as `cantwin trace` decodes a live bus.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use cantwin_capture::Event;
use cantwin_report::{Decoder, Options, Protocol};
use cantwin_scenario::{BuildEnv, Registry, Scenario};
use cantwin_twin::FileDate;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The capture: pcap or pcapng with LINKTYPE_CAN_SOCKETCAN, or a candump log; the format
    /// is recognised from its content.
    file: PathBuf,
    /// Decode each frame after it: CANopen (services of the pre-defined connection set,
    /// PDOs named from --eds, LSS), DeviceNet (identifier groups, explicit messages) or CAL
    /// CMS, by the protocol of its channel.
    #[arg(long)]
    decode: bool,
    /// The protocol a channel carries: PROTOCOL for every channel or CHANNEL=PROTOCOL
    /// (canopen, devicenet or cal; repeatable). Default canopen, or what --scenario says.
    #[arg(
        long = "protocol",
        value_name = "[CHANNEL=]PROTOCOL",
        requires = "decode"
    )]
    protocol: Vec<String>,
    /// Take each channel's protocol from the scenario whose buses it recorded (a channel is
    /// named after its bus): CANopen where a twin is a CANopen node, DeviceNet where a twin
    /// serves a DeviceNet EDS (the ADV200 in its DeviceNet personality), CAL where the twins
    /// are neither (the OPEN DRIVE). --protocol overrides it.
    #[arg(long, value_name = "FILE", requires = "decode")]
    scenario: Option<PathBuf>,
    /// Name PDO values from a node's EDS or DCF: NODE=FILE (repeatable).
    #[arg(long = "eds", value_name = "NODE=FILE", requires = "decode")]
    eds: Vec<String>,
    /// Channel name of a pcap file's records (pcap has none).
    #[arg(long, value_name = "NAME", default_value = "can0")]
    pcap_channel: String,
}

/// The protocol each bus of `scenario` carries, judged from its twins at power-up.
pub fn scenario_protocols(scenario: &Scenario) -> Result<BTreeMap<String, Protocol>> {
    let built = scenario.build(&Registry::builtin(), &BuildEnv::default())?;
    let date = FileDate {
        year: 2000,
        month: 1,
        day: 1,
        hour: 0,
        minute: 0,
        second: 0,
    };
    let mut out = BTreeMap::new();
    for (name, bus) in &built.buses {
        let twins: Vec<_> = built
            .devices
            .iter()
            .filter(|d| d.port.bus() == *bus)
            .filter_map(|d| built.sim.twin(d.port))
            .collect();
        let protocol = if twins.is_empty()
            || twins
                .iter()
                .any(|t| t.canopen_node_id().is_some() || t.lss_slave())
        {
            Protocol::CanOpen
        } else if twins.iter().any(|t| t.data_sheet(&date).is_ok()) {
            Protocol::DeviceNet
        } else {
            Protocol::Cal
        };
        out.insert(name.clone(), protocol);
    }
    Ok(out)
}

fn options(args: &Args) -> Result<Options> {
    let mut opts = Options::default();
    if let Some(file) = &args.scenario {
        let scenario = Scenario::load(file)?;
        opts.protocols = scenario_protocols(&scenario)?;
    }
    for spec in &args.protocol {
        let parse = |p: &str| -> Result<Protocol> {
            p.parse()
                .map_err(|e| anyhow::anyhow!("--protocol {spec}: {e}"))
        };
        match spec.split_once('=') {
            Some((ch, p)) => {
                opts.protocols.insert(ch.to_string(), parse(p)?);
            }
            None => {
                if args.scenario.is_some() {
                    bail!("--protocol {spec} for every channel overrides --scenario: give one");
                }
                opts.default_protocol = parse(spec)?;
            }
        }
    }
    crate::canopen::add_eds_pdos(&mut opts.pdos, &args.eds)?;
    Ok(opts)
}

pub fn run(args: &Args) -> Result<()> {
    let opts = options(args)?;
    let mut reader = cantwin_capture::open(&args.file)
        .with_context(|| format!("reading {}", args.file.display()))?
        .with_pcap_channel(args.pcap_channel.clone());
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    let mut decoder = args.decode.then(|| Decoder::new(&opts));
    let mut records = 0u64;
    let json = crate::output::json();
    let result = (|| -> Result<()> {
        while let Some(r) = reader.read_record()? {
            let decoded = match (&r.event, decoder.as_mut()) {
                (Event::Frame(f), Some(d)) => Some(d.describe(&r.channel, f)),
                _ => None,
            };
            if json {
                writeln!(out, "{}", record_json(&r, decoded.as_deref()))?;
            } else {
                let line = cantwin_capture::format_record(&r);
                match decoded.as_deref() {
                    Some(text) if !text.is_empty() => writeln!(out, "{line}  {text}")?,
                    _ => writeln!(out, "{line}")?,
                }
            }
            records += 1;
        }
        Ok(())
    })();
    out.flush().ok();
    // A closed pipe (`| head`) ends the process quietly in `main`, as for every command.
    result.with_context(|| format!("reading {} after {records} records", args.file.display()))?;
    if reader.skipped() > 0 && !json {
        writeln!(
            std::io::stdout(),
            "# {} CAN FD / CAN XL frames skipped",
            reader.skipped()
        )
        .ok();
    }
    eprintln!(
        "{} ({:?})",
        crate::report::count(records, "record", "records"),
        reader.format()
    );
    Ok(())
}

/// One JSON object per record (JSON Lines): time, channel, and the frame or error class,
/// with the decoded text under `--decode`.
fn record_json(r: &cantwin_capture::Record, decoded: Option<&str>) -> serde_json::Value {
    let mut v = match &r.event {
        Event::Frame(f) => {
            let mut v = crate::output::frame_json(f);
            v["frame"] = serde_json::json!(f.to_string());
            v
        }
        Event::Error(e) => serde_json::json!({
            "error": e.to_string(),
            "class": e.class(),
            "data": crate::output::hex(&e.data()),
        }),
    };
    v["timestamp_ns"] = serde_json::json!(r.timestamp_ns);
    v["channel"] = serde_json::json!(r.channel);
    if let Some(text) = decoded {
        v["decoded"] = serde_json::json!(text);
    }
    v
}
