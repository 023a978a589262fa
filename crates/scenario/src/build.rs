//! Turning a scenario into a running simulation.

use cantwin_bus::{BusConfig, BusId, PortId, Simulation};
use cantwin_twin::{FaultError, SignalError};

use crate::error::{Located, ScenarioError};
use crate::model::Scenario;
use crate::registry::{BuildEnv, Registry, Settings};

/// A device placed on a bus.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BuiltDevice {
    /// Its name in the scenario.
    pub name: String,
    /// Its kind.
    pub kind: String,
    /// Its port.
    pub port: PortId,
    /// Its CANopen node-ID, when its kind is a CANopen slave.
    pub node_id: Option<u8>,
}

impl BuiltDevice {
    /// `e` as scripts report it: a signal the device does not have is named with the
    /// device's kind ("a tm3 device has no signal …").
    pub fn signal_message(&self, e: &SignalError) -> String {
        match e {
            SignalError::Unknown { .. } => self.has(e),
            other => other.to_string(),
        }
    }

    /// `e` as scripts report it: a device without such faults is named with its kind ("a
    /// cia301 device has no internal faults to inject").
    pub fn fault_message(&self, e: &FaultError) -> String {
        match e {
            FaultError::None { .. } => self.has(e),
            other => other.to_string(),
        }
    }

    /// "a KIND device has WHAT", with "an" before a kind that starts with a vowel.
    fn has(&self, what: impl core::fmt::Display) -> String {
        let kind = &self.kind;
        let article = if kind.starts_with(['a', 'e', 'i', 'o', 'u']) {
            "an"
        } else {
            "a"
        };
        format!("{article} {kind} device has {what}")
    }
}

/// A scenario built into a simulation, with names resolved to ids.
pub struct Built {
    /// The simulation, at time zero.
    pub sim: Simulation,
    /// Buses by name, in file order.
    pub buses: Vec<(String, BusId)>,
    /// Devices in file order.
    pub devices: Vec<BuiltDevice>,
    /// What the build found that does not stop the scenario but that the user must hear
    /// of, each naming its device (e.g. stored parameters that cannot be read: the device
    /// starts on its defaults and raises its alarm). Front ends print them.
    pub warnings: Vec<String>,
}

impl Built {
    /// The bus named `name`.
    pub fn bus(&self, name: &str) -> Option<BusId> {
        self.buses
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, id)| *id)
    }

    /// The device named `name`.
    pub fn device(&self, name: &str) -> Option<&BuiltDevice> {
        self.devices.iter().find(|d| d.name == name)
    }
}

impl Scenario {
    /// Build the buses and devices. Devices are powered at time zero in file order.
    pub fn build(&self, registry: &Registry, env: &BuildEnv) -> Result<Built, ScenarioError> {
        let mut sim = Simulation::new();
        let mut buses = Vec::new();
        for b in &self.buses {
            let id = sim.add_bus(BusConfig::new(b.name.clone(), b.bit_rate).with_seed(self.seed));
            buses.push((b.name.clone(), id));
        }
        let mut devices = Vec::new();
        let mut warnings = Vec::new();
        for d in &self.devices {
            let kind = registry.get(&d.kind).ok_or_else(|| {
                let known: Vec<&str> = registry.kinds().map(|k| k.name()).collect();
                ScenarioError::Invalid {
                    at: Located {
                        file: self.file.clone(),
                        line: Some(d.line),
                        key: Some(format!("device[{}].kind", d.index)),
                    },
                    message: format!(
                        "unknown device kind {:?} (kinds: {})",
                        d.kind,
                        known.join(", ")
                    ),
                }
            })?;
            let (spec, bus_id) = self
                .buses
                .iter()
                .zip(&buses)
                .find(|(b, _)| b.name == d.bus)
                .map(|(b, (_, id))| (b, *id))
                .ok_or_else(|| ScenarioError::Invalid {
                    at: Located {
                        file: self.file.clone(),
                        line: Some(d.line),
                        key: Some(format!("device[{}].bus", d.index)),
                    },
                    message: format!("no bus named {:?}", d.bus),
                })?;
            let settings = Settings::new(d, &self.file);
            let (node, port_config) = kind.build(&settings, spec, env)?;
            settings.finish()?;
            warnings.extend(
                settings
                    .take_warnings()
                    .into_iter()
                    .map(|w| format!("device {:?}: {w}", d.name)),
            );
            let bus = sim.bus_mut(bus_id).ok_or_else(|| ScenarioError::Invalid {
                at: Located {
                    file: self.file.clone(),
                    line: Some(d.line),
                    key: None,
                },
                message: format!("bus {:?} vanished while building", d.bus),
            })?;
            let port = bus.attach_node(node, port_config);
            let rate = sim.twin(port).and_then(|t| t.controller_bit_rate());
            if let Some(bus) = sim.bus_mut(bus_id)
                && rate.is_some_and(|r| r != bus.bit_rate())
            {
                // A controller at another rate than the bus's: the bus models it.
                let _ = bus.set_bit_rate_mismatch(port, rate);
            }
            let node_id = sim.twin(port).and_then(|t| t.canopen_node_id());
            // Two slaves with one node-ID would answer the same SDO request and send on the
            // same COB-IDs (CiA 301 §7.3.2.1: the node-ID is unique within a network).
            if let Some(n) = node_id
                && let Some(other) = devices
                    .iter()
                    .find(|o: &&BuiltDevice| o.node_id == Some(n) && o.port.bus() == bus_id)
            {
                let key = if d.settings.contains_key("node_id") {
                    "node_id"
                } else {
                    "name"
                };
                return Err(Settings::new(d, &self.file).error(
                    key,
                    format!(
                        "node-ID {n} is already used by device {:?} on bus {:?}",
                        other.name, d.bus
                    ),
                ));
            }
            devices.push(BuiltDevice {
                name: d.name.clone(),
                kind: d.kind.clone(),
                port,
                node_id,
            });
        }
        Ok(Built {
            sim,
            buses,
            devices,
            warnings,
        })
    }
}
