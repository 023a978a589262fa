//! `cantwin bench silkit`: frames per second and latency through cantwin as SIL Kit's CAN
//! network simulator, against SIL Kit alone, in one run (issue floors in BENCHMARKS.md).

use std::time::{Duration as WallDuration, Instant as WallInstant};

use anyhow::{Context, Result, bail};
use cantwin_silkit::SilKit;

/// Steps of 1 ms each participant sends a frame in, per measurement.
const BENCH_STEPS: u64 = 2000;

/// One configuration's trials: the best trial's figures (the floors are judged on them)
/// and the median ones, each figure's best and median taken over the trials separately.
#[derive(Debug, Clone, Copy)]
struct BenchFigures {
    frames_per_second: (f64, f64),
    latency_us: (f64, f64),
    step_us: (f64, f64),
    latency_steps: (f64, f64),
}

impl BenchFigures {
    /// The figures of `trials` (never empty): the highest frames/s and the lowest times are
    /// the best, the trial least disturbed by other processes' load.
    fn of(trials: &[cantwin_silkit::bench::BenchReport]) -> BenchFigures {
        let figure = |f: &dyn Fn(&cantwin_silkit::bench::BenchReport) -> f64, higher: bool| {
            let mut v: Vec<f64> = trials.iter().map(f).collect();
            v.sort_by(f64::total_cmp);
            let best = if higher { v[v.len() - 1] } else { v[0] };
            (best, median(&v))
        };
        BenchFigures {
            frames_per_second: figure(&|r| r.frames_per_second, true),
            latency_us: figure(&|r| r.latency_us, false),
            step_us: figure(&|r| r.step_us(), false),
            latency_steps: figure(&|r| r.latency_steps(), false),
        }
    }
}

/// The median of sorted, non-empty `v` (of an even count, the mean of the middle two).
fn median(v: &[f64]) -> f64 {
    let n = v.len();
    (v[(n - 1) / 2] + v[n / 2]) / 2.0
}

/// `best (median m)`, with `decimals` decimals and `unit`.
fn best_median((best, median): (f64, f64), decimals: usize, unit: &str) -> String {
    format!("{best:.decimals$}{unit} (median {median:.decimals$}{unit})")
}

