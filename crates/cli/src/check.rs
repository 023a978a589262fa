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
    let report = cantwin_scenario::check(&scenario, &Registry::builtin(), env)?;
    println!("{report}");
    if !report.passed() {
        bail!("{}: check failed", path.display());
    }
    Ok(())
}
