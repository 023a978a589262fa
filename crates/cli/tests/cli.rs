//! The real `cantwin` binary, run as a user would.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

use std::process::Command;

#[test]
fn demo_runs_without_arguments_and_tells_the_story() {
    let (ok, out, err) = cantwin(&["demo"]);
    assert!(ok, "demo failed: {err}");
    // Arbitration at power-up: 0x181 beats 0x182 beats 0x701, at exact bus times (500 kbit/s:
    // 2 µs a bit; 69 stuffed bits to the end of EOF = 138 µs minus the 3 intermission bits).
    let a = out.find("0.000132000  181#0000").expect("0x181 first");
    let b = out.find("0.000268000  182#0000").expect("0x182 second");
    let c = out.find("0.000404000  701#0000").expect("0x701 third");
    assert!(a < b && b < c);
    // Injected corruption: three error frames and the retransmission.
    assert_eq!(out.matches("ERROR FRAME: bit error").count(), 3);
    assert!(out.contains("0.200688000  182#0200"));
    // Remote frames answered.
    assert!(out.contains("285#R4"));
    assert!(out.contains("the responder answered 4 remote frames"));
    // Bus-off and recovery, error-passive of the lonely node.
    assert!(out.contains("controller BUS-OFF"));
    assert!(out.contains("recovered from bus-off"));
    assert!(out.contains("lonely     controller error-passive (TEC 128)"));
    // CANopen: boot-up, NMT, SDO with an abort and its meaning, SYNC and TPDOs, EMCY,
    // heartbeat loss and a new boot-up.
    assert!(
        out.contains("705#00                 BOOT-UP node 5"),
        "{out}"
    );
    assert!(
        out.contains("\"cantwin generic CiA 301 device\" (30 bytes"),
        "{out}"
    );
    assert!(out.contains("0x2002sub0: 0x06090031"), "{out}");
    assert!(
        out.contains("EMCY node 5 code 0x5000 (device hardware)"),
        "{out}"
    );
    assert!(out.contains("heartbeat of node 5 lost"), "{out}");
    assert!(out.contains("node 5 booted"), "{out}");
    // The ADV200 worked example ramps to 1500 rpm.
    assert!(out.contains("0x0003   1500 rpm"), "{out}");
    // DeviceNet: the worked example's poll (4 bytes out, 6 in) runs the motor to 1500 rpm.
    assert!(out.contains("465#0301DC05"), "{out}");
    assert!(
        out.contains("input 03 00 DC 05 00 10  speed  1500 rpm"),
        "{out}"
    );
    // CiA 401 I/O: outputs by RPDO, an input change by TPDO, a module pulled out.
    assert!(
        out.contains("module 2 outputs 0..3: [true, false, true, false]"),
        "{out}"
    );
    assert!(out.contains("183#08"), "{out}");
    assert!(out.contains("EMCY from node 3: 0x7003"), "{out}");
    // CAL: the OPEN DRIVE ramps to 50 Hz and trips on overload.
    assert!(out.contains("50.00 Hz"), "{out}");
    assert!(
        out.contains("alarm notification 00 80: OVERLOAD (A2/A3)"),
        "{out}"
    );
}

#[test]
fn demo_is_deterministic() {
    let strip = |s: String| {
        s.lines()
            .filter(|l| !l.contains("of wall time"))
            .collect::<Vec<_>>()
            .join("\n")
    };
    let (_, a, _) = cantwin(&["demo", "--verbose"]);
    let (_, b, _) = cantwin(&["demo", "--verbose"]);
    assert_eq!(strip(a), strip(b));
}

#[test]
fn every_command_has_help_with_examples() {
    for cmd in [
        &["--help"][..],
        &["demo", "--help"],
        &["bench", "--help"],
        &["sim", "--help"],
        &["dump", "--help"],
        &["eds", "--help"],
        &["eds", "check", "--help"],
        &["eds", "dcf", "--help"],
        &["cal", "--help"],
        &["report", "--help"],
        &["gateway", "--help"],
        &["cal", "cmd", "--help"],
        &["cal", "param", "--help"],
        &["sdo", "read", "--help"],
        &["sdo", "write", "--help"],
        &["nmt", "--help"],
        &["scan", "--help"],
        &["trace", "--help"],
        &["monitor", "--help"],
    ] {
        let (ok, out, _) = cantwin(cmd);
        assert!(ok);
        assert!(out.contains("Examples:"), "{cmd:?}: {out}");
    }
}

