//! The manual's worked example (§1.6) on a 500 kbit/s virtual bus: prints TPDO1 (status word,
//! actual speed, analog input 2) after each SYNC while the motor ramps to 1500 rpm, and how
//! long the simulation took.
//!
//! `cargo run -p cantwin-adv200 --example worked_example [seconds]`

use cantwin_adv200::example;
use cantwin_can::Duration;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let seconds: u64 = match std::env::args().nth(1) {
        Some(s) => s.parse()?,
        None => 2,
    };
    let started = std::time::Instant::now();
    let samples = example::simulate(
        1500,
        Duration::from_millis(10),
        Duration::from_millis(seconds * 1000),
    )?;
    let wall = started.elapsed();
    for s in samples.iter().step_by(10) {
        println!(
            "{:>12.6} s  status {:#06x}  speed {:>5} rpm  AI2 {:>6}",
            s.time.as_nanos() as f64 / 1e9,
            s.status,
            s.speed,
            s.analog_input_2
        );
    }
    println!(
        "{} SYNC cycles, {seconds} s of bus time simulated in {:.3} s",
        samples.len(),
        wall.as_secs_f64()
    );
    Ok(())
}
