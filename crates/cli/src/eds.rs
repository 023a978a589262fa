//! `cantwin eds`: check, document and commission CiA 306 device description files.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use cantwin_can::BitRate;
use cantwin_canopen::od::ObjectDictionary;
use cantwin_eds::{DeviceCommissioning, Eds, EdsValue, Severity};

#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, clap::Subcommand)]
enum Command {
    /// Write the EDS of a CANopen twin of a scenario, generated from its object dictionary;
    /// with -o, the device profile for `cantwin conform` beside it (NAME.profile.toml).
    #[command(
        after_help = "Examples:\n  cantwin eds export --scenario scenarios/cia301-device.toml --device node5 -o node5.eds\n  \
                            cantwin eds export --scenario scenarios/tm3-island.toml --device island"
    )]
    Export {
        /// The scenario.
        #[arg(long)]
        scenario: PathBuf,
        /// The device's name in the scenario.
        #[arg(long)]
        device: String,
        /// Write here instead of standard output.
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
    /// Check an EDS or DCF: every diagnostic (error, warning, note) with its line, section
    /// and key — syntax, mandatory objects, object lists, sub-object counts, types, limits,
    /// $NODEID values — and advice such as a life time factor (0x100D) below 2. The file is
    /// read the way a twin reads it; exits non-zero only when there are errors.
    #[command(
        after_help = "Examples:\n  cantwin eds check device.eds\n  cantwin eds check --strict node5.dcf"
    )]
    Check {
        /// The file.
        file: PathBuf,
        /// Count warnings as errors.
        #[arg(long)]
        strict: bool,
    },
    /// Document a device as Markdown: device information and every object.
    #[command(
        after_help = "Examples:\n  cantwin eds doc device.eds > device.md\n  cantwin eds doc device.eds -o device.md"
    )]
    Doc {
        /// The file.
        file: PathBuf,
        /// Write here instead of standard output.
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
    /// Make a DCF for one node from an EDS: $NODEID resolved, every value as its
    /// ParameterValue, [DeviceComissioning] filled in, and values changed with --set.
    #[command(
        after_help = "Examples:\n  cantwin eds dcf device.eds --node-id 5 -o node5.dcf\n  \
                            cantwin eds dcf device.eds --node-id 12 --bit-rate 500k --set 0x1017:0=1000 --set 0x1008:0=\"Pump 3\""
    )]
    Dcf {
        /// The EDS (or DCF) to start from.
        file: PathBuf,
        /// The node-ID (1–127).
        #[arg(long, value_parser = clap::value_parser!(u8).range(1..=127))]
        node_id: u8,
        /// The node's name (NodeName).
        #[arg(long)]
        name: Option<String>,
        /// The bit rate (Baudrate), e.g. 500k or 1M.
        #[arg(long)]
        bit_rate: Option<BitRate>,
        /// Set a value: INDEX:SUB=VALUE (index in hex with 0x, sub decimal or hex), repeatable.
        #[arg(long = "set", value_name = "INDEX:SUB=VALUE")]
        sets: Vec<String>,
        /// Write here instead of standard output.
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
}

/// Reads a file the way a twin does: nothing is refused, the diagnostics come with it.
fn load(file: &Path) -> Result<cantwin_eds::Loaded> {
    let bytes = std::fs::read(file).with_context(|| format!("reading {}", file.display()))?;
    Ok(cantwin_eds::load_bytes(&bytes))
}

fn emit(text: &str, output: Option<&Path>) -> Result<()> {
    match output {
        Some(path) => {
            std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
        }
        None => {
            print!("{text}");
            Ok(())
        }
    }
}

/// Warnings cantwin adds to the file checks: advice from the device manuals.
fn advice(eds: &Eds) -> Vec<String> {
    let mut out = Vec::new();
    let value = |index, sub| {
        eds.entry(index, sub)
            .and_then(|e| e.default_value.as_ref())
            .and_then(|v| v.evaluate(1))
    };
    if let (Some(guard), Some(factor)) = (value(0x100C, 0), value(0x100D, 0))
        && guard != 0
        && factor < 2
    {
        out.push(format!(
            "warning: [100D] DefaultValue: life time factor {factor} is below 2: a single lost guarding \
             request makes the node report a guarding error (use 2 or more)"
        ));
    }
    out
}

/// The object dictionary of the twin on `port`, if it has one.
fn twin_dictionary(
    sim: &cantwin_bus::Simulation,
    port: cantwin_bus::PortId,
) -> Option<&ObjectDictionary> {
    sim.twin(port)?.dictionary()
}

