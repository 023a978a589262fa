//! Hot paths of the bus: arbitration among many pending frames, and dispatch of completed
//! frames to many nodes.

// criterion's macros generate undocumented functions.
#![allow(missing_docs)]

use cantwin_bus::bench::{BenchConfig, run};
use cantwin_can::{BitRate, Duration};
use criterion::{Criterion, criterion_group, criterion_main};

fn saturated(c: &mut Criterion) {
    let mut group = c.benchmark_group("saturated_bus");
    for nodes in [8u16, 32, 127] {
        group.bench_function(format!("{nodes}_nodes_100ms"), |b| {
            b.iter(|| {
                run(BenchConfig {
                    nodes,
                    bit_rate: BitRate::R1M,
                    period: Duration::from_millis(1),
                    duration: Duration::from_millis(100),
                })
            })
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = saturated
}
criterion_main!(benches);
