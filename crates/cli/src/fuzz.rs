//! `cantwin fuzz`: property-based fuzzing, on stable Rust, of every decoder and state
//! machine that reads outside input. Each case is seeded from the campaign seed and the
//! case number, so a failure replays with `--seed S --from N --cases 1`; the property
//! checked is the project's rule that bad input gets the protocol's own answer or a clear
//! error, never a panic (decoders) or a stuck simulation (twins). Results go through
//! `black_box` so an optimised build cannot skip a decoder whose result is unused.

use std::hint::black_box;
use std::io::Cursor;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::time::Instant as WallInstant;

use anyhow::{Result, bail};
use cantwin_bus::{PortConfig, Recorder, SplitMix64};
use cantwin_can::{Duration, Frame, Id, Instant, Node, Outbox};
use cantwin_scenario::{BuildEnv, Registry, Scenario};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Cases per target.
    #[arg(long, default_value_t = 1000)]
    cases: u64,
    /// The campaign's seed (decimal or 0x-prefixed hexadecimal).
    #[arg(long, default_value = "0xC0FFEE", value_parser = parse_seed)]
    seed: u64,
    /// The first case number (to replay a reported failure).
    #[arg(long, default_value_t = 0)]
    from: u64,
    /// Targets to run (default: all). `cantwin fuzz --list` names them.
    targets: Vec<String>,
    /// List the targets and exit.
    #[arg(long)]
    list: bool,
}

fn parse_seed(s: &str) -> Result<u64, String> {
    match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(hex) => u64::from_str_radix(hex, 16),
        None => s.parse(),
    }
    .map_err(|e| format!("{s:?}: {e}"))
}

/// One fuzz target: a name, what it feeds, and the function that runs case `rng`.
struct Target {
    name: &'static str,
    about: &'static str,
    run: fn(&mut SplitMix64),
}

const SCENARIO_CIA301: &str = include_str!("../../../scenarios/cia301-device.toml");
const SCENARIO_OPENDRIVE: &str = include_str!("../../../scenarios/opendrive.toml");
const SCENARIO_ADV200_DNET: &str = include_str!("../../../scenarios/adv200-devicenet.toml");
const SCENARIO_ADV200_DS402: &str = include_str!("../../../scenarios/adv200-ds402.toml");
const SCENARIO_TM3: &str = include_str!("../../../scenarios/tm3-island.toml");
const EDS_DRIVE: &str = include_str!("../../eds/tests/corpus/drive.eds");
const EDS_IO: &str = include_str!("../../eds/tests/corpus/io_module.eds");
const EDS_QUIRKS: &str = include_str!("../../eds/tests/corpus/quirks.eds");
const EDS_ADV200: &str = include_str!("../../adv200/eds/adv200-ds402.eds");

fn targets() -> Vec<Target> {
    vec![
        Target {
            name: "canopen-wire",
            about: "CiA 301 frame decoders: NMT, error control, SYNC, TIME, EMCY, SDO requests, responses and block segments",
            run: canopen_wire,
        },
        Target {
            name: "socketcand",
            about: "socketcand protocol elements from clients and servers",
            run: socketcand,
        },
        Target {
            name: "slcan",
            about: "slcan (Lawicel) command and frame lines",
            run: slcan,
        },
        Target {
            name: "capture",
            about: "pcap, pcapng and candump readers on damaged files",
            run: capture,
        },
        Target {
            name: "eds",
            about: "CiA 306 EDS/DCF parser on mutated EDS files",
            run: eds,
        },
        Target {
            name: "scenario",
            about: "scenario parser and builder on mutated scenario files",
            run: scenario,
        },
        Target {
            name: "twin-cia301",
            about: "CiA 301 device (SDO server, NMT, PDO, storage commands) fed random frames",
            run: |r| twin(r, SCENARIO_CIA301),
        },
        Target {
            name: "twin-opendrive",
            about: "OPEN DRIVE CAL server fed random frames",
            run: |r| twin(r, SCENARIO_OPENDRIVE),
        },
        Target {
            name: "twin-adv200-devicenet",
            about: "ADV200 DeviceNet slave (explicit and I/O messaging) fed random frames",
            run: |r| twin(r, SCENARIO_ADV200_DNET),
        },
        Target {
            name: "twin-adv200-ds402",
            about: "ADV200 CiA 402 drive fed random frames",
            run: |r| twin(r, SCENARIO_ADV200_DS402),
        },
        Target {
            name: "twin-tm3",
            about: "TM3 CANopen island fed random frames",
            run: |r| twin(r, SCENARIO_TM3),
        },
    ]
}

