//! cantwin as SIL Kit's CAN network simulator, across processes: the simulator in this
//! process, foreign participants (the example program, plain SIL Kit) in others. Every
//! time asserted is computed from cantwin's bus model: frame lengths with stuff bits at
//! 500 kbit/s (2 µs a bit).

mod common;

use std::path::Path;
use std::process::Command;
use std::sync::atomic::AtomicBool;
use std::time::Duration as WallDuration;

use cantwin_bus::{BusConfig, PortConfig, Simulation};
use cantwin_bus::{FaultRule, FrameSelector};
use cantwin_can::{BitRate, ControllerEvent, Duration, Frame, Instant, Node, Outbox};
use cantwin_scenario::Scenario;
use cantwin_silkit::{
    BridgeConfig, BridgeError, BusFault, NetsimConfig, NetsimFaults, NetsimOutcome,
    ParticipantState, SilKit, faults_from_scenario, run_network_simulator_with_faults,
};
use common::{
    Lines, QUIET_CONFIG, Registry, deadlines, example_participant, silkit_dir, system_controller,
};

const BIT_NS: u64 = 2_000;

fn participant(dir: &Path, uri: &str, name: &str, extra: &[&str]) -> Lines {
    let mut cmd = Command::new(example_participant());
    cmd.env("CANTWIN_SILKIT_DIR", dir)
        .args(["--registry", uri, "--name", name, "--network", "can0"])
        .args(["--step", "1000000", "--bit-rate", "500000"])
        .args(extra);
    Lines::spawn(cmd)
}

/// The network simulator on a thread of its own, within the tests' bounds for `peers`.
fn netsim(
    dir: &Path,
    uri: &str,
    peers: &'static [&'static str],
) -> std::thread::JoinHandle<Result<NetsimOutcome, BridgeError>> {
    netsim_with_faults(dir, uri, peers, NetsimFaults::default())
}

/// [`netsim`] applying `faults`.
fn netsim_with_faults(
    dir: &Path,
    uri: &str,
    peers: &'static [&'static str],
    faults: NetsimFaults,
) -> std::thread::JoinHandle<Result<NetsimOutcome, BridgeError>> {
    let kit = SilKit::load_from(&dir.join("libSilKit.so")).expect("load");
    let bridge = BridgeConfig {
        registry_uri: uri.to_string(),
        participant: "cantwin".into(),
        configuration: QUIET_CONFIG.into(),
    };
    std::thread::spawn(move || {
        let stop = AtomicBool::new(false);
        // Steps of 2 ms against the participants' 1 ms: frames sent in odd milliseconds
        // always reach the bus at the next even one (see the netsim module documentation).
        let config = NetsimConfig {
            step: Duration::from_millis(2),
            ..NetsimConfig::default()
        };
        run_network_simulator_with_faults(
            &kit,
            &bridge,
            &["can0".to_string()],
            config,
            &faults,
            &stop,
            &deadlines(peers),
        )
    })
}

/// The bus-level `[[at]]` actions of the scenario `text` (named `name` in errors) as the
/// network simulator's faults on can0, with the scenario's seed.
fn faults_of(text: &str, name: &str) -> NetsimFaults {
    let scenario = Scenario::parse(text, name).expect("scenario");
    NetsimFaults {
        seed: scenario.seed,
        faults: faults_from_scenario(&scenario, &["can0".to_string()]).expect("faults"),
    }
}

/// A network simulator applying `faults` to participant A (sending as `a_args` say) and
/// participant B (listening), each in its own process: what A and B printed, and the
/// simulator's outcome, once the simulation has shut down.
fn faulted_a_and_b(
    dir: &Path,
    faults: NetsimFaults,
    a_args: &[&str],
) -> (Vec<String>, Vec<String>, NetsimOutcome) {
    let registry = Registry::start(dir);
    let _sc = system_controller(dir, &registry.uri, &["cantwin", "A", "B"]);
    let sim = netsim_with_faults(dir, &registry.uri, &["A", "B"], faults);
    let mut a = participant(dir, &registry.uri, "A", a_args);
    let mut b = participant(dir, &registry.uri, "B", &[]);
    let a_lines = a.finish(WallDuration::from_secs(30));
    let b_lines = b.finish(WallDuration::from_secs(30));
    let out = sim
        .join()
        .expect("simulator thread")
        .expect("network simulator");
    assert_eq!(out.final_state, ParticipantState::Shutdown);
    (a_lines, b_lines, out)
}

