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
    let summary = cantwin_capture::dump(&mut reader, &mut out);
    out.flush().ok();
    let summary = summary.with_context(|| format!("reading {}", args.file.display()))?;
    eprintln!("{} records ({:?})", summary.records, reader.format());
    Ok(())
}
