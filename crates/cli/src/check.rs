//! `cantwin sim SCENARIO --check`: run the scenario's script (`[[at]]` stimuli and
//! `[[expect]]` expectations) in virtual time and judge it.

use std::path::Path;

use anyhow::{Result, bail};
use cantwin_scenario::{BuildEnv, Registry, Scenario};

/// Runs the script of the scenario at `path`; prints every verdict; fails when an
/// expectation failed or the scenario has no script.
pub fn run(path: &Path, env: &BuildEnv) -> Result<()> {
    let scenario = Scenario::load(path)?;
    if scenario.script.is_empty() {
        bail!(
            "{}: no [[at]] or [[expect]] tables to check (see docs/scenarios.md)",
            path.display()
        );
    }
    // Stored state that cannot be used is only found by building (the script's run builds
    // its own copy and does not hand the warnings back).
    if env.state_dir.is_some() {
        for w in scenario.build(&Registry::builtin(), env)?.warnings {
            eprintln!("cantwin sim: warning: {w}");
        }
    }
    let end_ms = scenario.script.end_time().as_nanos() / 1_000_000;
    let bar = crate::output::steps(end_ms, "virtual ms");
    let report = cantwin_scenario::check_with_progress(
        &scenario,
        &Registry::builtin(),
        env,
        &mut |now, _| bar.set_position(now.as_nanos() / 1_000_000),
    );
    bar.finish_and_clear();
    let report = report?;
    if crate::output::json() {
        let outcomes: Vec<serde_json::Value> = report
            .outcomes
            .iter()
            .map(|o| {
                serde_json::json!({
                    "line": o.line, "label": o.label, "passed": o.passed, "detail": o.detail,
                })
            })
            .collect();
        crate::output::emit(&serde_json::json!({
            "file": report.file.display().to_string(),
            "passed": report.passed(),
            "outcomes": outcomes,
            "actions": report.actions,
            "frames": report.frames,
            "error_frames": report.error_frames,
            "end_s": report.end.as_nanos() as f64 / 1e9,
        }))?;
    } else {
        println!("{report}");
    }
    if !report.passed() {
        bail!("{}: check failed", path.display());
    }
    Ok(())
}