/// `cantwin bench silkit`: frames per second and latency through cantwin as network
/// simulator with 2 and 8 participants, each against SIL Kit without a network simulator in
/// the same run, best of `trials` trials of each (the two in turn in every trial, so that a
/// burst of load disturbs one trial of each rather than every trial of one); with `write`,
/// recorded in `file`. When it was not named and SIL Kit is not there, it is skipped with the
/// reason.
pub fn bench(write: bool, file: &std::path::Path, named: bool, trials: usize) -> Result<()> {
    let kit = match SilKit::load() {
        Ok(kit) => kit,
        Err(e) if !named => {
            eprintln!("bench silkit: skipped: {e}");
            return Ok(());
        }
        Err(e) => return Err(e).context("bench silkit needs Vector SIL Kit"),
    };
    let registry_exe = std::env::var_os("CANTWIN_SILKIT_REGISTRY")
        .map(std::path::PathBuf::from)
        .or_else(|| kit.path().parent().map(|d| d.join("sil-kit-registry")))
        .filter(|p| p.exists())
        .context(
            "bench silkit needs sil-kit-registry beside libSilKit.so or named by CANTWIN_SILKIT_REGISTRY",
        )?;
    let trials = trials.max(1);
    let load_before = crate::bench::load_average();
    let mut rows = Vec::new();
    for participants in [2usize, 8] {
        let mut runs: [Vec<cantwin_silkit::bench::BenchReport>; 2] = [Vec::new(), Vec::new()];
        for trial in 1..=trials {
            for (k, netsim) in [false, true].into_iter().enumerate() {
                let registry = BenchRegistry::start(&registry_exe)?;
                let r = cantwin_silkit::bench::run(
                    &kit,
                    &registry.uri,
                    cantwin_silkit::bench::BenchConfig {
                        participants,
                        steps: BENCH_STEPS,
                        netsim,
                    },
                )
                .with_context(|| {
                    format!("bench silkit: {participants} participants, trial {trial}/{trials}")
                })?;
                let expected = participants as u64 * BENCH_STEPS;
                if r.frames != expected {
                    bail!(
                        "bench silkit: {} of {expected} frames acknowledged with {participants} participants{}, trial {trial}/{trials}",
                        r.frames,
                        if netsim { " through cantwin" } else { "" }
                    );
                }
                runs[k].push(r);
            }
        }
        rows.push((
            participants,
            BenchFigures::of(&runs[0]),
            BenchFigures::of(&runs[1]),
        ));
    }
    let load_after = crate::bench::load_average();
    let mut table = String::from(
        "| participants | SIL Kit alone: frames/s | through cantwin: frames/s | ratio (floor ≥ 0.5 at 8) | SIL Kit alone: latency | through cantwin: latency | ratio (floor ≤ 2 at 8) |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for (n, alone, net) in &rows {
        table.push_str(&format!(
            "| {n} | {} | {} | {:.2} (medians {:.2}) | {} | {} | {:.2} (medians {:.2}) |\n",
            best_median(alone.frames_per_second, 0, ""),
            best_median(net.frames_per_second, 0, ""),
            net.frames_per_second.0 / alone.frames_per_second.0,
            net.frames_per_second.1 / alone.frames_per_second.1,
            best_median(alone.latency_us, 0, " µs"),
            best_median(net.latency_us, 0, " µs"),
            net.latency_us.0 / alone.latency_us.0,
            net.latency_us.1 / alone.latency_us.1,
        ));
    }
    let mut steps = String::from(
        "| participants | SIL Kit alone: wall time per step | through cantwin: wall time per step | SIL Kit alone: latency in steps | through cantwin: latency in steps |\n\
         |---|---|---|---|---|\n",
    );
    for (n, alone, net) in &rows {
        steps.push_str(&format!(
            "| {n} | {} | {} | {} | {} |\n",
            best_median(
                (alone.step_us.0 / 1000.0, alone.step_us.1 / 1000.0),
                2,
                " ms"
            ),
            best_median((net.step_us.0 / 1000.0, net.step_us.1 / 1000.0), 2, " ms"),
            best_median(alone.latency_steps, 2, ""),
            best_median(net.latency_steps, 2, ""),
        ));
    }
    let verdict = rows
        .iter()
        .find(|(n, _, _)| *n == 8)
        .map(|(_, alone, net)| {
            let fps = net.frames_per_second.0 / alone.frames_per_second.0;
            let lat = net.latency_us.0 / alone.latency_us.0;
            let met = |ok: bool| if ok { "met" } else { "not met" };
            format!(
                "Floors with 8 participants, best trials: frames/s {fps:.2}× SIL Kit alone \
                 (floor ≥ 0.5×: {}), latency {lat:.2}× (floor ≤ 2×: {}).",
                met(fps >= 0.5),
                met(lat <= 2.0)
            )
        })
        .unwrap_or_default();
    let load = format!("Load average (1, 5, 15 min) before: {load_before}; after: {load_after}.");
    // The latency floor in steps, for the record: what a step costs and how many a frame
    // waits, through cantwin and alone, with 8 participants (best trials).
    let in_steps = rows
        .iter()
        .find(|(n, _, _)| *n == 8)
        .map(|(_, alone, net)| {
            format!(
                "With 8 participants a step takes {:.2} ms of wall time through cantwin against \
                 {:.2} ms alone, and a frame arrives {:.1} steps after it was sent through cantwin \
                 against {:.1} alone: the latency ratio is about the product of the two ratios.",
                net.step_us.0 / 1000.0,
                alone.step_us.0 / 1000.0,
                net.latency_steps.0,
                alone.latency_steps.0
            )
        })
        .unwrap_or_default();
    if crate::output::json() {
        let pair = |(best, median): (f64, f64)| serde_json::json!({"best": best, "median": median});
        crate::output::emit(&serde_json::json!({
            "bench": "silkit",
            "trials": trials,
            "load_before": load_before,
            "load_after": load_after,
            "rows": rows.iter().map(|(n, a, b)| serde_json::json!({
                "participants": n,
                "alone_frames_per_second": pair(a.frames_per_second),
                "netsim_frames_per_second": pair(b.frames_per_second),
                "alone_latency_us": pair(a.latency_us),
                "netsim_latency_us": pair(b.latency_us),
                "alone_step_us": pair(a.step_us),
                "netsim_step_us": pair(b.step_us),
                "alone_latency_steps": pair(a.latency_steps),
                "netsim_latency_steps": pair(b.latency_steps),
            })).collect::<Vec<_>>(),
        }))?;
    } else {
        println!("{table}\n{steps}\n{verdict}\n{load}");
    }
    if write {
        let count = if trials == 1 {
            "1 trial".to_string()
        } else {
            format!("{trials} trials")
        };
        let body = format!(
            "## silkit — CAN frames through SIL Kit, with cantwin as network simulator\n\n\
             Best of {count} of each configuration (SIL Kit alone and through cantwin in turn \
             in every trial), the median in brackets; ratios of the best trials, of the medians \
             in brackets. The floors are judged on the best trials.\n\n\
             {table}\n{verdict}\n\n\
             The same runs in synchronisation steps: wall time per 1 ms step, and the latency \
             as that many steps' wall time.\n\n\
             {steps}\n\
             Each participant (a SIL Kit participant of its own, all in one process, on loopback) \
             sends one 5-byte frame in each of {BENCH_STEPS} synchronised 1 ms steps at 1 Mbit/s; \
             the first also measures, for every frame of the others, the wall time from \
             `SendFrame` to its reception. frames/s counts frames acknowledged `Transmitted` per \
             wall second. \"Through cantwin\" adds `cantwin silkit netsim` (steps of 1 ms) as the \
             network's simulator: arbitration, bit timing and ACK on cantwin's bus, one more \
             synchronised participant, and a frame reaches the others in the simulator's step \
             after it was sent. That step is what the latency measures: without a simulator a \
             frame goes straight from sender to receivers, within the step it was sent in, \
             through cantwin it waits until every participant has finished the step it was sent \
             in, since the simulator puts the frames of one step on the bus together to \
             arbitrate them by identifier, and each step takes longer with one more \
             participant to synchronise; the floor on latency would need the simulator to take \
             each request alone as it comes, in wall-clock order, which gives up arbitration \
             between participants and the reproducible frame times. {in_steps} {load} SIL Kit \
             {}; {}; {}.\n\n\
             Reproduce: `scripts/fetch-silkit.sh`, then \
             `CANTWIN_SILKIT_DIR=target/silkit/silkit-py-1.0.5 cargo run --release --bin cantwin -- bench silkit --write`.\n",
            kit.version().unwrap_or_default(),
            crate::benchmarks_md::machine_description(),
            crate::benchmarks_md::today()
        );
        crate::benchmarks_md::write_section(file, "silkit", &body)?;
    }
    Ok(())
}

