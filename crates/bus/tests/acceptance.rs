//! The acceptance cache and `Node::acceptance_version`: a node's verdicts are asked again
//! only when its version changes (or when it keeps none), and a changed filter takes effect
//! from the next frame.
#![allow(clippy::unwrap_used)]

mod common;

use std::cell::Cell;

use cantwin_bus::{BusConfig, PortConfig, Simulation};
use cantwin_can::{BitRate, Duration, Frame, Id, Instant, Node, Outbox};
use common::{Probe, std_frame};

const A: u16 = 0x100;
const B: u16 = 0x200;
const SWITCH: u16 = 0x050;

/// Passes `A` and `SWITCH`; after a frame on `SWITCH` also `B`. It is called every 100 µs
/// (a tick), so without a version its verdicts would be asked again for every frame.
struct Switcher {
    versioned: bool,
    switched: bool,
    next: Instant,
    asked: Cell<u32>,
    rx: Vec<(u64, u32)>,
}

impl Switcher {
    fn new(versioned: bool) -> Self {
        Switcher {
            versioned,
            switched: false,
            next: Instant::ZERO,
            asked: Cell::new(0),
            rx: Vec::new(),
        }
    }
}

impl Node for Switcher {
    fn on_frame(&mut self, frame: &Frame, now: Instant, _: &mut Outbox) {
        let id = frame.id().as_raw();
        self.rx.push((now.as_nanos(), id));
        if id == u32::from(SWITCH) {
            self.switched = true;
        }
    }
    fn on_tick(&mut self, now: Instant, _: &mut Outbox) {
        self.next = now + Duration::from_micros(100);
    }
    fn next_deadline(&self) -> Option<Instant> {
        Some(self.next)
    }
    fn accepts(&self, id: Id) -> bool {
        self.asked.set(self.asked.get() + 1);
        let raw = id.as_raw();
        raw == u32::from(A) || raw == u32::from(SWITCH) || (self.switched && raw == u32::from(B))
    }
    fn acceptance_version(&self) -> Option<u64> {
        self.versioned.then_some(u64::from(self.switched))
    }
}

/// What a run leaves: the switcher's received (time, id), how often it was asked, and the
/// sender's sent frames.
struct Run {
    rx: Vec<(u64, u32)>,
    asked: u32,
    sent: Vec<(u64, Frame)>,
}

/// Frames on A and B every millisecond for 20 ms, SWITCH at 10.5 ms.
fn run(versioned: bool) -> Run {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let mut sender = Probe::new();
    for ms in 0..20u64 {
        sender = sender
            .at(ms * 1_000_000, std_frame(A, &[1]))
            .at(ms * 1_000_000, std_frame(B, &[2]));
    }
    sender = sender.at(10_500_000, std_frame(SWITCH, &[]));
    let tx = sim.attach(bus, sender, PortConfig::default()).unwrap();
    let sw = sim
        .attach(bus, Switcher::new(versioned), PortConfig::default())
        .unwrap();
    sim.run_until(Instant::from_nanos(25_000_000));
    let s: &Switcher = sim.node(sw).unwrap();
    let sent = sim.node::<Probe>(tx).unwrap().sent.clone();
    Run {
        rx: s.rx.clone(),
        asked: s.asked.get(),
        sent,
    }
}

/// What the switcher must have received: every A, the SWITCH, and the Bs that ended after
/// the SWITCH did.
fn expected(sent: &[(u64, Frame)]) -> Vec<(u64, u32)> {
    let switch_at = sent
        .iter()
        .find(|(_, f)| f.id().as_raw() == u32::from(SWITCH))
        .unwrap()
        .0;
    sent.iter()
        .filter(|(t, f)| f.id().as_raw() != u32::from(B) || *t > switch_at)
        .map(|(t, f)| (*t, f.id().as_raw()))
        .collect()
}

#[test]
fn a_versioned_node_is_asked_again_only_when_its_version_changes() {
    let Run { rx, asked, sent } = run(true);
    assert_eq!(rx, expected(&sent));
    assert!(
        rx.iter().any(|(_, id)| *id == u32::from(B)),
        "B passes after the switch"
    );
    // A, B and SWITCH once each, then A and B again after the version changed.
    assert_eq!(asked, 5);
}

#[test]
fn a_node_without_a_version_is_asked_again_after_its_calls() {
    let Run { rx, asked, sent } = run(false);
    assert_eq!(rx, expected(&sent));
    // Called every 100 µs, so asked again for nearly every one of the 41 frames.
    assert!(asked > 30, "asked {asked} times");
}
