//! `cantwin gateway --ascii` commissioning the device of `scenarios/lss-commissioning.toml`
//! (no node-ID yet) with CANopenNode's LSS commands, and `os`/`hex` values, byte for byte.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

use std::io::Write;
use std::process::{Command, Stdio};

#[test]
fn cia309_3_lss_commands_commission_a_node_without_node_id() {
    let (mut sim, addr) = sim_with_socketcand(&scenario_file("lss-commissioning.toml"), "300");
    let mut gw = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args(["gateway", "--ascii", "--socketcand", &addr])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let talk = [
        // Not configured: the SDO server is silent.
        ("[1] set sdo_timeout 100", "[1] OK"),
        ("[2] 48 read 0x1018 4 u32", "[2] ERROR:0x05040000"),
        ("[3] lss_switch_glob 1", "[3] OK"),
        ("[4] lss_get_node", "[4] 0xFF"),
        (
            "[5] lss_inquire_addr",
            "[5] 0x00000CA7 0x00000131 0x00010000 0x00000030",
        ),
        ("[6] lss_inquire_addr 1", "[6] 0x00000131"),
        ("[7] lss_set_node 200", "[7] ERROR:101"),
        ("[8] lss_set_node 0", "[8] ERROR:502"),
        ("[9] lss_conf_bitrate 0 9", "[9] ERROR:503"),
        ("[10] lss_set_node 0x30", "[10] OK"),
        ("[11] lss_conf_bitrate 0 2", "[11] OK"),
        ("[12] lss_store", "[12] OK"),
        // Back to waiting: the node takes node-ID 48 and boots.
        ("[13] lss_switch_glob 0", "[13] OK"),
        ("[14] 48 read 0x1018 4 u32", "[14] 48"),
        ("[15] 48 read 0x2000 0 os", "[15] AAECAw=="),
        ("[16] 48 write 0x2000 0 os BAUG", "[16] OK"),
        ("[17] 48 read 0x2000 0 hex", "[17] 04 05 06"),
        ("[18] 48 write 0x2000 0 hex 0A0B 0c", "[18] OK"),
        ("[19] 48 read 0x2000 0", "[19] 0A 0B 0C"),
        ("", ""),
        // Nobody is left without node-ID.
        ("[20] _lss_fastscan 20", "[20] ERROR:103"),
        ("[21] lss_allnodes 20", "# Found 0 nodes, search finished."),
        ("", "[21] OK"),
        ("[22] lss_frob", "[22] ERROR:100"),
        ("lss_get_node", "[22] ERROR:101"),
    ];
    {
        let mut stdin = gw.stdin.take().unwrap();
        // An empty request of the table that only marks a second answer line is not sent;
        // the one after [19] is (an empty line gets an empty answer).
        for (i, (q, _)) in talk.iter().enumerate() {
            if q.is_empty() && i != 19 {
                continue;
            }
            writeln!(stdin, "{q}").unwrap();
        }
    }
    let out = gw.wait_with_output().unwrap();
    let _ = sim.kill();
    let _ = sim.wait();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let expected: Vec<&str> = talk.iter().map(|(_, a)| *a).collect();
    assert_eq!(lines, expected, "{text}");
}

/// `lss_allnodes` on the in-process scenario, the vendor-ID matched and the product code
/// skipped: the node without node-ID is found by fastscan (50 ms per step, about 3.5 s),
/// given node-ID 10 and stored, and the search ends when no node is left.
#[test]
fn cia309_3_lss_allnodes_gives_each_node_without_node_id_one() {
    let mut gw = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args([
            "gateway",
            "--ascii",
            "--scenario",
            &scenario_file("lss-commissioning.toml"),
        ])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    {
        let mut stdin = gw.stdin.take().unwrap();
        writeln!(stdin, "[1] lss_allnodes 50 10 1 2 0xCA7 1 0 0 0 0 0").unwrap();
        writeln!(stdin, "[2] 10 read 0x1018 4 x32").unwrap();
    }
    let out = gw.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        String::from_utf8(out.stdout).unwrap(),
        // The comment lines end with LF, the answer with CR LF (CANopenNode's gateway).
        "# Node-ID 10 assigned to: 0x00000CA7 0x00000000 0x00010000 0x00000030\n\
         # Found 1 nodes, search finished.\n[1] OK\r\n[2] 0x00000030\r\n"
    );
}
