//! `cantwin gateway --ascii` (CiA 309-3 ASCII mapping) against `cantwin sim` running the
//! generic CiA 301 device of `scenarios/cia301-device.toml` (node 5), over stdin/stdout and
//! over TCP, answering byte for byte as CANopenNode's gateway answers its `cocomm` client:
//! every answer ended by CR LF, `help` its text alone.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};

const DEVICE_NAME: &str =
    "cantwin generic CiA 301 device with a 64 KiB DOMAIN at 0x2000, four RPDOs and four TPDOs";

/// The requests of both tests and the answers expected, in order.
fn conversation() -> Vec<(String, String)> {
    let pairs = [
        ("[1] 5 read 0x1008 0 vs", format!("[1] \"{DEVICE_NAME}\"")),
        ("[2] 5 write 0x1017 0 u16 250", "[2] OK".into()),
        ("[3] 5 read 0x1017 0 u16", "[3] 250".into()),
        ("[4] 5 read 0x1234 0 u8", "[4] ERROR:0x06020000".into()),
        ("[5] 5 read 0x1018 1 x32", "[5] 0x00000CA7".into()),
        // Reset node: 0x1017 back to the power-on value (the scenario's heartbeat_ms).
        ("[6] 5 reset node", "[6] OK".into()),
        ("[7] 5 read 0x1017 0 u16", "[7] 100".into()),
        ("[8] set node 5", "[8] OK".into()),
        ("[9] set sdo_timeout 200", "[9] OK".into()),
        // Stopped: the SDO server is silent (CiA 301 §7.3.2.2.1), the client times out.
        ("[10] stop", "[10] OK".into()),
        ("[11] read 0x1000 0 u32", "[11] ERROR:0x05040000".into()),
        ("[12] start", "[12] OK".into()),
        ("[13] read 0x2002 0 u8", "[13] 0".into()),
        ("[14] preop", "[14] OK".into()),
        ("[15] write 0x2002 0 u8 101", "[15] ERROR:0x06090031".into()),
        ("[16] reset comm", "[16] OK".into()),
        ("[17] 5 read", "[17] ERROR:101".into()),
        ("[18] 5 jump", "[18] ERROR:100".into()),
        // One network: any 16-bit net is taken and not used, more is 106.
        ("[19] 2 5 start", "[19] OK".into()),
        ("[20] 0 5 read 0x1018 1 x32", "[20] 0x00000CA7".into()),
        ("[21] 0xFFFF 5 read 0x1018 1 x32", "[21] 0x00000CA7".into()),
        ("[22] 0x10000 5 start", "[22] ERROR:106".into()),
        // REAL32 as C's `%g`: the vendor-ID's bits are a denormal.
        ("[23] 5 read 0x1018 1 r32", "[23] 4.53881e-42".into()),
    ];
    pairs.into_iter().map(|(q, a)| (q.to_string(), a)).collect()
}

