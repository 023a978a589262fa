//! Fuzzing at the process boundary: a real `cantwin sim` child with its socketcand, slcan and
//! web gateways on loopback, attacked over TCP the way an attacker or a broken tool would,
//! while a good client keeps reading an object by SDO through the socketcand gateway; and the
//! CLI's file commands run as children on mutated files under a deadline and an address
//! space limit.
//!
//! Each attack reports what it tried, how many of its connections the server held open at
//! once, the child's resident memory (`VmRSS` of `/proc/PID/status`) and open descriptors
//! (`/proc/PID/fd`) before, at the peak and after, and the good client's SDO round trip
//! (median, p99, failures). A finding is a fact the harness measured that breaks the
//! project's rule for servers (safe by default: bounded connections, buffers, jobs and
//! timeouts; a flood costs the user nothing): the server died or stopped answering, the good
//! client waited longer than [`SLOW_MS`] at p99 or not at all, memory or descriptors stayed
//! up after the attack. The harness reports; it fixes nothing.

use std::io::{BufRead, BufReader, ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow, bail};
use cantwin_can::SplitMix64;

/// A good client's p99 SDO round trip above this is a finding (a CAN round trip at
/// 500 kbit/s plus loopback TCP takes well under a millisecond; a human notices 250 ms).
pub const SLOW_MS: f64 = 250.0;
/// How long the good client waits for one SDO answer before counting a failure.
const PROBE_TIMEOUT: Duration = Duration::from_secs(1);
/// Memory still held this long after the attack's connections closed, above the level
/// before it, is a finding.
const RSS_GROWTH_KIB: u64 = 64 * 1024;
/// Descriptors still open after the attack above the level before it (the server may keep
/// a few for its own use).
const FD_GROWTH: usize = 8;
/// How long after the attack descriptors may take to be given back.
const FD_SETTLE: Duration = Duration::from_secs(3);
/// How long after the attack a new good client may have to wait for its first SDO answer.
/// Frames the attack's connections queued before they closed are still sent (as from a
/// socket that is closed with frames in its queue) and win arbitration against the good
/// client's 0x605: at 500 kbit/s sixty connections' queues take about a second to drain.
const AFTER_ATTACK: Duration = Duration::from_secs(5);

/// The descriptor limit the server runs under (RLIMIT_NOFILE through `prlimit`, when
/// installed).
const SERVER_NOFILE: u32 = 1024;

/// The scenario the server runs: one CiA 301 device, node 5, whose 0x1018 sub 1 the good
/// client reads.
const SCENARIO: &str = r#"name = "boundary fuzz"
seed = 23

[[bus]]
name = "can0"
bit_rate = "500k"

[[device]]
name = "node5"
kind = "cia301"
bus = "can0"
node_id = 5
heartbeat_ms = 100
vendor_id = 0x00000CA7
"#;

/// The boundary targets: name and what each attacks.
pub const TARGETS: [(&str, &str); 6] = [
    (
        "net-socketcand",
        "socketcand raw mode over TCP: garbage, damaged elements, frame floods, slow readers, connection churn",
    ),
    (
        "net-bcm",
        "socketcand broadcast manager: cyclic jobs for distinct identifiers until refused, subscriptions",
    ),
    (
        "net-slcan",
        "slcan over TCP: damaged and overlong lines, frame floods, slow readers, churn",
    ),
    (
        "net-http",
        "web dashboard HTTP: half-sent requests held open, garbage, huge headers, foreign Host/Origin, wrong content types",
    ),
    (
        "net-sse",
        "web dashboard event streams (/events) opened and never read, and churned",
    ),
    (
        "files",
        "cantwin eds check, dump and replay on mutated files, each a child under a deadline and an address space limit",
    ),
];

/// What one attack measured.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct AttackReport {
    /// The target.
    pub target: String,
    /// Attack actions tried (connections opened, elements, lines, requests, files run).
    pub attacks: u64,
    /// The most attack connections open at once (that the server had not closed).
    pub connections_held: usize,
    /// The child's resident memory before the attack, at its peak, and after (KiB).
    pub rss_kib: [u64; 3],
    /// The child's open descriptors before, at the peak and after.
    pub fds: [usize; 3],
    /// The good client's SDO round trips answered, and not answered within 1 s.
    pub probes: usize,
    /// Probes not answered within [`PROBE_TIMEOUT`].
    pub probe_failures: usize,
    /// Median and p99 of the good client's round trip (ms).
    pub latency_ms: [f64; 2],
    /// Facts that break the rule for servers (or file commands), as sentences.
    pub findings: Vec<String>,
    /// What the server answered, as sentences (e.g. how often it refused a BCM job).
    pub notes: Vec<String>,
    /// Wall time of the attack (s).
    pub seconds: f64,
}