#[test]
fn monitor_refuses_a_pipe_and_names_the_keys_in_its_help() {
    // Standard output is a pipe here: the monitor says so instead of drawing into it.
    let (ok, _, err) = cantwin(&[
        "monitor",
        "--scenario",
        &scenario_file("monitor-network.toml"),
    ]);
    assert!(!ok);
    assert!(err.contains("draws on a terminal"), "{err}");
    assert!(err.contains("cantwin trace"), "{err}");
    let (ok, out, _) = cantwin(&["monitor", "--help"]);
    assert!(ok);
    for key in ["q quit", "space pause", "PgUp/PgDn scroll", "/ filter"] {
        assert!(out.contains(key), "{key}: {out}");
    }
}

#[test]
fn bench_rejects_unknown_names_and_bad_durations() {
    let (ok, _, err) = cantwin(&["bench", "nosuch"]);
    assert!(!ok);
    assert!(err.contains("unknown benchmark \"nosuch\""), "{err}");
    let (ok, _, err) = cantwin(&["bench", "bus", "--seconds", "0"]);
    assert!(!ok);
    assert!(err.contains("--seconds must be a positive number"), "{err}");
    let (ok, out, err) = cantwin(&["bench", "bus", "--seconds", "0.01", "--trials", "0"]);
    assert!(!ok);
    assert!(err.contains("--trials must be at least 1, not 0"), "{err}");
    // Refused before anything runs.
    assert!(out.is_empty() && !err.contains("trial 1/"), "{out}{err}");
}

