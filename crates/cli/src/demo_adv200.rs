//! `cantwin demo`, drive part: the manual's worked example of the Gefran ADV200 with its
//! EXP-CAN card (node 12 at 500 kbit/s, §1.6), in virtual time.

use anyhow::{Context, Result};
use cantwin_adv200::example::{NODE, simulate};
use cantwin_can::Duration;

pub fn run() -> Result<()> {
    println!(
        "Drive: the Gefran ADV200 with its EXP-CAN card, configured as in the manual's worked"
    );
    println!(
        "example (node {NODE}, 500 kbit/s; control word and ramp reference in RPDO1, status word,"
    );
    println!("actual speed and analog input 2 in TPDO1). A master starts the node, sends enable +");
    println!("start with 1500 rpm, and a SYNC every 10 ms; TPDO1 answers every SYNC:\n");
    let samples = simulate(1500, Duration::from_millis(10), Duration::from_millis(2500))
        .context("running the worked example")?;
    println!(
        "  {:>12}  {:>6}  {:>9}  {:>7}",
        "bus time", "status", "speed", "AI 2"
    );
    let mut next_ms = 0u64;
    for s in &samples {
        let t_ms = s.time.as_nanos() / 1_000_000;
        if t_ms >= next_ms {
            println!(
                "  {:>12}  0x{:04X}  {:>5} rpm  {:>7}",
                s.time.to_string(),
                s.status,
                s.speed,
                s.analog_input_2
            );
            next_ms = t_ms - t_ms % 250 + 250;
        }
    }
    if let Some(last) = samples.last() {
        println!(
            "\n  {} TPDO1 frames; the speed follows the ramp to {} rpm; status bit 0 (enabled) is {}, bit 2 (zero speed) is {}.",
            samples.len(),
            last.speed,
            last.status & 1,
            (last.status >> 2) & 1
        );
    }
    Ok(())
}