/// The limits of a boundary campaign.
#[derive(Debug, Clone)]
pub struct Options {
    /// The `cantwin` binary to run as the server and for the file commands.
    pub exe: PathBuf,
    /// Wall time of each network attack.
    pub attack_time: Duration,
    /// Attack connections kept open at most.
    pub connections: usize,
    /// Mutated files per file command.
    pub files: usize,
    /// The campaign's seed.
    pub seed: u64,
    /// Scratch directory (the scenario file, mutated files).
    pub scratch: PathBuf,
}

/// Runs the named boundary targets (all of [`TARGETS`] when `names` is empty), one server
/// child for the network ones, and returns what each measured.
pub fn run(names: &[&str], opts: &Options) -> Result<Vec<AttackReport>> {
    std::fs::create_dir_all(&opts.scratch)
        .with_context(|| format!("creating {}", opts.scratch.display()))?;
    let chosen: Vec<&str> = TARGETS
        .iter()
        .map(|(n, _)| *n)
        .filter(|n| names.is_empty() || names.contains(n))
        .collect();
    let mut reports = Vec::new();
    let net: Vec<&str> = chosen.iter().copied().filter(|n| *n != "files").collect();
    if !net.is_empty() {
        let mut server = Server::start(opts)?;
        // The good client's figures without an attack, to compare the others with.
        let mut rng = SplitMix64::new(opts.seed);
        reports.push(attack(&mut server, "baseline", opts, &mut rng)?);
        for (k, name) in net.iter().enumerate() {
            let mut rng = SplitMix64::new(opts.seed ^ (k as u64 + 1).wrapping_mul(0x9E37));
            reports.push(attack(&mut server, name, opts, &mut rng)?);
        }
        server.stop();
    }
    if chosen.contains(&"files") {
        reports.push(files(opts)?);
    }
    Ok(reports)
}

/// The `cantwin sim` child and the addresses of its gateways.
struct Server {
    child: Child,
    socketcand: SocketAddr,
    slcan: SocketAddr,
    web: SocketAddr,
}

impl Server {
    fn start(opts: &Options) -> Result<Server> {
        let scenario = opts.scratch.join("boundary.toml");
        std::fs::write(&scenario, SCENARIO)?;
        // Under the descriptor limit of a common default (`ulimit -n 1024`), so that a server
        // without connection caps runs out of descriptors within the attack, as it would
        // for a user.
        let mut cmd = if have_prlimit() {
            let mut c = Command::new("prlimit");
            c.arg(format!("--nofile={SERVER_NOFILE}"))
                .arg("--")
                .arg(&opts.exe);
            c
        } else {
            Command::new(&opts.exe)
        };
        let mut child = cmd
            .args(["-q", "sim"])
            .arg(&scenario)
            .args(["--socketcand", "0", "--slcan", "0", "--web", "0"])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .with_context(|| format!("starting {} sim", opts.exe.display()))?;
        let stdout = child.stdout.take().ok_or_else(|| anyhow!("no stdout"))?;
        let (mut socketcand, mut slcan, mut web) = (None, None, None);
        for line in BufReader::new(stdout).lines() {
            let line = line?;
            let mut words = line.split_whitespace();
            match (words.next(), words.next()) {
                (Some("socketcand"), Some(a)) => socketcand = a.parse().ok(),
                (Some("slcan"), Some(a)) => slcan = a.parse().ok(),
                (Some("web"), Some(url)) => {
                    web = url
                        .trim_start_matches("http://")
                        .split('/')
                        .next()
                        .and_then(|a| a.parse().ok())
                }
                _ => {}
            }
            if socketcand.is_some() && slcan.is_some() && web.is_some() {
                break;
            }
        }
        let (Some(socketcand), Some(slcan), Some(web)) = (socketcand, slcan, web) else {
            let _ = child.kill();
            let _ = child.wait();
            bail!("cantwin sim did not print the addresses of its three gateways");
        };
        Ok(Server {
            child,
            socketcand,
            slcan,
            web,
        })
    }

    fn pid(&self) -> u32 {
        self.child.id()
    }

    fn alive(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    fn stop(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `VmRSS` of process `pid`, in KiB (0 where /proc is not there).
pub fn rss_kib(pid: u32) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("VmRSS:"))
                .and_then(|v| v.split_whitespace().next()?.parse().ok())
        })
        .unwrap_or(0)
}

/// `VmHWM` (peak resident memory) of process `pid`, in KiB (0 where /proc is not there).
fn hwm_kib(pid: u32) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.split_whitespace().next()?.parse().ok())
        })
        .unwrap_or(0)
}

/// Open descriptors of process `pid` (0 where /proc is not there).
pub fn fds(pid: u32) -> usize {
    std::fs::read_dir(format!("/proc/{pid}/fd")).map_or(0, |d| d.count())
}

