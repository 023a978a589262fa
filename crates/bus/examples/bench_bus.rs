//! The `cantwin bench bus` scenario on its own: `cargo run --release -p cantwin-bus --example
//! bench_bus [seconds]`.

use cantwin_bus::bench::{BenchConfig, limit, saturated_bus};
use cantwin_can::Duration;

fn main() {
    let secs = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(60);
    let r = saturated_bus(Duration::from_secs(secs));
    println!(
        "{} nodes, {} bus time in {:.3} s wall",
        r.config.nodes,
        r.bus_time,
        r.wall_time.as_secs_f64()
    );
    println!("real-time factor      {:.0}", r.real_time_factor());
    println!("delivered frames      {}", r.delivered);
    println!("frames / wall second  {:.0}", r.frames_per_wall_second());
    println!("ns / delivered frame  {:.0}", r.ns_per_frame());
    println!("offers / dropped      {} / {}", r.offers, r.dropped_offers);
    println!("bus load              {:.2} %", r.bus_load_percent);
    let l = limit::run(BenchConfig::saturated(Duration::from_secs(secs)));
    println!(
        "fixed limit           {:.1} ns / frame; bus / limit {:.1}",
        l.ns_per_frame(),
        r.ns_per_frame() / l.ns_per_frame().max(1e-9)
    );
}