fn bytes(rng: &mut SplitMix64, max: usize) -> Vec<u8> {
    let n = (rng.next_u64() as usize) % (max + 1);
    (0..n).map(|_| rng.next_u64() as u8).collect()
}

fn below(rng: &mut SplitMix64, n: u64) -> u64 {
    rng.next_u64() % n.max(1)
}

/// A random classic frame; identifiers biased to `near` (seen on the bus) when given.
fn frame(rng: &mut SplitMix64, near: &[u16]) -> Frame {
    let raw: u16 = match (below(rng, 4), near.is_empty()) {
        (0, _) | (_, true) => below(rng, 0x800) as u16,
        (1, false) => {
            // A request to the node whose response was seen (0x580 + n → 0x600 + n).
            let x = near[below(rng, near.len() as u64) as usize];
            0x600 | (x & 0x7F)
        }
        (2, false) => [0x000, 0x080, 0x100][below(rng, 3) as usize],
        _ => {
            let x = near[below(rng, near.len() as u64) as usize];
            (x ^ (below(rng, 4) as u16)) & 0x7FF
        }
    };
    let id = Id::standard(raw).unwrap_or(Id::Standard(cantwin_can::StandardId::MAX));
    if below(rng, 16) == 0 {
        return Frame::remote(id, below(rng, 9) as u8)
            .unwrap_or_else(|_| Frame::data_array(id, []));
    }
    let data = bytes(rng, 8);
    Frame::data(id, &data).unwrap_or_else(|_| Frame::data_array(id, []))
}

/// Mutates text: byte flips, deletions, duplications, digit and line swaps.
fn mutate(rng: &mut SplitMix64, seed: &str) -> Vec<u8> {
    let mut b = seed.as_bytes().to_vec();
    for _ in 0..1 + below(rng, 8) {
        if b.is_empty() {
            b.push(rng.next_u64() as u8);
            continue;
        }
        let i = below(rng, b.len() as u64) as usize;
        match below(rng, 6) {
            0 => b[i] = rng.next_u64() as u8,
            1 => {
                let end = (i + 1 + below(rng, 64) as usize).min(b.len());
                b.drain(i..end);
            }
            2 => {
                let end = (i + 1 + below(rng, 64) as usize).min(b.len());
                let chunk = b[i..end].to_vec();
                b.splice(i..i, chunk);
            }
            3 => {
                // A digit run replaced by an extreme number.
                let n = [
                    "0",
                    "255",
                    "65535",
                    "4294967295",
                    "-1",
                    "99999999999999999999",
                    "0x7FF",
                ][below(rng, 7) as usize];
                if b[i].is_ascii_digit() {
                    let end = (i..b.len())
                        .find(|&j| !b[j].is_ascii_digit())
                        .unwrap_or(b.len());
                    b.splice(i..end, n.bytes());
                }
            }
            4 => b.insert(
                i,
                [b'\n', b'=', b'[', b']', b'"', b'#', 0][below(rng, 7) as usize],
            ),
            _ => b.truncate(i),
        }
    }
    b
}

