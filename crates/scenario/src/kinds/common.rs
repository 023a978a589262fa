//! Settings and device set-up shared by the CANopen kinds (`cia301`, `eds`), and test
//! helpers shared by the kinds' unit tests.

use std::sync::Arc;

use cantwin_can::Duration;
use cantwin_canopen::device::{Device, DeviceConfig};
use cantwin_canopen::od::OdDescription;
use cantwin_canopen::storage::FileStorage;

use crate::error::ScenarioError;
use crate::registry::{BuildEnv, Settings};

/// Refuses a `node_id` outside 1–127, the CANopen node-ID range (CiA 301 §7.3.2.1).
pub(crate) fn check_node_id(s: &Settings<'_>, node_id: u8) -> Result<(), ScenarioError> {
    if !(1..=127).contains(&node_id) {
        return Err(s.error(
            "node_id",
            format!("`node_id` is 1–127 (CiA 301 §7.3.2.1), not {node_id}"),
        ));
    }
    Ok(())
}

/// The `sdo_timeout_ms` key (default 1000 ms, never 0): how long the SDO server waits for
/// the client before it aborts the transfer with 0x0504 0000 (SDO protocol timed out).
pub(crate) fn sdo_timeout(s: &Settings<'_>) -> Result<Duration, ScenarioError> {
    let ms: u64 = s.get_or("sdo_timeout_ms", 1000)?;
    if ms == 0 {
        return Err(s.error("sdo_timeout_ms", "`sdo_timeout_ms` must be greater than 0"));
    }
    Ok(Duration::from_millis(ms))
}

/// A CiA 301 device with node-ID `node_id` over `desc`, whose stored parameters (0x1010)
/// live under the scenario's state directory, one folder per device name, when there is one.
pub(crate) fn canopen_device(
    s: &Settings<'_>,
    env: &BuildEnv,
    desc: Arc<OdDescription>,
    node_id: u8,
    sdo_timeout: Duration,
) -> Result<Device, ScenarioError> {
    let config = DeviceConfig {
        sdo_timeout,
        ..DeviceConfig::new(node_id)
    };
    let mut device = Device::new(desc, config).map_err(|e| s.error("node_id", e.to_string()))?;
    if let Some(storage) = parameter_file(s, env)? {
        device.set_storage(Box::new(storage));
    }
    Ok(device)
}

/// What the device called `s` stores, in its own folder of the scenario's state directory
/// (`STATE_DIR/<device name>/`), opened with `open`; `None` without a state directory.
/// `what` names it in the error when the folder cannot be used.
pub(crate) fn in_state_dir<T, E: std::fmt::Display>(
    s: &Settings<'_>,
    env: &BuildEnv,
    what: &str,
    open: impl FnOnce(std::path::PathBuf) -> Result<T, E>,
) -> Result<Option<T>, ScenarioError> {
    let Some(dir) = &env.state_dir else {
        return Ok(None);
    };
    let dir = dir.join(&s.device().name);
    open(dir.clone()).map(Some).map_err(|e| {
        s.error(
            "name",
            format!("cannot keep {what} in {}: {e}", dir.display()),
        )
    })
}

/// The CiA 301 parameter storage (0x1010/0x1011) of the device called `s` under the state
/// directory, if there is one. CiA 301 §7.5.2.10: the device runs on its defaults for a
/// group it cannot load and raises EMCY 0x5000; the user learns which file and why before
/// it runs.
pub(crate) fn parameter_file(
    s: &Settings<'_>,
    env: &BuildEnv,
) -> Result<Option<FileStorage>, ScenarioError> {
    let storage = in_state_dir(s, env, "stored parameters", FileStorage::new)?;
    for problem in storage.iter().flat_map(FileStorage::check) {
        s.warn(format!(
            "{problem}; the device starts on its defaults and raises EMCY 0x5000"
        ));
    }
    Ok(storage)
}

/// Replaces `path` with `bytes` atomically: a temporary file beside it, fsync, rename,
/// fsync of the directory, so that a crash leaves the old contents or the new, never a
/// torn file (the project's rule for stored state).
pub(crate) fn replace_file(path: &std::path::Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    let dir = path.parent().unwrap_or(std::path::Path::new("."));
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".tmp");
    let tmp = dir.join(name);
    {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)?;
    #[cfg(unix)]
    std::fs::File::open(dir)?.sync_all()?;
    Ok(())
}

/// Helpers for the kinds' unit tests.
#[cfg(test)]
pub(crate) mod testing {
    use cantwin_bus::{BusId, PortId, Recorder, TapId};
    use cantwin_can::Frame;
    use cantwin_twin::SignalValue;

    use crate::build::Built;
    use crate::error::ScenarioError;
    use crate::{Registry, Scenario};

    /// The scenario `text` built with the built-in kinds and no state directory; the text
    /// itself must parse.
    pub(crate) fn try_build(text: &str) -> Result<Built, ScenarioError> {
        Scenario::parse(text, "t.toml")
            .unwrap()
            .build(&Registry::builtin(), &Default::default())
    }

    /// The scenario `text`, built.
    pub(crate) fn built(text: &str) -> Built {
        try_build(text).unwrap()
    }

    /// Why the scenario `text` does not build.
    pub(crate) fn build_error(text: &str) -> String {
        match try_build(text) {
            Ok(_) => panic!("built: {text}"),
            Err(e) => e.to_string(),
        }
    }

    /// The scenario file `name` shipped in the repository's `scenarios/` folder, built with
    /// the built-in kinds and no state directory.
    pub(crate) fn shipped(name: &str) -> Built {
        let path = format!("{}/../../scenarios/{name}", env!("CARGO_MANIFEST_DIR"));
        let text = std::fs::read_to_string(&path).unwrap();
        let scenario = Scenario::parse(&text, &path).unwrap();
        scenario
            .build(&Registry::builtin(), &Default::default())
            .unwrap()
    }

    /// Signal `name` of the twin on `port`, or why not as text.
    pub(crate) fn read_signal(
        built: &Built,
        port: PortId,
        name: &str,
    ) -> Result<SignalValue, String> {
        built
            .sim
            .twin(port)
            .unwrap()
            .read_signal(&name.into())
            .map_err(|e| e.to_string())
    }

    /// Sets signal `name` of the twin on `port` to `value` now, or says why not as text.
    pub(crate) fn set_signal(
        built: &mut Built,
        port: PortId,
        name: &str,
        value: SignalValue,
    ) -> Result<(), String> {
        built
            .sim
            .with_twin(port, |t, cx| t.set_signal(&name.into(), &value, cx))
            .unwrap()
            .map_err(|e| e.to_string())
    }

    /// The frames the recorder `tap` on `bus` has seen, in bus order.
    pub(crate) fn recorded(built: &Built, bus: BusId, tap: TapId) -> Vec<Frame> {
        built
            .sim
            .bus(bus)
            .unwrap()
            .tap::<Recorder>(tap)
            .unwrap()
            .frames()
            .map(|f| f.frame)
            .collect()
    }
}
