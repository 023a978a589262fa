//! `kind = "eds"`: a CiA 301 device whose object dictionary is a user's EDS or DCF file
//! (CiA 306).
//!
//! Keys:
//!
//! | key | default | meaning |
//! |---|---|---|
//! | `file` | required | the EDS or DCF, relative to the scenario file's directory |
//! | `node_id` | the DCF's `[DeviceComissioning] NodeID` | 1–127; required when the file gives none |
//! | `heartbeat_ms` | the file's 0x1017 default | overrides the default of 0x1017 |
//! | `sdo_timeout_ms` | 1000 | SDO server timeout |
//! | `lss` | false | answer LSS (CiA 305, see [`super::lss`]); `node_id` may then be 0xFF or `"unconfigured"` |
//!
//! The file is the device's truth: every VAR, DOMAIN, ARRAY and RECORD object of the file
//! (and the DEFTYPE entries of basic types, such as the dummy entries 0x0002–0x0007) becomes
//! an object of the dictionary with the file's data type, access, limits and default value
//! (`$NODEID` resolved with the node-ID). A DCF's `ParameterValue`s configure the device
//! when its `[DeviceComissioning]` is for the device's node-ID (or names none); otherwise
//! they are left aside with a warning. Files are read as they are written in the field
//! (`cantwin_eds::load`): what CiA 306 does not allow is read past, the way `cantwin eds
//! check` reports it, and only a file no dictionary can hold (an entry without a data type)
//! is refused. Applied `ParameterValue`s replace the defaults, so the device comes up
//! configured after power-up and after every reset, as a commissioned device would (CiA 306
//! DCF: the values the device is configured with).
//!
//! The device offers the CiA 301 services whose objects the file has, and only those:
//!
//! * without 0x1017 it produces no heartbeat, and `heartbeat_ms` is an error;
//! * without 0x1200 it still answers SDO on the default connection (0x600/0x580 + node-ID),
//!   which CiA 301 §7.2.4.1 requires of every device;
//! * PDOs are the 0x1400–0x15FF/0x1800–0x19FF communication objects with their mapping
//!   objects 0x1600–0x17FF/0x1A00–0x1BFF; a file without them has no PDOs; a PDO whose
//!   mapping cannot run (an object the file lacks) stays off, with a build warning, and the
//!   others run;
//! * without 0x1014 the EMCY producer uses 0x80 + node-ID; without 0x1010/0x1011 nothing is
//!   stored.
//!
//! With `--state-dir`, the device keeps what 0x1010 stores in `STATE_DIR/<device name>/`.

use std::path::{Path, PathBuf};

use cantwin_bus::{BoxedNode, PortConfig};
use cantwin_eds::{ConvertError, EdsValue, configured, device_warnings, load_bytes, to_od};

use super::common::{canopen_device, check_node_id, sdo_timeout};
use crate::error::ScenarioError;
use crate::registry::{BuildEnv, DeviceKind, Settings};
use crate::spec::BusSpec;

/// The device's transmit queue: a full SDO upload block (127 segments, CiA 301
/// §7.2.4.3.10) plus the frames other services queue meanwhile.
pub const TX_QUEUE_DEPTH: usize = 256;

/// The `eds` kind.
pub struct EdsKind;

/// `file` resolved against the directory of the scenario file.
fn resolve(scenario: &Path, file: &str) -> PathBuf {
    let file = Path::new(file);
    if file.is_absolute() {
        return file.to_path_buf();
    }
    match scenario.parent() {
        Some(dir) => dir.join(file),
        None => file.to_path_buf(),
    }
}