/// A good socketcand client in raw mode reading 0x1018 sub 1 of node 5.
struct Probe {
    stream: TcpStream,
    buf: Vec<u8>,
}

impl Probe {
    fn connect(addr: SocketAddr) -> std::io::Result<Probe> {
        let stream = TcpStream::connect_timeout(&addr, PROBE_TIMEOUT)?;
        stream.set_nodelay(true)?;
        let mut p = Probe {
            stream,
            buf: Vec::new(),
        };
        let deadline = Instant::now() + PROBE_TIMEOUT;
        p.expect(b"< hi >", deadline)?;
        p.stream.write_all(b"< open can0 >")?;
        p.expect(b"< ok >", deadline)?;
        p.stream.write_all(b"< rawmode >")?;
        p.expect(b"< ok >", deadline)?;
        Ok(p)
    }

    /// Reads elements until one starting with `prefix`, by `deadline`.
    fn expect(&mut self, prefix: &[u8], deadline: Instant) -> std::io::Result<()> {
        loop {
            while let Some(end) = self.buf.iter().position(|b| *b == b'>') {
                let element: Vec<u8> = self.buf.drain(..=end).collect();
                let element = element.trim_ascii_start();
                if element.starts_with(prefix) {
                    return Ok(());
                }
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(ErrorKind::TimedOut.into());
            }
            self.stream.set_read_timeout(Some(left))?;
            let mut chunk = [0u8; 4096];
            match self.stream.read(&mut chunk) {
                Ok(0) => return Err(ErrorKind::UnexpectedEof.into()),
                Ok(n) => self.buf.extend_from_slice(&chunk[..n]),
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                    return Err(ErrorKind::TimedOut.into());
                }
                Err(e) => return Err(e),
            }
        }
    }

    /// One expedited SDO upload of 0x1018 sub 1 (CiA 301 §7.2.4.3.3): its round trip.
    fn upload(&mut self) -> std::io::Result<Duration> {
        let t = Instant::now();
        self.stream
            .write_all(b"< send 605 8 40 18 10 01 00 00 00 00 >")?;
        self.expect(b"< frame 585 ", t + PROBE_TIMEOUT)?;
        Ok(t.elapsed())
    }
}

/// The good client's probes during an attack, on a thread of their own.
struct Prober {
    stop: Arc<AtomicBool>,
    peak_rss: Arc<AtomicU64>,
    peak_fds: Arc<AtomicU64>,
    thread: std::thread::JoinHandle<(Vec<Duration>, usize)>,
}

impl Prober {
    fn start(addr: SocketAddr, pid: u32) -> Prober {
        let stop = Arc::new(AtomicBool::new(false));
        let peak_rss = Arc::new(AtomicU64::new(rss_kib(pid)));
        let peak_fds = Arc::new(AtomicU64::new(fds(pid) as u64));
        let (s, r, f) = (stop.clone(), peak_rss.clone(), peak_fds.clone());
        let thread = std::thread::spawn(move || {
            let mut times = Vec::new();
            let mut failures = 0;
            let mut probe = None;
            while !s.load(Ordering::Relaxed) {
                r.fetch_max(rss_kib(pid), Ordering::Relaxed);
                f.fetch_max(fds(pid) as u64, Ordering::Relaxed);
                if probe.is_none() {
                    probe = Probe::connect(addr).ok();
                }
                match probe.as_mut().map(Probe::upload) {
                    Some(Ok(t)) => times.push(t),
                    _ => {
                        failures += 1;
                        // A new connection for the next probe: the old one may hold a late
                        // answer.
                        probe = None;
                    }
                }
                std::thread::sleep(Duration::from_millis(10));
            }
            (times, failures)
        });
        Prober {
            stop,
            peak_rss,
            peak_fds,
            thread,
        }
    }

    fn finish(self) -> (Vec<Duration>, usize, u64, usize) {
        self.stop.store(true, Ordering::Relaxed);
        let (times, failures) = self.thread.join().unwrap_or_default();
        (
            times,
            failures,
            self.peak_rss.load(Ordering::Relaxed),
            self.peak_fds.load(Ordering::Relaxed) as usize,
        )
    }
}

fn percentile(sorted: &[Duration], p: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let k = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[k].as_secs_f64() * 1e3
}

fn below(rng: &mut SplitMix64, n: u64) -> u64 {
    if n == 0 { 0 } else { rng.next_u64() % n }
}

fn random_bytes(rng: &mut SplitMix64, n: usize) -> Vec<u8> {
    (0..n).map(|_| rng.next_u64() as u8).collect()
}

