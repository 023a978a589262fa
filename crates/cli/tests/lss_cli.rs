//! `cantwin lss` against `cantwin sim` running `scenarios/lss-commissioning.toml`: a node
//! without node-ID selected by its LSS address, given node-ID 7 and stored; it then answers
//! SDO as node 7. (Fastscan, a few hundred answer times long, is tested in virtual time.)
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

#[test]
fn cia305_cantwin_lss_commissions_a_node_selected_by_its_address() {
    let (_sim, addr) = sim_with_socketcand(&scenario_file("lss-commissioning.toml"), "300");
    let lss = |args: &[&str]| {
        let mut all = vec!["lss", "--socketcand", &addr];
        all.extend_from_slice(args);
        let (ok, out, err) = cantwin(&all);
        assert!(ok, "cantwin lss {args:?}: {err}");
        out.trim().to_string()
    };
    assert_eq!(
        lss(&["--timeout", "300", "identify", "non-configured"]),
        "1 node(s) answered"
    );
    assert_eq!(
        lss(&["switch", "selective", "0xCA7", "305", "0x10000", "0x30"]),
        "OK: vendor 0x00000CA7 product 0x00000131 revision 0x00010000 serial 0x00000030 is in LSS configuration"
    );
    assert_eq!(lss(&["inquire", "node-id"]), "0xFF (no node-ID)");
    assert_eq!(lss(&["inquire", "serial"]), "0x00000030");
    assert_eq!(lss(&["--json", "inquire", "node-id"]), r#"{"node_id":255}"#);
    let (ok, _, err) = cantwin(&["lss", "--socketcand", &addr, "conf-bitrate", "100k"]);
    assert!(
        !ok && err.contains("no entry in the CiA 301 bit timing table"),
        "{err}"
    );
    assert!(lss(&["set-node", "7"]).starts_with("OK: node-ID 7 pending"));
    assert_eq!(
        lss(&["conf-bitrate", "500k"]),
        "OK: 500k pending (table index 2)"
    );
    assert_eq!(lss(&["store"]), "OK: stored");
    assert_eq!(lss(&["switch", "global", "waiting"]), "OK");
    let (ok, out, err) = cantwin(&[
        "sdo",
        "--socketcand",
        &addr,
        "read",
        "7",
        "0x1018",
        "4",
        "u32",
    ]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "48 (0x00000030)");
    assert_eq!(
        lss(&["--timeout", "300", "identify", "non-configured"]),
        "0 node(s) answered"
    );
}

/// `commission --fastscan`: the node without node-ID is found bit by bit (50 ms per step,
/// about 7 s), given node-ID 9, stored, and boots.
#[test]
fn cia305_cantwin_lss_commissions_the_node_found_by_fastscan() {
    let (_sim, addr) = sim_with_socketcand(&scenario_file("lss-commissioning.toml"), "300");
    let (ok, out, err) = cantwin(&[
        "lss",
        "--socketcand",
        &addr,
        "--timeout",
        "50",
        "commission",
        "9",
        "--fastscan",
    ]);
    assert!(ok, "{err}");
    assert_eq!(
        out.trim(),
        "OK: vendor 0x00000CA7 product 0x00000131 revision 0x00010000 serial 0x00000030 has node-ID 9"
    );
    let (ok, out, err) = cantwin(&[
        "sdo",
        "--socketcand",
        &addr,
        "read",
        "9",
        "0x1018",
        "4",
        "u32",
    ]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "48 (0x00000030)");
}

#[test]
fn every_lss_command_has_help_with_examples() {
    for cmd in [
        &["lss", "--help"][..],
        &["lss", "switch", "global", "--help"],
        &["lss", "switch", "selective", "--help"],
        &["lss", "set-node", "--help"],
        &["lss", "conf-bitrate", "--help"],
        &["lss", "activate-bitrate", "--help"],
        &["lss", "store", "--help"],
        &["lss", "inquire", "--help"],
        &["lss", "identify", "remote", "--help"],
        &["lss", "identify", "non-configured", "--help"],
        &["lss", "fastscan", "--help"],
        &["lss", "commission", "--help"],
    ] {
        let (ok, out, _) = cantwin(cmd);
        assert!(ok, "{cmd:?}");
        assert!(out.contains("Examples:"), "{cmd:?}: {out}");
    }
    let (ok, _, err) = cantwin(&["lss", "--scenario", "x.toml", "set-node", "128"]);
    assert!(!ok && err.contains("1–127, or 255"), "{err}");
}
