//! Identifiers of buses and ports in a simulation.

use core::fmt;

/// A bus in a [`crate::Simulation`] (a standalone [`crate::Bus`] is bus 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct BusId(pub(crate) u32);

impl BusId {
    /// The bus's index in its simulation, in the order buses were added.
    pub const fn index(self) -> u32 {
        self.0
    }
}

impl fmt::Display for BusId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "bus{}", self.0)
    }
}

/// A port (a node's attachment point) on a bus. Port numbers are never reused: a detached
/// port stays dead.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct PortId {
    pub(crate) bus: BusId,
    pub(crate) index: u32,
}

impl PortId {
    /// The bus the port is on.
    pub const fn bus(self) -> BusId {
        self.bus
    }

    /// The port's index on its bus, in attachment order from 0.
    pub const fn index(self) -> u32 {
        self.index
    }
}

impl fmt::Display for PortId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.port{}", self.bus, self.index)
    }
}