impl DeviceKind for EdsKind {
    fn name(&self) -> &'static str {
        "eds"
    }

    fn summary(&self) -> &'static str {
        "CiA 301 device from an EDS/DCF file: file, node_id, heartbeat_ms, sdo_timeout_ms, lss"
    }

    fn build(
        &self,
        s: &Settings<'_>,
        bus: &BusSpec,
        env: &BuildEnv,
    ) -> Result<(BoxedNode, PortConfig), ScenarioError> {
        let file: String = s.require("file")?;
        let path = resolve(s.file(), &file);
        let bytes = std::fs::read(&path)
            .map_err(|e| s.error("file", format!("cannot read {}: {e}", path.display())))?;
        // Files in the field bend CiA 306 in many ways; the device is what the file evidently
        // means (`cantwin eds check` prints what was read past). Only a file no dictionary can
        // hold is refused, by `to_od` below.
        let loaded = load_bytes(&bytes);

        let from_dcf = loaded.eds.commissioning.as_ref().and_then(|c| c.node_id);
        let lss: bool = s.get_or("lss", false)?;
        let node_id: u8 = match (super::lss::node_id(s, lss)?, from_dcf) {
            (Some(n), _) | (None, Some(n)) => n,
            (None, None) => {
                return Err(s.error(
                    "node_id",
                    format!(
                        "an eds device needs `node_id` ({} has no [DeviceComissioning] NodeID)",
                        path.display()
                    ),
                ));
            }
        };
        if !lss {
            check_node_id(s, node_id)?;
        }
        // A DCF's ParameterValues are the configuration of one commissioned node (CiA 306
        // DCF): COB-IDs among them are often written out for that node-ID. They configure
        // the device when the file says it is commissioned ([DeviceComissioning]) for the
        // node-ID the device runs with; stray values in an EDS, or a DCF for another node,
        // would put its SDO server and PDOs on another node's identifiers.
        let commissioned = loaded
            .eds
            .commissioning
            .as_ref()
            .is_some_and(|c| c.node_id.is_none_or(|n| n == node_id));
        let mut eds = if commissioned {
            configured(&loaded.eds)
        } else {
            match &loaded.eds.commissioning {
                Some(_) => s.warn(format!(
                    "{}: the ParameterValues are not applied: the file is not commissioned for node {node_id} ([DeviceComissioning] NodeID); the device runs on the DefaultValues",
                    path.display()
                )),
                // ParameterValues without [DeviceComissioning]: nothing says which node they
                // were written for.
                None if loaded.eds.is_dcf() => s.warn(format!(
                    "{}: the ParameterValues are not applied: the file has no [DeviceComissioning] section, so it names no node they were written for; node {node_id} runs on the DefaultValues",
                    path.display()
                )),
                None => {}
            }
            loaded.eds.clone()
        };

        if let Some(ms) = s.get::<u16>("heartbeat_ms")? {
            let Some(hb) = eds.objects.get_mut(&0x1017) else {
                return Err(s.error(
                    "heartbeat_ms",
                    format!(
                        "{} has no object 0x1017 (producer heartbeat time): the device cannot send heartbeats",
                        path.display()
                    ),
                ));
            };
            hb.entry.default_value = Some(EdsValue::Integer(i128::from(ms)));
        }
        let sdo_timeout = sdo_timeout(s)?;

        let desc = to_od(&eds).map_err(|e| {
            // Name the line of the entry that makes the dictionary impossible.
            let at = match &e {
                ConvertError::DataType { index, sub, .. } => {
                    let sections = [format!("{index:04X}"), format!("{index:04X}sub{sub:X}")];
                    loaded
                        .report
                        .errors()
                        .find(|i| {
                            sections.contains(&i.section) && i.key.as_deref() == Some("DataType")
                        })
                        .map(|i| format!(" ({i})"))
                }
                _ => None,
            };
            s.error(
                "file",
                format!(
                    "{}: not a usable object dictionary: {e}{}",
                    path.display(),
                    at.unwrap_or_default()
                ),
            )
        })?;
        // What the device does that the file's user should hear of: a PDO whose mapping
        // names an object the file lacks stays off (CiA 301 §7.5.2.36), a default outside
        // its limits is where the object starts. Said with the line `eds check` gives.
        for w in device_warnings(&eds) {
            let at = loaded
                .report
                .issues
                .iter()
                .find(|i| i.section == w.section && i.key == w.key && i.message == w.message);
            s.warn(format!("{}: {}", path.display(), at.unwrap_or(&w)));
        }
        let port = PortConfig {
            queue_depth: TX_QUEUE_DEPTH,
            ..PortConfig::default()
        };
        let desc = std::sync::Arc::new(desc);
        // A `[DummyUsage]` that supports no dummy type (every `Dummy000n=0`, CiA 306 §4.5.5)
        // refuses dummy entries in RPDO mappings (CiA 301 §7.4.7.1); without the section
        // every dummy type is accepted.
        let dummies = eds
            .dummy_usage
            .as_ref()
            .is_none_or(|d| d.values().any(|&supported| supported));
        let obey_dummy_usage = move |mut dev: cantwin_canopen::device::Device| {
            if let Some(p) = dev.pdo_mut() {
                p.set_dummy_mapping(dummies);
            }
            dev
        };
        if lss {
            let make: super::lss::Make<cantwin_canopen::device::Device> = Box::new(move |id| {
                let config = cantwin_canopen::device::DeviceConfig {
                    sdo_timeout,
                    ..cantwin_canopen::device::DeviceConfig::new(id)
                };
                cantwin_canopen::device::Device::new(std::sync::Arc::clone(&desc), config)
                    .ok()
                    .map(obey_dummy_usage)
            });
            let node = super::lss::build(s, env, bus, node_id, make)?;
            return Ok((BoxedNode::twin(node), port));
        }
        let device = obey_dummy_usage(canopen_device(s, env, desc, node_id, sdo_timeout)?);
        Ok((BoxedNode::twin(device), port))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_names_every_key() {
        for key in ["file", "node_id", "heartbeat_ms", "sdo_timeout_ms", "lss"] {
            assert!(EdsKind.summary().contains(key), "{key}");
        }
    }

    #[test]
    fn file_is_relative_to_the_scenario_directory() {
        assert_eq!(
            resolve(Path::new("scenarios/x.toml"), "eds/a.eds"),
            PathBuf::from("scenarios/eds/a.eds")
        );
        assert_eq!(
            resolve(Path::new("x.toml"), "a.eds"),
            PathBuf::from("a.eds")
        );
        assert_eq!(
            resolve(Path::new("scenarios/x.toml"), "/abs/a.eds"),
            PathBuf::from("/abs/a.eds")
        );
    }
}
