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
    // Limits upside down are a warning (taken swapped), printed with its line; the file
    // passes.
    let (ok, out, err) = cantwin(&["eds", "check", &corpus("irregular/i10_limits.eds")]);
    assert!(ok, "{out}{err}");
    assert!(
        out.contains(
            "warning: line 80 [2002] LowLimit: 100 is above HighLimit 1; the limits are taken swapped (1..=100)"
        ),
        "{out}"
    );
    assert!(out.contains(" 0 errors, 1 warnings"), "{out}");
}

/// A PDO whose default mapping names an object the file lacks is a warning of `eds check`
/// at the entry's line; the diagnostics come in the order of their lines.
#[test]
fn cia306_eds_check_says_which_pdo_is_off() {
    let (ok, out, err) = cantwin(&["eds", "check", &corpus("pdo_missing_object.eds")]);
    assert!(ok, "{out}{err}");
    assert!(
        out.contains(
            "warning: line 289 [1A01sub1] DefaultValue: TPDO 2 maps 0x6041, which the file does not define: the PDO is off"
        ),
        "{out}"
    );
    let (_, out, _) = cantwin(&["eds", "check", &corpus("sample_like.dcf")]);
    let lines: Vec<usize> = out
        .lines()
        .filter_map(|l| l.split(" line ").nth(1)?.split(' ').next()?.parse().ok())
        .collect();
    assert!(lines.len() > 2, "{out}");
    assert!(lines.windows(2).all(|w| w[0] <= w[1]), "{out}");
}

/// A DCF made for node 7 and made again for node 9: the COB-IDs that are node 7's
/// `$NODEID` defaults are written for node 9 (with a note); one the integrator set is kept,
/// with a warning that it is node-specific.
#[test]
fn cia306_eds_dcf_for_another_node_moves_the_node_based_values() {
    let dir = temp_dir("eds-dcf-renode");
    let n7 = dir.join("n7.dcf");
    let n9 = dir.join("n9.dcf");
    let (ok, _, err) = cantwin(&[
        "eds",
        "dcf",
        &corpus("pdo_missing_object.eds"),
        "--node-id",
        "7",
        "--set",
        "0x1400:1=0x80000301",
        "-o",
        n7.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let section = |text: &str, name: &str| {
        let start = text.find(&format!("[{name}]\n")).unwrap();
        text[start..].split("\n\n").next().unwrap().to_owned()
    };
    let t7 = std::fs::read_to_string(&n7).unwrap();
    assert!(
        section(&t7, "1800sub1").contains("ParameterValue=0x187"),
        "{t7}"
    );
    let (ok, _, err) = cantwin(&[
        "eds",
        "dcf",
        n7.to_str().unwrap(),
        "--node-id",
        "9",
        "-o",
        n9.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let t9 = std::fs::read_to_string(&n9).unwrap();
    assert!(
        section(&t9, "DeviceComissioning").contains("NodeID=9"),
        "{t9}"
    );
    assert!(
        section(&t9, "1800sub1").contains("ParameterValue=0x189"),
        "{t9}"
    );
    assert!(
        section(&t9, "1801sub1").contains("ParameterValue=0x289"),
        "{t9}"
    );
    assert!(
        err.contains(
            "note: [1800sub1] ParameterValue: 0x187 is the DefaultValue $NODEID+0x180 of node 7; written for node 9 (0x189)"
        ),
        "{err}"
    );
    assert!(
        section(&t9, "1400sub1").contains("ParameterValue=0x80000301"),
        "{t9}"
    );
    assert!(
        err.contains(
            "warning: [1400sub1] ParameterValue: 0x80000301 is kept, but it is node-specific"
        ),
        "{err}"
    );
    // Made again for the node it is for, nothing moves and nothing is said.
    let (ok, _, err) = cantwin(&["eds", "dcf", n9.to_str().unwrap(), "--node-id", "9"]);
    assert!(ok, "{err}");
    assert!(
        !err.contains("[1800sub1]") && !err.contains("[1400sub1]"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A DefaultValue outside the file's limits is not made a ParameterValue (the node could
/// not take it): the DCF is written without one, with a warning that says what to do; an
/// empty DefaultValue is said to be empty.
#[test]
fn cia306_eds_dcf_leaves_a_default_outside_the_limits_unset() {
    let dir = temp_dir("eds-dcf-limits");
    let eds = dir.join("d.eds");
    let text = std::fs::read_to_string(corpus("pdo_missing_object.eds"))
        .unwrap()
        .replace(
            "ParameterName=Outputs\nObjectType=7\nDataType=5\nAccessType=rw\nPDOMapping=1\nDefaultValue=0\n",
            "ParameterName=Outputs\nObjectType=7\nDataType=5\nAccessType=rw\nPDOMapping=1\nDefaultValue=0\nLowLimit=1\nHighLimit=9\n",
        )
        .replace(
            "ParameterName=Inputs\nObjectType=7\nDataType=5\nAccessType=ro\nPDOMapping=1\nDefaultValue=0x5A\n",
            "ParameterName=Inputs\nObjectType=7\nDataType=5\nAccessType=ro\nPDOMapping=1\nDefaultValue=\n",
        );
    assert!(text.contains("LowLimit=1\nHighLimit=9\n") && text.contains("DefaultValue=\n"));
    std::fs::write(&eds, text).unwrap();
    let out_file = dir.join("d.dcf");
    let (ok, _, err) = cantwin(&[
        "eds",
        "dcf",
        eds.to_str().unwrap(),
        "--node-id",
        "5",
        "-o",
        out_file.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(
        err.contains(
            "warning: [2001] ParameterValue: the DefaultValue 0 is below LowLimit 1 (limits 1..=9), which the node cannot take; left unset: give the node's value with --set 0x2001:0=VALUE"
        ),
        "{err}"
    );
    assert!(
        err.contains(
            "note: [2000] ParameterValue: the DefaultValue is empty and there is no ParameterValue; left unset"
        ),
        "{err}"
    );
    let dcf = std::fs::read_to_string(&out_file).unwrap();
    let start = dcf.find("[2001]\n").unwrap();
    let section = dcf[start..].split("\n\n").next().unwrap();
    assert!(!section.contains("ParameterValue"), "{dcf}");
    // With the value given, the DCF has it.
    let (ok, out, err) = cantwin(&[
        "eds",
        "dcf",
        eds.to_str().unwrap(),
        "--node-id",
        "5",
        "--set",
        "0x2001:0=3",
    ]);
    assert!(ok, "{err}");
    let start = out.find("[2001]\n").unwrap();
    assert!(
        out[start..]
            .split("\n\n")
            .next()
            .unwrap()
            .contains("ParameterValue=0x3"),
        "{out}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
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
