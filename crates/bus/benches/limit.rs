//! The fixed limit of the saturated bus ([`cantwin_bus::bench::limit`]) beside the bus
//! itself, with the same nodes, offers and filters: the least work a delivered frame needs,
//! and what the bus spends. Criterion's time per element is the wall time per delivered
//! frame of each.

// criterion's macros generate undocumented functions.
#![allow(missing_docs, clippy::unwrap_used)]

use cantwin_bus::bench::{BenchConfig, limit, run};
use cantwin_can::Duration;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

fn limit_and_bus(c: &mut Criterion) {
    let mut group = c.benchmark_group("limit");
    for nodes in [8u16, 32, 127] {
        let config = BenchConfig {
            nodes,
            ..BenchConfig::saturated(Duration::from_millis(100))
        };
        let frames = limit::run(config).delivered;
        assert_eq!(frames, run(config).delivered, "the limit follows the bus");
        group.throughput(Throughput::Elements(frames));
        group.bench_function(format!("{nodes}_nodes_limit"), |b| {
            b.iter(|| limit::run(config))
        });
        group.bench_function(format!("{nodes}_nodes_bus"), |b| b.iter(|| run(config)));
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = limit_and_bus
}
criterion_main!(benches);
