//! The captures of the shipped scenarios are a contract: every scenario in `scenarios/` and
//! `scenarios/faults/` gives the same bus events (frames, error frames, controller events)
//! at the same nanoseconds as recorded in `tests/captures.txt`.
//!
//! Beside them, the probes in `tests/captures/` pin what the twins do on the wire where the
//! shipped scenarios leave them idle (parameter access, aborts, PDO lengths, NMT resets).
//!
//! A scenario with a script runs as `cantwin sim FILE --check` runs it; one without runs for
//! [`UNSCRIPTED_RUN`] of virtual time. Each run is summarised by its event count and an
//! FNV-1a digest of every event; the full trace of the last run is written to
//! `CARGO_TARGET_TMPDIR/captures/NAME.txt` so that a difference can be read with `diff`.
//!
//! When a change alters a capture on purpose (a fix of a deviation from a manual or a
//! standard), rerun with `CANTWIN_BLESS=1` to rewrite `tests/captures.txt`, and name the fix
//! in the commit that changes the file.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use cantwin_bus::{BusEvent, Recorder};
use cantwin_can::{Duration, Instant};
use cantwin_scenario::{BuildEnv, Registry, Scenario, check};

/// How long a scenario without a script runs.
const UNSCRIPTED_RUN: Duration = Duration::from_secs(10);

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn scenario_files() -> Vec<PathBuf> {
    let mut files = Vec::new();
    for dir in ["scenarios", "scenarios/faults"] {
        let Ok(entries) = std::fs::read_dir(repo().join(dir)) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.extension().is_some_and(|x| x == "toml") {
                files.push(p);
            }
        }
    }
    files.sort();
    let Ok(entries) =
        std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/captures"))
    else {
        return files;
    };
    let mut probes: Vec<PathBuf> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    probes.sort();
    files.extend(probes);
    files
}

/// The name a scenario is recorded under: its path below `scenarios/`, or `probes/FILE`.
fn name_of(path: &Path) -> String {
    let probes = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/captures");
    if let Ok(rel) = path.strip_prefix(&probes) {
        return format!("probes/{}", rel.to_string_lossy());
    }
    let base = repo().join("scenarios");
    let rel = path.strip_prefix(&base).unwrap_or(path);
    rel.to_string_lossy().replace('\\', "/")
}

/// Every bus's events, one line each, in bus order, buses in file order.
fn trace(path: &Path) -> Result<String, String> {
    let scenario = Scenario::load(path).map_err(|e| e.to_string())?;
    let registry = Registry::builtin();
    let env = BuildEnv::default();
    let buses: Vec<(String, Vec<BusEvent>)> = if scenario.script.is_empty() {
        let mut built = scenario.build(&registry, &env).map_err(|e| e.to_string())?;
        let mut taps = Vec::new();
        for (name, id) in built.buses.clone() {
            if let Some(bus) = built.sim.bus_mut(id) {
                taps.push((name, id, bus.add_tap(Recorder::new())));
            }
        }
        built.sim.run_until(Instant::ZERO + UNSCRIPTED_RUN);
        taps.into_iter()
            .map(|(name, id, tap)| {
                let events = built
                    .sim
                    .bus_mut(id)
                    .and_then(|b| b.tap_mut::<Recorder>(tap))
                    .map(|r| core::mem::take(&mut r.events))
                    .unwrap_or_default();
                (name, events)
            })
            .collect()
    } else {
        check(&scenario, &registry, &env)
            .map_err(|e| e.to_string())?
            .events
    };
    let mut text = String::new();
    for (bus, events) in &buses {
        for e in events {
            let _ = writeln!(text, "{bus} {e:?}");
        }
    }
    Ok(text)
}

fn fnv1a(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

#[test]
fn shipped_scenarios_keep_their_captures() {
    let golden_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/captures.txt");
    let dump = Path::new(env!("CARGO_TARGET_TMPDIR")).join("captures");
    let _ = std::fs::create_dir_all(&dump);
    let mut actual = String::new();
    for file in scenario_files() {
        let name = name_of(&file);
        let text = match trace(&file) {
            Ok(t) => t,
            Err(e) => panic!("{name}: {e}"),
        };
        let _ = std::fs::write(dump.join(name.replace('/', "_") + ".txt"), &text);
        let _ = writeln!(
            actual,
            "{name} {} {:016x}",
            text.lines().count(),
            fnv1a(&text)
        );
    }
    assert!(
        actual.lines().count() >= 20,
        "the shipped scenarios were not found:\n{actual}"
    );
    if std::env::var_os("CANTWIN_BLESS").is_some() {
        std::fs::write(&golden_path, &actual).expect("tests/captures.txt is writable");
        return;
    }
    let golden = std::fs::read_to_string(&golden_path).unwrap_or_default();
    let changed: Vec<String> = actual
        .lines()
        .filter(|l| !golden.lines().any(|g| g == *l))
        .map(|l| {
            let name = l.split(' ').next().unwrap_or(l);
            let was = golden
                .lines()
                .find(|g| g.split(' ').next() == Some(name))
                .unwrap_or("(not recorded)");
            format!("  {l}\n    recorded: {was}")
        })
        .collect();
    let gone: Vec<&str> = golden
        .lines()
        .filter(|g| {
            let name = g.split(' ').next().unwrap_or(g);
            !actual.lines().any(|l| l.split(' ').next() == Some(name))
        })
        .collect();
    assert!(
        changed.is_empty() && gone.is_empty(),
        "captures differ from tests/captures.txt (traces in {}):\n{}\nno longer run: {gone:?}",
        dump.display(),
        changed.join("\n")
    );
}