/// A registry on 127.0.0.1 with a port the system picks, for the bench; killed when dropped.
struct BenchRegistry {
    uri: String,
    child: std::process::Child,
    dir: std::path::PathBuf,
}

impl BenchRegistry {
    fn start(exe: &std::path::Path) -> Result<BenchRegistry> {
        let dir = std::env::temp_dir().join(format!(
            "cantwin-bench-silkit-{}-{}",
            std::process::id(),
            WallInstant::now().elapsed().as_nanos()
        ));
        std::fs::create_dir_all(&dir).context("creating a temporary directory")?;
        let cfg = dir.join("registry.yaml");
        let child = std::process::Command::new(exe)
            .args(["-u", "silkit://127.0.0.1:0", "-g"])
            .arg(&cfg)
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .with_context(|| format!("starting {}", exe.display()))?;
        let mut reg = BenchRegistry {
            uri: String::new(),
            child,
            dir,
        };
        // The registry writes the file, naming the port it listens on, once it listens.
        let until = WallInstant::now() + WallDuration::from_secs(20);
        loop {
            if let Ok(text) = std::fs::read_to_string(&cfg)
                && let Some(uri) = text
                    .lines()
                    .find_map(|l| l.trim().strip_prefix("RegistryUri:"))
            {
                reg.uri = uri.trim().trim_matches(['\'', '"']).to_string();
                return Ok(reg);
            }
            if WallInstant::now() >= until {
                bail!("{} did not start in 20 s", exe.display());
            }
            std::thread::sleep(WallDuration::from_millis(10));
        }
    }
}

impl Drop for BenchRegistry {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