#[test]
fn two_foreign_participants_arbitrate_through_cantwins_bus_with_exact_frame_times() {
    let Some(dir) = silkit_dir() else { return };
    let registry = Registry::start(&dir);
    let _sc = system_controller(&dir, &registry.uri, &["cantwin", "A", "B"]);
    let sim = netsim(&dir, &registry.uri, &["A", "B"]);
    let mut a = participant(
        &dir,
        &registry.uri,
        "A",
        &["--send", "5000000:200#11", "--stop-at", "20000000"],
    );
    let mut b = participant(&dir, &registry.uri, "B", &["--send", "5000000:100#2233"]);
    let a_lines = a.finish(WallDuration::from_secs(30));
    let b_lines = b.finish(WallDuration::from_secs(30));
    let out = sim
        .join()
        .expect("simulator thread")
        .expect("network simulator");
    assert_eq!(out.final_state, ParticipantState::Shutdown);

    // Both requests reach the bus at 6 ms; 0x100 wins arbitration (ISO 11898-1 §10.4.4.2),
    // 0x200 starts when the bus is idle after it (3 bits of intermission included in the
    // length), each delivered at the end of its EOF.
    let f100 = Frame::std(0x100, &[0x22, 0x33]).expect("frame");
    let f200 = Frame::std(0x200, &[0x11]).expect("frame");
    let (n100, n200) = (u64::from(f100.bit_length()), u64::from(f200.bit_length()));
    let end100 = 6_000_000 + (n100 - 3) * BIT_NS;
    let end200 = 6_000_000 + n100 * BIT_NS + (n200 - 3) * BIT_NS;
    for (lines, want) in [
        (
            &a_lines,
            [
                format!("rx {end100} 100#2233"),
                format!("ack {end200} Transmitted 200"),
            ],
        ),
        (
            &b_lines,
            [
                format!("ack {end100} Transmitted 100"),
                format!("rx {end200} 200#11"),
            ],
        ),
    ] {
        for w in &want {
            assert!(lines.contains(w), "{w:?} missing: {lines:#?}");
        }
        // Detailed simulation: the controllers' states come from the simulator.
        assert!(lines.iter().any(|l| l.ends_with(" Started")), "{lines:#?}");
        assert!(
            lines.iter().any(|l| l.ends_with(" ErrorActive")),
            "{lines:#?}"
        );
    }
    let counters = out.networks[0].counters();
    assert_eq!((counters.frames, counters.refused), (2, 0));
}

/// A node on a bus of its own, recording its controller's events (the reference).
struct Lone(Vec<(ControllerEvent, Instant)>);

impl Node for Lone {
    fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
    fn on_controller_event(&mut self, e: ControllerEvent, now: Instant, _: &mut Outbox) {
        self.0.push((e, now));
    }
}

