//! Device kinds and the settings they read.

use std::cell::RefCell;
use std::collections::BTreeSet;

use std::path::PathBuf;

use cantwin_bus::{BoxedNode, PortConfig};
use serde::de::DeserializeOwned;

use crate::error::{Located, ScenarioError};
use crate::spec::{BusSpec, DeviceSpec};

/// What the host provides to devices being built.
#[derive(Debug, Clone, Default)]
pub struct BuildEnv {
    /// Where devices keep what they store (CANopen 0x1010) between runs; `None` keeps it in
    /// memory only.
    pub state_dir: Option<PathBuf>,
}

/// A kind of device a scenario can place on a bus.
pub trait DeviceKind: Send + Sync {
    /// The `kind = "…"` value.
    fn name(&self) -> &'static str;
    /// One line for `cantwin scenario kinds` and error messages.
    fn summary(&self) -> &'static str;
    /// Build the node from the device's settings. Read every key through `settings`; keys
    /// left unread are reported as unknown. A device that is a twin is boxed as one
    /// ([`BoxedNode::twin`]): front ends and scripts reach it through the simulation
    /// ([`Simulation::twin`](cantwin_bus::Simulation::twin)).
    fn build(
        &self,
        settings: &Settings<'_>,
        bus: &BusSpec,
        env: &BuildEnv,
    ) -> Result<(BoxedNode, PortConfig), ScenarioError>;
}

/// The device kinds a scenario may use.
pub struct Registry {
    kinds: Vec<Box<dyn DeviceKind>>,
}

impl Registry {
    /// An empty registry ([`Registry::builtin`] has every kind built into cantwin).
    pub fn new() -> Self {
        Registry { kinds: Vec::new() }
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

/// A device's kind-specific keys, read by its [`DeviceKind`]. Errors name the line and key.
pub struct Settings<'a> {
    device: &'a DeviceSpec,
    file: &'a std::path::Path,
    read: RefCell<BTreeSet<String>>,
    warnings: RefCell<Vec<String>>,
}

impl<'a> Settings<'a> {
    pub(crate) fn new(device: &'a DeviceSpec, file: &'a std::path::Path) -> Self {
        Settings {
            device,
            file,
            read: RefCell::new(BTreeSet::new()),
            warnings: RefCell::new(Vec::new()),
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

    /// Reports something that does not stop the device from being built but that the user
    /// must hear of (stored parameters that cannot be read, so the device starts on its
    /// defaults): it reaches [`Built::warnings`](crate::Built::warnings).
    pub fn warn(&self, message: impl Into<String>) {
        self.warnings.borrow_mut().push(message.into());
    }

    /// The warnings reported so far, taken.
    pub(crate) fn take_warnings(&self) -> Vec<String> {
        self.warnings.take()
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
