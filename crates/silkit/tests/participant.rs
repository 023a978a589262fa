//! Twins as SIL Kit participants, across processes: a registry on 127.0.0.1, cantwin's bridge
//! with the ADV200 DS402 scenario in this process, the example participant (plain SIL Kit,
//! no cantwin bus code) playing the PLC master in another.

mod common;

use std::path::Path;
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration as WallDuration;

use cantwin_bus::{PacedConfig, PacedSimulation, Recorder};
use cantwin_can::Duration;
use cantwin_scenario::{BuildEnv, Built, Registry as Kinds, Scenario};
use cantwin_silkit::{
    BridgeConfig, BridgeError, Deadlines, PacedBridge, ParticipantState, SilKit,
    run_synchronized_within,
};
use common::{
    Lines, QUIET_CONFIG, Registry, deadlines, example_participant, silkit_dir, system_controller,
};

fn adv200() -> Built {
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/adv200-ds402.toml");
    let scenario = Scenario::load(file).expect("scenario");
    scenario
        .build(&Kinds::builtin(), &BuildEnv { state_dir: None })
        .expect("build")
}

fn config(uri: &str) -> BridgeConfig {
    BridgeConfig {
        registry_uri: uri.to_string(),
        participant: "cantwin".into(),
        configuration: QUIET_CONFIG.into(),
    }
}

fn plc(dir: &Path, uri: &str, extra: &[&str]) -> Lines {
    let mut cmd = Command::new(example_participant());
    cmd.env("CANTWIN_SILKIT_DIR", dir)
        .args(["--registry", uri, "--name", "PLC", "--network", "can0"])
        .args(extra);
    Lines::spawn(cmd)
}

/// SDO upload request for 0x1018:01 (vendor-ID) to node 2 (CiA 301 §7.2.4.3.3).
const SDO_READ_VENDOR: &str = "20000000:602#4018100100000000";

/// One synchronised run: the PLC starts node 2 at 10 ms, reads 0x1018:01 at 20 ms, stops the
/// simulation at 50 ms. Returns the PLC's report and cantwin's bus trace (id, start, end).
fn synchronised_run(dir: &Path) -> (Vec<String>, Vec<(u32, u64, u64)>, ParticipantState) {
    let registry = Registry::start(dir);
    let _sc = system_controller(dir, &registry.uri, &["cantwin", "PLC"]);
    let mut plc = plc(
        dir,
        &registry.uri,
        &[
            "--step",
            "1000000",
            "--send",
            "10000000:000#0102",
            "--send",
            SDO_READ_VENDOR,
            "--stop-at",
            "50000000",
        ],
    );
    let kit = SilKit::load_from(&dir.join("libSilKit.so")).expect("load");
    let mut built = adv200();
    let bus = built.buses[0].1;
    let tap = built
        .sim
        .bus_mut(bus)
        .expect("bus")
        .add_tap(Recorder::new());
    let stop = AtomicBool::new(false);
    let out = run_synchronized_within(
        &kit,
        built.sim,
        &built.buses,
        &config(&registry.uri),
        Duration::from_millis(1),
        &stop,
        &deadlines(&["PLC"]),
    )
    .expect("synchronised run");
    assert!(out.left.is_empty(), "{:?}", out.left);
    // The step at 50 ms ran the bus to just before it, then the PLC stopped.
    assert_eq!(out.sim.now().as_nanos(), 49_999_999);
    let trace = out
        .sim
        .bus(bus)
        .and_then(|b| b.tap::<Recorder>(tap))
        .expect("tap")
        .frames()
        .map(|f| (f.frame.id().as_raw(), f.start.as_nanos(), f.end.as_nanos()))
        .collect();
    (
        plc.finish(WallDuration::from_secs(30)),
        trace,
        out.final_state,
    )
}

