//! Property tests: arbitration order and timing for any set of pending frames, replay
//! determinism under random faults, and exact benchmark bookkeeping for any load.
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_bus::bench::{BenchConfig, run};
use cantwin_bus::{Bus, BusConfig, FaultRule, FrameSelector, PortConfig, Recorder};
use cantwin_can::{BitRate, Duration, Frame, Id, Instant};
use common::Probe;
use proptest::prelude::*;

fn frame_strategy() -> impl Strategy<Value = Frame> {
    (
        any::<bool>(),
        0u32..0x1FFF_FFFF,
        any::<bool>(),
        proptest::collection::vec(any::<u8>(), 0..=8),
    )
        .prop_map(|(ext, raw, remote, data)| {
            let id = if ext {
                Id::extended(raw).unwrap()
            } else {
                Id::standard((raw & 0x7FF) as u16).unwrap()
            };
            if remote {
                Frame::remote(id, data.len() as u8).unwrap()
            } else {
                Frame::data(id, &data).unwrap()
            }
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    /// ISO 11898-1 §10.4.4.2: frames pending together go out in arbitration order, back to
    /// back, each delivered at the end of its EOF.
    #[test]
    fn pending_frames_go_out_in_arbitration_order_back_to_back(
        frames in proptest::collection::vec(frame_strategy(), 1..12)
    ) {
        // Distinct arbitration fields: two nodes never send the same one (CAN forbids it).
        let mut frames = frames;
        frames.sort_by_key(Frame::arbitration_key);
        frames.dedup_by_key(|f| f.arbitration_key());
        let mut bus = Bus::new(BusConfig::new("p", BitRate::R1M));
        let tap = bus.add_tap(Recorder::new());
        for f in frames.iter().rev() {
            bus.attach(Probe::sending(&[*f]), PortConfig::default());
        }
        // Someone to acknowledge even a single frame.
        bus.attach(Probe::new(), PortConfig::default());
        bus.run_until(Instant::from_nanos(100_000_000));
        let rec = bus.tap::<Recorder>(tap).unwrap();
        let seen: Vec<(Frame, u64, u64)> =
            rec.frames().map(|r| (r.frame, r.start.as_nanos(), r.end.as_nanos())).collect();
        let mut t = 0;
        let mut expect = Vec::new();
        for f in &frames {
            let n = u64::from(f.bit_length());
            expect.push((*f, t, t + (n - 3) * 1000));
            t += n * 1000;
        }
        prop_assert_eq!(seen, expect);
    }

    /// Same seed, same trace, to the nanosecond.
    #[test]
    fn faulty_scenarios_replay_identically(
        seed in any::<u64>(),
        corrupt in 0.0f64..0.5,
        drop in 0.0f64..0.5,
        frames in proptest::collection::vec(frame_strategy(), 1..6)
    ) {
        let trace = || {
            let mut bus = Bus::new(BusConfig::new("p", BitRate::R250K).with_seed(seed));
            let tap = bus.add_tap(Recorder::new());
            for (i, f) in frames.iter().enumerate() {
                let mut p = Probe::new();
                for k in 0..5u64 {
                    p = p.at(k * 700_000 + i as u64 * 1_000, *f);
                }
                bus.attach(p, PortConfig::default());
            }
            bus.attach(Probe::new(), PortConfig::default());
            bus.inject(FaultRule::corrupt(FrameSelector::Fraction(corrupt)));
            bus.inject(FaultRule::drop(FrameSelector::Fraction(drop)));
            bus.run_until(Instant::from_nanos(50_000_000));
            bus.tap::<Recorder>(tap).unwrap().events.clone()
        };
        prop_assert_eq!(trace(), trace());
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    /// The benchmark node counts every offer it skips: its totals match the bus's own
    /// bookkeeping of naive nodes for any size, rate and period.
    #[test]
    fn benchmark_bookkeeping_is_exact(
        nodes in 2u16..40,
        rate in prop::sample::select(vec![BitRate::R125K, BitRate::R500K, BitRate::R1M]),
        period_us in 100u64..3000,
    ) {
        let config = BenchConfig {
            nodes,
            bit_rate: rate,
            period: Duration::from_micros(period_us),
            duration: Duration::from_millis(30),
        };
        let report = run(config);
        let offers_per_node = 30_000 / period_us + 1;
        prop_assert_eq!(report.offers, u64::from(nodes) * offers_per_node);
        let naive = common::naive_bench(config);
        prop_assert_eq!(report.delivered, naive.0);
        prop_assert_eq!(report.dropped_offers, naive.1);
        prop_assert_eq!(report.received, naive.2);
    }
}