#[test]
fn a_lone_participant_gets_no_ack_and_goes_error_passive() {
    let Some(dir) = silkit_dir() else { return };
    // cantwin's bus model, alone: when does a lone sender go error-passive?
    let frame = Frame::std(0x123, &[0x01]).expect("frame");
    let mut reference = Simulation::new();
    let bus = reference.add_bus(BusConfig::new("can0", BitRate::R500K));
    let port = reference
        .attach(bus, Lone(Vec::new()), PortConfig::DEFAULT)
        .expect("attach");
    reference.run_until(Instant::from_nanos(6_000_000));
    reference.transmit(port, frame).expect("transmit");
    reference.run_until(Instant::from_nanos(20_000_000));
    let passive = reference
        .node::<Lone>(port)
        .expect("node")
        .0
        .iter()
        .find(|(e, _)| *e == ControllerEvent::ErrorPassive)
        .map(|(_, t)| t.as_nanos())
        .expect("the reference goes error-passive");

    let registry = Registry::start(&dir);
    let _sc = system_controller(&dir, &registry.uri, &["cantwin", "A"]);
    let sim = netsim(&dir, &registry.uri, &["A"]);
    let mut a = participant(
        &dir,
        &registry.uri,
        "A",
        &["--send", "5000000:123#01", "--stop-at", "20000000"],
    );
    let lines = a.finish(WallDuration::from_secs(30));
    let out = sim
        .join()
        .expect("simulator thread")
        .expect("network simulator");
    assert_eq!(out.final_state, ParticipantState::Shutdown);
    assert!(
        lines.contains(&format!("error-state {passive} ErrorPassive")),
        "ErrorPassive at {passive} missing: {lines:#?}"
    );
    // Never acknowledged, so never reported transmitted.
    assert!(!lines.iter().any(|l| l.starts_with("ack ")), "{lines:#?}");
    assert_eq!(out.networks[0].counters().frames, 0);
}

#[test]
fn requests_beyond_the_transmit_queue_are_answered_transmit_queue_full() {
    let Some(dir) = silkit_dir() else { return };
    let registry = Registry::start(&dir);
    let _sc = system_controller(&dir, &registry.uri, &["cantwin", "A"]);
    let sim = netsim(&dir, &registry.uri, &["A"]);
    // Alone, A's frames are never acknowledged, so none leaves the queue: 20 requests in one
    // step against 16 transmit buffers.
    let sends: Vec<String> = (0..20)
        .map(|i| format!("5000000:{:03X}#", 0x100 + i))
        .collect();
    let mut args: Vec<&str> = Vec::new();
    for s in &sends {
        args.extend(["--send", s.as_str()]);
    }
    args.extend(["--stop-at", "10000000"]);
    let mut a = participant(&dir, &registry.uri, "A", &args);
    let lines = a.finish(WallDuration::from_secs(30));
    let out = sim
        .join()
        .expect("simulator thread")
        .expect("network simulator");
    assert_eq!(out.final_state, ParticipantState::Shutdown);
    let full: Vec<&String> = lines
        .iter()
        .filter(|l| l.contains("TransmitQueueFull"))
        .collect();
    // The last four, at the step that took them.
    let want: Vec<String> = (16..20)
        .map(|i| format!("ack 6000000 TransmitQueueFull {:X}", 0x100 + i))
        .collect();
    assert_eq!(full, want.iter().collect::<Vec<_>>(), "{lines:#?}");
    assert_eq!(out.networks[0].counters().queue_full, 4);
}

#[test]
fn stopping_a_controller_cancels_its_pending_requests() {
    let Some(dir) = silkit_dir() else { return };
    let registry = Registry::start(&dir);
    let _sc = system_controller(&dir, &registry.uri, &["cantwin", "A"]);
    let sim = netsim(&dir, &registry.uri, &["A"]);
    // Alone, A's frame waits for an ACK for ever; stopping the controller at 9 ms (taken by
    // the simulator at 10 ms) cancels it and reports the new state.
    let mut a = participant(
        &dir,
        &registry.uri,
        "A",
        &[
            "--send",
            "5000000:123#01",
            "--can-stop-at",
            "9000000",
            "--stop-at",
            "14000000",
        ],
    );
    let lines = a.finish(WallDuration::from_secs(30));
    let out = sim
        .join()
        .expect("simulator thread")
        .expect("network simulator");
    assert_eq!(out.final_state, ParticipantState::Shutdown);
    let acks: Vec<&String> = lines.iter().filter(|l| l.starts_with("ack ")).collect();
    assert_eq!(acks, ["ack 10000000 Canceled 123"], "{lines:#?}");
    assert!(
        lines.contains(&"state 10000000 Stopped".to_string()),
        "{lines:#?}"
    );
}

