//! `cantwin fuzz`: property-based fuzzing, on stable Rust, of every decoder and state
//! machine that reads outside input. Each case is seeded from the campaign seed and the
//! case number, so a failure replays with `--seed S --from N --cases 1`; the property
//! checked is the project's rule that bad input gets the protocol's own answer or a clear
//! error, never a panic (decoders) or a stuck simulation (twins). The targets live in the
//! crates they exercise (their `fuzz` modules); this module runs the campaign and prints.
//!
//! The boundary targets ([`boundary`], `net-*` and `files`) run a real `cantwin sim` with
//! its gateways and attack it over loopback, and run the file commands as children on
//! mutated files; `--boundary` runs them all, `--attack-seconds` sets how long each lasts.

pub mod boundary;

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::time::Instant as WallInstant;

use anyhow::{Result, bail};
use cantwin_can::SplitMix64;
use cantwin_scenario::fuzz::{
    SCENARIO_ADV200_DNET, SCENARIO_ADV200_DS402, SCENARIO_CIA301, SCENARIO_OPENDRIVE, SCENARIO_TM3,
    twin,
};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Cases per target.
    #[arg(long, default_value_t = 1000)]
    cases: u64,
    /// The campaign's seed (decimal or 0x-prefixed hexadecimal).
    #[arg(long, default_value = "0xC0FFEE", value_parser = parse_seed)]
    seed: u64,
    /// The first case number (to replay a reported failure).
    #[arg(long, default_value_t = 0)]
    from: u64,
    /// Targets to run (default: all). `cantwin fuzz --list` names them.
    targets: Vec<String>,
    /// List the targets and exit.
    #[arg(long)]
    list: bool,
    /// Run every boundary target (servers over loopback, file commands as children) instead
    /// of the in-process ones.
    #[arg(long)]
    boundary: bool,
    /// Wall time of each network attack of the boundary targets, in seconds.
    #[arg(long, default_value_t = 5.0, value_name = "SECONDS")]
    attack_seconds: f64,
    /// Attack connections a boundary target keeps open at most.
    #[arg(long, default_value_t = 200)]
    connections: usize,
    /// Mutated files the `files` target runs the file commands on.
    #[arg(long, default_value_t = 300)]
    files: usize,
}

fn parse_seed(s: &str) -> Result<u64, String> {
    match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(hex) => u64::from_str_radix(hex, 16),
        None => s.parse(),
    }
    .map_err(|e| format!("{s:?}: {e}"))
}

/// One fuzz target: a name, what it feeds, and the function that runs case `rng`.
struct Target {
    name: &'static str,
    about: &'static str,
    run: fn(&mut SplitMix64),
}

fn targets() -> Vec<Target> {
    vec![
        Target {
            name: "canopen-wire",
            about: "CiA 301 frame decoders: NMT, error control, SYNC, TIME, EMCY, SDO requests, responses and block segments",
            run: cantwin_canopen::fuzz::wire_decoders,
        },
        Target {
            name: "socketcand",
            about: "socketcand protocol elements from clients and servers",
            run: cantwin_gateway::fuzz::socketcand,
        },
        Target {
            name: "slcan",
            about: "slcan (Lawicel) command and frame lines",
            run: cantwin_gateway::fuzz::slcan,
        },
        Target {
            name: "capture",
            about: "pcap, pcapng and candump readers on damaged files",
            run: cantwin_capture::fuzz::readers,
        },
        Target {
            name: "eds",
            about: "CiA 306 EDS/DCF parser on mutated EDS files",
            run: cantwin_eds::fuzz::parser,
        },
        Target {
            name: "scenario",
            about: "scenario parser and builder on mutated scenario files",
            run: cantwin_scenario::fuzz::parse_and_build,
        },
        Target {
            name: "twin-cia301",
            about: "CiA 301 device (SDO server, NMT, PDO, storage commands) fed random frames",
            run: |r| twin(r, SCENARIO_CIA301),
        },
        Target {
            name: "twin-opendrive",
            about: "OPEN DRIVE CAL server fed random frames",
            run: |r| twin(r, SCENARIO_OPENDRIVE),
        },
        Target {
            name: "twin-adv200-devicenet",
            about: "ADV200 DeviceNet slave (explicit and I/O messaging) fed random frames",
            run: |r| twin(r, SCENARIO_ADV200_DNET),
        },
        Target {
            name: "twin-adv200-ds402",
            about: "ADV200 CiA 402 drive fed random frames",
            run: |r| twin(r, SCENARIO_ADV200_DS402),
        },
        Target {
            name: "twin-tm3",
            about: "TM3 CANopen island fed random frames",
            run: |r| twin(r, SCENARIO_TM3),
        },
    ]
}

