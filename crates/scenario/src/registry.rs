//! Device kinds and the settings they read.

use std::cell::RefCell;
use std::collections::BTreeSet;

use cantwin_bus::{AnyNode, PortConfig, PortId, Simulation};
use serde::de::DeserializeOwned;

use crate::build::BuildEnv;
use crate::error::{Located, ScenarioError};
use crate::live::LiveValue;
use crate::model::{BusSpec, DeviceSpec};

/// A kind of device a scenario can place on a bus.
pub trait DeviceKind: Send + Sync {
    /// The `kind = "…"` value.
    fn name(&self) -> &'static str;
    /// One line for `cantwin scenario kinds` and error messages.
    fn summary(&self) -> &'static str;
    /// Build the node from the device's settings. Read every key through `settings`; keys
    /// left unread are reported as unknown.
    fn build(
        &self,
        settings: &Settings<'_>,
        bus: &BusSpec,
        env: &BuildEnv,
    ) -> Result<(Box<dyn AnyNode>, PortConfig), ScenarioError>;

    /// The little-endian bytes of object `index`/`sub` of the node this kind built on
    /// `port`, for `[[expect]] value = …` in scenario scripts. `None` (the default) when the
    /// kind has no object dictionary or not that object.
    fn read_object(&self, sim: &Simulation, port: PortId, index: u16, sub: u8) -> Option<Vec<u8>> {
        let _ = (sim, port, index, sub);
        None
    }

    /// Give the node this kind built on `port` an internal defect named `fault` in the
    /// kind's words (a fault with no cause on the bus, such as a card's internal error), or
    /// repair it with `None`, for `action = "inject"` / `"repair"` in scenario scripts. The
    /// default refuses: the kind has no internal faults.
    fn inject(
        &self,
        sim: &mut Simulation,
        port: PortId,
        fault: Option<&str>,
    ) -> Result<(), String> {
        let _ = (sim, port, fault);
        Err(format!(
            "a {} device has no internal faults to inject",
            self.name()
        ))
    }

    /// The live values of the model of the node this kind built on `port` (measurements,
    /// inputs, outputs), for dashboards. Empty (the default) when the kind shows none.
    fn live_values(&self, sim: &Simulation, port: PortId) -> Vec<LiveValue> {
        let _ = (sim, port);
        Vec::new()
    }

    /// The CANopen node-ID (CiA 301 §7.3.2.1) of the node this kind built on `port`, for the
    /// duplicate check of a bus and for telling a master's frames from a twin's. `None` (the
    /// default) when the kind is not a CANopen slave.
    fn canopen_node_id(&self, sim: &Simulation, port: PortId) -> Option<u8> {
        let _ = (sim, port);
        None
    }

    /// Sets the physical quantity `name` (an input, a load, a module pulled out) of the
    /// node this kind built on `port` to `value`, now, for `[[at]] action = "set"`. The
    /// error says why not, naming the signals the kind knows.
    fn set_signal(
        &self,
        sim: &mut Simulation,
        port: PortId,
        name: &str,
        value: &toml::Value,
    ) -> Result<(), String> {
        let _ = (sim, port, value);
        Err(format!(
            "a {} device has no signal {name:?} to set",
            self.name()
        ))
    }

    /// Reads the physical quantity `name` (an output, an alarm) of the node this kind built
    /// on `port`, for `[[expect]] signal = …`.
    fn read_signal(
        &self,
        sim: &Simulation,
        port: PortId,
        name: &str,
    ) -> Result<toml::Value, String> {
        let _ = (sim, port);
        Err(format!(
            "a {} device has no signal {name:?} to read",
            self.name()
        ))
    }
}

/// The device kinds a scenario may use.
pub struct Registry {
    kinds: Vec<Box<dyn DeviceKind>>,
}

impl Registry {
    /// An empty registry.
    pub fn new() -> Self {
        Registry { kinds: Vec::new() }
    }

