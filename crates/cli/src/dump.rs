//! `cantwin dump FILE`: print a capture (pcap, pcapng or candump log), one record a line.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The capture: pcap or pcapng with LINKTYPE_CAN_SOCKETCAN, or a candump log; the format
    /// is recognised from its content.
    file: PathBuf,
}

pub fn run(args: &Args) -> Result<()> {
    let mut reader = cantwin_capture::open(&args.file)
        .with_context(|| format!("reading {}", args.file.display()))?;
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    if crate::output::json() {
        return dump_json(&mut reader, &mut out, args);
    }
    let summary = cantwin_capture::dump(&mut reader, &mut out);
    out.flush().ok();
    let summary = summary.with_context(|| format!("reading {}", args.file.display()))?;
    eprintln!(
        "{} ({:?})",
        crate::report::count(summary.records, "record", "records"),
        reader.format()
    );
    Ok(())
}

/// One JSON object per record (JSON Lines): time, channel, and the frame or error class.
fn dump_json<R: std::io::BufRead>(
    reader: &mut cantwin_capture::CaptureReader<R>,
    out: &mut impl Write,
    args: &Args,
) -> Result<()> {
    use cantwin_capture::Event;
    let mut records = 0u64;
    let result = (|| -> Result<()> {
        while let Some(r) = reader.read_record()? {
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
            writeln!(out, "{v}")?;
            records += 1;
        }
        Ok(())
    })();
    out.flush().ok();
    result.with_context(|| format!("reading {} after {records} records", args.file.display()))
}