#[test]
fn cia309_3_gateway_on_stdin_reads_writes_aborts_and_sends_nmt() {
    let (mut sim, addr) = sim_with_socketcand(&scenario_file("cia301-device.toml"), "300");
    let mut gw = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args(["gateway", "--ascii", "--socketcand", &addr])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let talk = conversation();
    {
        let mut stdin = gw.stdin.take().unwrap();
        for (q, _) in &talk {
            writeln!(stdin, "{q}").unwrap();
        }
        writeln!(stdin, "[24] help").unwrap();
        writeln!(stdin, "[25] 5 read 0x1017 0 u16").unwrap();
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
    // Each answer ends with CR LF on stdout too.
    let mut rest = text.as_str();
    for (q, a) in &talk {
        let answer = format!("{a}\r\n");
        assert!(rest.starts_with(&answer), "answer to {q}: {rest:?}");
        rest = &rest[answer.len()..];
    }
    assert_help_then(rest, "[25] 100\r\n");
}

/// `rest` is `help`'s answer as CANopenNode's gateway frames it (an LF, the text with LF
/// between its lines, one CR LF at its end, no sequence number and no OK), then `next`.
fn assert_help_then(rest: &str, next: &str) {
    let end = rest.find("\r\n").unwrap();
    let help = &rest[..end];
    assert!(
        help.starts_with("\nRequest: [<seq>] [[<net>] <node>] <command>"),
        "{help:?}"
    );
    assert!(
        help.contains("\n  write <index> <sub> <type> <value>"),
        "{help:?}"
    );
    assert!(help.contains("\nTypes: b i8"), "{help:?}");
    assert!(!help.contains("OK\n") && !help.contains("[24]"), "{help:?}");
    assert_eq!(&rest[end + 2..], next);
}

#[test]
fn cia309_3_gateway_serves_tcp_clients() {
    let (mut sim, addr) = sim_with_socketcand(&scenario_file("cia301-device.toml"), "300");
    let mut gw = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        // CiA 309-3 ASCII is the default protocol: no --ascii needed.
        .args(["gateway", "--listen", "0", "--socketcand", &addr])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut first = String::new();
    BufReader::new(gw.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    let gw_addr = first.strip_prefix("gateway ").unwrap().trim().to_string();
    assert!(gw_addr.starts_with("127.0.0.1:"), "{first}");

    let stream = std::net::TcpStream::connect(&gw_addr).unwrap();
    stream
        .set_read_timeout(Some(std::time::Duration::from_secs(10)))
        .unwrap();
    let mut reader = BufReader::new(stream.try_clone().unwrap());
    let mut writer = stream;
    let mut ask = |q: &str| {
        write!(writer, "{q}\r\n").unwrap();
        read_answer(&mut reader).trim_end().to_string()
    };
    for (q, a) in conversation() {
        assert_eq!(ask(&q), a, "answer to {q}");
    }
    // A line longer than the gateway takes is refused as a syntax error, and the client
    // stays connected.
    let long = format!("[30] 5 write 0x1008 0 vs {}", "x".repeat(2000));
    assert_eq!(ask(&long), "[23] ERROR:101");
    assert_eq!(ask("[31] 5 read 0x1017 0 u16"), "[31] 100");
    // `help` is one answer up to its CR LF, as `cocomm` reads it.
    let help = format!("{}\r\n", ask("[24] help"));
    assert_help_then(&help, "");
    assert_eq!(ask("[25] 5 read 0x1017 0 u16"), "[25] 100");

    // A second client has its own default node.
    let other = std::net::TcpStream::connect(&gw_addr).unwrap();
    other
        .set_read_timeout(Some(std::time::Duration::from_secs(10)))
        .unwrap();
    let mut other_reader = BufReader::new(other.try_clone().unwrap());
    let mut other_writer = other;
    write!(other_writer, "[1] read 0x1017 0 u16\r\n").unwrap();
    let mut line = String::new();
    other_reader.read_line(&mut line).unwrap();
    assert_eq!(line, "[1] ERROR:105\r\n");

    let _ = gw.kill();
    let _ = gw.wait();
    let _ = sim.kill();
    let _ = sim.wait();
}

/// One answer as `cocomm` reads it: everything up to and with the first CR LF.
fn read_answer(reader: &mut impl BufRead) -> String {
    let mut answer = String::new();
    while !answer.ends_with("\r\n") {
        let n = reader.read_line(&mut answer).unwrap();
        assert!(n > 0, "the gateway closed the connection after {answer:?}");
    }
    answer
}

/// The request of line `i` of a long session and its answer: SDO uploads of the vendor-ID,
/// every tenth an NMT command (a frame of the master's too).
fn long_session_line(i: usize) -> (String, String) {
    if i % 10 == 0 {
        (format!("[{i}] 5 start"), format!("[{i}] OK"))
    } else {
        (
            format!("[{i}] 5 read 0x1018 1 x32"),
            format!("[{i}] 0x00000CA7"),
        )
    }
}

/// Every request is answered however many came before it: each frame the master sends is
/// confirmed to it, so its transmit window (16 frames) never fills.
#[test]
fn cia309_3_gateway_answers_every_request_of_a_long_session() {
    let mut gw = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args([
            "gateway",
            "--scenario",
            &scenario_file("cia301-device.toml"),
        ])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let talk: Vec<(String, String)> = (1..=200).map(long_session_line).collect();
    {
        let mut stdin = gw.stdin.take().unwrap();
        for (q, _) in &talk {
            writeln!(stdin, "{q}").unwrap();
        }
    }
    let out = gw.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let expected: String = talk.iter().map(|(_, a)| format!("{a}\r\n")).collect();
    assert_eq!(String::from_utf8(out.stdout).unwrap(), expected);
}

/// `cantwin gateway --listen 0` on the scenario `name`: the process (killed when dropped)
/// and the address it listens on, as its first line says.
fn gateway_on_tcp(name: &str) -> (Killed, String) {
    let mut gw = Killed(
        Command::new(env!("CARGO_BIN_EXE_cantwin"))
            .args([
                "gateway",
                "--listen",
                "0",
                "--scenario",
                &scenario_file(name),
            ])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let mut first = String::new();
    BufReader::new(gw.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    let addr = first.strip_prefix("gateway ").unwrap().trim().to_string();
    (gw, addr)
}

/// Two TCP clients taking turns, 100 requests each: the window is the gateway's, shared by
/// every client, and stays open for all of them.
#[test]
fn cia309_3_gateway_answers_every_request_of_two_tcp_clients() {
    let (_gw, gw_addr) = gateway_on_tcp("cia301-device.toml");
    let connect = || {
        let stream = std::net::TcpStream::connect(&gw_addr).unwrap();
        stream
            .set_read_timeout(Some(std::time::Duration::from_secs(10)))
            .unwrap();
        (BufReader::new(stream.try_clone().unwrap()), stream)
    };
    let mut clients = [connect(), connect()];
    for i in 1..=200 {
        let (reader, writer) = &mut clients[i % 2];
        let (q, a) = long_session_line(i);
        write!(writer, "{q}\r\n").unwrap();
        assert_eq!(read_answer(reader), format!("{a}\r\n"), "answer to {q}");
    }
}

/// Each answer comes in one piece, its CR LF with it: `cocomm` takes what its first read
/// returns as the whole answer when it holds a CR LF (and an OK only as `] OK` CR LF).
#[test]
fn cia309_3_gateway_sends_each_answer_with_its_cr_lf_in_one_piece() {
    let (_gw, gw_addr) = gateway_on_tcp("cia301-device.toml");
    let mut stream = std::net::TcpStream::connect(&gw_addr).unwrap();
    stream
        .set_read_timeout(Some(std::time::Duration::from_secs(10)))
        .unwrap();
    for i in 1..=10 {
        for (q, a) in [
            (format!("[{i}] 5 start"), format!("[{i}] OK\r\n")),
            (
                format!("[{i}] 5 read 0x1018 1 x32"),
                format!("[{i}] 0x00000CA7\r\n"),
            ),
            (
                format!("[{i}] 5 read 0x1234 0"),
                format!("[{i}] ERROR:0x06020000\r\n"),
            ),
        ] {
            writeln!(stream, "{q}").unwrap();
            let mut buf = [0u8; 1000];
            let n = std::io::Read::read(&mut stream, &mut buf).unwrap();
            assert_eq!(String::from_utf8_lossy(&buf[..n]), a, "first read for {q}");
        }
    }
}

/// The gateway on an in-process scenario: the `eds` device of `scenarios/eds-device.toml`
/// answers with its EDS's values.
#[test]
fn cia309_3_gateway_reads_the_eds_device_of_a_scenario() {
    let mut gw = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args([
            "gateway",
            "--ascii",
            "--scenario",
            &scenario_file("eds-device.toml"),
        ])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    {
        let mut stdin = gw.stdin.take().unwrap();
        for q in [
            "[1] 6 read 0x1008 0 vs",
            "[2] 6 read 0x2000 0 u16",
            "[3] 6 write 0x2000 0 u16 10001",
            "[4] 6 read 0x1000 0 x32",
            "[5] 6 read 0x6000 1 x8",
        ] {
            writeln!(stdin, "{q}").unwrap();
        }
    }
    let out = gw.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        String::from_utf8(out.stdout).unwrap(),
        "[1] \"cantwin example I/O module\"\r\n[2] 3000\r\n[3] ERROR:0x06090031\r\n\
         [4] 0x00030191\r\n[5] 0xA5\r\n"
    );
}