#[test]
fn a_twin_and_a_foreign_participant_exchange_frames_in_synchronised_virtual_time() {
    let Some(dir) = silkit_dir() else { return };
    let (lines, trace, state) = synchronised_run(&dir);
    assert_eq!(state, ParticipantState::Shutdown);
    // The twin's boot-up (CiA 301 §7.2.8.3.2.1) ends on cantwin's bus in [0, 1 ms) and leaves
    // in the step at 1 ms, stamped with it.
    assert!(
        lines.contains(&"rx 1000000 702#00".to_string()),
        "{lines:#?}"
    );
    // The PLC's frames enter cantwin's bus at the virtual time they were sent.
    let nmt = trace
        .iter()
        .find(|f| f.0 == 0x000)
        .expect("NMT start on the bus");
    let sdo = trace
        .iter()
        .find(|f| f.0 == 0x602)
        .expect("SDO request on the bus");
    assert_eq!((nmt.1, sdo.1), (10_000_000, 20_000_000), "{trace:?}");
    // The answer ends on the bus right after the request, so it leaves in the next step.
    let answer = trace
        .iter()
        .find(|f| f.0 == 0x582)
        .expect("SDO answer on the bus");
    assert!(answer.1 >= sdo.2 && answer.2 < 21_000_000, "{trace:?}");
    let rx_answer = lines
        .iter()
        .find(|l| l.contains(" 582#"))
        .unwrap_or_else(|| panic!("no SDO answer: {lines:#?}"));
    assert!(
        rx_answer.starts_with("rx 21000000 582#43181001"),
        "{rx_answer}"
    );
    assert!(
        lines.contains(&"ack 10000000 Transmitted 0".to_string()),
        "{lines:#?}"
    );
    assert_eq!(lines.last().map(String::as_str), Some("final Shutdown"));
}

#[test]
fn a_synchronised_distributed_run_replays_identically() {
    let Some(dir) = silkit_dir() else { return };
    let first = synchronised_run(&dir);
    let second = synchronised_run(&dir);
    assert_eq!(first, second);
}

#[test]
fn stopping_cantwin_stops_the_whole_synchronised_simulation() {
    let Some(dir) = silkit_dir() else { return };
    let registry = Registry::start(&dir);
    let _sc = system_controller(&dir, &registry.uri, &["cantwin", "PLC"]);
    let mut plc = plc(&dir, &registry.uri, &["--step", "1000000"]);
    let kit = SilKit::load_from(&dir.join("libSilKit.so")).expect("load");
    let built = adv200();
    let stop = Arc::new(AtomicBool::new(false));
    let uri = registry.uri.clone();
    let runner = {
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || {
            run_synchronized_within(
                &kit,
                built.sim,
                &built.buses,
                &config(&uri),
                Duration::from_millis(1),
                &stop,
                &deadlines(&["PLC"]),
            )
        })
    };
    assert!(
        plc.wait_for(WallDuration::from_secs(20), |l| l == "rx 1000000 702#00")
            .is_some(),
        "{:#?}",
        plc.seen
    );
    stop.store(true, Ordering::SeqCst);
    let out = runner.join().expect("runner").expect("run");
    assert_eq!(out.final_state, ParticipantState::Shutdown);
    let lines = plc.finish(WallDuration::from_secs(20));
    assert_eq!(lines.last().map(String::as_str), Some("final Shutdown"));
}

#[test]
fn a_participant_leaving_mid_run_ends_the_synchronised_simulation_with_its_name() {
    let Some(dir) = silkit_dir() else { return };
    let registry = Registry::start(&dir);
    let _sc = system_controller(&dir, &registry.uri, &["cantwin", "PLC"]);
    let mut plc = plc(
        &dir,
        &registry.uri,
        &[
            "--step",
            "1000000",
            "--send",
            "10000000:000#0102",
            "--exit-at",
            "15000000",
        ],
    );
    let kit = SilKit::load_from(&dir.join("libSilKit.so")).expect("load");
    let built = adv200();
    let stop = AtomicBool::new(false);
    let out = run_synchronized_within(
        &kit,
        built.sim,
        &built.buses,
        &config(&registry.uri),
        Duration::from_millis(1),
        &stop,
        &deadlines(&["PLC"]),
    )
    .expect("run");
    assert_eq!(out.left, ["PLC"]);
    assert_eq!(out.final_state, ParticipantState::Shutdown);
    // Time stood still once the PLC was gone: it left in its step at 15 ms.
    assert!(out.sim.now().as_nanos() < 17_000_000, "{}", out.sim.now());
    assert_eq!(out.counters.frames_in, 1);
    let lines = plc.finish(WallDuration::from_secs(10));
    assert_eq!(lines.last().map(String::as_str), Some("exit"));
}

