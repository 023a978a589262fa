//! socketcand broadcast-manager jobs under a flood: a connection's jobs are bounded
//! ([`Limits::bcm_jobs`]) and answered with the daemon's error element past the bound, and a
//! command costs the same however many jobs the connection has.
#![allow(clippy::unwrap_used)]

mod common;

use std::io::Write as _;
use std::time::{Duration, Instant};

use cantwin_gateway::Limits;
use cantwin_gateway::memory::MemoryBus;
use common::{Peer, socketcand_server};

/// A client with `vcan0` open, in broadcast-manager mode.
fn bcm_client(addr: std::net::SocketAddr) -> Peer {
    let mut c = Peer::connect(addr);
    assert_eq!(c.read_once(), b"< hi >");
    c.write(b"< open vcan0 >");
    assert_eq!(c.read_once(), b"< ok >");
    c
}

/// `n` `add` commands for distinct extended identifiers with a 10 s cycle (each frame goes out
/// once, at once), in one write.
fn adds(n: u32) -> Vec<u8> {
    let mut out = Vec::with_capacity(n as usize * 32);
    for i in 0..n {
        write!(out, "< add 10 0 {:08X} 1 {:X} >", 0x1000_0000 + i, i & 0xFF).unwrap();
    }
    out
}

/// The process's CPU time (user + system) in seconds, from `/proc/self/stat` (clock ticks of
/// 1/100 s, the Linux `USER_HZ`).
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap();
    let after_name = &stat[stat.rfind(')').unwrap() + 2..];
    let fields: Vec<&str> = after_name.split(' ').collect();
    // Fields 14 and 15 of proc(5) (utime, stime); the slice starts at field 3.
    let ticks: u64 = fields[11].parse::<u64>().unwrap() + fields[12].parse::<u64>().unwrap();
    ticks as f64 / 100.0
}

#[test]
fn jobs_beyond_the_limit_get_the_daemons_error_element_and_change_nothing() {
    let bus = MemoryBus::new(["vcan0"]);
    let srv = socketcand_server(
        &bus,
        Limits {
            bcm_jobs: 3,
            ..Limits::default()
        },
    );
    let mut c = bcm_client(srv.local_addr());
    c.write(b"< add 1 0 123 1 01 >< update 124 1 02 >< subscribe 0 0 200 >");
    // The fourth job, of either kind, is refused; a job that exists may still change.
    c.write(b"< add 1 0 125 1 03 >< subscribe 0 0 201 >< update 123 1 04 >< echo >");
    assert_eq!(
        c.read_element(),
        "< error too many broadcast manager jobs >"
    );
    assert_eq!(
        c.read_element(),
        "< error too many broadcast manager jobs >"
    );
    assert_eq!(c.read_element(), "< echo >");
    // Deleting one makes room for one.
    c.write(b"< delete 124 >< add 0 0 125 1 03 >< unsubscribe 200 >< subscribe 0 0 201 >");
    c.write(b"< add 0 0 126 1 05 >< echo >");
    assert_eq!(
        c.read_element(),
        "< error too many broadcast manager jobs >"
    );
    assert_eq!(c.read_element(), "< echo >");
    assert_eq!(srv.stats().error_replies, 3);
    // The session goes on: its subscription delivers.
    bus.inject(
        "vcan0",
        cantwin_can::Frame::std(0x201, &[7]).unwrap(),
        common::ts(),
    );
    assert_eq!(c.read_element(), "< frame 201 1700000000.000250 07  >");
}

#[test]
fn the_default_limit_is_4096_jobs_per_connection() {
    assert_eq!(Limits::default().bcm_jobs, 4096);
    let bus = MemoryBus::new(["vcan0"]);
    let srv = socketcand_server(&bus, Limits::default());
    let mut c = bcm_client(srv.local_addr());
    c.write(&adds(4097));
    c.write(b"< echo >");
    assert_eq!(
        c.read_element(),
        "< error too many broadcast manager jobs >"
    );
    assert_eq!(c.read_element(), "< echo >");
    // A second connection has its own jobs.
    let mut d = bcm_client(srv.local_addr());
    d.write(b"< add 0 0 123 0 >< echo >");
    assert_eq!(d.read_element(), "< echo >");
}

/// Figures for RELIABILITY.md: CPU and wall time of 50 k, 100 k and 200 k `add` jobs on one
/// connection, with the job limit raised to let them all in. Run with
/// `cargo test -p cantwin-gateway --release --test socketcand_bcm_jobs -- --ignored --nocapture`.
#[test]
#[ignore = "a measurement, not a check: prints figures"]
fn add_flood_figures() {
    for n in [50_000u32, 100_000, 200_000] {
        let bus = MemoryBus::new(["vcan0"]);
        let srv = socketcand_server(
            &bus,
            Limits {
                bcm_jobs: n as usize,
                ..Limits::default()
            },
        );
        let mut c = Peer::connect(srv.local_addr());
        c.s.set_read_timeout(Some(Duration::from_secs(600)))
            .unwrap();
        assert_eq!(c.read_once(), b"< hi >");
        c.write(b"< open vcan0 >");
        assert_eq!(c.read_once(), b"< ok >");
        let flood = adds(n);
        let (cpu, wall) = (cpu_seconds(), Instant::now());
        c.write(&flood);
        c.write(b"< echo >");
        assert_eq!(c.read_element(), "< echo >");
        let (cpu, wall) = (cpu_seconds() - cpu, wall.elapsed().as_secs_f64());
        // A good client's round trip while the connection holds its jobs.
        let mut good = Peer::connect(srv.local_addr());
        assert_eq!(good.read_once(), b"< hi >");
        let t = Instant::now();
        good.write(b"< echo >");
        assert_eq!(good.read_element(), "< echo >");
        println!(
            "{n} adds: {cpu:.2} s CPU, {wall:.2} s wall; another client's echo {:.2} ms",
            t.elapsed().as_secs_f64() * 1e3
        );
        drop(c);
        srv.shutdown();
    }
}