/// Flips, deletes, duplicates or inserts a few bytes of `seed`.
fn mutate(rng: &mut SplitMix64, seed: &[u8]) -> Vec<u8> {
    let mut v = seed.to_vec();
    for _ in 0..1 + below(rng, 8) {
        if v.is_empty() {
            v.push(rng.next_u64() as u8);
            continue;
        }
        let i = below(rng, v.len() as u64) as usize;
        match below(rng, 5) {
            0 => v[i] ^= 1 << below(rng, 8),
            1 => {
                v.remove(i);
            }
            2 => v.insert(i, rng.next_u64() as u8),
            3 => {
                let end = (i + 1 + below(rng, 16) as usize).min(v.len());
                let dup: Vec<u8> = v[i..end].to_vec();
                v.splice(i..i, dup);
            }
            _ => v[i] = b"<> 0123456789ABCDEF\r\n:"[below(rng, 22) as usize],
        }
    }
    v
}

/// An attack connection: writes never block the harness for long.
fn open(addr: SocketAddr) -> Option<TcpStream> {
    let s = TcpStream::connect_timeout(&addr, Duration::from_millis(500)).ok()?;
    s.set_write_timeout(Some(Duration::from_millis(20))).ok()?;
    s.set_nonblocking(false).ok()?;
    Some(s)
}

/// Whether the server closed `s` (a read sees the end, or a reset); drains what it sent.
fn closed(s: &mut TcpStream) -> bool {
    if s.set_nonblocking(true).is_err() {
        return true;
    }
    let mut buf = [0u8; 8192];
    let r = loop {
        match s.read(&mut buf) {
            Ok(0) => break true,
            Ok(_) => continue,
            Err(e) if e.kind() == ErrorKind::WouldBlock => break false,
            Err(_) => break true,
        }
    };
    let _ = s.set_nonblocking(false);
    r
}

/// The connections an attack holds, as slots it fills, uses, churns and counts.
struct Pool {
    conns: Vec<Option<TcpStream>>,
    held: usize,
}

impl Pool {
    fn new(n: usize) -> Pool {
        Pool {
            conns: (0..n).map(|_| None).collect(),
            held: 0,
        }
    }

    /// Counts the open connections the server still holds (dropping those it closed).
    fn count(&mut self) {
        let mut open = 0;
        for c in &mut self.conns {
            if let Some(s) = c {
                if closed(s) {
                    *c = None;
                } else {
                    open += 1;
                }
            }
        }
        self.held = self.held.max(open);
    }
}

/// Payloads of the socketcand raw-mode attack.
fn socketcand_payload(rng: &mut SplitMix64) -> Vec<u8> {
    const SEEDS: [&[u8]; 6] = [
        b"< open can0 >< rawmode >",
        b"< send 123 8 11 22 33 44 55 66 77 88 >",
        b"< send 1FFFFFFF 8 01 02 03 04 05 06 07 08 >",
        b"< send 705 1  >",
        b"< bcmmode >< add 0 1 123 8 1 2 3 4 5 6 7 8 >",
        b"< echo >< statistics 1 >",
    ];
    match below(rng, 6) {
        0 => {
            let n = 1 + below(rng, 512) as usize;
            random_bytes(rng, n)
        }
        1 => {
            // An element that never ends.
            let mut v = b"< send 123 8 ".to_vec();
            v.extend(std::iter::repeat_n(b'1', 4096 + below(rng, 8192) as usize));
            v
        }
        2 => {
            let mut v = Vec::new();
            for _ in 0..100 {
                v.extend_from_slice(
                    format!(
                        "< send {:03X} 8 de ad be ef 00 11 22 33 >",
                        0x100 + below(rng, 0x500)
                    )
                    .as_bytes(),
                );
            }
            v
        }
        _ => {
            let seed = SEEDS[below(rng, SEEDS.len() as u64) as usize];
            mutate(rng, seed)
        }
    }
}

/// Payloads of the slcan attack.
fn slcan_payload(rng: &mut SplitMix64) -> Vec<u8> {
    const SEEDS: [&[u8]; 6] = [
        b"S6\rO\r",
        b"t12381122334455667788\r",
        b"T1FFFFFFF80102030405060708\r",
        b"r1238\r",
        b"V\rN\rF\rC\r",
        b"t6058401810010000000\r",
    ];
    match below(rng, 6) {
        0 => {
            let n = 1 + below(rng, 512) as usize;
            random_bytes(rng, n)
        }
        1 => vec![b'T'; 4096 + below(rng, 8192) as usize],
        2 => {
            let mut v = b"O\r".to_vec();
            for _ in 0..100 {
                v.extend_from_slice(
                    format!("t{:03X}8DEADBEEF00112233\r", 0x100 + below(rng, 0x500)).as_bytes(),
                );
            }
            v
        }
        _ => {
            let seed = SEEDS[below(rng, SEEDS.len() as u64) as usize];
            mutate(rng, seed)
        }
    }
}