/// The twin's EDS and its kind.
fn export(scenario: &Path, device: &str) -> Result<(String, String)> {
    let sc = cantwin_scenario::Scenario::load(scenario)?;
    let mut built = sc.build(&cantwin_scenario::Registry::builtin(), &Default::default())?;
    // Powered up, the twin holds its power-on values (CiA 306 §4.6.3 defaults), among them
    // those it sets itself at reset communication (`heartbeat_ms`).
    built.sim.run_until(cantwin_can::Instant::ZERO);
    let dev = built.device(device).with_context(|| {
        let names: Vec<&str> = built.devices.iter().map(|d| d.name.as_str()).collect();
        format!(
            "{} has no device {device:?} (devices: {})",
            scenario.display(),
            names.join(", ")
        )
    })?;
    let od = twin_dictionary(&built.sim, dev.port).with_context(|| {
        if built.sim.twin(dev.port).is_some_and(|t| t.lss_slave()) {
            format!(
                "{device:?} ({}) has no node-ID yet and waits for an LSS master (CiA 305): its \
                 dictionary exists once it has one; export from a copy of the scenario that \
                 gives it a node-ID (the EDS names its identifiers by $NODEID either way)",
                dev.kind
            )
        } else {
            format!(
                "{device:?} ({}) is not a CANopen device, or its card is not in a CANopen personality",
                dev.kind
            )
        }
    })?;
    let desc = od.description();
    let count = |range: std::ops::RangeInclusive<u16>| {
        desc.objects()
            .filter(|o| range.contains(&o.index()))
            .count() as u16
    };
    let text = |index, sub| match od.get(index, sub) {
        Ok(cantwin_canopen::od::Value::VisibleString(s)) => Some(s),
        _ => None,
    };
    let mut info = cantwin_eds::DeviceInfo {
        // The manufacturer of a twinned product (CiA 306 `VendorName`); the generic
        // CiA 301 devices are the project's own.
        vendor_name: Some(
            match dev.kind.as_str() {
                "tm3" => cantwin_tm3::od::VENDOR_NAME,
                "adv200" => cantwin_adv200::eds::VENDOR_NAME,
                _ => "cantwin",
            }
            .into(),
        ),
        // The expedited-only ADV200 card's 0x1008 holds four bytes ("ADV2"): the product
        // is named as its manual does.
        product_name: match dev.kind.as_str() {
            "adv200" => Some(cantwin_adv200::eds::PRODUCT_NAME.into()),
            _ => text(0x1008, 0).or_else(|| Some(device.to_string())),
        },
        granularity: Some(8),
        nr_of_rx_pdo: Some(count(0x1400..=0x15FF)),
        nr_of_tx_pdo: Some(count(0x1800..=0x19FF)),
        simple_boot_up_slave: Some(true),
        simple_boot_up_master: Some(false),
        group_messaging: Some(false),
        lss_supported: Some(built.sim.twin(dev.port).is_some_and(|t| t.lss_slave())),
        dynamic_channels_supported: Some(0),
        ..Default::default()
    };
    if let Some(bus) = built.sim.bus(dev.port.bus()) {
        info.set_baud_rates(&[bus.bit_rate().bits_per_second() / 1000]);
    }
    let mut eds = cantwin_eds::from_od(
        desc,
        info,
        cantwin_eds::FileInfo::new(format!("{device}.eds")),
    );
    cantwin_eds::power_on_defaults(&mut eds, od);
    Ok((cantwin_eds::write(&eds), dev.kind.clone()))
}

