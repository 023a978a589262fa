//! `cantwin report CAPTURE`: one self-contained HTML page about a capture (bus load,
//! identifiers, decoded timeline, anomalies), built by `cantwin-report`.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use cantwin_can::BitRate;
use cantwin_report::{Options, Protocol};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The capture: pcap, pcapng or candump log.
    capture: PathBuf,
    /// Where to write the page (default: CAPTURE.html beside the capture).
    #[arg(short, long, value_name = "FILE")]
    output: Option<PathBuf>,
    /// Bit rate of a channel for the bus load: CHANNEL=RATE, or RATE for every channel.
    /// Repeatable. Captures do not record the bit rate: without this, 500k is assumed (as
    /// `cantwin monitor` does), and the output says so.
    #[arg(long = "bit-rate", value_name = "[CHANNEL=]RATE")]
    bit_rate: Vec<String>,
    /// Protocol of a channel: CHANNEL=canopen|devicenet|cal, or canopen|devicenet|cal for
    /// every channel (default canopen), as `cantwin dump --decode` takes it. Repeatable.
    #[arg(long = "protocol", value_name = "[CHANNEL=]PROTOCOL")]
    protocol: Vec<String>,
    /// Name PDO values from a node's EDS or DCF: NODE=FILE (repeatable).
    #[arg(long = "eds", value_name = "NODE=FILE")]
    eds: Vec<String>,
    /// Width of a bus load window in milliseconds (default: 100 ms, widened so that a long
    /// capture has at most 2000 windows).
    #[arg(long, value_name = "MS")]
    window_ms: Option<u64>,
    /// Channel name of a pcap file's records (pcap has none).
    #[arg(long, value_name = "NAME", default_value = "can0")]
    pcap_channel: String,
}

/// `1 record`, `2 records`: a count with its noun in the right number.
pub fn count(n: u64, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}

fn options(args: &Args) -> Result<Options> {
    let mut opts = Options::default();
    for spec in &args.bit_rate {
        match spec.split_once('=') {
            Some((ch, rate)) => {
                let rate: BitRate = rate.parse().with_context(|| format!("--bit-rate {spec}"))?;
                opts.bit_rates.insert(ch.to_string(), rate);
            }
            None => {
                opts.default_bit_rate =
                    Some(spec.parse().with_context(|| format!("--bit-rate {spec}"))?);
            }
        }
    }
    if let Some(ms) = args.window_ms {
        if ms == 0 {
            bail!("--window-ms must be at least 1");
        }
        opts.window_ns = Some(ms.saturating_mul(1_000_000));
    }
    for spec in &args.protocol {
        let (channel, p) = match spec.split_once('=') {
            Some((ch, p)) => (Some(ch), p),
            None => (None, spec.as_str()),
        };
        let p: Protocol = p
            .parse()
            .map_err(|e| anyhow::anyhow!("--protocol {spec}: {e}"))?;
        match channel {
            Some(ch) => {
                opts.protocols.insert(ch.to_string(), p);
            }
            None => opts.default_protocol = p,
        }
    }
    for spec in &args.eds {
        let (node, file) = spec
            .split_once('=')
            .with_context(|| format!("--eds {spec:?}: expected NODE=FILE"))?;
        let node: u8 = match node.parse() {
            Ok(n @ 1..=127) => n,
            _ => bail!("--eds {spec:?}: node-ID must be 1..127"),
        };
        let bytes = std::fs::read(file).with_context(|| format!("reading {file}"))?;
        cantwin_report::canopen::add_eds_pdos(&mut opts.pdos, node, &bytes)
            .with_context(|| file.to_string())?;
    }
    Ok(opts)
}

pub fn run(args: &Args) -> Result<()> {
    let opts = options(args)?;
    let path = &args.capture;
    let mut reader = cantwin_capture::open(path)
        .with_context(|| format!("opening {}", path.display()))?
        .with_pcap_channel(args.pcap_channel.clone());
    // Streamed: a capture larger than memory is analysed as it is read.
    let mut analysis = cantwin_report::Analysis::new(&opts);
    let mut records = 0u64;
    while let Some(record) = reader
        .read_record()
        .with_context(|| format!("reading {}", path.display()))?
    {
        analysis.push(&record);
        records += 1;
    }
    let report = analysis.finish();
    let out = args.output.clone().unwrap_or_else(|| {
        let mut name = path.as_os_str().to_owned();
        name.push(".html");
        PathBuf::from(name)
    });
    std::fs::write(&out, cantwin_report::render_html(&report))
        .with_context(|| format!("writing {}", out.display()))?;
    let rates: Vec<String> = report
        .channels
        .iter()
        .map(|c| {
            let assumed = if c.bit_rate_assumed {
                " assumed (the capture does not record it; --bit-rate to give it)"
            } else {
                ""
            };
            format!("{} at {}{assumed}", c.name, c.bit_rate)
        })
        .collect();
    crate::output::result(
        format_args!(
            "{}: {}, {}, {}; bus load of {}",
            out.display(),
            count(records, "record", "records"),
            count(report.sdo_total, "SDO transfer", "SDO transfers"),
            count(report.anomalies.len() as u64, "anomaly", "anomalies"),
            if rates.is_empty() {
                "no channel".to_string()
            } else {
                rates.join(", ")
            }
        ),
        || {
            serde_json::json!({
                "output": out.display().to_string(),
                "records": records,
                "sdo_transfers": report.sdo_total,
                "anomalies": report.anomalies.len(),
                "channels": report.channels.iter().map(|c| serde_json::json!({
                    "name": c.name,
                    "bit_rate": c.bit_rate.bits_per_second(),
                    "bit_rate_assumed": c.bit_rate_assumed,
                })).collect::<Vec<_>>(),
            })
        },
    )?;
    Ok(())
}
