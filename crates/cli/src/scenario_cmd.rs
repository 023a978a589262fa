//! `cantwin scenario check FILE...`: load and build scenarios without running them, and
//! check what their scripts refer to, so that a broken file is found before a long run.

use std::path::PathBuf;

use anyhow::{Result, bail};
use cantwin_scenario::{BuildEnv, Registry, Scenario, ScenarioError};
use serde_json::json;

use crate::output;

#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, clap::Subcommand)]
enum Command {
    /// Load, build and validate scenario files without running them; print one line per
    /// file (`ok` or the error with file, line and key) and exit 1 if any is broken.
    #[command(
        after_help = "Examples:\n  cantwin scenario check scenarios/*.toml\n  \
                            cantwin scenario check --json my-rig.toml\n\n\
                            Checked: TOML syntax, known keys, bus and device names, device kinds and their \
                            settings (node-IDs 1–127, unique per bus), and the script's [[at]]/[[expect]] \
                            tables (devices and buses they name, objects a `value` expectation reads)."
    )]
    Check {
        /// Scenario files (TOML).
        #[arg(required = true, value_name = "FILE")]
        files: Vec<PathBuf>,
    },
}

/// What checking one file found.
struct Verdict {
    file: PathBuf,
    outcome: std::result::Result<Summary, ScenarioError>,
}

struct Summary {
    name: String,
    buses: usize,
    devices: usize,
    actions: usize,
    expectations: usize,
}

fn check_one(file: PathBuf, registry: &Registry) -> Verdict {
    let outcome = Scenario::load(&file).and_then(|scenario| {
        // An empty state directory would make devices read and write files: build with the
        // state kept in memory, as a first run would.
        cantwin_scenario::validate(&scenario, registry, &BuildEnv::default())?;
        Ok(Summary {
            buses: scenario.buses.len(),
            devices: scenario.devices.len(),
            actions: scenario.script.actions.len(),
            expectations: scenario.script.expectations.len(),
            name: scenario.name,
        })
    });
    Verdict { file, outcome }
}

impl Verdict {
    fn json(&self) -> serde_json::Value {
        match &self.outcome {
            Ok(s) => json!({
                "file": self.file.display().to_string(),
                "ok": true,
                "name": s.name,
                "buses": s.buses,
                "devices": s.devices,
                "actions": s.actions,
                "expectations": s.expectations,
            }),
            Err(e) => {
                let at = e.location();
                json!({
                    "file": self.file.display().to_string(),
                    "ok": false,
                    "error": {
                        "message": error_message(e),
                        "line": at.and_then(|a| a.line),
                        "key": at.and_then(|a| a.key.clone()),
                        "text": e.to_string(),
                    },
                })
            }
        }
    }
}

fn count(n: usize, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}

/// The message of an error without its location prefix.
fn error_message(e: &ScenarioError) -> String {
    match e {
        ScenarioError::Io { source, .. } => source.to_string(),
        ScenarioError::Syntax { message, .. } | ScenarioError::Invalid { message, .. } => {
            message.clone()
        }
    }
}

pub fn run(args: &Args) -> Result<()> {
    let Command::Check { files } = &args.command;
    let registry = Registry::builtin();
    let mut broken = 0usize;
    for file in files {
        let v = check_one(file.clone(), &registry);
        if output::json() {
            output::emit(&v.json())?;
        } else {
            match &v.outcome {
                Ok(s) => println!(
                    "ok {}: {} ({}, {}, {}, {})",
                    v.file.display(),
                    s.name,
                    count(s.buses, "bus", "buses"),
                    count(s.devices, "device", "devices"),
                    count(s.actions, "action", "actions"),
                    count(s.expectations, "expectation", "expectations")
                ),
                // Errors name file, line and key themselves (`FILE:LINE: key `K`: …`).
                Err(e) => eprintln!("error: {e}"),
            }
        }
        if v.outcome.is_err() {
            broken += 1;
        }
    }
    if broken > 0 {
        bail!("{broken} of {} scenario files are broken", files.len());
    }
    Ok(())
}
