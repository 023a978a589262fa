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
/// connection, with the job limit raised to let them all in, and 200 k with the default
/// limit (the rest refused); meanwhile another client's `echo` round trips, one per
/// millisecond. Run with
/// `cargo test -p cantwin-gateway --release --test socketcand_bcm_jobs -- --ignored --nocapture`.
#[test]
#[ignore = "a measurement, not a check: prints figures"]
fn add_flood_figures() {
    use std::io::Write as _;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};

    for (n, limit) in [
        (50_000u32, 50_000usize),
        (100_000, 100_000),
        (200_000, 200_000),
        (200_000, Limits::default().bcm_jobs),
    ] {
        let bus = MemoryBus::new(["vcan0"]);
        let srv = socketcand_server(
            &bus,
            Limits {
                bcm_jobs: limit,
                ..Limits::default()
            },
        );
        let mut good = bcm_client(srv.local_addr());
        let stop = Arc::new(AtomicBool::new(false));
        let prober = {
            let stop = Arc::clone(&stop);
            std::thread::spawn(move || {
                let mut rtt = Vec::new();
                while !stop.load(Ordering::Relaxed) {
                    let t = Instant::now();
                    good.write(b"< echo >");
                    assert_eq!(good.read_element(), "< echo >");
                    rtt.push(t.elapsed());
                    std::thread::sleep(Duration::from_millis(1));
                }
                rtt
            })
        };
        let mut c = bcm_client(srv.local_addr());
        c.s.set_read_timeout(Some(Duration::from_secs(600)))
            .unwrap();
        let mut w = c.s.try_clone().unwrap();
        let flood = adds(n);
        let (cpu, wall) = (cpu_seconds(), Instant::now());
        let writer = std::thread::spawn(move || {
            w.write_all(&flood).unwrap();
            w.write_all(b"< echo >").unwrap();
        });
        // Read in bulk: the figures are the server's, not a byte-by-byte reader's.
        let refusal = b"< error too many broadcast manager jobs >";
        let mut replies = Vec::new();
        let mut buf = vec![0u8; 1 << 16];
        while !replies.ends_with(b"< echo >") {
            let got = std::io::Read::read(&mut c.s, &mut buf).unwrap();
            assert!(got > 0, "closed");
            replies.extend_from_slice(&buf[..got]);
        }
        let refused = replies.len().saturating_sub(8) / refusal.len();
        assert_eq!(refused * refusal.len() + 8, replies.len());
        writer.join().unwrap();
        let (cpu, wall) = (cpu_seconds() - cpu, wall.elapsed().as_secs_f64());
        stop.store(true, Ordering::Relaxed);
        let mut rtt = prober.join().unwrap();
        rtt.sort();
        let q = |f: f64| rtt[((rtt.len() - 1) as f64 * f) as usize].as_secs_f64() * 1e3;
        println!(
            "{n} adds, limit {limit}: {refused} refused, {cpu:.2} s CPU, {wall:.2} s wall; \
             another client's echo p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms ({} round trips)",
            q(0.5),
            q(0.99),
            q(1.0),
            rtt.len()
        );
        drop(c);
        srv.shutdown();
    }
}