/// Payloads of the HTTP attack on the dashboard at `web`.
fn http_payload(rng: &mut SplitMix64, web: SocketAddr) -> Vec<u8> {
    let host = format!("127.0.0.1:{}", web.port());
    match below(rng, 8) {
        // Half a request, never finished (held open by the server until its header timeout).
        0 => format!("GET / HTTP/1.1\r\nHost: {host}\r\nX-Slow: ").into_bytes(),
        1 => {
            let n = 1 + below(rng, 1024) as usize;
            random_bytes(rng, n)
        },
        2 => {
            let mut v = format!("GET / HTTP/1.1\r\nHost: {host}\r\nX-Big: ").into_bytes();
            v.extend(std::iter::repeat_n(b'a', 64 * 1024));
            v.extend_from_slice(b"\r\n\r\n");
            v
        }
        3 => b"POST /api/nmt HTTP/1.1\r\nHost: attacker.example\r\nOrigin: http://attacker.example\r\nContent-Type: text/plain\r\nContent-Length: 30\r\n\r\n{\"node\":5,\"command\":\"stop\"}  ".to_vec(),
        4 => format!("POST /api/power HTTP/1.1\r\nHost: {host}\r\nContent-Type: application/json\r\nContent-Length: 1000000\r\n\r\n{{").into_bytes(),
        5 => format!("GET /api/snapshot HTTP/1.1\r\nHost: {host}\r\n\r\n").into_bytes(),
        6 => format!("GET /../../etc/passwd HTTP/1.1\r\nHost: {host}\r\n\r\n").into_bytes(),
        _ => mutate(
            rng,
            format!("GET /api/snapshot HTTP/1.1\r\nHost: {host}\r\nConnection: keep-alive\r\n\r\n")
                .as_bytes(),
        ),
    }
}

/// Fills and churns a pool of connections to `addr` with `payload`s until `deadline`.
fn flood(
    addr: SocketAddr,
    pool: &mut Pool,
    rng: &mut SplitMix64,
    deadline: Instant,
    mut payload: impl FnMut(&mut SplitMix64) -> Vec<u8>,
) -> u64 {
    let mut tried = 0u64;
    let mut since_count = 0;
    while Instant::now() < deadline {
        let k = below(rng, pool.conns.len() as u64) as usize;
        match below(rng, 10) {
            // Churn: close a connection.
            0 => pool.conns[k] = None,
            // A slow reader: a connection that is written to but never read from.
            _ => {
                if pool.conns[k].is_none() {
                    pool.conns[k] = open(addr);
                    tried += 1;
                }
                if let Some(s) = &mut pool.conns[k] {
                    let data = payload(rng);
                    if s.write_all(&data).is_err() {
                        pool.conns[k] = None;
                    }
                    tried += 1;
                }
            }
        }
        since_count += 1;
        if since_count >= 64 {
            pool.count();
            since_count = 0;
        }
    }
    pool.count();
    tried
}

/// Counts `< error` elements in what `s` has sent so far (without blocking); whether the
/// server closed it.
fn count_errors(s: &mut TcpStream, errors: &mut u64, tail: &mut Vec<u8>) -> bool {
    if s.set_nonblocking(true).is_err() {
        return true;
    }
    let mut buf = [0u8; 65536];
    let closed = loop {
        match s.read(&mut buf) {
            Ok(0) => break true,
            Ok(n) => {
                tail.extend_from_slice(&buf[..n]);
                *errors += tail.windows(7).filter(|w| w == b"< error").count() as u64;
                // Keep the end, in case an element is cut between two reads.
                let keep = tail.len().min(6);
                tail.drain(..tail.len() - keep);
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => break false,
            Err(_) => break true,
        }
    };
    let _ = s.set_nonblocking(false);
    closed
}

/// Cyclic BCM jobs for distinct identifiers on a few connections until the deadline or
/// the server refuses them (its error answer), and subscriptions. Returns the jobs sent,
/// the error answers and the connections the server closed.
fn bcm(
    addr: SocketAddr,
    pool: &mut Pool,
    rng: &mut SplitMix64,
    deadline: Instant,
) -> (u64, u64, usize) {
    let mut tried = 0u64;
    let mut errors = 0u64;
    let mut closed_by_server = 0;
    let mut tails: Vec<Vec<u8>> = vec![Vec::new(); pool.conns.len()];
    let lanes = pool.conns.len().min(4);
    for c in pool.conns.iter_mut().take(lanes) {
        if let Some(mut s) = open(addr) {
            let _ = s.write_all(b"< open can0 >");
            *c = Some(s);
        }
    }
    let mut id = 0u32;
    'outer: while Instant::now() < deadline {
        if pool.conns.iter().take(lanes).all(Option::is_none) {
            break;
        }
        for (c, tail) in pool.conns.iter_mut().zip(&mut tails).take(lanes) {
            let Some(s) = c else { continue };
            let mut batch = Vec::new();
            for _ in 0..200 {
                id = (id + 1) % 0x2000_0000;
                // One job per identifier, every 1 s (extended identifiers: 8 hex digits).
                batch.extend_from_slice(
                    format!("< add 1 0 {id:08X} 8 1 2 3 4 5 6 7 8 >").as_bytes(),
                );
                if below(rng, 8) == 0 {
                    batch.extend_from_slice(format!("< subscribe 0 0 {id:08X} >").as_bytes());
                }
                tried += 1;
            }
            if s.write_all(&batch).is_err() || count_errors(s, &mut errors, tail) {
                let _ = count_errors(s, &mut errors, tail);
                *c = None;
                closed_by_server += 1;
            }
            if Instant::now() >= deadline {
                break 'outer;
            }
        }
    }
    for (c, tail) in pool.conns.iter_mut().zip(&mut tails).take(lanes) {
        if let Some(s) = c {
            let _ = count_errors(s, &mut errors, tail);
        }
    }
    pool.count();
    (tried, errors, closed_by_server)
}