/// Outcome of a target's campaign.
pub struct TargetResult {
    /// The target.
    pub name: &'static str,
    /// Cases run.
    pub cases: u64,
    /// Failing cases: (case number, panic message).
    pub failures: Vec<(u64, String)>,
    /// Wall time.
    pub seconds: f64,
}

fn case_seed(seed: u64, target: &str, case: u64) -> u64 {
    let mut h = SplitMix64::new(seed ^ case.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let mut x = h.next_u64();
    for b in target.bytes() {
        x = (x ^ u64::from(b)).wrapping_mul(0x0100_0000_01B3);
    }
    x
}

/// Runs `cases` cases of each selected target.
pub fn campaign(
    names: &[String],
    seed: u64,
    from: u64,
    cases: u64,
    bar: &indicatif::ProgressBar,
    mut progress: impl FnMut(&TargetResult),
) -> Result<Vec<TargetResult>> {
    let all = targets();
    for n in names {
        if !all.iter().any(|t| t.name == n) {
            let known: Vec<&str> = all.iter().map(|t| t.name).collect();
            bail!("no fuzz target {n:?} (targets: {})", known.join(", "));
        }
    }
    let previous = std::panic::take_hook();
    // Panics are collected as failures with their message, not printed as they happen.
    std::panic::set_hook(Box::new(|_| {}));
    let mut results = Vec::new();
    for t in all
        .iter()
        .filter(|t| names.is_empty() || names.iter().any(|n| n == t.name))
    {
        let started = WallInstant::now();
        let mut failures = Vec::new();
        for case in from..from.saturating_add(cases) {
            let mut rng = SplitMix64::new(case_seed(seed, t.name, case));
            let run = t.run;
            if let Err(p) = catch_unwind(AssertUnwindSafe(|| run(&mut rng))) {
                let msg = p
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| p.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "panic".into());
                failures.push((case, msg));
            }
            bar.inc(1);
        }
        let r = TargetResult {
            name: t.name,
            cases,
            failures,
            seconds: started.elapsed().as_secs_f64(),
        };
        progress(&r);
        results.push(r);
    }
    std::panic::set_hook(previous);
    Ok(results)
}

pub fn run(args: &Args) -> Result<()> {
    let json = crate::output::json();
    if args.list {
        for t in targets() {
            crate::output::result(
                format_args!("{:24} {}", t.name, t.about),
                || serde_json::json!({"target": t.name, "about": t.about}),
            )?;
        }
        for (name, about) in boundary::TARGETS {
            crate::output::result(
                format_args!("{name:24} {about}"),
                || serde_json::json!({"target": name, "about": about, "boundary": true}),
            )?;
        }
        return Ok(());
    }
    let (outside, inside): (Vec<&String>, Vec<&String>) = args
        .targets
        .iter()
        .partition(|n| boundary::TARGETS.iter().any(|(b, _)| b == n));
    if args.boundary || !outside.is_empty() {
        if !inside.is_empty() {
            bail!(
                "boundary targets run on their own: name only boundary targets, or none with --boundary"
            );
        }
        let names: Vec<&str> = outside.iter().map(|s| s.as_str()).collect();
        return run_boundary(args, &names, json);
    }
    if !json {
        println!(
            "cantwin fuzz: seed {:#x}, cases {}..{}",
            args.seed,
            args.from,
            args.from.saturating_add(args.cases)
        );
    }
    let chosen = targets()
        .iter()
        .filter(|t| args.targets.is_empty() || args.targets.iter().any(|n| n == t.name))
        .count() as u64;
    let bar = crate::output::steps(chosen.saturating_mul(args.cases), "fuzz cases");
    let results = campaign(&args.targets, args.seed, args.from, args.cases, &bar, |r| {
        if json {
            return;
        }
        bar.suspend(|| {
            println!(
                "{:24} {:>10} cases {:>4} failures {:>8.1} s",
                r.name,
                r.cases,
                r.failures.len(),
                r.seconds
            );
            for (case, msg) in r.failures.iter().take(5) {
                println!(
                    "  case {case}: {msg}\n  replay: cantwin fuzz --seed {:#x} --from {case} --cases 1 {}",
                    args.seed, r.name
                );
            }
        });
    })?;
    bar.finish_and_clear();
    let cases: u64 = results.iter().map(|r| r.cases).sum();
    let failures: usize = results.iter().map(|r| r.failures.len()).sum();
    if json {
        let targets: Vec<serde_json::Value> = results
            .iter()
            .map(|r| {
                let failed: Vec<serde_json::Value> = r
                    .failures
                    .iter()
                    .map(|(case, msg)| serde_json::json!({"case": case, "message": msg}))
                    .collect();
                serde_json::json!({
                    "target": r.name,
                    "cases": r.cases,
                    "failures": failed,
                    "seconds": r.seconds,
                })
            })
            .collect();
        crate::output::emit(&serde_json::json!({
            "seed": args.seed,
            "from": args.from,
            "cases": cases,
            "failures": failures,
            "targets": targets,
        }))?;
    } else {
        println!("total: {cases} cases, {failures} failures");
    }
    if failures > 0 {
        bail!("{failures} fuzz cases failed");
    }
    Ok(())
}