fn canopen_wire(rng: &mut SplitMix64) {
    use cantwin_canopen::sdo::wire::{BlockSegment, Request, Response};
    use cantwin_canopen::wire::{self, Emcy, ErrorControl, NmtCommand, Sync, Time};
    let f = frame(rng, &[]);
    let _ = black_box(NmtCommand::decode(&f));
    let _ = black_box(ErrorControl::decode(&f, below(rng, 128) as u8));
    let _ = black_box(Sync::decode(&f));
    let _ = black_box(Time::decode(&f));
    let _ = black_box(Emcy::decode(&f));
    let m = wire::decode(&f);
    let _ = black_box(m.sdo_request());
    let _ = black_box(m.sdo_response());
    let mut b = [0u8; 8];
    b.iter_mut().for_each(|x| *x = rng.next_u64() as u8);
    let _ = black_box(Request::decode(&b));
    let _ = black_box(Response::decode(&b));
    let _ = black_box(BlockSegment::decode(&b));
}

const SOCKETCAND_SEEDS: &[&str] = &[
    "< open can0 >",
    "< send 123 8 11 22 33 44 55 66 77 88 >",
    "< rawmode >",
    "< frame 123 23.424242 11 22 33 44 >",
    "< hi >",
    "< ok >",
    "< error bad >",
    "< add 1 0 123 8 11 22 33 44 55 66 77 88 >",
    "< echo >",
];

fn socketcand(rng: &mut SplitMix64) {
    use cantwin_gateway::socketcand::wire::{parse_command, parse_server_message};
    let input = if below(rng, 4) == 0 {
        bytes(rng, 64)
    } else {
        let seed = SOCKETCAND_SEEDS[below(rng, SOCKETCAND_SEEDS.len() as u64) as usize];
        mutate(rng, seed)
    };
    let _ = black_box(parse_command(&input));
    let _ = black_box(parse_server_message(&input));
}

const SLCAN_SEEDS: &[&str] = &[
    "t12381122334455667788",
    "T1234567F2AABB",
    "r1230",
    "R123456780",
    "S6",
    "O",
    "C",
    "V",
    "F",
    "Z1",
];

fn slcan(rng: &mut SplitMix64) {
    use cantwin_gateway::slcan::wire::{parse_command, parse_frame};
    let input = if below(rng, 4) == 0 {
        bytes(rng, 40)
    } else {
        let seed = SLCAN_SEEDS[below(rng, SLCAN_SEEDS.len() as u64) as usize];
        mutate(rng, seed)
    };
    let _ = black_box(parse_command(&input));
    let _ = black_box(parse_frame(&input));
}

/// A small valid capture of each format, written with the capture crate's writers.
fn capture_seed(rng: &mut SplitMix64) -> Vec<u8> {
    let pcap_header: [u8; 24] = [
        0xD4, 0xC3, 0xB2, 0xA1, 2, 0, 4, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 4, 0, 227, 0, 0, 0,
    ];
    match below(rng, 3) {
        0 => {
            let mut v = pcap_header.to_vec();
            // One record: ts, caplen 16, len 16, SocketCAN header + 8 bytes.
            v.extend_from_slice(&[1, 0, 0, 0, 2, 0, 0, 0, 16, 0, 0, 0, 16, 0, 0, 0]);
            v.extend_from_slice(&[0, 0, 0x01, 0x23, 8, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8]);
            v
        }
        1 => {
            // pcapng: section header block, interface description block (LINKTYPE 227).
            let mut v = vec![
                0x0A, 0x0D, 0x0D, 0x0A, 28, 0, 0, 0, 0x4D, 0x3C, 0x2B, 0x1A, 1, 0, 0, 0,
            ];
            v.extend_from_slice(&[0xFF; 8]);
            v.extend_from_slice(&[28, 0, 0, 0]);
            v.extend_from_slice(&[
                1, 0, 0, 0, 20, 0, 0, 0, 227, 0, 0, 0, 0, 0, 4, 0, 20, 0, 0, 0,
            ]);
            v
        }
        _ => b"(1700000000.000000) can0 123#1122334455667788\n(1700000000.100000) can0 705#7F\n"
            .to_vec(),
    }
}

