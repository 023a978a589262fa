//! The virtual bus as a [`BusConnector`]: a paced simulation's buses, by name, for gateways.

use cantwin_bus::{BusError, ExternalConfig, ExternalPort, PortConfig, SimHandle, TimeMap};
use cantwin_can::Frame;

use crate::port::{BusConnector, BusPort, PortError, Received};

/// The buses of a paced simulation ([`cantwin_bus::PacedSimulation`]), opened by their names
/// ([`cantwin_bus::BusConfig::name`]).
///
/// Each opened port is an external port of the simulation: a node whose frames arbitrate and
/// take bus time like any other, which acknowledges frames, and which receives every frame
/// except its own, stamped with the wall time the simulation maps the end of the frame to.
///
/// ```
/// use cantwin_bus::{BusConfig, PacedConfig, PacedSimulation, Simulation};
/// use cantwin_can::{BitRate, Frame};
/// use cantwin_gateway::paced::PacedBus;
/// use cantwin_gateway::{BusConnector, BusPort};
/// use std::time::Duration;
///
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let mut sim = Simulation::new();
/// sim.add_bus(BusConfig::new("can0", BitRate::R500K));
/// let paced = PacedSimulation::start(sim, PacedConfig::default());
/// let buses = PacedBus::new(paced.handle());
/// let a = buses.open("can0", 64)?;
/// let b = buses.open("can0", 64)?;
/// a.send(Frame::std(0x181, &[1, 2, 3])?)?;
/// let rx = b.recv_timeout(Duration::from_secs(5))?.ok_or("nothing received")?;
/// assert_eq!(rx.frame, Frame::std(0x181, &[1, 2, 3])?);
/// # Ok(())
/// # }
/// ```
#[derive(Debug, Clone)]
pub struct PacedBus {
    handle: SimHandle,
    port: PortConfig,
}

impl PacedBus {
    /// The buses of the simulation behind `handle`; ports get [`PortConfig::DEFAULT`] without
    /// self-reception.
    pub fn new(handle: SimHandle) -> Self {
        PacedBus {
            handle,
            port: PortConfig::DEFAULT.with_echo(false),
        }
    }

    /// Ports opened from now on get this configuration (transmit queue depth and order).
    /// Self-reception stays off: a gateway client never receives its own frames.
    pub fn with_port_config(mut self, config: PortConfig) -> Self {
        self.port = config.with_echo(false);
        self
    }
}

fn port_error(e: BusError) -> PortError {
    match e {
        BusError::QueueFull(_) => PortError::TxQueueFull,
        BusError::Stopped | BusError::NoSuchPort(_) | BusError::NoSuchBus(_) => PortError::Closed,
        e @ BusError::PoweredOff(_) => PortError::Transport(e.to_string()),
    }
}

impl BusConnector for PacedBus {
    fn open(&self, channel: &str, rx_capacity: usize) -> Result<Box<dyn BusPort>, PortError> {
        self.open_labelled(channel, rx_capacity, None)
    }

    /// Opens a port named `client` on its bus ([`cantwin_bus::Bus::port_label`]), so front
    /// ends can say who sent its frames.
    fn open_for(
        &self,
        channel: &str,
        rx_capacity: usize,
        client: &str,
    ) -> Result<Box<dyn BusPort>, PortError> {
        self.open_labelled(channel, rx_capacity, Some(client))
    }
}

impl PacedBus {
    fn open_labelled(
        &self,
        channel: &str,
        rx_capacity: usize,
        client: Option<&str>,
    ) -> Result<Box<dyn BusPort>, PortError> {
        let bus = self
            .handle
            .with(|sim| {
                sim.buses()
                    .iter()
                    .find(|b| b.name() == channel)
                    .map(|b| b.id())
            })
            .map_err(port_error)?
            .ok_or_else(|| PortError::UnknownChannel(channel.to_owned()))?;
        let port = self
            .handle
            .attach_external(
                bus,
                ExternalConfig {
                    port: self.port,
                    rx_capacity: rx_capacity.max(1),
                },
            )
            .map_err(port_error)?;
        if let Some(client) = client {
            let id = port.port();
            self.handle
                .with(|sim| {
                    if let Some(b) = sim.bus_mut(bus) {
                        b.set_port_label(id, client);
                    }
                })
                .map_err(port_error)?;
        }
        Ok(Box::new(PacedPort {
            port,
            handle: self.handle.clone(),
        }))
    }
}

/// A port on a paced bus; dropping it detaches it. It delivers frames on the simulation's
/// thread when asked ([`BusPort::deliver_to`]).
struct PacedPort {
    port: ExternalPort,
    handle: SimHandle,
}

impl BusPort for PacedPort {
    fn send(&self, frame: Frame) -> Result<(), PortError> {
        self.port.send(frame).map_err(port_error)
    }

    fn recv_timeout(&self, timeout: std::time::Duration) -> Result<Option<Received>, PortError> {
        Ok(self
            .port
            .recv_timeout(timeout)
            .map_err(port_error)?
            .map(|rx| Received {
                frame: rx.frame,
                timestamp: self.handle.time_map().wall_time(rx.at),
            }))
    }

    fn overflows(&self) -> u64 {
        self.port.overruns()
    }

    fn deliver_to(&self, mut sink: Box<dyn FnMut(Received) + Send>) -> bool {
        self.port
            .deliver_to(move |rx: cantwin_bus::Received, map: TimeMap| {
                sink(Received {
                    frame: rx.frame,
                    timestamp: map.wall_time(rx.at),
                });
            })
            .is_ok()
    }
}
