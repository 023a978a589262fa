//! Ports: how a node is attached to a bus.

use std::any::Any;

use cantwin_can::{BitRate, ErrorCounters, Node};
use cantwin_twin::Twin;

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

/// How the bus reaches the [`Twin`] behind a node whose concrete type it no longer knows:
/// recorded, monomorphised, when the twin is attached ([`BoxedNode::twin`]).
#[derive(Clone, Copy)]
pub(crate) struct TwinAccess {
    get: fn(&dyn AnyNode) -> Option<&dyn Twin>,
    get_mut: fn(&mut dyn AnyNode) -> Option<&mut dyn Twin>,
}

fn twin_of<T: Twin + 'static>(node: &dyn AnyNode) -> Option<&dyn Twin> {
    node.as_any().downcast_ref::<T>().map(|t| t as &dyn Twin)
}

fn twin_of_mut<T: Twin + 'static>(node: &mut dyn AnyNode) -> Option<&mut dyn Twin> {
    node.as_any_mut()
        .downcast_mut::<T>()
        .map(|t| t as &mut dyn Twin)
}

impl TwinAccess {
    pub(crate) fn of<T: Twin + 'static>() -> Self {
        TwinAccess {
            get: twin_of::<T>,
            get_mut: twin_of_mut::<T>,
        }
    }

    pub(crate) fn get<'a>(&self, node: &'a dyn AnyNode) -> Option<&'a dyn Twin> {
        (self.get)(node)
    }

    pub(crate) fn get_mut<'a>(&self, node: &'a mut dyn AnyNode) -> Option<&'a mut dyn Twin> {
        (self.get_mut)(node)
    }
}

/// A boxed node ready to attach ([`crate::Bus::attach_node`]), which remembers whether it
/// is a [`Twin`] so that front ends reach it as one ([`crate::Bus::twin`]) without naming
/// its type.
pub struct BoxedNode {
    pub(crate) node: Box<dyn AnyNode>,
    pub(crate) twin: Option<TwinAccess>,
}

impl BoxedNode {
    /// A node that is not a twin (a master, a generator, a scripted test node).
    pub fn plain<N: AnyNode>(node: N) -> Self {
        BoxedNode {
            node: Box::new(node),
            twin: None,
        }
    }

    /// A node that is a twin.
    pub fn twin<N: AnyNode + Twin>(node: N) -> Self {
        BoxedNode {
            node: Box::new(node),
            twin: Some(TwinAccess::of::<N>()),
        }
    }
}

impl core::fmt::Debug for BoxedNode {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("BoxedNode")
            .field("twin", &self.twin.is_some())
            .finish_non_exhaustive()
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