fn capture(rng: &mut SplitMix64) {
    let seed = capture_seed(rng);
    let text = String::from_utf8_lossy(&seed).into_owned();
    let input = if below(rng, 8) == 0 {
        bytes(rng, 256)
    } else {
        let mut m = mutate(rng, &text);
        if !seed.is_ascii() {
            // Lossy text would have replaced the binary bytes: mutate the bytes directly.
            m = seed.clone();
            for _ in 0..1 + below(rng, 6) {
                if m.is_empty() {
                    break;
                }
                let i = below(rng, m.len() as u64) as usize;
                match below(rng, 3) {
                    0 => m[i] = rng.next_u64() as u8,
                    1 => m.truncate(i),
                    _ => m.extend(bytes(rng, 40)),
                }
            }
        }
        m
    };
    if let Ok(reader) = cantwin_capture::CaptureReader::new(Cursor::new(input)) {
        // Bounded: a damaged length field must not make the reader loop forever.
        for record in reader.take(10_000) {
            if record.is_err() {
                break;
            }
        }
    }
}

fn eds(rng: &mut SplitMix64) {
    let seed = [EDS_DRIVE, EDS_IO, EDS_QUIRKS, EDS_ADV200][below(rng, 4) as usize];
    let input = mutate(rng, seed);
    let _ = black_box(cantwin_eds::parse_bytes(&input));
}

fn scenario(rng: &mut SplitMix64) {
    let seed = [
        SCENARIO_CIA301,
        SCENARIO_OPENDRIVE,
        SCENARIO_ADV200_DNET,
        SCENARIO_TM3,
    ][below(rng, 4) as usize];
    let input = mutate(rng, seed);
    let Ok(text) = String::from_utf8(input) else {
        return;
    };
    if let Ok(s) = Scenario::parse(&text, "fuzz.toml") {
        let _ = black_box(s.build(&Registry::builtin(), &BuildEnv::default()));
    }
}

/// A port that only listens (and acknowledges), through which the fuzzer sends.
struct Injector;

