//! Errors of the bus API.

use crate::ids::{BusId, PortId};

/// Why a bus or simulation operation was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum BusError {
    /// No bus with this identifier in the simulation.
    #[error("no {0} in this simulation")]
    NoSuchBus(BusId),
    /// The port does not exist on this bus, or was detached.
    #[error("no {0} on this bus (never attached or detached)")]
    NoSuchPort(PortId),
    /// The port's transmit queue was full: the frame was dropped and counted.
    #[error("transmit queue of {0} is full")]
    QueueFull(PortId),
    /// The port's node is powered off.
    #[error("{0} is powered off")]
    PoweredOff(PortId),
    /// The paced simulation has stopped, or the external port was detached.
    #[error("the simulation has stopped or the port was detached")]
    Stopped,
}