    /// Every kind built into cantwin.
    pub fn builtin() -> Self {
        let mut r = Registry::new();
        r.register(Box::new(crate::kinds::generator::Generator));
        r.register(Box::new(crate::kinds::master::MasterKind));
        r.register(Box::new(crate::kinds::cia301::Cia301::default()));
        r.register(Box::new(crate::kinds::opendrive::OpenDriveKind));
        r.register(Box::new(crate::kinds::adv200::Adv200Kind::default()));
        r.register(Box::new(crate::kinds::tm3::Tm3Kind::default()));
        r.register(Box::new(crate::kinds::eds::EdsKind));
        r
    }

    /// Add a kind (a later kind with the same name replaces the earlier one).
    pub fn register(&mut self, kind: Box<dyn DeviceKind>) {
        self.kinds.retain(|k| k.name() != kind.name());
        self.kinds.push(kind);
    }

    /// The kind named `name`.
    pub fn get(&self, name: &str) -> Option<&dyn DeviceKind> {
        self.kinds
            .iter()
            .find(|k| k.name() == name)
            .map(|k| k.as_ref())
    }

    /// All kinds, in registration order.
    pub fn kinds(&self) -> impl Iterator<Item = &dyn DeviceKind> {
        self.kinds.iter().map(|k| k.as_ref())
    }
}

impl Default for Registry {
    fn default() -> Self {
        Registry::builtin()
    }
}

/// A device's kind-specific keys, read by its [`DeviceKind`]. Errors name the line and key.
pub struct Settings<'a> {
    device: &'a DeviceSpec,
    file: &'a std::path::Path,
    read: RefCell<BTreeSet<String>>,
}

impl<'a> Settings<'a> {
    pub(crate) fn new(device: &'a DeviceSpec, file: &'a std::path::Path) -> Self {
        Settings {
            device,
            file,
            read: RefCell::new(BTreeSet::new()),
        }
    }

    /// The scenario file the device is defined in (kinds resolve relative paths against
    /// its directory).
    pub fn file(&self) -> &std::path::Path {
        self.file
    }

    /// The device these settings belong to.
    pub fn device(&self) -> &DeviceSpec {
        self.device
    }

    /// The value of `key`, if present, converted to `T`.
    pub fn get<T: DeserializeOwned>(&self, key: &str) -> Result<Option<T>, ScenarioError> {
        self.read.borrow_mut().insert(key.to_string());
        match self.device.settings.get(key) {
            None => Ok(None),
            Some((value, _)) => T::deserialize(value.clone())
                .map(Some)
                .map_err(|e| self.error(key, e.message().trim_end().to_string())),
        }
    }

    /// The value of `key`, or an error naming it when it is missing.
    pub fn require<T: DeserializeOwned>(&self, key: &str) -> Result<T, ScenarioError> {
        self.get(key)?
            .ok_or_else(|| self.error(key, format!("a {} device needs `{key}`", self.device.kind)))
    }

    /// The value of `key`, or `default`.
    pub fn get_or<T: DeserializeOwned>(&self, key: &str, default: T) -> Result<T, ScenarioError> {
        Ok(self.get(key)?.unwrap_or(default))
    }

    /// An error about `key` (at its line, or the device's line when the key is absent).
    pub fn error(&self, key: &str, message: impl Into<String>) -> ScenarioError {
        let line = self
            .device
            .settings
            .get(key)
            .map(|(_, l)| *l)
            .unwrap_or(self.device.line);
        ScenarioError::Invalid {
            at: Located {
                file: self.file.to_path_buf(),
                line: Some(line),
                key: Some(format!("device[{}].{key}", self.device.index)),
            },
            message: message.into(),
        }
    }

    /// Fail on keys the kind did not read: a typo must not be silently ignored.
    pub fn finish(&self) -> Result<(), ScenarioError> {
        let read = self.read.borrow();
        match self.device.settings.keys().find(|k| !read.contains(*k)) {
            None => Ok(()),
            Some(k) => {
                let mut known: Vec<&str> = read.iter().map(String::as_str).collect();
                known.sort_unstable();
                Err(self.error(
                    k,
                    format!(
                        "unknown key `{k}` for a {} device (known: name, kind, bus, {})",
                        self.device.kind,
                        known.join(", ")
                    ),
                ))
            }
        }
    }
}