impl Node for Injector {
    fn on_frame(&mut self, _frame: &Frame, _now: Instant, _out: &mut Outbox) {}
    fn on_tick(&mut self, _now: Instant, _out: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

/// Builds the scenario, lets it run 20 ms, then sends 1–64 random frames at random times
/// over 50 ms (identifiers biased to those the twins sent) and runs 100 ms more.
fn twin(rng: &mut SplitMix64, text: &str) {
    let Ok(s) = Scenario::parse(text, "fuzz.toml") else {
        panic!("the seed scenario does not parse");
    };
    let Ok(mut built) = s.build(&Registry::builtin(), &BuildEnv::default()) else {
        panic!("the seed scenario does not build");
    };
    let Some((_, bus_id)) = built.buses.first().cloned() else {
        return;
    };
    let Some(bus) = built.sim.bus_mut(bus_id) else {
        return;
    };
    let port = bus.attach(Injector, PortConfig::default().with_queue_depth(128));
    let tap = bus.add_tap(Recorder::new());
    built.sim.run_for(Duration::from_millis(20));
    let mut near: Vec<u16> = built
        .sim
        .bus(bus_id)
        .and_then(|b| b.tap::<Recorder>(tap))
        .map(|r| {
            r.frames()
                .filter_map(|f| match f.frame.id() {
                    Id::Standard(s) => Some(s.as_raw()),
                    Id::Extended(_) => None,
                })
                .collect()
        })
        .unwrap_or_default();
    near.sort_unstable();
    near.dedup();
    let n = 1 + below(rng, 64);
    let mut times: Vec<u64> = (0..n).map(|_| below(rng, 50_000_000)).collect();
    times.sort_unstable();
    let start = built.sim.now();
    for t in times {
        built.sim.run_until(start + Duration::from_nanos(t));
        let f = frame(rng, &near);
        // A full queue is an answer too (the frame is dropped and counted).
        let _ = built.sim.transmit(port, f);
    }
    built.sim.run_for(Duration::from_millis(100));
}

/// Outcome of a target's campaign.
pub struct TargetResult {
    /// The target.
    pub name: &'static str,
    /// Cases run.
    pub cases: u64,
    /// Failing cases: (case number, panic message).
    pub failures: Vec<(u64, String)>,
    /// Wall time.
    pub seconds: f64,
}

fn case_seed(seed: u64, target: &str, case: u64) -> u64 {
    let mut h = SplitMix64::new(seed ^ case.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let mut x = h.next_u64();
    for b in target.bytes() {
        x = (x ^ u64::from(b)).wrapping_mul(0x0100_0000_01B3);
    }
    x
}

/// Runs `cases` cases of each selected target.
pub fn campaign(
    names: &[String],
    seed: u64,
    from: u64,
    cases: u64,
    bar: &indicatif::ProgressBar,
    mut progress: impl FnMut(&TargetResult),
) -> Result<Vec<TargetResult>> {
    let all = targets();
    for n in names {
        if !all.iter().any(|t| t.name == n) {
            let known: Vec<&str> = all.iter().map(|t| t.name).collect();
            bail!("no fuzz target {n:?} (targets: {})", known.join(", "));
        }
    }
    let previous = std::panic::take_hook();
    // Panics are collected as failures with their message, not printed as they happen.
    std::panic::set_hook(Box::new(|_| {}));
    let mut results = Vec::new();
    for t in all
        .iter()
        .filter(|t| names.is_empty() || names.iter().any(|n| n == t.name))
    {
        let started = WallInstant::now();
        let mut failures = Vec::new();
        for case in from..from.saturating_add(cases) {
            let mut rng = SplitMix64::new(case_seed(seed, t.name, case));
            let run = t.run;
            if let Err(p) = catch_unwind(AssertUnwindSafe(|| run(&mut rng))) {
                let msg = p
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| p.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "panic".into());
                failures.push((case, msg));
            }
            bar.inc(1);
        }
        let r = TargetResult {
            name: t.name,
            cases,
            failures,
            seconds: started.elapsed().as_secs_f64(),
        };
        progress(&r);
        results.push(r);
    }
    std::panic::set_hook(previous);
    Ok(results)
}

pub fn run(args: &Args) -> Result<()> {
    let json = crate::output::json();
    if args.list {
        for t in targets() {
            crate::output::result(
                format_args!("{:24} {}", t.name, t.about),
                || serde_json::json!({"target": t.name, "about": t.about}),
            )?;
        }
        return Ok(());
    }
    if !json {
        println!(
            "cantwin fuzz: seed {:#x}, cases {}..{}",
            args.seed,
            args.from,
            args.from.saturating_add(args.cases)
        );
    }
    let chosen = targets()
        .iter()
        .filter(|t| args.targets.is_empty() || args.targets.iter().any(|n| n == t.name))
        .count() as u64;
    let bar = crate::output::steps(chosen.saturating_mul(args.cases), "fuzz cases");
    let results = campaign(&args.targets, args.seed, args.from, args.cases, &bar, |r| {
        if json {
            return;
        }
        bar.suspend(|| {
            println!(
                "{:24} {:>10} cases {:>4} failures {:>8.1} s",
                r.name,
                r.cases,
                r.failures.len(),
                r.seconds
            );
            for (case, msg) in r.failures.iter().take(5) {
                println!(
                    "  case {case}: {msg}\n  replay: cantwin fuzz --seed {:#x} --from {case} --cases 1 {}",
                    args.seed, r.name
                );
            }
        });
    })?;
    bar.finish_and_clear();
    let cases: u64 = results.iter().map(|r| r.cases).sum();
    let failures: usize = results.iter().map(|r| r.failures.len()).sum();
    if json {
        let targets: Vec<serde_json::Value> = results
            .iter()
            .map(|r| {
                let failed: Vec<serde_json::Value> = r
                    .failures
                    .iter()
                    .map(|(case, msg)| serde_json::json!({"case": case, "message": msg}))
                    .collect();
                serde_json::json!({
                    "target": r.name,
                    "cases": r.cases,
                    "failures": failed,
                    "seconds": r.seconds,
                })
            })
            .collect();
        crate::output::emit(&serde_json::json!({
            "seed": args.seed,
            "from": args.from,
            "cases": cases,
            "failures": failures,
            "targets": targets,
        }))?;
    } else {
        println!("total: {cases} cases, {failures} failures");
    }
    if failures > 0 {
        bail!("{failures} fuzz cases failed");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The suite's short campaign: every target, a fixed number of cases, no failure.
    #[test]
    fn short_campaign_of_every_target_finds_no_failure() {
        let results = campaign(
            &[],
            0x5EED,
            0,
            24,
            &indicatif::ProgressBar::hidden(),
            |_| {},
        )
        .unwrap();
        assert_eq!(results.len(), targets().len());
        for r in &results {
            assert_eq!(r.cases, 24);
            assert!(r.failures.is_empty(), "{}: {:?}", r.name, r.failures);
        }
    }

    #[test]
    fn an_unknown_target_is_refused_with_the_list() {
        let e = campaign(
            &["nope".into()],
            0,
            0,
            1,
            &indicatif::ProgressBar::hidden(),
            |_| {},
        )
        .err()
        .unwrap()
        .to_string();
        assert!(
            e.contains("no fuzz target \"nope\"") && e.contains("canopen-wire"),
            "{e}"
        );
    }

    #[test]
    fn seeds_are_decimal_or_hex_as_printed_in_replay_lines() {
        assert_eq!(parse_seed("0xC0FFEE"), Ok(0xC0FFEE));
        assert_eq!(parse_seed("12"), Ok(12));
        assert!(parse_seed("0xZZ").is_err());
    }

    /// Mutations start from valid inputs, so the campaigns reach past the headers.
    #[test]
    fn every_seed_input_is_valid() {
        let mut rng = SplitMix64::new(1);
        let mut formats = std::collections::BTreeSet::new();
        for _ in 0..64 {
            let seed = capture_seed(&mut rng);
            let reader = cantwin_capture::CaptureReader::new(Cursor::new(seed)).unwrap();
            formats.insert(format!("{:?}", reader.format()));
            let records: Vec<_> = reader.collect::<Result<_, _>>().unwrap();
            assert!(records.len() <= 2);
        }
        assert_eq!(formats.len(), 3, "{formats:?}");
        for eds in [EDS_DRIVE, EDS_IO, EDS_QUIRKS, EDS_ADV200] {
            cantwin_eds::parse_bytes(eds.as_bytes()).unwrap();
        }
        for s in [
            SCENARIO_CIA301,
            SCENARIO_OPENDRIVE,
            SCENARIO_ADV200_DNET,
            SCENARIO_ADV200_DS402,
            SCENARIO_TM3,
        ] {
            Scenario::parse(s, "seed.toml")
                .unwrap()
                .build(&Registry::builtin(), &BuildEnv::default())
                .unwrap();
        }
        for c in SOCKETCAND_SEEDS {
            let ok = cantwin_gateway::socketcand::wire::parse_command(c.as_bytes()).is_ok()
                || cantwin_gateway::socketcand::wire::parse_server_message(c.as_bytes()).is_ok();
            assert!(ok, "{c}");
        }
        for c in SLCAN_SEEDS {
            assert!(
                cantwin_gateway::slcan::wire::parse_command(c.as_bytes()).is_ok(),
                "{c}"
            );
        }
    }

    #[test]
    fn cases_replay_from_their_seed() {
        let a = case_seed(1, "eds", 7);
        assert_eq!(a, case_seed(1, "eds", 7));
        assert_ne!(a, case_seed(1, "eds", 8));
        assert_ne!(a, case_seed(1, "slcan", 7));
        let mut r1 = SplitMix64::new(a);
        let mut r2 = SplitMix64::new(a);
        assert_eq!(mutate(&mut r1, EDS_IO), mutate(&mut r2, EDS_IO));
    }
}
