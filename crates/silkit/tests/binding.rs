//! The safe binding against the real libSilKit: loading, errors, a participant's lifecycle,
//! time synchronisation and CAN controller callbacks, with the example participant in
//! another process as the peer.

mod common;

use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use cantwin_silkit::{
    CanFrame, Direction, DirectionMask, Error, OperationMode, Participant, ParticipantState,
    SilKit, TransmitStatus,
};
use common::{Lines, QUIET_CONFIG, Registry, example_participant, silkit_dir, system_controller};

#[test]
fn a_missing_library_is_named_with_how_to_get_it() {
    let err = SilKit::load_from(std::path::Path::new("/nonexistent/libSilKit.so"))
        .expect_err("no library there");
    assert!(matches!(err, Error::NotFound { .. }), "{err:?}");
    let text = err.to_string();
    for needle in [
        "libSilKit.so",
        "/nonexistent",
        "CANTWIN_SILKIT_LIB",
        "scripts/fetch-silkit.sh",
    ] {
        assert!(text.contains(needle), "{needle:?} missing from: {text}");
    }
}

#[test]
fn the_fetched_library_is_silkit_5_with_the_network_simulator_api() {
    let Some(dir) = silkit_dir() else { return };
    let kit = SilKit::load_from(&dir.join("libSilKit.so")).expect("load");
    assert_eq!(kit.version().expect("version"), "5.0.3");
    assert!(kit.has_network_simulator());
}

#[test]
fn no_registry_is_a_clear_error_not_a_hang() {
    let Some(dir) = silkit_dir() else { return };
    let kit = SilKit::load_from(&dir.join("libSilKit.so")).expect("load");
    // Port 1 on loopback: nothing listens; one connect attempt.
    let cfg = r#"{"Logging":{"Sinks":[{"Type":"Stdout","Level":"Off"}]},"Middleware":{"ConnectAttempts":1}}"#;
    let err =
        Participant::create(&kit, "Lonely", "silkit://127.0.0.1:1", cfg).expect_err("no registry");
    assert!(
        matches!(
            err,
            Error::Call {
                function: "SilKit_Participant_Create",
                ..
            }
        ),
        "{err:?}"
    );
}

