//! The `eds` device kind: a CiA 301 device whose dictionary is an EDS/DCF file (CiA 306).
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};

use cantwin_bus::{PortId, Recorder, TapId};
use cantwin_can::{Duration, Frame, Id, Instant};
use cantwin_scenario::{BuildEnv, Built, Registry, Scenario};

fn scenarios() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios")
}

/// A built scenario with a recorder on its bus; `listener` sends the test's frames.
struct Rig {
    built: Built,
    tap: TapId,
    peer: PortId,
    dev: PortId,
}

impl Rig {
    fn load(path: &Path, dev: &str) -> Rig {
        let mut built = Scenario::load(path)
            .unwrap()
            .build(&Registry::builtin(), &BuildEnv::default())
            .unwrap();
        let bus = built.bus("can0").unwrap();
        let tap = built.sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
        let peer = built.device("listener").unwrap().port;
        let dev = built.device(dev).unwrap().port;
        Rig {
            built,
            tap,
            peer,
            dev,
        }
    }

    fn send(&mut self, id: u16, data: &[u8]) {
        self.built
            .sim
            .transmit(self.peer, Frame::std(id, data).unwrap())
            .unwrap();
        self.built.sim.run_for(Duration::from_millis(10));
    }

    /// Every frame the device sent: (id, data, start of frame).
    fn device_frames(&self) -> Vec<(u16, Vec<u8>, Instant)> {
        let bus = self.built.bus("can0").unwrap();
        self.built
            .sim
            .bus(bus)
            .unwrap()
            .tap::<Recorder>(self.tap)
            .unwrap()
            .frames()
            .filter(|f| f.sender == self.dev)
            .map(|f| {
                let Id::Standard(id) = f.frame.id() else {
                    panic!("extended frame from the device");
                };
                (id.as_raw(), f.frame.data_bytes().to_vec(), f.start)
            })
            .collect()
    }

    /// The data of the last SDO response (0x580 + `node`).
    fn sdo_response(&self, node: u16) -> Vec<u8> {
        self.device_frames()
            .into_iter()
            .filter(|(id, _, _)| *id == 0x580 + node)
            .map(|(_, d, _)| d)
            .next_back()
            .unwrap()
    }

    fn read_object(&self, name: &str, index: u16, sub: u8) -> Option<Vec<u8>> {
        let port = self.built.device(name).unwrap().port;
        self.built.sim.twin(port)?.read_object(index, sub).ok()
    }
}