/// One network attack on the running server, with its measurements and findings.
fn attack(
    server: &mut Server,
    name: &str,
    opts: &Options,
    rng: &mut SplitMix64,
) -> Result<AttackReport> {
    let pid = server.pid();
    let started = Instant::now();
    let rss_before = rss_kib(pid);
    let fds_before = fds(pid);
    let prober = Prober::start(server.socketcand, pid);
    let deadline = Instant::now() + opts.attack_time;
    let mut pool = Pool::new(opts.connections.max(1));
    let mut notes = Vec::new();
    let attacks = match name {
        "net-socketcand" => flood(
            server.socketcand,
            &mut pool,
            rng,
            deadline,
            socketcand_payload,
        ),
        "net-bcm" => {
            let (jobs, errors, closed) = bcm(server.socketcand, &mut pool, rng, deadline);
            notes.push(format!(
                "{jobs} add jobs sent on 4 connections; {errors} error answers; {closed} connections closed by the server"
            ));
            jobs
        }
        "net-slcan" => flood(server.slcan, &mut pool, rng, deadline, slcan_payload),
        "net-http" => {
            let web = server.web;
            flood(web, &mut pool, rng, deadline, |r| http_payload(r, web))
        }
        "net-sse" => {
            let host = format!("127.0.0.1:{}", server.web.port());
            flood(server.web, &mut pool, rng, deadline, |r| {
                if below(r, 4) == 0 {
                    mutate(
                        r,
                        format!("GET /events HTTP/1.1\r\nHost: {host}\r\n\r\n").as_bytes(),
                    )
                } else {
                    format!(
                        "GET /events HTTP/1.1\r\nHost: {host}\r\nAccept: text/event-stream\r\n\r\n"
                    )
                    .into_bytes()
                }
            })
        }
        "baseline" => {
            std::thread::sleep(opts.attack_time);
            0
        }
        other => bail!("no boundary target {other:?}"),
    };
    let held = pool.held;
    drop(pool);
    let (mut times, failures, peak_rss, peak_fds) = prober.finish();
    // The attack's connections are closed: give the server a moment to let them go.
    std::thread::sleep(Duration::from_millis(300));
    times.sort();
    let alive = server.alive();
    let after_ok = alive && {
        let until = Instant::now() + AFTER_ATTACK;
        loop {
            let answered = Probe::connect(server.socketcand)
                .and_then(|mut p| p.upload())
                .is_ok();
            if answered || Instant::now() >= until {
                break answered;
            }
        }
    };
    let rss_after = rss_kib(pid);
    // A server learns that an event-stream client left only when its next write fails: give
    // descriptors up to FD_SETTLE to come back before counting what is still held.
    let settle_until = Instant::now() + FD_SETTLE;
    let mut fds_after = fds(pid);
    while fds_after > fds_before + FD_GROWTH && Instant::now() < settle_until {
        std::thread::sleep(Duration::from_millis(100));
        fds_after = fds(pid);
    }
    let mut r = AttackReport {
        target: name.to_string(),
        attacks,
        connections_held: held,
        rss_kib: [rss_before, peak_rss.max(rss_after), rss_after],
        fds: [fds_before, peak_fds.max(fds_after), fds_after],
        probes: times.len(),
        probe_failures: failures,
        latency_ms: [percentile(&times, 0.5), percentile(&times, 0.99)],
        findings: Vec::new(),
        notes,
        seconds: started.elapsed().as_secs_f64(),
    };
    if !alive {
        r.findings.push("the server process died".into());
    } else if !after_ok {
        r.findings.push(format!(
            "after the attack a new good client got no SDO answer within {} s",
            AFTER_ATTACK.as_secs()
        ));
    }
    if failures > 0 {
        r.findings.push(format!(
            "the good client got no SDO answer within 1 s {failures} times during the attack"
        ));
    }
    if r.latency_ms[1] > SLOW_MS {
        r.findings.push(format!(
            "the good client's p99 SDO round trip was {:.1} ms",
            r.latency_ms[1]
        ));
    }
    if rss_after > rss_before + RSS_GROWTH_KIB {
        r.findings.push(format!(
            "resident memory grew from {rss_before} KiB to {rss_after} KiB and stayed there"
        ));
    }
    if fds_after > fds_before + FD_GROWTH {
        r.findings.push(format!(
            "open descriptors went from {fds_before} to {fds_after} after the attack closed its connections"
        ));
    }
    Ok(r)
}