/// A coordinated, synchronised participant in this process and the example participant in
/// another: frames both ways carry the sender's virtual time, the sender gets `Transmitted`,
/// and the stop from here ends both lifecycles.
#[test]
fn frames_cross_between_processes_in_virtual_time() {
    let Some(dir) = silkit_dir() else { return };
    let registry = Registry::start(&dir);
    let _sc = system_controller(&dir, &registry.uri, &["Here", "There"]);
    let mut cmd = Command::new(example_participant());
    cmd.env("CANTWIN_SILKIT_DIR", &dir).args([
        "--registry",
        &registry.uri,
        "--name",
        "There",
        "--network",
        "can0",
        "--step",
        "1000000",
        "--send",
        "3000000:0701#05",
    ]);
    let mut there = Lines::spawn(cmd);

    let kit = SilKit::load_from(&dir.join("libSilKit.so")).expect("load");
    let p = Participant::create(&kit, "Here", &registry.uri, QUIET_CONFIG).expect("participant");
    let can = p.can_controller("Here-CAN", "can0").expect("controller");
    let rx = Arc::new(Mutex::new(Vec::new()));
    let acks = Arc::new(Mutex::new(Vec::new()));
    {
        let rx = Arc::clone(&rx);
        can.on_frame(DirectionMask::Receive, move |ev| {
            rx.lock().expect("rx").push(ev)
        })
        .expect("frame handler");
        let acks = Arc::clone(&acks);
        can.on_transmit(move |ev| acks.lock().expect("acks").push(ev))
            .expect("transmit handler");
    }
    let lifecycle = p.lifecycle(OperationMode::Coordinated).expect("lifecycle");
    {
        let can = can.clone();
        lifecycle
            .on_communication_ready(move || {
                let _ = can.start();
            })
            .expect("ready handler");
    }
    let ts = lifecycle.time_sync().expect("time sync");
    let steps = Arc::new(Mutex::new(Vec::new()));
    {
        let (can, lifecycle, steps) = (can.clone(), lifecycle.clone(), Arc::clone(&steps));
        ts.on_step(1_000_000, move |now, duration| {
            steps.lock().expect("steps").push((now, duration));
            if now == 2_000_000 {
                let f = CanFrame {
                    id: 0x181,
                    flags: 0,
                    dlc: 2,
                    data: vec![0xAB, 0xCD],
                };
                let _ = can.send(&f, 42);
            }
            if now == 10_000_000 {
                let _ = lifecycle.stop("test done");
            }
        })
        .expect("step handler");
    }
    lifecycle.start().expect("start");
    let state = p
        .wait_for_lifecycle_timeout(&lifecycle, common::RUN)
        .expect("the lifecycle ends");
    assert_eq!(state, ParticipantState::Shutdown);

    // Steps of exactly the size asked for, from 0 to the stop.
    let steps = steps.lock().expect("steps");
    let want: Vec<(u64, u64)> = (0..=10).map(|i| (i * 1_000_000, 1_000_000)).collect();
    assert_eq!(&steps[..want.len().min(steps.len())], &want[..]);
    let lines = there.finish(Duration::from_secs(20));
    assert!(
        lines.contains(&"rx 2000000 181#ABCD".to_string()),
        "{lines:#?}"
    );
    assert!(lines.contains(&"final Shutdown".to_string()), "{lines:#?}");
    let rx = rx.lock().expect("rx");
    assert_eq!(rx.len(), 1, "{rx:?}");
    assert_eq!(
        (
            rx[0].timestamp,
            rx[0].frame.id,
            rx[0].frame.data.as_slice(),
            rx[0].direction
        ),
        (3_000_000, 0x701, &[5u8][..], Direction::Receive)
    );
    let acks = acks.lock().expect("acks");
    assert_eq!(acks.len(), 1, "{acks:?}");
    assert_eq!(
        (
            acks[0].timestamp,
            acks[0].status,
            acks[0].can_id,
            acks[0].user_context
        ),
        (2_000_000, TransmitStatus::Transmitted, 0x181, 42)
    );
    drop(p);
    // A handle that outlives its participant reports it, it does not crash.
    assert!(matches!(can.start(), Err(Error::Destroyed)));
}

/// A coordinated participant whose required peer dies before it joins (here `/bin/false`
/// stands in for it) never runs: the bounded wait ends with the state it is stuck in.
#[test]
fn a_bounded_lifecycle_wait_ends_when_a_required_peer_never_joins() {
    let Some(dir) = silkit_dir() else { return };
    let registry = Registry::start(&dir);
    let _sc = system_controller(&dir, &registry.uri, &["Here", "There"]);
    let mut there = Lines::spawn(Command::new("/bin/false"));
    assert!(!there.status(Duration::from_secs(10)).success());
    let kit = SilKit::load_from(&dir.join("libSilKit.so")).expect("load");
    let p = Participant::create(&kit, "Here", &registry.uri, QUIET_CONFIG).expect("participant");
    let lifecycle = p.lifecycle(OperationMode::Coordinated).expect("lifecycle");
    lifecycle.start().expect("start");
    let bound = Duration::from_secs(2);
    let started = std::time::Instant::now();
    let err = p
        .wait_for_lifecycle_timeout(&lifecycle, bound)
        .expect_err("There never joins");
    let took = started.elapsed();
    let Error::Timeout { after, state, .. } = err else {
        panic!("{err:?}")
    };
    assert_eq!(after, bound);
    assert!(
        matches!(
            state,
            ParticipantState::ServicesCreated
                | ParticipantState::CommunicationInitializing
                | ParticipantState::CommunicationInitialized
                | ParticipantState::ReadyToRun
        ),
        "{state:?}"
    );
    assert!(err.to_string().contains("Shutdown"), "{err}");
    assert!(
        took >= bound && took < bound + Duration::from_secs(10),
        "{took:?}"
    );
}
