//! `cantwin conform`: the CiA 301/306 conformance cases of `cantwin-conform` against one
//! device, over a socketcand connection, an slcan adapter on TCP, a SocketCAN interface of
//! this host (cargo feature `socketcan`), or a scenario run in virtual time.

use std::net::ToSocketAddrs;
use std::path::{Path, PathBuf};
use std::time::Duration as WallDuration;

use anyhow::{Context, Result, bail};
use cantwin_can::Duration;
use cantwin_conform::{
    Area, Options, PortTransport, Profile, ProfileFile, Report, Transport, VirtualBus,
};
use cantwin_gateway::BusConnector as _;
use cantwin_gateway::socketcand::Remote;
use cantwin_scenario::{BuildEnv, Registry, Scenario};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The device's node-ID (1–127).
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=127), required_unless_present = "list")]
    node_id: Option<u8>,
    /// The device's EDS or DCF.
    #[arg(long, value_name = "FILE", required_unless_present = "list")]
    eds: Option<PathBuf>,
    /// A device profile (TOML): optional features the EDS cannot express and the
    /// deviations the device's manual prescribes (`cantwin eds export` writes one beside a
    /// twin's EDS).
    #[arg(long, value_name = "FILE")]
    profile: Option<PathBuf>,
    /// A socketcand server in front of the device, HOST:PORT. (A SocketCAN interface of
    /// this host directly: `--socketcan IFACE`, in a cantwin built with `cargo build
    /// --features socketcan`.)
    #[arg(long, value_name = "HOST:PORT", conflicts_with_all = ["scenario", "slcan"])]
    socketcand: Option<String>,
    /// A SocketCAN interface of this host on the device's bus (can0, vcan0), up at the
    /// device's bit rate.
    #[cfg(feature = "socketcan")]
    #[arg(
        long,
        value_name = "IFACE",
        conflicts_with_all = ["scenario", "slcan", "socketcand"]
    )]
    socketcan: Option<String>,
    /// An slcan (Lawicel) adapter on TCP in front of the device, HOST:PORT: cantwin's slcan
    /// gateway, or a serial adapter behind a TCP-to-serial bridge.
    #[arg(long, value_name = "HOST:PORT", conflicts_with = "scenario")]
    slcan: Option<String>,
    /// The bit rate an slcan adapter is set to before it opens (e.g. 500k); cantwin's
    /// gateway keeps its bus's.
    #[arg(long, value_name = "RATE", requires = "slcan")]
    bit_rate: Option<cantwin_can::BitRate>,
    /// Run this scenario in-process in virtual time and test its device.
    #[arg(long, value_name = "FILE")]
    scenario: Option<PathBuf>,
    /// The bus (socketcand channel): default the scenario's only bus, or can0.
    #[arg(long, value_name = "NAME")]
    bus: Option<String>,
    /// Run only this area (repeatable): eds, sdo, od, pdo, sync-emcy-time,
    /// error-control, nmt, store-restore.
    #[arg(long, value_name = "AREA")]
    only: Vec<String>,
    /// Skip this case (repeatable), e.g. sdo.abort-timeout.
    #[arg(long, value_name = "CASE")]
    skip: Vec<String>,
    /// Write JUnit XML here.
    #[arg(long, value_name = "FILE")]
    junit: Option<PathBuf>,
    /// Write the report as JSON here.
    #[arg(long = "json-report", value_name = "FILE")]
    json_report: Option<PathBuf>,
    /// Write an HTML page here: every case with its clause and its frames.
    #[arg(long, value_name = "FILE")]
    html: Option<PathBuf>,
    /// How long the device has to answer an SDO request, in ms.
    #[arg(long, default_value_t = 1000)]
    sdo_timeout_ms: u64,
    /// How long the device has to send its boot-up message after an NMT reset, in
    /// seconds (0.01–600; a device that loads a large configuration at reset node may
    /// need more than the default).
    #[arg(long, value_name = "SECONDS", default_value_t = 2.0)]
    boot_timeout: f64,
    /// Timing cases accept periods within this many percent of the nominal one.
    #[arg(long, default_value_t = 10.0)]
    tolerance_percent: f64,
    /// List the cases with their clauses and exit.
    #[arg(long)]
    list: bool,
}