/// The boundary campaign: runs, prints each target's figures and findings, fails on a
/// finding.
fn run_boundary(args: &Args, names: &[&str], json: bool) -> Result<()> {
    if !(args.attack_seconds.is_finite() && args.attack_seconds > 0.0) {
        bail!("--attack-seconds must be a positive number of seconds");
    }
    let scratch = boundary::scratch_dir();
    let opts = boundary::Options {
        exe: std::env::current_exe()?,
        attack_time: std::time::Duration::from_secs_f64(args.attack_seconds),
        connections: args.connections,
        files: args.files,
        seed: args.seed,
        scratch: scratch.clone(),
    };
    let reports = boundary::run(names, &opts);
    boundary::remove_scratch(&scratch);
    let reports = reports?;
    let findings: usize = reports.iter().map(|r| r.findings.len()).sum();
    if json {
        crate::output::emit(
            &serde_json::json!({ "seed": args.seed, "findings": findings, "targets": reports }),
        )?;
    } else {
        println!(
            "{:16} {:>9} {:>6} {:>21} {:>14} {:>8} {:>9} {:>9}",
            "target",
            "attacks",
            "held",
            "RSS KiB before/peak/after",
            "fds b/p/a",
            "probes",
            "p50 ms",
            "p99 ms"
        );
        for r in &reports {
            println!(
                "{:16} {:>9} {:>6} {:>7}/{:>7}/{:>7} {:>4}/{:>4}/{:>4} {:>4}/{:<3} {:>9.2} {:>9.2}",
                r.target,
                r.attacks,
                r.connections_held,
                r.rss_kib[0],
                r.rss_kib[1],
                r.rss_kib[2],
                r.fds[0],
                r.fds[1],
                r.fds[2],
                r.probes,
                r.probe_failures,
                r.latency_ms[0],
                r.latency_ms[1]
            );
            for n in &r.notes {
                println!("  note: {n}");
            }
            for f in &r.findings {
                println!("  finding: {f}");
            }
        }
        println!("total: {findings} findings");
    }
    if findings > 0 {
        bail!("{findings} boundary findings");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The suite's short campaign: every target, a fixed number of cases, no failure.
    #[test]
    fn short_campaign_of_every_target_finds_no_failure() {
        let results = campaign(
            &[],
            0x5EED,
            0,
            24,
            &indicatif::ProgressBar::hidden(),
            |_| {},
        )
        .unwrap();
        assert_eq!(results.len(), targets().len());
        for r in &results {
            assert_eq!(r.cases, 24);
            assert!(r.failures.is_empty(), "{}: {:?}", r.name, r.failures);
        }
    }

    #[test]
    fn an_unknown_target_is_refused_with_the_list() {
        let e = campaign(
            &["nope".into()],
            0,
            0,
            1,
            &indicatif::ProgressBar::hidden(),
            |_| {},
        )
        .err()
        .unwrap()
        .to_string();
        assert!(
            e.contains("no fuzz target \"nope\"") && e.contains("canopen-wire"),
            "{e}"
        );
    }

    #[test]
    fn seeds_are_decimal_or_hex_as_printed_in_replay_lines() {
        assert_eq!(parse_seed("0xC0FFEE"), Ok(0xC0FFEE));
        assert_eq!(parse_seed("12"), Ok(12));
        assert!(parse_seed("0xZZ").is_err());
    }

    #[test]
    fn cases_replay_from_their_seed() {
        let a = case_seed(1, "eds", 7);
        assert_eq!(a, case_seed(1, "eds", 7));
        assert_ne!(a, case_seed(1, "eds", 8));
        assert_ne!(a, case_seed(1, "slcan", 7));
        let mut r1 = SplitMix64::new(a);
        let mut r2 = SplitMix64::new(a);
        let eds_io = cantwin_eds::fuzz::SEEDS[1];
        assert_eq!(
            cantwin_can::fuzz::mutate(&mut r1, eds_io),
            cantwin_can::fuzz::mutate(&mut r2, eds_io)
        );
    }
}
