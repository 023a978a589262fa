//! `cantwin eds` on files as users bring them: `check` prints every diagnostic with its line
//! and fails only on errors (`--strict`: on warnings too); `dcf` keeps a DCF's values and
//! invents none; `export` of a twin made from a file keeps its dummy objects and its text.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

fn corpus(name: &str) -> String {
    format!("{}/../eds/tests/corpus/{name}", env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn cia306_eds_check_reports_instead_of_refusing() {
    for name in ["sample_like.dcf", "datatypes_like.eds", "servo_like.eds"] {
        let (ok, out, err) = cantwin(&["eds", "check", &corpus(name)]);
        assert!(ok, "{name}: {out}{err}");
        assert!(out.contains(" 0 errors"), "{name}: {out}");
    }
    let (_, out, _) = cantwin(&["eds", "check", &corpus("sample_like.dcf")]);
    assert!(
        out.contains(
            "warning: line 502 [ManufacturerObjects] SupportedObjects: says 0, 1 entries are listed"
        ),
        "{out}"
    );
    // --strict makes the warnings count.
    let (ok, _, err) = cantwin(&["eds", "check", "--strict", &corpus("servo_like.eds")]);
    assert!(!ok);
    assert!(err.contains("warnings (--strict)"), "{err}");
    // An error is printed with its line, and the exit status says so.
    let (ok, out, err) = cantwin(&["eds", "check", &corpus("irregular/i10_limits.eds")]);
    assert!(!ok);
    assert!(
        out.contains("error: line 80 [2002] LowLimit: above HighLimit; the limits are ignored"),
        "{out}"
    );
    assert!(err.contains("has 1 errors"), "{err}");
}

#[test]
fn cia306_eds_dcf_keeps_parameter_values_and_invents_none() {
    let dir = temp_dir("eds-dcf-real");
    let out_file = dir.join("node.dcf");
    let (ok, _, err) = cantwin(&[
        "eds",
        "dcf",
        &corpus("irregular/i12_dcf.dcf"),
        "--node-id",
        "33",
        "-o",
        out_file.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let text = std::fs::read_to_string(&out_file).unwrap();
    let section = |name: &str| {
        let start = text.find(&format!("[{name}]\n")).unwrap();
        text[start..].split("\n\n").next().unwrap().to_owned()
    };
    assert!(section("1017").contains("ParameterValue=0x32"), "{text}");
    assert!(section("2000").contains("ParameterValue=0x5DC"), "{text}");
    let (ok, out, _) = cantwin(&["eds", "check", out_file.to_str().unwrap()]);
    assert!(ok, "{out}");
    // An INTEGER8 limited to 0..=127 without a default, and a string without one: left
    // unset, said on standard error, and the DCF passes its own check.
    let (ok, _, err) = cantwin(&[
        "eds",
        "dcf",
        &corpus("sample_like.dcf"),
        "--node-id",
        "18",
        "-o",
        out_file.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let text = std::fs::read_to_string(&out_file).unwrap();
    let section = |name: &str| {
        let start = text.find(&format!("[{name}]\n")).unwrap();
        text[start..].split("\n\n").next().unwrap().to_owned()
    };
    for index in ["2000", "3020"] {
        assert!(!section(index).contains("ParameterValue"), "{text}");
        assert!(
            err.contains(&format!(
                "note: [{index}] ParameterValue: no DefaultValue and no ParameterValue; left unset"
            )),
            "{err}"
        );
    }
    assert!(section("3021").contains("ParameterValue=0x2"), "{text}");
    let (ok, out, _) = cantwin(&["eds", "check", out_file.to_str().unwrap()]);
    assert!(ok, "{out}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn cia306_eds_export_of_a_twin_keeps_dummy_objects_and_text() {
    let dir = temp_dir("eds-export-real");
    let scenario = dir.join("s.toml");
    for (file, node) in [("servo_like.eds", 5), ("irregular/i16_utf8.eds", 6)] {
        std::fs::write(
            &scenario,
            format!(
                "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\n[[device]]\nname = \"dev\"\nkind = \"eds\"\nbus = \"can0\"\nfile = \"{}\"\nnode_id = {node}\n",
                corpus(file)
            ),
        )
        .unwrap();
        let (ok, out, err) = cantwin(&[
            "eds",
            "export",
            "--scenario",
            scenario.to_str().unwrap(),
            "--device",
            "dev",
        ]);
        assert!(ok, "{err}");
        if file == "servo_like.eds" {
            for index in ["0002", "0003", "0004", "0005", "0006", "0007"] {
                let start = out
                    .find(&format!("[{index}]\n"))
                    .unwrap_or_else(|| panic!("{index}\n{out}"));
                assert!(out[start..].contains("ObjectType=0x5"), "{out}");
            }
        } else {
            assert!(out.contains("DefaultValue=5 € pro Stück"), "{out}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A DCF's ParameterValues configure the twin that runs as the node it was commissioned
/// for; run as another node, the twin keeps the file's DefaultValues (hard-written COB-IDs
/// of the other node would move its services).
#[test]
fn cia306_dcf_values_configure_the_node_they_were_made_for() {
    let dir = temp_dir("eds-dcf-node");
    let scenario = dir.join("s.toml");
    for (node, heartbeat) in [(33, "DefaultValue=0x32"), (5, "DefaultValue=0x0")] {
        std::fs::write(
            &scenario,
            format!(
                "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\n[[device]]\nname = \"dev\"\nkind = \"eds\"\nbus = \"can0\"\nfile = \"{}\"\nnode_id = {node}\n",
                corpus("irregular/i12_dcf.dcf")
            ),
        )
        .unwrap();
        let (ok, out, err) = cantwin(&[
            "eds",
            "export",
            "--scenario",
            scenario.to_str().unwrap(),
            "--device",
            "dev",
        ]);
        assert!(ok, "{err}");
        let start = out.find("[1017]\n").unwrap();
        let section = out[start..].split("\n\n").next().unwrap();
        assert!(section.contains(heartbeat), "node {node}: {section}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn cia306_eds_export_of_the_tm3_names_its_manufacturer_and_1016_sub_0_ro() {
    let scenario = scenario_file("tm3-island.toml");
    let (ok, out, err) = cantwin(&[
        "eds",
        "export",
        "--scenario",
        &scenario,
        "--device",
        "island",
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("VendorName=Schneider Electric\n"), "{out}");
    let start = out.find("[1016sub0]\n").unwrap();
    let section = out[start..].split("\n\n").next().unwrap();
    assert!(section.contains("AccessType=ro\n"), "{section}");
}

#[test]
fn cia306_eds_export_of_the_adv200_names_its_manufacturer_and_product() {
    let scenario = scenario_file("adv200-example.toml");
    let (ok, out, err) = cantwin(&[
        "eds",
        "export",
        "--scenario",
        &scenario,
        "--device",
        "drive",
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("VendorName=Gefran\n"), "{out}");
    // Not the four bytes the expedited-only card's 0x1008 holds.
    assert!(out.contains("ProductName=ADV200 EXP-CAN/DN-ADV\n"), "{out}");
}

/// An LSS slave's EDS says so (CiA 306 §4.6.1 `LSS_Supported`, CiA 305); one that has no
/// node-ID yet has no dictionary to export, and the error says why and what to do.
#[test]
fn cia306_eds_export_of_an_lss_slave_states_lss_supported() {
    let dir = temp_dir("eds-lss");
    let scenario = dir.join("s.toml");
    let device = |node_id: &str, lss: bool| {
        format!(
            "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\n[[device]]\nname = \"dev\"\nkind = \"cia301\"\nbus = \"can0\"\nnode_id = {node_id}\nlss = {lss}\n"
        )
    };
    let export = |text: String| {
        std::fs::write(&scenario, text).unwrap();
        let s = scenario.to_str().unwrap();
        cantwin(&["eds", "export", "--scenario", s, "--device", "dev"])
    };
    let (ok, out, err) = export(device("5", true));
    assert!(ok, "{err}");
    assert!(out.contains("\nLSS_Supported=1\n"), "{out}");
    let (ok, out, err) = export(device("5", false));
    assert!(ok, "{err}");
    assert!(out.contains("\nLSS_Supported=0\n"), "{out}");
    let (ok, _, err) = export(device("\"unconfigured\"", true));
    assert!(!ok);
    assert!(
        err.contains("has no node-ID yet and waits for an LSS master"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The exported EDS gives a communication parameter the twin sets at every reset
/// communication its power-on value as default (CiA 306 §4.6.3): `heartbeat_ms = 100` is
/// 0x1017's default, where the shared description says 0; COB-IDs keep their `$NODEID` form.
#[test]
fn cia306_eds_export_states_the_twins_power_on_values() {
    let scenario = scenario_file("cia301-device.toml");
    let (ok, out, err) = cantwin(&[
        "eds",
        "export",
        "--scenario",
        &scenario,
        "--device",
        "node5",
    ]);
    assert!(ok, "{err}");
    let section = |name: &str| {
        let start = out
            .find(&format!("[{name}]\n"))
            .unwrap_or_else(|| panic!("{name}\n{out}"));
        out[start..].split("\n\n").next().unwrap().to_string()
    };
    let heartbeat = section("1017");
    assert!(
        heartbeat.contains("DefaultValue=100\n") || heartbeat.contains("DefaultValue=0x64\n"),
        "{heartbeat}"
    );
    assert!(
        section("1800sub1").contains("$NODEID"),
        "{}",
        section("1800sub1")
    );
}