fn write(path: &Path, text: &str) -> Result<()> {
    // Written whole to a temporary file and renamed: a reader never sees half a report.
    let tmp = path.with_extension("partial");
    std::fs::write(&tmp, text).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))
}

/// Checks, before the run, that each report `args` asks for can be written: its directory
/// exists and takes a file. An error names the path as given.
fn check_report_paths(args: &Args) -> Result<()> {
    for (flag, path) in [
        ("--junit", &args.junit),
        ("--json-report", &args.json_report),
        ("--html", &args.html),
    ] {
        let Some(path) = path else { continue };
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        if !dir.is_dir() {
            bail!(
                "{flag} {}: the directory {} does not exist",
                path.display(),
                dir.display()
            );
        }
        if path.is_dir() {
            bail!("{flag} {}: is a directory", path.display());
        }
        // The same temporary file the report is written through, created and removed.
        let probe = path.with_extension("partial");
        std::fs::write(&probe, b"")
            .and_then(|()| std::fs::remove_file(&probe))
            .with_context(|| format!("{flag} {}: cannot write there", path.display()))?;
    }
    Ok(())
}

/// Writes the reports `args` asks for.
fn write_reports(args: &Args, report: &Report) -> Result<()> {
    if let Some(path) = &args.junit {
        write(path, &cantwin_conform::output::junit(report))?;
    }
    if let Some(path) = &args.json_report {
        write(path, &cantwin_conform::output::json(report))?;
    }
    if let Some(path) = &args.html {
        write(path, &cantwin_conform::output::html(report))?;
    }
    Ok(())
}

fn options(args: &Args) -> Result<Options> {
    let mut only = Vec::new();
    for a in &args.only {
        let area = Area::from_name(a).with_context(|| {
            let names: Vec<&str> = Area::ALL.iter().map(|a| a.name()).collect();
            format!("--only {a:?}: no such area ({})", names.join(", "))
        })?;
        only.push(area);
    }
    let ids: Vec<&str> = cantwin_conform::catalogue().iter().map(|c| c.id).collect();
    for s in &args.skip {
        if !ids.contains(&s.as_str()) {
            bail!("--skip {s:?}: no such case (cantwin conform --list shows them)");
        }
    }
    if !(0.0..=100.0).contains(&args.tolerance_percent) {
        bail!("--tolerance-percent must be between 0 and 100");
    }
    if !(0.01..=600.0).contains(&args.boot_timeout) {
        bail!(
            "--boot-timeout {}: must be between 0.01 and 600 seconds",
            args.boot_timeout
        );
    }
    Ok(Options {
        only,
        skip: args.skip.clone(),
        sdo_timeout: Duration::from_millis(args.sdo_timeout_ms.max(1)),
        tolerance: args.tolerance_percent / 100.0,
        boot_timeout: Duration::from_secs_f64(args.boot_timeout),
        ..Options::default()
    })
}