pub fn run(args: &Args) -> Result<()> {
    match &args.command {
        Command::Export {
            scenario,
            device,
            output,
        } => {
            let (text, kind) = export(scenario, device)?;
            emit(&text, output.as_deref())?;
            // Beside the EDS, the device profile `cantwin conform --profile` reads: what
            // CiA 306 cannot express and the deviations the twin's manual prescribes.
            if let Some(path) = output {
                let profile = path.with_extension("profile.toml");
                let text = cantwin_conform::profile::shipped(&kind).to_toml();
                std::fs::write(&profile, text)
                    .with_context(|| format!("writing {}", profile.display()))?;
            }
            Ok(())
        }
        Command::Check { file, strict } => {
            let cantwin_eds::Loaded { eds, report } = load(file)?;
            let count = |sev| report.issues.iter().filter(|i| i.severity == sev).count();
            let advice = advice(&eds);
            let errors = count(Severity::Error);
            let warnings = count(Severity::Warning) + advice.len();
            let notes = count(Severity::Note);
            if crate::output::json() {
                let issues: Vec<serde_json::Value> = report
                    .issues
                    .iter()
                    .map(|i| {
                        serde_json::json!({
                            "severity": format!("{:?}", i.severity).to_lowercase(),
                            "line": i.line,
                            "section": i.section,
                            "key": i.key,
                            "message": i.message,
                            "text": i.to_string(),
                        })
                    })
                    .chain(
                        advice
                            .iter()
                            .map(|a| serde_json::json!({"severity": "advice", "text": a})),
                    )
                    .collect();
                crate::output::emit(&serde_json::json!({
                    "file": file.display().to_string(),
                    "objects": eds.objects.len(),
                    "errors": errors,
                    "warnings": warnings,
                    "notes": notes,
                    "issues": issues,
                }))?;
            } else {
                for issue in &report.issues {
                    println!("{}: {issue}", file.display());
                }
                for a in &advice {
                    println!("{}: {a}", file.display());
                }
                println!(
                    "{}: {} objects, {errors} errors, {warnings} warnings, {notes} notes",
                    file.display(),
                    eds.objects.len()
                );
            }
            if errors > 0 {
                bail!("{} has {errors} errors", file.display());
            }
            if *strict && warnings > 0 {
                bail!("{} has {warnings} warnings (--strict)", file.display());
            }
            Ok(())
        }
        Command::Doc { file, output } => {
            let eds = load(file)?.eds;
            emit(&cantwin_eds::render_markdown(&eds), output.as_deref())
        }
        Command::Dcf {
            file,
            node_id,
            name,
            bit_rate,
            sets,
            output,
        } => {
            let cantwin_eds::Loaded { eds, report } = load(file)?;
            // The same test a twin makes: a file no dictionary can hold has no DCF either.
            cantwin_eds::to_od(&eds).map_err(|e| anyhow::anyhow!("{}: {e}", file.display()))?;
            let commissioning = DeviceCommissioning {
                node_id: Some(*node_id),
                node_name: name.clone(),
                baudrate: bit_rate.map(|r| (r.bits_per_second() / 1000) as u16),
                ..eds.commissioning.clone().unwrap_or_default()
            };
            let (mut dcf, notes) = cantwin_eds::commission(&eds, *node_id, commissioning);
            for set in sets {
                apply_set(&mut dcf, set)?;
            }
            for n in &notes {
                eprintln!("{}: {n}", file.display());
            }
            // The DCF is refused only for what it says that the file did not: an error the
            // --set values brought in.
            let before: Vec<(String, Option<String>, String)> = eds
                .check()
                .errors()
                .map(|i| (i.section.clone(), i.key.clone(), i.message.clone()))
                .collect();
            let new: Vec<String> = dcf
                .check()
                .errors()
                .filter(|i| {
                    !before.contains(&(i.section.clone(), i.key.clone(), i.message.clone()))
                })
                .map(ToString::to_string)
                .collect();
            if !new.is_empty() {
                bail!("the DCF would not be valid:\n{}", new.join("\n"));
            }
            if report.errors().next().is_some() {
                eprintln!(
                    "{}: has errors, read past as `cantwin eds check` shows",
                    file.display()
                );
            }
            emit(&cantwin_eds::write(&dcf), output.as_deref())
        }
    }
}

/// `INDEX:SUB=VALUE` → the sub-object's ParameterValue.
fn apply_set(dcf: &mut Eds, set: &str) -> Result<()> {
    let bad = || anyhow::anyhow!("--set {set:?}: expected INDEX:SUB=VALUE, e.g. 0x1017:0=1000");
    let (target, value) = set.split_once('=').ok_or_else(bad)?;
    let (index, sub) = target.split_once(':').ok_or_else(bad)?;
    let num = |t: &str| -> Option<u32> {
        let t = t.trim();
        match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
            Some(h) => u32::from_str_radix(h, 16).ok(),
            None => t.parse().ok(),
        }
    };
    let index = num(index)
        .and_then(|v| u16::try_from(v).ok())
        .ok_or_else(bad)?;
    let sub = num(sub)
        .and_then(|v| u8::try_from(v).ok())
        .ok_or_else(bad)?;
    let object = dcf
        .objects
        .get_mut(&index)
        .ok_or_else(|| anyhow::anyhow!("--set {set:?}: the file has no object {index:#06X}"))?;
    let entry = if object.subs.is_empty() && sub == 0 {
        &mut object.entry
    } else {
        object.subs.get_mut(&sub).ok_or_else(|| {
            anyhow::anyhow!("--set {set:?}: object {index:#06X} has no sub-index {sub}")
        })?
    };
    let value = value.trim().trim_matches('"');
    let parsed = EdsValue::parse(entry.data_type, value)
        .map_err(|e| anyhow::anyhow!("--set {set:?}: {e}"))?;
    entry.parameter_value = Some(parsed);
    Ok(())
}