/// The outcome of one file command run as a child.
struct Run {
    seconds: f64,
    /// The child's peak resident memory as last seen (`VmHWM`, KiB).
    peak_kib: u64,
    timed_out: bool,
    /// Killed by a signal other than the harness's own (the address space limit makes an
    /// allocation fail: abort).
    signal: Option<i32>,
    panicked: bool,
}

/// How long a file command may take on a small mutated file.
const FILE_DEADLINE: Duration = Duration::from_secs(10);
/// The address space a file command may use (RLIMIT_AS through `prlimit`, when installed).
const FILE_AS_LIMIT: u64 = 2 << 30;

fn run_limited(opts: &Options, args: &[&std::ffi::OsStr], prlimit: bool) -> Result<Run> {
    let mut cmd = if prlimit {
        let mut c = Command::new("prlimit");
        c.arg(format!("--as={FILE_AS_LIMIT}"))
            .arg("--")
            .arg(&opts.exe);
        c
    } else {
        Command::new(&opts.exe)
    };
    let started = Instant::now();
    let mut child = cmd
        .arg("-q")
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .context("running a file command")?;
    let mut stderr = child.stderr.take().ok_or_else(|| anyhow!("no stderr"))?;
    let reader = std::thread::spawn(move || {
        let mut text = Vec::new();
        let _ = (&mut stderr).take(1 << 20).read_to_end(&mut text);
        String::from_utf8_lossy(&text).into_owned()
    });
    let mut timed_out = false;
    let mut peak_kib = 0;
    let status = loop {
        // `prlimit` sets the limit and executes the command: the same process.
        peak_kib = peak_kib.max(hwm_kib(child.id()));
        if let Some(s) = child.try_wait()? {
            break s;
        }
        if started.elapsed() > FILE_DEADLINE {
            timed_out = true;
            let _ = child.kill();
            break child.wait()?;
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let text = reader.join().unwrap_or_default();
    #[cfg(unix)]
    let signal = {
        use std::os::unix::process::ExitStatusExt;
        status.signal().filter(|_| !timed_out)
    };
    #[cfg(not(unix))]
    let signal = None;
    Ok(Run {
        seconds: started.elapsed().as_secs_f64(),
        peak_kib,
        timed_out,
        signal,
        panicked: text.contains("panicked"),
    })
}

fn have_prlimit() -> bool {
    Command::new("prlimit")
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// A small valid capture: 40 frames of a CANopen exchange, as a pcap (LINKTYPE_CAN_SOCKETCAN).
fn seed_pcap() -> Vec<u8> {
    let mut v = Vec::new();
    v.extend_from_slice(&0xA1B2_C3D4u32.to_le_bytes());
    v.extend_from_slice(&2u16.to_le_bytes());
    v.extend_from_slice(&4u16.to_le_bytes());
    v.extend_from_slice(&0u32.to_le_bytes());
    v.extend_from_slice(&0u32.to_le_bytes());
    v.extend_from_slice(&65535u32.to_le_bytes());
    v.extend_from_slice(&227u32.to_le_bytes());
    for k in 0..40u32 {
        let (id, data): (u32, [u8; 8]) = if k % 2 == 0 {
            (0x605, [0x40, 0x18, 0x10, 0x01, 0, 0, 0, 0])
        } else {
            (0x585, [0x43, 0x18, 0x10, 0x01, 0xA7, 0x0C, 0, 0])
        };
        v.extend_from_slice(&(1_700_000_000 + k / 10).to_le_bytes());
        v.extend_from_slice(&((k % 10) * 100_000).to_le_bytes());
        v.extend_from_slice(&16u32.to_le_bytes());
        v.extend_from_slice(&16u32.to_le_bytes());
        // SocketCAN frame: identifier big-endian, DLC, three bytes of padding, data.
        v.extend_from_slice(&id.to_be_bytes());
        v.extend_from_slice(&[8, 0, 0, 0]);
        v.extend_from_slice(&data);
    }
    v
}

fn seed_candump() -> Vec<u8> {
    let mut s = String::new();
    for k in 0..40 {
        let line = if k % 2 == 0 {
            "605#4018100100000000"
        } else {
            "585#43181001A70C0000"
        };
        s.push_str(&format!("(1700000000.{:06}) can0 {line}\n", k * 50_000));
    }
    s.into_bytes()
}

const SEED_EDS: &str = include_str!("../../../../scenarios/eds/example-io.eds");

/// The file commands on mutated files.
fn files(opts: &Options) -> Result<AttackReport> {
    let started = Instant::now();
    let prlimit = have_prlimit();
    let mut rng = SplitMix64::new(opts.seed ^ 0xF11E5);
    let scenario = opts.scratch.join("boundary.toml");
    std::fs::write(&scenario, SCENARIO)?;
    let mut r = AttackReport {
        target: "files".into(),
        ..AttackReport::default()
    };
    let seeds: [(&str, Vec<u8>); 3] = [
        ("eds", SEED_EDS.as_bytes().to_vec()),
        ("pcap", seed_pcap()),
        ("log", seed_candump()),
    ];
    let mut slowest = 0.0f64;
    for k in 0..opts.files {
        let (ext, seed) = &seeds[k % seeds.len()];
        let file = opts.scratch.join(format!("mutated-{k}.{ext}"));
        let bytes = if k < seeds.len() {
            seed.clone()
        } else {
            mutate(&mut rng, seed)
        };
        std::fs::write(&file, &bytes)?;
        let commands: Vec<Vec<&std::ffi::OsStr>> = if *ext == "eds" {
            vec![vec!["eds".as_ref(), "check".as_ref(), file.as_os_str()]]
        } else {
            vec![
                vec!["dump".as_ref(), file.as_os_str()],
                vec![
                    "replay".as_ref(),
                    "--scenario".as_ref(),
                    scenario.as_os_str(),
                    file.as_os_str(),
                ],
            ]
        };
        for args in commands {
            let run = run_limited(opts, &args, prlimit)?;
            r.attacks += 1;
            slowest = slowest.max(run.seconds);
            r.rss_kib[1] = r.rss_kib[1].max(run.peak_kib);
            let what = || {
                format!(
                    "cantwin {} on {}",
                    args.iter()
                        .take(1)
                        .map(|a| a.to_string_lossy())
                        .collect::<String>(),
                    file.display()
                )
            };
            if run.timed_out {
                r.findings
                    .push(format!("{} ran past {} s", what(), FILE_DEADLINE.as_secs()));
            }
            if run.panicked {
                r.findings.push(format!("{} panicked", what()));
            }
            if let Some(sig) = run.signal {
                r.findings.push(format!(
                    "{} was killed by signal {sig} (with RLIMIT_AS {} MiB: {prlimit})",
                    what(),
                    FILE_AS_LIMIT >> 20
                ));
            }
        }
        let _ = std::fs::remove_file(&file);
    }
    // For the file commands the latency figure is the slowest run, the memory peak the
    // largest a child reached.
    r.latency_ms = [0.0, slowest * 1e3];
    r.notes.push(format!(
        "{} runs; slowest {:.0} ms; largest peak resident memory {} KiB; RLIMIT_AS {}",
        r.attacks,
        slowest * 1e3,
        r.rss_kib[1],
        if prlimit {
            format!("{} MiB", FILE_AS_LIMIT >> 20)
        } else {
            "not set (no prlimit)".into()
        }
    ));
    r.seconds = started.elapsed().as_secs_f64();
    Ok(r)
}

/// A scratch directory for a campaign.
pub fn scratch_dir() -> PathBuf {
    std::env::temp_dir().join(format!("cantwin-boundary-{}", std::process::id()))
}

/// Removes a campaign's scratch directory.
pub fn remove_scratch(dir: &Path) {
    let _ = std::fs::remove_dir_all(dir);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_are_valid_inputs_for_their_commands() {
        let pcap = seed_pcap();
        let mut r = cantwin_capture::CaptureReader::new(std::io::Cursor::new(&pcap)).unwrap();
        let mut n = 0;
        while r.read_record().unwrap().is_some() {
            n += 1;
        }
        assert_eq!(n, 40);
        assert!(cantwin_eds::parse(SEED_EDS).is_ok());
    }

    #[test]
    fn percentiles_of_sorted_round_trips() {
        let t: Vec<Duration> = (1..=100).map(Duration::from_millis).collect();
        assert_eq!(percentile(&t, 0.5), 51.0);
        assert_eq!(percentile(&t, 0.99), 99.0);
        assert_eq!(percentile(&[], 0.99), 0.0);
    }
}
