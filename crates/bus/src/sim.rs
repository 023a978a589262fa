//! Several buses run together in one time line.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use cantwin_can::{Duration, Frame, Instant};
use cantwin_twin::{Context, Twin};

use crate::bus::{Bus, BusConfig};
use crate::error::BusError;
use crate::ids::{BusId, PortId};
use crate::port::{AnyNode, PortConfig};
use crate::time_map::TimeMap;

/// A set of buses sharing one clock, run in virtual time: [`Simulation::run_until`] jumps
/// from one event to the next, whatever bus it is on. Events at the same instant on
/// different buses run bus by bus, in the order the buses were added, so a scenario replays
/// identically. For the wall clock, hand the simulation to [`crate::PacedSimulation`].
#[derive(Debug, Default)]
pub struct Simulation {
    buses: Vec<Bus>,
    now: Instant,
    time_map: Option<TimeMap>,
    /// [`Simulation::run_until`]'s agenda: each bus's next event time, least first, ties by
    /// bus. Kept between calls only for its allocation.
    agenda: BinaryHeap<Reverse<(Instant, usize)>>,
}

impl Simulation {
    /// An empty simulation at time zero.
    pub fn new() -> Self {
        Simulation::default()
    }

    /// Add a bus, starting at the current time.
    pub fn add_bus(&mut self, config: BusConfig) -> BusId {
        let id = BusId(self.buses.len() as u32);
        let mut bus = Bus::with_id(id, config, self.now);
        bus.set_time_map(self.time_map);
        self.buses.push(bus);
        id
    }

    /// A bus.
    pub fn bus(&self, id: BusId) -> Option<&Bus> {
        self.buses.get(id.0 as usize)
    }

    /// A bus, mutably: attach nodes, inject faults, read statistics.
    pub fn bus_mut(&mut self, id: BusId) -> Option<&mut Bus> {
        self.buses.get_mut(id.0 as usize)
    }

    fn bus_or_err(&mut self, id: BusId) -> Result<&mut Bus, BusError> {
        self.buses
            .get_mut(id.0 as usize)
            .ok_or(BusError::NoSuchBus(id))
    }

    /// Every bus, in the order added.
    pub fn buses(&self) -> &[Bus] {
        &self.buses
    }

    /// Attach a node to a bus (see [`Bus::attach`]).
    pub fn attach<N: AnyNode>(
        &mut self,
        bus: BusId,
        node: N,
        config: PortConfig,
    ) -> Result<PortId, BusError> {
        Ok(self.bus_or_err(bus)?.attach(node, config))
    }

    /// The node on `port`, if it is a `T`.
    pub fn node<T: 'static>(&self, port: PortId) -> Option<&T> {
        self.bus(port.bus)?.node(port)
    }

    /// The node on `port`, mutably, if it is a `T` (see [`Bus::node_mut`]).
    pub fn node_mut<T: 'static>(&mut self, port: PortId) -> Option<&mut T> {
        self.bus_mut(port.bus)?.node_mut(port)
    }

    /// The node on `port` as a [`Twin`], if it was attached as one (see [`Bus::twin`]).
    pub fn twin(&self, port: PortId) -> Option<&dyn Twin> {
        self.bus(port.bus)?.twin(port)
    }

    /// The node on `port` as a mutable [`Twin`] (see [`Bus::twin_mut`]).
    pub fn twin_mut(&mut self, port: PortId) -> Option<&mut dyn Twin> {
        self.bus_mut(port.bus)?.twin_mut(port)
    }

    /// Run `f` on the twin on `port` now, its frames queued afterwards (see
    /// [`Bus::with_twin`]).
    pub fn with_twin<R>(
        &mut self,
        port: PortId,
        f: impl FnOnce(&mut dyn Twin, &mut Context<'_>) -> R,
    ) -> Option<R> {
        self.bus_mut(port.bus)?.with_twin(port, f)
    }

    /// Queue a frame on a port now (see [`Bus::transmit`]).
    pub fn transmit(&mut self, port: PortId, frame: Frame) -> Result<(), BusError> {
        self.bus_or_err(port.bus)?.transmit(port, frame)
    }

    /// The current time.
    pub fn now(&self) -> Instant {
        self.now
    }

    /// In a paced simulation, the mapping of bus time to wall time.
    pub fn time_map(&self) -> Option<TimeMap> {
        self.time_map
    }

    pub(crate) fn set_time_map(&mut self, map: Option<TimeMap>) {
        self.time_map = map;
        for bus in &mut self.buses {
            bus.set_time_map(map);
        }
    }

    /// When something next happens on any bus.
    pub fn next_event_time(&mut self) -> Option<Instant> {
        self.buses.iter_mut().filter_map(Bus::next_event_time).min()
    }

    /// Advance to `t`, processing every event at or before it on every bus.
    pub fn run_until(&mut self, t: Instant) {
        if let [bus] = self.buses.as_mut_slice() {
            bus.run_until(t);
        } else {
            // The earliest event of all, ties to the bus added first. Stepping a bus changes
            // only that bus's next event (nodes reach no other bus), so only its entry is
            // renewed: O(log buses) per event rather than a look at every bus.
            self.agenda.clear();
            for (i, bus) in self.buses.iter_mut().enumerate() {
                if let Some(n) = bus.next_event_time() {
                    self.agenda.push(Reverse((n, i)));
                }
            }
            while let Some(Reverse((n, i))) = self.agenda.pop() {
                if n > t {
                    break;
                }
                let bus = &mut self.buses[i];
                bus.step(n);
                if let Some(next) = bus.next_event_time() {
                    self.agenda.push(Reverse((next, i)));
                }
            }
            for bus in &mut self.buses {
                bus.run_until(t);
            }
        }
        if t > self.now {
            self.now = t;
        }
    }

    /// Process the next instant with something to do on any bus; returns it, or `None` if
    /// nothing will ever happen again.
    pub fn step_next(&mut self) -> Option<Instant> {
        let mut best: Option<(Instant, usize)> = None;
        for (i, bus) in self.buses.iter_mut().enumerate() {
            if let Some(n) = bus.next_event_time()
                && best.is_none_or(|(b, _)| n < b)
            {
                best = Some((n, i));
            }
        }
        let (t, _) = best?;
        self.run_until(t);
        Some(t)
    }

    /// Advance by `d`.
    pub fn run_for(&mut self, d: Duration) {
        self.run_until(self.now + d);
    }
}