/// Unsynchronised: the twins paced to the wall clock, the PLC autonomous. A PLC that leaves
/// does not disturb cantwin, and the next one is served.
#[test]
fn unsynchronised_twins_serve_participants_that_come_and_go() {
    let Some(dir) = silkit_dir() else { return };
    let registry = Registry::start(&dir);
    let kit = SilKit::load_from(&dir.join("libSilKit.so")).expect("load");
    let built = adv200();
    let paced = PacedSimulation::start(built.sim, PacedConfig::default());
    let bridge = PacedBridge::start(&kit, &paced.handle(), &built.buses, &config(&registry.uri))
        .expect("bridge");
    for round in 0..2 {
        let mut plc = plc(
            &dir,
            &registry.uri,
            &[
                "--send",
                "200000000:000#0102",
                "--send",
                "300000000:602#4018100100000000",
                "--stop-at",
                "600000000",
            ],
        );
        let lines = plc.finish(WallDuration::from_secs(20));
        assert!(
            lines
                .iter()
                .any(|l| l.starts_with("rx ") && l.contains(" 582#43181001")),
            "round {round}: {lines:#?}"
        );
        assert_eq!(bridge.state().expect("state"), ParticipantState::Running);
    }
    let counters = bridge.stop().expect("stop");
    assert_eq!(counters.frames_in, 4);
    assert!(counters.frames_out >= 2, "{counters:?}");
    let sim = paced.stop().expect("simulation");
    assert!(sim.buses()[0].stats().frames() >= 5);
}

/// A required participant that dies before it joins (here the PLC, given an argument it
/// refuses) keeps the system controller from ever starting the simulation: the run ends
/// with an error naming it once the join bound runs out, instead of waiting for ever.
#[test]
fn a_participant_dying_before_it_joins_ends_the_run_naming_it_within_the_bound() {
    let Some(dir) = silkit_dir() else { return };
    let registry = Registry::start(&dir);
    let _sc = system_controller(&dir, &registry.uri, &["cantwin", "PLC"]);
    let mut plc = plc(&dir, &registry.uri, &["--no-such-argument"]);
    assert!(!plc.status(WallDuration::from_secs(10)).success());
    let kit = SilKit::load_from(&dir.join("libSilKit.so")).expect("load");
    let built = adv200();
    let stop = AtomicBool::new(false);
    let bound = WallDuration::from_secs(2);
    let started = std::time::Instant::now();
    let err = run_synchronized_within(
        &kit,
        built.sim,
        &built.buses,
        &config(&registry.uri),
        Duration::from_millis(1),
        &stop,
        &Deadlines::new(bound, common::RUN).expecting(&["PLC"]),
    )
    .expect_err("the simulation cannot start without the PLC");
    let took = started.elapsed();
    let BridgeError::NotStarted {
        after,
        state,
        ref never_joined,
        ref never_ran,
        ..
    } = err
    else {
        panic!("{err:?}")
    };
    assert_eq!(after, bound);
    assert_eq!(never_joined, &["PLC".to_string()]);
    assert!(never_ran.is_empty(), "{never_ran:?}");
    assert_ne!(state, ParticipantState::Running);
    assert!(
        err.to_string().contains("participant PLC never joined"),
        "{err}"
    );
    // The bound, plus the participant's creation and destruction (generous: a loaded box).
    assert!(
        took >= bound && took < bound + WallDuration::from_secs(15),
        "{took:?}"
    );
}

/// A run that never ends (the PLC runs without stopping) is stopped once the run bound runs
/// out, with an error saying so; the PLC sees the stop.
#[test]
fn a_run_beyond_its_bound_is_stopped_with_an_error_saying_so() {
    let Some(dir) = silkit_dir() else { return };
    let registry = Registry::start(&dir);
    let _sc = system_controller(&dir, &registry.uri, &["cantwin", "PLC"]);
    let mut plc = plc(&dir, &registry.uri, &["--step", "1000000"]);
    let kit = SilKit::load_from(&dir.join("libSilKit.so")).expect("load");
    let built = adv200();
    let stop = AtomicBool::new(false);
    let bound = WallDuration::from_millis(1500);
    let err = run_synchronized_within(
        &kit,
        built.sim,
        &built.buses,
        &config(&registry.uri),
        Duration::from_millis(1),
        &stop,
        &Deadlines::new(common::JOIN, bound).expecting(&["PLC"]),
    )
    .expect_err("the PLC never stops");
    let BridgeError::NotStopped { after, state, .. } = err else {
        panic!("{err:?}")
    };
    assert_eq!((after, state), (bound, ParticipantState::Running));
    assert!(err.to_string().contains("did not end within"), "{err}");
    let lines = plc.finish(WallDuration::from_secs(20));
    assert_eq!(lines.last().map(String::as_str), Some("final Shutdown"));
}