/// A fresh directory for files a test writes.
fn temp_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("cantwin-eds-kind-{}-{test}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A scenario with one `eds` device (`keys` added) and a listener, written next to files.
fn scenario_in(dir: &Path, keys: &str) -> PathBuf {
    let text = format!(
        "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\n\
         [[device]]\nname = \"dev\"\nkind = \"eds\"\nbus = \"can0\"\n{keys}\n\n\
         [[device]]\nname = \"listener\"\nkind = \"generator\"\nbus = \"can0\"\nid = 0x7FF\nperiod_ms = 1000\ncount = 0\n"
    );
    let path = dir.join("s.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn build_error(path: &Path) -> String {
    match Scenario::load(path)
        .unwrap()
        .build(&Registry::builtin(), &BuildEnv::default())
    {
        Ok(_) => panic!("{} was accepted", path.display()),
        Err(e) => e.to_string(),
    }
}

/// CiA 301 §7.2.8.3.2.1 boot-up, then SDO expedited uploads (§7.2.4.3.4) answering with the
/// EDS's `DefaultValue`s, `$NODEID` resolved.
#[test]
fn cia306_example_eds_boots_and_answers_sdo_with_its_defaults() {
    let mut rig = Rig::load(&scenarios().join("eds-device.toml"), "io6");
    rig.built.sim.run_for(Duration::from_millis(10));
    let frames = rig.device_frames();
    assert_eq!(frames[0], (0x706, vec![0], Instant::from_nanos(0)));

    // 0x2000 "Filter time", UNSIGNED16 default 0x0BB8.
    rig.send(0x606, &[0x40, 0x00, 0x20, 0x00, 0, 0, 0, 0]);
    assert_eq!(
        rig.sdo_response(6),
        [0x4B, 0x00, 0x20, 0x00, 0xB8, 0x0B, 0, 0]
    );
    // 0x1200 sub 2: $NODEID+0x580.
    rig.send(0x606, &[0x40, 0x00, 0x12, 0x02, 0, 0, 0, 0]);
    assert_eq!(
        rig.sdo_response(6),
        [0x43, 0x00, 0x12, 0x02, 0x86, 0x05, 0, 0]
    );
    // An object the EDS does not define: abort 0x06020000.
    rig.send(0x606, &[0x40, 0x34, 0x12, 0x00, 0, 0, 0, 0]);
    assert_eq!(
        rig.sdo_response(6),
        [0x80, 0x34, 0x12, 0x00, 0x00, 0x00, 0x02, 0x06]
    );
    assert_eq!(
        rig.read_object("io6", 0x1018, 2),
        Some(vec![0x06, 0x03, 0, 0])
    );
    // heartbeat_ms overrides the EDS's 0x1017 default of 0.
    assert_eq!(rig.read_object("io6", 0x1017, 0), Some(vec![0xF4, 0x01]));
}

/// CiA 301 §7.2.2: after NMT start, TPDO1 (0x180 + node-ID, event-driven type 254) carries
/// 0x6000 sub 1 and 0x2000 as 0x1A00 maps them, every 100 ms of event timer (0x1800 sub 5).
#[test]
fn cia306_example_eds_sends_tpdo1_as_mapped_every_event_timer() {
    let mut rig = Rig::load(&scenarios().join("eds-device.toml"), "io6");
    rig.built.sim.run_for(Duration::from_millis(10));
    rig.send(0x000, &[0x01, 0x06]);
    rig.built.sim.run_for(Duration::from_millis(400));
    let tpdos: Vec<(Vec<u8>, Instant)> = rig
        .device_frames()
        .into_iter()
        .filter(|(id, _, _)| *id == 0x186)
        .map(|(_, d, t)| (d, t))
        .collect();
    assert!(tpdos.len() >= 4, "{tpdos:?}");
    for (data, _) in &tpdos {
        assert_eq!(data, &[0xA5, 0xB8, 0x0B]);
    }
    let starts: Vec<u64> = tpdos.iter().map(|(_, t)| t.as_nanos()).collect();
    // The NMT frame sent at 10 ms is received at 10.132 ms (its end of frame at 500 kbit/s):
    // the device enters Operational and sends TPDO1 at once, after the 3-bit intermission
    // (6 µs); the event timer runs from the transition, so the next ones are 100 ms apart
    // from 10.132 ms.
    assert_eq!(
        starts,
        [
            10_138_000,
            110_132_000,
            210_132_000,
            310_132_000,
            410_132_000
        ]
    );
}

/// CiA 306 DCF: `ParameterValue`s are the device's configured values and
/// `[DeviceComissioning] NodeID` its node-ID when the scenario gives none.
#[test]
fn cia306_dcf_parameter_values_and_node_id_are_applied() {
    let dir = temp_dir("dcf");
    let eds = std::fs::read_to_string(scenarios().join("eds/example-io.eds")).unwrap();
    let dcf = eds
        .replace(
            "DefaultValue=0x0BB8\n",
            "DefaultValue=0x0BB8\nParameterValue=250\n",
        )
        .replace(
            "[FileInfo]\n",
            "[DeviceComissioning]\nNodeID=9\nNodeName=io9\nBaudrate=500\n\n[FileInfo]\n",
        );
    assert_ne!(dcf, eds);
    std::fs::write(dir.join("io9.dcf"), dcf).unwrap();
    let path = scenario_in(&dir, "file = \"io9.dcf\"");
    let mut rig = Rig::load(&path, "dev");
    rig.built.sim.run_for(Duration::from_millis(10));
    assert_eq!(rig.device_frames()[0].0, 0x709);
    rig.send(0x609, &[0x40, 0x00, 0x20, 0x00, 0, 0, 0, 0]);
    assert_eq!(rig.sdo_response(9), [0x4B, 0x00, 0x20, 0x00, 250, 0, 0, 0]);
    // Reset node comes back to the configured value, not the EDS default.
    rig.send(0x609, &[0x2B, 0x00, 0x20, 0x00, 7, 0, 0, 0]);
    assert_eq!(rig.read_object("dev", 0x2000, 0), Some(vec![7, 0]));
    rig.send(0x000, &[0x81, 9]);
    assert_eq!(rig.read_object("dev", 0x2000, 0), Some(vec![250, 0]));
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn malformed_eds_is_reported_with_its_line() {
    let dir = temp_dir("malformed");
    // An unreadable access type is read past (held read-only); an entry without a data type
    // makes the dictionary impossible and is named with its line.
    std::fs::write(
        dir.join("bad.eds"),
        "[1000]\nParameterName=Device type\nDataType=0x0007\nAccessType=rx\n\n[2000]\nParameterName=x\nAccessType=rw\n",
    )
    .unwrap();
    let e = build_error(&scenario_in(&dir, "file = \"bad.eds\"\nnode_id = 3"));
    assert!(e.contains("file"), "{e}");
    assert!(e.contains("line 6 [2000] DataType"), "{e}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn missing_file_node_id_and_heartbeat_object_are_reported_by_key() {
    let dir = temp_dir("keys");
    let e = build_error(&scenario_in(&dir, "node_id = 3"));
    assert!(e.contains("needs `file`"), "{e}");
    let e = build_error(&scenario_in(&dir, "file = \"absent.eds\"\nnode_id = 3"));
    assert!(e.contains(".file") && e.contains("absent.eds"), "{e}");
    std::fs::write(
        dir.join("min.eds"),
        "[1000]\nParameterName=Device type\nObjectType=0x7\nDataType=0x0007\nAccessType=ro\nDefaultValue=0\n",
    )
    .unwrap();
    let e = build_error(&scenario_in(&dir, "file = \"min.eds\""));
    assert!(e.contains(".node_id") && e.contains("NodeID"), "{e}");
    let e = build_error(&scenario_in(&dir, "file = \"min.eds\"\nnode_id = 128"));
    assert!(e.contains("1–127"), "{e}");
    let e = build_error(&scenario_in(
        &dir,
        "file = \"min.eds\"\nnode_id = 3\nheartbeat_ms = 100",
    ));
    assert!(e.contains(".heartbeat_ms") && e.contains("0x1017"), "{e}");
    // Without 0x1200 the device still answers on the default SDO connection.
    let mut rig = Rig::load(&scenario_in(&dir, "file = \"min.eds\"\nnode_id = 3"), "dev");
    rig.built.sim.run_for(Duration::from_millis(10));
    rig.send(0x603, &[0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]);
    assert_eq!(rig.sdo_response(3), [0x43, 0x00, 0x10, 0x00, 0, 0, 0, 0]);
    let _ = std::fs::remove_dir_all(dir);
}

/// CiA 306 DCF: ParameterValues in a file without `[DeviceComissioning]` are not applied, and
/// the warning says that no section names their node (not that the file was commissioned
/// for another one); an EDS without ParameterValues draws no warning.
#[test]
fn parameter_values_without_device_comissioning_are_reported_as_such() {
    let dir = temp_dir("nocomm");
    let eds = std::fs::read_to_string(scenarios().join("eds/example-io.eds")).unwrap();
    let dcf = eds.replace(
        "DefaultValue=0x0BB8\n",
        "DefaultValue=0x0BB8\nParameterValue=250\n",
    );
    assert_ne!(dcf, eds);
    std::fs::write(dir.join("io.dcf"), dcf).unwrap();
    std::fs::write(dir.join("io.eds"), &eds).unwrap();
    let warnings = |file: &str| {
        let path = scenario_in(&dir, &format!("file = \"{file}\"\nnode_id = 9"));
        Scenario::load(&path)
            .unwrap()
            .build(&Registry::builtin(), &BuildEnv::default())
            .unwrap()
            .warnings
    };
    let w = warnings("io.dcf");
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(w[0].contains("no [DeviceComissioning] section"), "{w:?}");
    assert!(!w[0].contains("not commissioned for node"), "{w:?}");
    assert!(warnings("io.eds").is_empty());
    let _ = std::fs::remove_dir_all(dir);
}

/// `[DummyUsage]` with every `Dummy000n=0` supports no dummy type (CiA 306 §4.5.5): a dummy
/// entry in an RPDO mapping is refused with 0x06040041 (CiA 301 §7.4.7.1); with
/// `Dummy0005=1` the UNSIGNED8 dummy is accepted.
#[test]
fn cia306_dummy_usage_that_supports_no_dummy_refuses_dummy_mapping() {
    let text = std::fs::read_to_string(scenarios().join("eds/example-io.eds")).unwrap();
    assert!(text.contains("[DummyUsage]\nDummy0001=0\n"));
    assert!(text.contains("Dummy0005=0\n"));
    let dir = temp_dir("dummy-usage");
    for (dummy0005, answer) in [
        (0, vec![0x80, 0x00, 0x16, 0x01, 0x41, 0x00, 0x04, 0x06]),
        (1, vec![0x60, 0x00, 0x16, 0x01, 0, 0, 0, 0]),
    ] {
        let file = dir.join("io.eds");
        std::fs::write(
            &file,
            text.replace("Dummy0005=0\n", &format!("Dummy0005={dummy0005}\n")),
        )
        .unwrap();
        let path = scenario_in(&dir, &format!("file = \"{}\"\nnode_id = 6", file.display()));
        let mut rig = Rig::load(&path, "dev");
        // The mapping procedure (CiA 301 §7.5.2.36): RPDO1 invalid, no entries, then the
        // dummy entry 0x0005 (UNSIGNED8), 8 bits.
        rig.send(0x606, &[0x23, 0x00, 0x14, 0x01, 0x06, 0x02, 0x00, 0x80]);
        assert_eq!(rig.sdo_response(6)[0], 0x60);
        rig.send(0x606, &[0x2F, 0x00, 0x16, 0x00, 0, 0, 0, 0]);
        assert_eq!(rig.sdo_response(6)[0], 0x60);
        rig.send(0x606, &[0x23, 0x00, 0x16, 0x01, 0x08, 0x00, 0x05, 0x00]);
        assert_eq!(rig.sdo_response(6), answer, "Dummy0005={dummy0005}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

fn corpus(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../eds/tests/corpus")
        .join(name)
}

/// An SDO expedited download (CiA 301 §7.2.4.3.3) of `value` (`len` bytes) to node 5 and
/// its answer.
fn download(rig: &mut Rig, index: u16, sub: u8, value: u32, len: u8) -> Vec<u8> {
    let cmd = 0x23 | ((4 - len) << 2);
    let [lo, hi] = index.to_le_bytes();
    let v = value.to_le_bytes();
    rig.send(0x605, &[cmd, lo, hi, sub, v[0], v[1], v[2], v[3]]);
    rig.sdo_response(5)
}

fn abort(index: u16, sub: u8, code: u32) -> Vec<u8> {
    let [lo, hi] = index.to_le_bytes();
    let c = code.to_le_bytes();
    vec![0x80, lo, hi, sub, c[0], c[1], c[2], c[3]]
}

/// A file shaped like python-canopen's `test/sample.eds`, whose TPDO 2 maps 0x6041, which
/// it does not define: that PDO stays off, said at build, and its COB-ID, still valid,
/// cannot be changed (CiA 301 §7.5.2.37); a transmission type of 245 is refused on any PDO
/// (0x06090030); TPDO 1 and RPDO 1 run.
#[test]
fn cia301_a_pdo_mapping_an_object_the_file_lacks_stays_off_and_the_others_run() {
    let dir = temp_dir("pdo-missing");
    let path = scenario_in(
        &dir,
        &format!(
            "file = \"{}\"\nnode_id = 5",
            corpus("pdo_missing_object.eds").display()
        ),
    );
    let warnings = build_warnings(&path);
    assert!(
        warnings.iter().any(|w| w.contains(
            "warning: line 289 [1A01sub1] DefaultValue: TPDO 2 maps 0x6041, which the file does not define: the PDO is off"
        )),
        "{warnings:?}"
    );
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    let mut rig = Rig::load(&path, "dev");
    rig.built.sim.run_for(Duration::from_millis(10));
    assert_eq!(
        download(&mut rig, 0x1800, 2, 245, 1),
        abort(0x1800, 2, 0x0609_0030)
    );
    assert_eq!(
        download(&mut rig, 0x1801, 1, 0x305, 4),
        abort(0x1801, 1, 0x0609_0030)
    );
    // The mapping of a PDO whose COB-ID is valid cannot be changed (§7.5.2.38), and, once
    // invalid, the PDO cannot be made valid again with the mapping it has.
    assert_eq!(
        download(&mut rig, 0x1A01, 0, 0, 1),
        abort(0x1A01, 0, 0x0601_0000)
    );
    assert_eq!(download(&mut rig, 0x1801, 1, 0x8000_0285, 4)[0], 0x60);
    assert_eq!(
        download(&mut rig, 0x1801, 1, 0x285, 4),
        abort(0x1801, 1, 0x0604_0043)
    );
    // OPERATIONAL: TPDO 1 sends 0x2000 (event-driven, once on entering), TPDO 2 nothing;
    // RPDO 1 writes 0x2001.
    rig.send(0x000, &[0x01, 5]);
    rig.send(0x205, &[0x77]);
    let frames = rig.device_frames();
    assert!(
        frames.iter().any(|(id, d, _)| *id == 0x185 && d == &[0x5A]),
        "{frames:?}"
    );
    assert!(!frames.iter().any(|(id, _, _)| *id == 0x285), "{frames:?}");
    assert_eq!(rig.read_object("dev", 0x2001, 0), Some(vec![0x77]));
    let _ = std::fs::remove_dir_all(dir);
}

/// A DefaultValue outside the file's limits is where the object starts, as the file says,
/// with a build warning; a download of that value is refused (CiA 301 §7.2.4.3.17).
#[test]
fn cia306_a_default_outside_the_limits_is_kept_and_said() {
    let dir = temp_dir("default-outside");
    let text = std::fs::read_to_string(corpus("pdo_missing_object.eds"))
        .unwrap()
        .replace(
            "ParameterName=Outputs\nObjectType=7\nDataType=5\nAccessType=rw\nPDOMapping=1\nDefaultValue=0\n",
            "ParameterName=Outputs\nObjectType=7\nDataType=5\nAccessType=rw\nPDOMapping=1\nDefaultValue=0\nLowLimit=1\nHighLimit=9\n",
        );
    assert!(text.contains("LowLimit=1\nHighLimit=9\n"));
    std::fs::write(dir.join("d.eds"), text).unwrap();
    let path = scenario_in(&dir, "file = \"d.eds\"\nnode_id = 5");
    let warnings = build_warnings(&path);
    assert!(
        warnings.iter().any(|w| w.contains(
            "[2001] DefaultValue: 0 is below LowLimit 1; the device starts at 0, as the file says"
        )),
        "{warnings:?}"
    );
    let mut rig = Rig::load(&path, "dev");
    assert_eq!(rig.read_object("dev", 0x2001, 0), Some(vec![0]));
    assert_eq!(
        download(&mut rig, 0x2001, 0, 0, 1),
        abort(0x2001, 0, 0x0609_0032)
    );
    assert_eq!(download(&mut rig, 0x2001, 0, 9, 1)[0], 0x60);
    let _ = std::fs::remove_dir_all(dir);
}

/// The warnings the scenario at `path` builds with.
fn build_warnings(path: &std::path::Path) -> Vec<String> {
    Scenario::load(path)
        .unwrap()
        .build(&Registry::builtin(), &BuildEnv::default())
        .unwrap()
        .warnings
}