#[test]
fn bench_bus_short_run_prints_figures_and_records_them() {
    let dir = std::env::temp_dir().join(format!("cantwin-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("BENCHMARKS.md");
    let (ok, out, err) = cantwin(&[
        "bench",
        "bus",
        "--seconds",
        "0.05",
        "--trials",
        "2",
        "--write",
        "--file",
        file.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    // Each trial is announced; the table gives the best trial and the median.
    assert!(
        err.contains("trial 1/2") && err.contains("trial 2/2"),
        "{err}"
    );
    assert!(
        out.contains("| figure | best of 2 trials (median) |"),
        "{out}"
    );
    assert!(out.contains("real-time factor"));
    let rtf = out
        .lines()
        .find(|l| l.starts_with("| **real-time factor**"))
        .unwrap_or_else(|| panic!("{out}"));
    let (best, median) = best_and_median(rtf);
    assert!(best >= median && median > 0.0, "{rtf}");
    assert!(out.contains("(best of 2 trials; median "), "{out}");
    let md = std::fs::read_to_string(&file).unwrap();
    assert!(md.contains("the best of 2 trials of the same deterministic run"));
    assert!(md.contains("<!-- bench:bus -->") && md.contains("<!-- /bench:bus -->"));
    assert!(md.contains("cantwin -- bench bus --write"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The best and the median of a table row whose value reads `**BEST** (median MEDIAN…`.
fn best_and_median(row: &str) -> (f64, f64) {
    let value = row.rsplit_once(" | ").unwrap().1.replace("**", "");
    let (best, rest) = value.split_once(" (median ").unwrap();
    let median = rest.split([';', ')']).next().unwrap();
    (best.trim().parse().unwrap(), median.trim().parse().unwrap())
}

#[test]
fn bench_canopen_short_runs_print_figures_and_record_their_sections() {
    let dir = std::env::temp_dir().join(format!("cantwin-bench-co-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("BENCHMARKS.md");
    let (ok, out, err) = cantwin(&[
        "bench",
        "network",
        "fleet",
        "sdo",
        "memory",
        "--seconds",
        "0.05",
        "--buses",
        "2",
        "--trials",
        "2",
        "--write",
        "--file",
        file.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("real-time factor"), "{out}");
    assert!(
        out.contains("expedited round trips per wall second"),
        "{out}"
    );
    assert!(out.contains("heap per device, CiA 301 defaults"), "{out}");
    // `cantwin sim` itself, as a child process: start-up and resident memory.
    assert!(
        out.contains("start-up of `cantwin sim` with 127 devices"),
        "{out}"
    );
    assert!(
        out.contains("RSS of `cantwin sim` with 127 devices"),
        "{out}"
    );
    // The twins in `cantwin sim` too: every node-ID of one bus (MAC ID for DeviceNet), and
    // what each twin after the first adds to the resident set.
    for (twin, n) in [
        ("TM3BCCO with 14 modules", 127),
        ("ADV200, CANopen worked example", 127),
        ("ADV200, DS402", 127),
        ("ADV200, DeviceNet", 63),
    ] {
        let row = out
            .lines()
            .find(|l| l.starts_with(&format!("| {twin} |")))
            .unwrap_or_else(|| panic!("{twin}: {out}"));
        let cells: Vec<&str> = row.trim_matches('|').split('|').map(str::trim).collect();
        assert_eq!(cells[1], n.to_string(), "{row}");
        let figure = |cell: &str, unit: &str| -> f64 {
            let v = cell.replace("**", "");
            v.strip_suffix(unit).unwrap().trim().parse().unwrap()
        };
        let (one, full) = (figure(cells[2], "MiB"), figure(cells[3], "MiB"));
        assert!(full >= one && one > 0.0, "{row}");
        assert!(figure(cells[4], "KiB") > 0.0, "{row}");
        assert!(figure(cells[5], "ms") > 0.0, "{row}");
    }
    assert!(
        out.contains("heap of the CiA 301 `Device` in a TM3BCCO with 14 modules"),
        "{out}"
    );
    assert!(err.contains("bench fleet: 2 networks"), "{err}");
    // Every way of filtering the network, and the expedited SDO figure, as best and median
    // of the two trials; the transfer fractions in simulated time once.
    assert!(
        out.contains("| how frames reach the devices — best of 2 trials (median) |"),
        "{out}"
    );
    for way in [
        "| firmware acceptance filters |",
        "| the devices' own acceptance filters |",
        "| every frame handed to every device, which filters it |",
        "| every frame through every device's whole stack |",
    ] {
        let row = out
            .lines()
            .find(|l| l.starts_with(way))
            .unwrap_or_else(|| panic!("{way}: {out}"));
        assert_eq!(row.matches("(median ").count(), 3, "{row}");
    }
    let expedited = out
        .lines()
        .find(|l| l.starts_with("| **expedited round trips per wall second**"))
        .unwrap_or_else(|| panic!("{out}"));
    let (best, median) = best_and_median(expedited);
    assert!(best >= median && median > 0.0, "{expedited}");
    assert_eq!(
        err.matches("expedited round trips per wall second").count(),
        2,
        "{err}"
    );
    let md = std::fs::read_to_string(&file).unwrap();
    for name in ["network", "fleet", "sdo", "memory"] {
        assert!(
            md.contains(&format!("<!-- bench:{name} -->")),
            "{name}: {md}"
        );
        assert!(
            md.contains(&format!("cantwin -- bench {name} --write")),
            "{name}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bench_twins_short_runs_print_figures_and_record_their_sections() {
    let dir = std::env::temp_dir().join(format!("cantwin-bench-tw-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("BENCHMARKS.md");
    let names = [
        "adv200-canopen",
        "adv200-ds402",
        "adv200-devicenet",
        "tm3",
        "opendrive",
    ];
    let mut args = vec!["bench"];
    args.extend(names);
    args.extend([
        "--seconds",
        "0.1",
        "--write",
        "--file",
        file.to_str().unwrap(),
    ]);
    let (ok, out, err) = cantwin(&args);
    assert!(ok, "{err}");
    assert!(out.contains("CPU per simulated second, twin"), "{out}");
    assert!(out.contains("twin / bare device"), "{out}");
    let md = std::fs::read_to_string(&file).unwrap();
    for name in names {
        assert!(
            md.contains(&format!("<!-- bench:{name} -->")),
            "{name}: {md}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

const GENERATORS: &str = "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\
    [[device]]\nname = \"a\"\nkind = \"generator\"\nbus = \"can0\"\nid = 0x100\nperiod_ms = 20\n\
    [[device]]\nname = \"b\"\nkind = \"generator\"\nbus = \"can0\"\nid = 0x200\nperiod_ms = 50\nlen = 0\n";

#[test]
fn sim_reports_scenario_errors_with_file_line_and_key() {
    let dir = temp_dir("sim-err");
    let file = dir.join("bad.toml");
    std::fs::write(&file, "[[bus]]\nname = \"can0\"\nbit_rate = \"9k\"\n").unwrap();
    let (ok, _, err) = cantwin(&["sim", file.to_str().unwrap(), "--duration", "1"]);
    assert!(!ok);
    assert!(
        err.contains("bad.toml:3: key `bus[0].bit_rate`: unsupported CAN bit rate \"9k\""),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn sim_refuses_ambiguous_slcan_bus_and_non_loopback_without_flag() {
    let dir = temp_dir("sim-args");
    let file = dir.join("two.toml");
    std::fs::write(
        &file,
        "[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n[[bus]]\nname = \"can1\"\nbit_rate = \"1M\"\n",
    )
    .unwrap();
    let (ok, _, err) = cantwin(&[
        "sim",
        file.to_str().unwrap(),
        "--slcan",
        "0",
        "--duration",
        "1",
    ]);
    assert!(!ok);
    assert!(
        err.contains("choose the one slcan serves with --slcan-bus NAME"),
        "{err}"
    );
    let (ok, _, err) = cantwin(&[
        "sim",
        file.to_str().unwrap(),
        "--socketcand",
        "0.0.0.0:0",
        "--duration",
        "1",
    ]);
    assert!(!ok);
    assert!(err.contains("not a loopback address"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn sim_serves_socketcand_and_prints_one_line_per_bus() {
    use std::io::BufRead;
    let dir = temp_dir("sim-run");
    let file = dir.join("gen.toml");
    std::fs::write(&file, GENERATORS).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args([
            "sim",
            file.to_str().unwrap(),
            "--socketcand",
            "0",
            "--duration",
            "3",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let mut line = String::new();
    std::io::BufReader::new(stdout)
        .read_line(&mut line)
        .unwrap();
    let parts: Vec<&str> = line.split_whitespace().collect();
    assert_eq!(parts.len(), 3, "{line}");
    assert_eq!(parts[0], "socketcand");
    assert_eq!(parts[2], "can0");
    let addr: std::net::SocketAddr = parts[1].parse().unwrap();
    assert!(addr.ip().is_loopback());
    let client = cantwin_gateway::socketcand::Client::connect(
        addr,
        "can0",
        std::time::Duration::from_secs(5),
    )
    .unwrap();
    use cantwin_gateway::BusPort;
    let mut ids = std::collections::BTreeSet::new();
    let until = std::time::Instant::now() + std::time::Duration::from_secs(2);
    while ids.len() < 2 && std::time::Instant::now() < until {
        if let Some(rx) = client
            .recv_timeout(std::time::Duration::from_millis(200))
            .unwrap()
        {
            ids.insert(rx.frame.id().as_raw());
        }
    }
    assert_eq!(ids.into_iter().collect::<Vec<_>>(), [0x100, 0x200]);
    drop(client);
    let status = child.wait().unwrap();
    assert!(status.success());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn sim_records_pcap_and_candump_that_dump_reads_back() {
    let dir = temp_dir("sim-capture");
    let file = dir.join("gen.toml");
    std::fs::write(&file, GENERATORS).unwrap();
    let pcap = dir.join("run.pcap");
    let log = dir.join("run.log");
    let (ok, _, err) = cantwin(&[
        "sim",
        file.to_str().unwrap(),
        "--duration",
        "0.3",
        "--pcap",
        pcap.to_str().unwrap(),
        "--candump",
        log.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let text = std::fs::read_to_string(&log).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert!(lines.len() >= 6, "{text}");
    assert!(
        lines
            .iter()
            .any(|l| l.ends_with(" can0 100#0000000000000000")),
        "{text}"
    );
    assert!(lines.iter().any(|l| l.ends_with(" can0 200#")), "{text}");
    // The pcap holds the same frames; dump prints them.
    let (ok, out, err) = cantwin(&["dump", pcap.to_str().unwrap()]);
    assert!(ok, "{err}");
    let dumped: Vec<&str> = out.lines().collect();
    assert_eq!(dumped.len(), lines.len(), "{out}");
    assert!(out.contains("100#0000000000000000"), "{out}");
    let (ok, _, err) = cantwin(&["dump", dir.join("missing.pcap").to_str().unwrap()]);
    assert!(!ok);
    assert!(err.contains("missing.pcap"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

fn corpus(name: &str) -> String {
    format!("{}/../eds/tests/corpus/{name}", env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn eds_check_reports_line_numbered_errors_and_exits_non_zero() {
    let (ok, out, _) = cantwin(&["eds", "check", &corpus("drive.eds")]);
    assert!(ok);
    assert!(out.contains("0 errors"), "{out}");
    let dir = temp_dir("eds-bad");
    let bad = dir.join("bad.eds");
    std::fs::write(
        &bad,
        "[1000]\nParameterName=x\nDataType=0x0007\nAccessType=rx\n",
    )
    .unwrap();
    let (ok, out, err) = cantwin(&["eds", "check", bad.to_str().unwrap()]);
    assert!(!ok);
    assert!(
        out.contains("error: line 4 [1000] AccessType: invalid value \"rx\""),
        "{out}"
    );
    assert!(!err.contains("Stack backtrace"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn eds_check_warns_about_a_life_time_factor_below_2() {
    let dir = temp_dir("eds-life");
    let file = dir.join("guard.eds");
    let text = std::fs::read_to_string(corpus("drive.eds"))
        .unwrap()
        .replace(
            "[MandatoryObjects]",
            "[100C]\nParameterName=Guard time\nObjectType=0x7\nDataType=0x0006\nAccessType=rw\n\
         DefaultValue=100\nPDOMapping=0\n\n[100D]\nParameterName=Life time factor\nObjectType=0x7\n\
         DataType=0x0005\nAccessType=rw\nDefaultValue=1\nPDOMapping=0\n\n[MandatoryObjects]",
        );
    std::fs::write(&file, text).unwrap();
    let (_, out, err) = cantwin(&["eds", "check", file.to_str().unwrap()]);
    assert!(out.contains("life time factor 1 is below 2"), "{out}{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn eds_dcf_commissions_a_node_and_doc_renders_markdown() {
    let (ok, out, err) = cantwin(&[
        "eds",
        "dcf",
        &corpus("drive.eds"),
        "--node-id",
        "12",
        "--bit-rate",
        "500k",
        "--name",
        "drive",
        "--set",
        "0x1008:0=Pump 3",
    ]);
    assert!(ok, "{err}");
    assert!(
        out.contains("[DeviceComissioning]\nNodeID=12\nNodeName=drive\nBaudrate=500\n"),
        "{out}"
    );
    assert!(out.contains("ParameterValue=Pump 3"), "{out}");
    let (ok, _, err) = cantwin(&[
        "eds",
        "dcf",
        &corpus("drive.eds"),
        "--node-id",
        "12",
        "--set",
        "0x7777:0=1",
    ]);
    assert!(!ok);
    assert!(err.contains("the file has no object 0x7777"), "{err}");
    let (ok, _, _) = cantwin(&["eds", "dcf", &corpus("drive.eds"), "--node-id", "128"]);
    assert!(!ok);
    let (ok, out, _) = cantwin(&["eds", "doc", &corpus("drive.eds")]);
    assert!(ok);
    assert!(out.starts_with("# Drive V1"), "{out}");
}

#[test]
fn cal_commands_drive_the_opendrive_twin_through_socketcand() {
    let (mut child, addr) = sim_with_socketcand(&scenario_file("opendrive.toml"), "300");
    let cal = |args: &[&str]| {
        let mut full = vec!["cal", "--socketcand", addr.as_str()];
        full.extend_from_slice(args);
        cantwin(&full)
    };
    let (ok, out, err) = cal(&["read"]);
    assert!(ok, "{err}");
    assert_eq!(
        out.trim(),
        "reference 0.00 Hz  reference-remote off  command-remote off  start off  reverse off"
    );
    let (ok, out, err) = cal(&[
        "cmd",
        "--reference-remote",
        "on",
        "--command-remote",
        "on",
        "--start",
        "on",
        "--ref",
        "50",
    ]);
    assert!(ok, "{err}");
    assert_eq!(
        out.trim(),
        "reference 50.00 Hz  reference-remote on  command-remote on  start on  reverse off"
    );
    // The drive keeps its state between commands: a remote-frame read sees the same.
    let (ok, out, err) = cal(&["read", "--remote"]);
    assert!(ok, "{err}");
    assert!(
        out.contains("reference 50.00 Hz") && out.contains("start on"),
        "{out}"
    );
    let (ok, out, err) = cal(&["param", "read", "max-frequency"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "max-frequency = 60 Hz (data 6000 = 0x1770)");
    // One unit per quantity, the manual's: Hz as for `cmd --ref`, seconds for the delay.
    let (ok, out, err) = cal(&["param", "write", "max-frequency", "55"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "max-frequency = 55 Hz (data 5500 = 0x157C)");
    let (ok, out, err) = cal(&["param", "write", "stop-delay", "1.5"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "stop-delay = 1.5 s (data 15 = 0x000F)");
    // 0.5 s is a value in seconds, sent as data 5; P94 starts at 1 s, so the drive refuses.
    let (ok, _, err) = cal(&["param", "write", "stop-delay", "0.5"]);
    assert!(!ok);
    assert!(err.contains("error code 2 (value not allowed)"), "{err}");
    // A value the drive refuses comes back as its error code.
    let (ok, _, err) = cal(&["param", "write", "thermal-current", "5"]);
    assert!(!ok);
    assert!(err.contains("error code 2 (value not allowed)"), "{err}");
    let (ok, out, err) = cal(&["events", "enable"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "alarm events enabled");
    child.kill().ok();
    child.wait().ok();
}

#[test]
fn client_commands_need_a_target() {
    let (ok, _, err) = cantwin(&["cal", "read"]);
    assert!(!ok);
    assert!(err.contains("--socketcand HOST:PORT"), "{err}");
}

#[test]
fn canopen_commands_against_the_cia301_twin_through_socketcand() {
    let (mut child, addr) = sim_with_socketcand(&scenario_file("cia301-device.toml"), "300");
    let run = |args: &[&str]| {
        let mut full = vec![args[0], "--socketcand", addr.as_str()];
        full.extend_from_slice(&args[1..]);
        cantwin(&full)
    };
    let (ok, out, err) = run(&["scan"]);
    assert!(ok, "{err}");
    assert!(out.contains("node   5  device type"), "{out}");
    assert!(out.trim_end().ends_with("1 nodes found"), "{out}");
    let (ok, out, err) = run(&["sdo", "read", "5", "0x1008", "0", "vs"]);
    assert!(ok, "{err}");
    assert!(out.starts_with("cantwin generic CiA 301 device"), "{out}");
    let (ok, out, err) = run(&["sdo", "write", "5", "0x1017", "0", "u16", "500"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "written 2 bytes to node 5 0x1017sub0");
    let (ok, out, err) = run(&["sdo", "read", "5", "0x1017", "0", "u16"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "500 (0x01F4)");
    // Aborts arrive with the code and its meaning.
    let (ok, _, err) = run(&["sdo", "read", "5", "0x6000", "0", "u16"]);
    assert!(!ok);
    assert!(
        err.contains("SDO aborted by the server: 0x06020000"),
        "{err}"
    );
    // A 64 KiB DOMAIN by block transfer into a file, and back by segmented transfer.
    let dir = temp_dir("sdo-domain");
    let file = dir.join("domain.bin");
    let (ok, _, err) = run(&[
        "sdo",
        "--mode",
        "block",
        "read",
        "5",
        "0x2000",
        "0",
        "--output",
        file.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let data = std::fs::read(&file).unwrap();
    assert_eq!(data.len(), 65536);
    assert_eq!(data[1..4], [1, 2, 3]);
    let mut changed = data.clone();
    changed.reverse();
    std::fs::write(&file, &changed).unwrap();
    let (ok, _, err) = run(&[
        "sdo",
        "--mode",
        "segmented",
        "write",
        "5",
        "0x2000",
        "0",
        "d",
        "--input",
        file.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let (ok, _, err) = run(&[
        "sdo",
        "--mode",
        "block",
        "read",
        "5",
        "0x2000",
        "0",
        "--output",
        file.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert_eq!(std::fs::read(&file).unwrap(), changed);
    std::fs::remove_dir_all(&dir).unwrap();
    // NMT and the trace of what follows.
    let (ok, out, err) = run(&["nmt", "preop", "5"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "sent 000#8005");
    let (ok, out, err) = run(&["trace", "--count", "1", "--seconds", "5"]);
    assert!(ok, "{err}");
    assert!(
        out.contains("705#7F") && out.contains("node 5 pre-operational"),
        "{out}"
    );
    let (ok, _, err) = run(&["sdo", "read", "5", "0x1017", "0", "q9"]);
    assert!(!ok);
    assert!(err.contains("unknown data type \"q9\""), "{err}");
    child.kill().ok();
    child.wait().ok();
}

#[test]
fn a_closed_pipe_ends_output_quietly() {
    use std::io::Read;
    // A capture whose listing is far larger than a pipe's buffer.
    let dir = temp_dir("pipe");
    let log = dir.join("big.log");
    let lines: String = (0..20_000)
        .map(|i| {
            format!(
                "({}.{:06}) can0 123#{:08X}\n",
                1_700_000_000 + i / 1000,
                i % 1000,
                i
            )
        })
        .collect();
    std::fs::write(&log, lines).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args(["dump", log.to_str().unwrap()])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Read one chunk, then close the pipe as `| head` does.
    let mut first = [0u8; 64];
    child.stdout.take().unwrap().read_exact(&mut first).unwrap();
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    let status = child.wait().unwrap();
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(status.code(), Some(141), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn cal_remote_frame_read_through_the_slcan_gateway() {
    use std::io::{BufRead, Read, Write};
    // DS 202-2 read of a basic variable by remote frame: the OPEN DRIVE answers message 0 on
    // its response COB (P181 = 439 = 0x1B7) to a remote frame with the same identifier.
    let mut child = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args([
            "sim",
            &scenario_file("opendrive.toml"),
            "--slcan",
            "0",
            "--duration",
            "20",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr: std::net::SocketAddr = line.split_whitespace().nth(1).unwrap().parse().unwrap();
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(std::time::Duration::from_secs(5)))
        .unwrap();
    // python-can's slcan open sequence, then the remote frame.
    s.write_all(b"C\rS6\rO\r").unwrap();
    std::thread::sleep(std::time::Duration::from_millis(200));
    s.write_all(b"r1B74\r").unwrap();
    let mut got = Vec::new();
    let mut buf = [0u8; 256];
    let until = std::time::Instant::now() + std::time::Duration::from_secs(5);
    while std::time::Instant::now() < until {
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => got.extend_from_slice(&buf[..n]),
            Err(_) => break,
        }
        if String::from_utf8_lossy(&got).contains("t1B7") {
            break;
        }
    }
    let text = String::from_utf8_lossy(&got).into_owned();
    // Control byte 00 (success), the state byte with every pair reset (0x55) and the
    // reference 0.00 Hz.
    assert!(text.contains("t1B7400550000\r"), "{text:?}");
    child.kill().ok();
    child.wait().ok();
}