fn transport(args: &Args) -> Result<Box<dyn Transport>> {
    #[cfg(feature = "socketcan")]
    if let Some(iface) = &args.socketcan {
        let t = cantwin_conform::transport_socketcan::open(iface)
            .with_context(|| format!("--socketcan {iface:?}"))?;
        return Ok(Box::new(t));
    }
    if let Some(spec) = &args.slcan {
        let t = cantwin_conform::transport_slcan::open(
            spec,
            args.bit_rate,
            WallDuration::from_secs(5),
        )?;
        return Ok(Box::new(t));
    }
    match (&args.socketcand, &args.scenario) {
        (Some(spec), _) => {
            let addr = spec
                .to_socket_addrs()
                .with_context(|| format!("--socketcand {spec:?}: expected HOST:PORT"))?
                .next()
                .with_context(|| format!("--socketcand {spec:?}: resolves to no address"))?;
            let bus = args.bus.clone().unwrap_or_else(|| "can0".into());
            let remote = Remote {
                addr,
                timeout: WallDuration::from_secs(5),
            };
            let port = remote
                .open(&bus, 16_384)
                .with_context(|| format!("opening bus {bus:?} on the socketcand server {addr}"))?;
            Ok(Box::new(PortTransport::new(
                port,
                format!("socketcand {addr} {bus}"),
            )))
        }
        (None, Some(file)) => {
            let scenario = Scenario::load(file)?;
            let built = scenario.build(&Registry::builtin(), &BuildEnv::default())?;
            let bus = match &args.bus {
                Some(b) => b.clone(),
                None if built.buses.len() == 1 => built.buses[0].0.clone(),
                None => bail!(
                    "{} has several buses: choose one with --bus NAME",
                    file.display()
                ),
            };
            let id = built
                .bus(&bus)
                .with_context(|| format!("{} has no bus {bus:?}", file.display()))?;
            let vb = VirtualBus::new(built.sim, id).context("attaching to the bus")?;
            Ok(Box::new(vb))
        }
        (None, None) => {
            bail!(
                "say where the device is: --socketcand HOST:PORT, --slcan HOST:PORT{} or --scenario FILE",
                if cfg!(feature = "socketcan") {
                    ", --socketcan IFACE"
                } else {
                    ""
                }
            )
        }
    }
}

pub fn run(args: &Args) -> Result<()> {
    if args.list {
        for c in cantwin_conform::catalogue() {
            let sev = match c.severity {
                cantwin_conform::Severity::Mandatory => "",
                cantwin_conform::Severity::Advisory => " (advisory)",
            };
            println!("{:<44} {} — {}{sev}", c.id, c.clause, c.title);
        }
        return Ok(());
    }
    let (Some(node_id), Some(eds_path)) = (args.node_id, &args.eds) else {
        bail!("--node-id and --eds are required");
    };
    let options = options(args)?;
    check_report_paths(args)?;
    let bytes =
        std::fs::read(eds_path).with_context(|| format!("reading {}", eds_path.display()))?;
    let eds = cantwin_eds::load_bytes(&bytes).eds;
    // A file that describes no object is not the device's EDS (an empty file, another
    // file given by mistake): every case would fail for the file's sake.
    if eds.objects.is_empty() {
        bail!(
            "--eds {}: no object dictionary in the file (CiA 306 §4.6): is it an EDS or DCF?",
            eds_path.display()
        );
    }
    let mut profile = Profile::from_eds(&eds);
    if let Some(path) = &args.profile {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let file = ProfileFile::parse(&text).with_context(|| format!("{}", path.display()))?;
        profile = profile.with_file(&file, &path.display().to_string());
    }
    let mut transport = transport(args)?;
    let total = cantwin_conform::catalogue()
        .iter()
        .filter(|c| options.only.is_empty() || options.only.contains(&c.area))
        .count();
    let pb = crate::output::steps(total as u64, "conform");
    // The reports are written as the run goes, at most once a second of wall time, marked
    // as interrupted: a killed run leaves the cases it ran.
    let mut written = std::time::Instant::now();
    let mut write_error = None;
    let report: Report = cantwin_conform::run(
        transport.as_mut(),
        node_id,
        &eds,
        &profile,
        &options,
        &mut |p| {
            pb.set_position(p.done as u64);
            pb.set_message(p.case.id.clone());
            if p.done < p.total && written.elapsed() >= WallDuration::from_secs(1) {
                written = std::time::Instant::now();
                let mut partial = p.report.clone();
                partial.stopped =
                    Some(format!("interrupted after {} of {} cases", p.done, p.total));
                if let Err(e) = write_reports(args, &partial) {
                    write_error.get_or_insert(e);
                }
            }
        },
    );
    pb.finish_and_clear();
    if let Some(e) = write_error {
        return Err(e);
    }
    write_reports(args, &report)?;
    if crate::output::json() {
        println!("{}", cantwin_conform::output::json(&report));
    } else {
        print!("{}", cantwin_conform::output::summary(&report));
    }
    if let Some(why) = &report.stopped {
        bail!("the run stopped: {why}");
    }
    if !report.passed() {
        bail!(
            "{} mandatory cases failed",
            report.mandatory_failures().count()
        );
    }
    Ok(())
}