/// A node on a bus recording when its frames were sent (the reference).
struct Sender(Vec<u64>);

impl Node for Sender {
    fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
    fn on_sent(&mut self, _: &Frame, now: Instant, _: &mut Outbox) {
        self.0.push(now.as_nanos());
    }
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

#[test]
fn scenario_at_actions_corrupt_the_frame_of_their_step_and_send_the_scripts_frame() {
    let Some(dir) = silkit_dir() else { return };
    let faults = faults_of(
        "name = \"corrupt at 6 ms\"\nseed = 7\n\n[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\n\
         [[at]]\ntime_ms = 6\naction = \"corrupt\"\nbus = \"can0\"\nfraction = 1.0\ncount = 1\n\n\
         [[at]]\ntime_ms = 10\naction = \"send\"\nbus = \"can0\"\nframe = \"300#AA\"\n",
        "corrupt.toml",
    );
    // cantwin's bus model with two controllers: the frame on the bus at 2 ms goes out as it
    // is; the one at 6 ms is corrupted once (error frame, ISO 11898-1 §10.11) and sent again.
    let frame = Frame::std(0x200, &[0x11]).expect("frame");
    let mut reference = Simulation::new();
    let bus = reference.add_bus(BusConfig::new("can0", BitRate::R500K).with_seed(7));
    let a = reference
        .attach(bus, Sender(Vec::new()), PortConfig::DEFAULT)
        .expect("attach");
    reference
        .attach(bus, Sender(Vec::new()), PortConfig::DEFAULT)
        .expect("attach");
    reference.run_until(Instant::from_nanos(2_000_000));
    reference.transmit(a, frame).expect("transmit");
    reference.run_until(Instant::from_nanos(6_000_000));
    reference
        .bus_mut(bus)
        .expect("bus")
        .inject(FaultRule::corrupt(FrameSelector::Fraction(1.0)).times(1));
    reference.transmit(a, frame).expect("transmit");
    reference.run_until(Instant::from_nanos(20_000_000));
    let sent = reference.node::<Sender>(a).expect("node").0.clone();
    let [clean, corrupted] = sent[..] else {
        panic!("the reference sends twice: {sent:?}")
    };
    let length = (u64::from(frame.bit_length()) - 3) * BIT_NS;
    assert_eq!(clean, 2_000_000 + length);
    assert!(corrupted > 6_000_000 + length, "{corrupted}");

    let (a_lines, b_lines, out) = faulted_a_and_b(
        &dir,
        faults,
        &[
            "--send",
            "1000000:200#11",
            "--send",
            "5000000:200#11",
            "--stop-at",
            "20000000",
        ],
    );
    for t in [clean, corrupted] {
        let ack = format!("ack {t} Transmitted 200");
        assert!(a_lines.contains(&ack), "{ack:?} missing: {a_lines:#?}");
        let rx = format!("rx {t} 200#11");
        assert!(b_lines.contains(&rx), "{rx:?} missing: {b_lines:#?}");
    }
    let acks = a_lines.iter().filter(|l| l.starts_with("ack ")).count();
    assert_eq!(acks, 2, "{a_lines:#?}");
    // The scenario's own frame, from its script port, at 10 ms.
    let script = Frame::std(0x300, &[0xAA]).expect("frame");
    let rx = format!(
        "rx {} 300#AA",
        10_000_000 + (u64::from(script.bit_length()) - 3) * BIT_NS
    );
    for lines in [&a_lines, &b_lines] {
        assert!(lines.contains(&rx), "{rx:?} missing: {lines:#?}");
    }
    let net = &out.networks[0];
    assert_eq!(
        net.applied_faults(),
        [
            (
                Instant::from_nanos(6_000_000),
                BusFault::Inject(FaultRule::corrupt(FrameSelector::Fraction(1.0)).times(1))
            ),
            (Instant::from_nanos(10_000_000), BusFault::Send(script)),
        ]
    );
    let (frames, error_frames, mut tecs) = net.with_simulation(|sim, bus| {
        let b = sim.bus(bus).expect("bus");
        let tecs: Vec<u16> = b
            .ports()
            .filter_map(|p| b.port_status(p).ok())
            .map(|s| s.counters.tec())
            .collect();
        (b.stats().frames(), b.stats().error_frames(), tecs)
    });
    assert_eq!((frames, error_frames), (3, 1));
    // A's transmit error counter: + 8 for the error, − 1 for the frame sent again
    // (ISO 11898-1 §12.1.4.2); B's and the script port's untouched.
    tecs.sort_unstable();
    assert_eq!(tecs, [0, 0, 7]);
}

/// A node on a bus recording its controller's events and its frames sent (the reference).
#[derive(Default)]
struct Recorder {
    events: Vec<(ControllerEvent, u64)>,
    sent: Vec<(u32, u64)>,
}

impl Node for Recorder {
    fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
    fn on_sent(&mut self, frame: &Frame, now: Instant, _: &mut Outbox) {
        self.sent.push((frame.id().as_raw(), now.as_nanos()));
    }
    fn on_controller_event(&mut self, e: ControllerEvent, now: Instant, _: &mut Outbox) {
        self.events.push((e, now.as_nanos()));
    }
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

/// Every error counter of a bus, TECs and RECs each sorted (the ports' order depends on
/// which participant's controller the simulator heard of first).
fn error_counters(bus: &cantwin_bus::Bus) -> (Vec<u16>, Vec<u16>) {
    let status: Vec<_> = bus
        .ports()
        .filter_map(|p| bus.port_status(p).ok())
        .collect();
    let mut tecs: Vec<u16> = status.iter().map(|s| s.counters.tec()).collect();
    let mut recs: Vec<u16> = status.iter().map(|s| s.counters.rec()).collect();
    tecs.sort_unstable();
    recs.sort_unstable();
    (tecs, recs)
}

/// A scenario's `corrupt` of every frame from 6 ms hits each of A's retransmissions: its TEC
/// rises by 8 each time (ISO 11898-1 §12.1.4.2 rule c), error-passive above 127, bus-off
/// above 255.
/// Bus-off, A takes no part in the bus: its two pending requests are `Canceled`, no frame
/// of it is sent again, B receives none. A request made during bus-off waits; after 128 × 11
/// recessive bits (rule l) A is error-active again and that frame goes out. Every time is
/// the reference bus's, to the nanosecond.
#[test]
fn repeated_corruption_takes_a_participant_bus_off_and_it_recovers_after_128_x_11_bits() {
    let Some(dir) = silkit_dir() else { return };
    let faults = faults_of(
        "name = \"bus-off\"\nseed = 3\n\n[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\n\
         [[at]]\ntime_ms = 6\naction = \"corrupt\"\nbus = \"can0\"\nfraction = 1.0\n\n\
         [[at]]\ntime_ms = 12\naction = \"clear_faults\"\nbus = \"can0\"\n",
        "bus-off.toml",
    );
    // cantwin's bus model with A and B. A's requests sent at 5 ms and 11 ms reach the bus at
    // the simulator's steps of 6 ms and 12 ms.
    let f200 = Frame::std(0x200, &[0x11]).expect("frame");
    let f201 = Frame::std(0x201, &[0x22]).expect("frame");
    let f202 = Frame::std(0x202, &[0x33]).expect("frame");
    let mut reference = Simulation::new();
    let bus = reference.add_bus(BusConfig::new("can0", BitRate::R500K).with_seed(3));
    let a = reference
        .attach(bus, Recorder::default(), PortConfig::DEFAULT)
        .expect("attach");
    reference
        .attach(bus, Recorder::default(), PortConfig::DEFAULT)
        .expect("attach");
    reference.run_until(Instant::from_nanos(6_000_000));
    reference
        .bus_mut(bus)
        .expect("bus")
        .inject(FaultRule::corrupt(FrameSelector::Fraction(1.0)));
    reference.transmit(a, f200).expect("transmit");
    reference.transmit(a, f201).expect("transmit");
    reference.run_until(Instant::from_nanos(12_000_000));
    reference.bus_mut(bus).expect("bus").clear_faults();
    reference.transmit(a, f202).expect("transmit");
    reference.run_until(Instant::from_nanos(20_000_000));
    let want_counters = error_counters(reference.bus(bus).expect("bus"));
    let want_stats = {
        let s = reference.bus(bus).expect("bus").stats();
        (s.frames(), s.error_frames())
    };
    let rec = reference.node::<Recorder>(a).expect("node");
    let at = |event: ControllerEvent| -> Vec<u64> {
        rec.events
            .iter()
            .filter(|(e, _)| *e == event)
            .map(|(_, t)| *t)
            .collect()
    };
    let [passive] = at(ControllerEvent::ErrorPassive)[..] else {
        panic!("the reference goes error-passive once: {:?}", rec.events)
    };
    let [bus_off] = at(ControllerEvent::BusOff)[..] else {
        panic!("the reference goes bus-off once: {:?}", rec.events)
    };
    let [recovered] = at(ControllerEvent::BusOffRecovered)[..] else {
        panic!("the reference recovers once: {:?}", rec.events)
    };
    // Both pending frames lost at bus-off (the one being retransmitted and the one behind
    // it), nothing sent before the recovery, then only the frame asked for during bus-off.
    assert_eq!(at(ControllerEvent::TxDropped), [bus_off, bus_off]);
    assert_eq!(recovered, bus_off + 128 * 11 * BIT_NS);
    assert!(passive < bus_off && bus_off < 12_000_000 && 12_000_000 < recovered);
    let end202 = recovered + (u64::from(f202.bit_length()) - 3) * BIT_NS;
    assert_eq!(rec.sent, [(0x202, end202)]);
    // 32 errors of + 8 take TEC from 0 past 255; none after.
    assert_eq!(want_stats, (1, 32));

    let (a_lines, b_lines, out) = faulted_a_and_b(
        &dir,
        faults,
        &[
            "--send",
            "5000000:200#11",
            "--send",
            "5000000:201#22",
            "--send",
            "11000000:202#33",
            "--stop-at",
            "20000000",
        ],
    );

    let a_states: Vec<&String> = a_lines
        .iter()
        .filter(|l| l.starts_with("error-state "))
        .collect();
    let want_states = [
        "error-state 0 ErrorActive".to_string(),
        format!("error-state {passive} ErrorPassive"),
        format!("error-state {bus_off} BusOff"),
        format!("error-state {recovered} ErrorActive"),
    ];
    assert_eq!(
        a_states,
        want_states.iter().collect::<Vec<_>>(),
        "{a_lines:#?}"
    );
    let a_acks: Vec<&String> = a_lines.iter().filter(|l| l.starts_with("ack ")).collect();
    let want_acks = [
        format!("ack {bus_off} Canceled 200"),
        format!("ack {bus_off} Canceled 201"),
        format!("ack {end202} Transmitted 202"),
    ];
    assert_eq!(a_acks, want_acks.iter().collect::<Vec<_>>(), "{a_lines:#?}");
    // B heard nothing of A's corrupted frames, and the one after the recovery at its time;
    // B itself stayed error-active (REC 32 at most).
    let b_rx: Vec<&String> = b_lines.iter().filter(|l| l.starts_with("rx ")).collect();
    assert_eq!(b_rx, [&format!("rx {end202} 202#33")], "{b_lines:#?}");
    let b_states: Vec<&String> = b_lines
        .iter()
        .filter(|l| l.starts_with("error-state "))
        .collect();
    assert_eq!(b_states, ["error-state 0 ErrorActive"], "{b_lines:#?}");

    let net = &out.networks[0];
    let (stats, counters) = net.with_simulation(|sim, bus| {
        let b = sim.bus(bus).expect("bus");
        (
            (b.stats().frames(), b.stats().error_frames()),
            error_counters(b),
        )
    });
    assert_eq!((stats, counters), (want_stats, want_counters));
    assert_eq!(net.counters().frames, 1);
}
