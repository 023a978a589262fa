//! `cantwin bench silkit`'s measurement counts every frame, with and without cantwin as
//! network simulator.

mod common;

use cantwin_silkit::SilKit;
use cantwin_silkit::bench::{BenchConfig, run};
use common::{Registry, silkit_dir};

#[test]
fn every_frame_is_acknowledged_and_timed_with_and_without_the_network_simulator() {
    let Some(dir) = silkit_dir() else { return };
    let kit = SilKit::load_from(&dir.join("libSilKit.so")).expect("load");
    for netsim in [false, true] {
        let registry = Registry::start(&dir);
        let r = run(
            &kit,
            &registry.uri,
            BenchConfig {
                participants: 3,
                steps: 20,
                netsim,
            },
        )
        .expect("bench run");
        assert_eq!(r.frames, 60, "netsim {netsim}: {r:?}");
        assert!(r.latency_us > 0.0 && r.frames_per_second > 0.0, "{r:?}");
        assert_eq!(r.steps, 21, "{r:?}");
        let step_us = r.wall.as_secs_f64() * 1e6 / 21.0;
        assert!((r.step_us() - step_us).abs() < 1e-6, "{r:?}");
        assert!(
            (r.latency_steps() * step_us - r.latency_us).abs() < 1e-6,
            "{r:?}"
        );
    }
}
