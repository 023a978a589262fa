//! Ports: how a node is attached to a bus.

use std::any::Any;

use cantwin_can::{BitRate, ErrorCounters, Node};

use crate::queue::TxOrder;
use crate::stats::PortStats;

/// How a node is attached to a bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PortConfig {
    /// Transmit queue depth (frames). A frame queued while it is full is dropped, counted and
    /// reported with [`cantwin_can::ControllerEvent::TxDropped`]. Minimum 1.
    pub queue_depth: usize,
    /// In which order queued frames are offered to arbitration.
    pub order: TxOrder,
    /// Self-reception: the node also gets its own frames through `on_frame` when they complete
    /// (just before `on_sent`).
    pub echo: bool,
    /// Recover from bus-off by itself after 128 × 11 recessive bits (ISO 11898-1 §12.1.4.2);
    /// otherwise only [`crate::Bus::recover_bus_off`] starts the recovery.
    pub auto_bus_off_recovery: bool,
    /// Whether the node is powered (and `on_power_up` called) when attached.
    pub powered: bool,
}

impl PortConfig {
    /// 32-frame priority queue, no echo, automatic bus-off recovery, powered.
    pub const DEFAULT: PortConfig = PortConfig {
        queue_depth: 32,
        order: TxOrder::Priority,
        echo: false,
        auto_bus_off_recovery: true,
        powered: true,
    };

    /// A single transmit mailbox.
    pub const fn mailbox() -> Self {
        PortConfig {
            queue_depth: 1,
            ..Self::DEFAULT
        }
    }

    /// With this queue depth.
    pub const fn with_queue_depth(mut self, depth: usize) -> Self {
        self.queue_depth = depth;
        self
    }

    /// With this queue order.
    pub const fn with_order(mut self, order: TxOrder) -> Self {
        self.order = order;
        self
    }

    /// With or without self-reception.
    pub const fn with_echo(mut self, echo: bool) -> Self {
        self.echo = echo;
        self
    }

    /// With or without automatic bus-off recovery.
    pub const fn with_auto_bus_off_recovery(mut self, auto: bool) -> Self {
        self.auto_bus_off_recovery = auto;
        self
    }

    /// Attached powered or unpowered.
    pub const fn with_powered(mut self, powered: bool) -> Self {
        self.powered = powered;
        self
    }
}

impl Default for PortConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A node the bus can hold and hand back with its concrete type (see [`crate::Bus::node`]).
/// Implemented for every `Node + Send + 'static`.
pub trait AnyNode: Node + Send + 'static {
    /// As [`Any`], for downcasting.
    fn as_any(&self) -> &dyn Any;
    /// As mutable [`Any`], for downcasting.
    fn as_any_mut(&mut self) -> &mut dyn Any;
    /// Into a boxed [`Any`], for taking a detached node back.
    fn into_any(self: Box<Self>) -> Box<dyn Any>;
}

impl<T: Node + Send + 'static> AnyNode for T {
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
    fn into_any(self: Box<Self>) -> Box<dyn Any> {
        self
    }
}

/// A snapshot of a port's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PortStatus {
    /// The controller's error counters and state.
    pub counters: ErrorCounters,
    /// Whether the node is powered.
    pub powered: bool,
    /// Whether the node is connected to the bus wires.
    pub connected: bool,
    /// The bit rate the node's controller is misconfigured to, if any.
    pub bit_rate_mismatch: Option<BitRate>,
    /// Whether the controller babbles.
    pub babbling: bool,
    /// Frames waiting in the transmit queue.
    pub queued: usize,
    /// The port's counters.
    pub stats: PortStats,
}
