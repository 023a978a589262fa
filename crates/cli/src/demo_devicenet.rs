//! `cantwin demo`, DeviceNet part: the ADV200 with its card switched to DeviceNet (PAR 4000)
//! and cantwin's scanner, the manual's worked example (§3.9: 4 bytes out, 6 bytes in), in
//! virtual time.

use anyhow::{Context, Result};
use cantwin_bus::{BusEvent, BusId, PortConfig, PortId, Recorder, Simulation};
use cantwin_can::{Duration, Instant};
use cantwin_devicenet::wire::{MacId, choice};
use cantwin_devicenet::{Scanner, ScannerConfig, ScannerEvent};
use cantwin_scenario::{BuildEnv, Registry, Scenario};

const SCENARIO: &str = r#"
name = "demo: ADV200 on DeviceNet"
seed = 300

[[bus]]
name = "dnet"
bit_rate = "500k"

[[device]]
name = "drive"
kind = "adv200"
bus = "dnet"
example = true
params = { 4000 = "DeviceNet" }
analog_inputs = [0.0, 2.5]
"#;

/// Attaches cantwin's scanner (MAC ID 0) to `bus`, beside the ADV200 at MAC ID 12 as in the
/// manual's worked example (§3.9): the scanner's port and the drive's MAC ID.
pub(crate) fn attach_scanner(sim: &mut Simulation, bus: BusId) -> Result<(PortId, MacId)> {
    let mac0 = MacId::new(0).context("MAC ID")?;
    let drive = MacId::new(12).context("MAC ID")?;
    let scanner = sim.attach(
        bus,
        Scanner::new(ScannerConfig::new(mac0, 1, 2)),
        PortConfig::default(),
    )?;
    Ok((scanner, drive))
}

/// Has the scanner on `scanner` allocate the explicit and polled I/O connections of `drive`,
/// set their expected packet rate, and poll it every `cycle` from `first` with the worked
/// example's output (§3.9): control word 0x0103 (enable, start, digital output 3), Ramp
/// ref 1 = 1500 rpm, 6 bytes expected back. Events queued so far are dropped.
pub(crate) fn start_polling(
    sim: &mut Simulation,
    scanner: PortId,
    drive: MacId,
    cycle: Duration,
    first: Instant,
) -> Result<()> {
    let m = sim.node_mut::<Scanner>(scanner).context("scanner")?;
    while m.poll_event().is_some() {}
    m.allocate(drive, choice::EXPLICIT | choice::POLLED)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    m.set_expected_packet_rate(drive, 2, 100)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    m.start_polling(drive, cycle, &[0x03, 0x01, 0xDC, 0x05], 6, first);
    Ok(())
}

fn hex(data: &[u8]) -> String {
    data.iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

pub fn run() -> Result<()> {
    let scenario = Scenario::parse(SCENARIO, "demo (embedded)")?;
    let built = scenario.build(&Registry::builtin(), &BuildEnv::default())?;
    let bus = built.bus("dnet").context("bus")?;
    let mut sim = built.sim;
    let (scanner, drive) = attach_scanner(&mut sim, bus)?;
    let tap = sim.bus_mut(bus).context("bus")?.add_tap(Recorder::new());
    let at = |ms: u64| Instant::ZERO + Duration::from_millis(ms);

    println!(
        "DeviceNet: the ADV200 with PAR 4000 = DeviceNet (MAC ID 12, 500 kbit/s) and cantwin's"
    );
    println!(
        "scanner (MAC ID 0). Both check for a duplicate MAC ID at power-up: two requests 1 s apart.\n"
    );
    sim.run_until(at(2100));
    // The listing learns the explicit connection's message body format from the Allocate
    // answer (the ADV200 grants 8/16), as a capture's decoder does.
    let mut formats = cantwin_report::devicenet::BodyFormats::new();
    {
        let rec = sim
            .bus(bus)
            .and_then(|b| b.tap::<Recorder>(tap))
            .context("recorder")?;
        for f in rec.frames().take(4) {
            println!(
                "  {:>12}  {:<22} {}",
                f.end.to_string(),
                f.frame.to_string(),
                formats.describe(&f.frame)
            );
        }
    }
    let shown = sim
        .bus(bus)
        .and_then(|b| b.tap::<Recorder>(tap))
        .map(|r| r.events.len())
        .unwrap_or(0);

    println!(
        "\nThe scanner allocates the explicit and polled I/O connections, sets the expected packet"
    );
    println!("rate, and polls every 10 ms with the worked example's output: control word 0x0103");
    println!("(enable, start, digital output 3) and Ramp ref 1 = 1500 rpm:");
    start_polling(
        &mut sim,
        scanner,
        drive,
        Duration::from_millis(10),
        at(2110),
    )?;
    sim.run_until(at(2140));
    {
        let rec = sim
            .bus(bus)
            .and_then(|b| b.tap::<Recorder>(tap))
            .context("recorder")?;
        for e in &rec.events[shown..] {
            if let BusEvent::Frame(f) = e {
                println!(
                    "  {:>12}  {:<22} {}",
                    f.end.to_string(),
                    f.frame.to_string(),
                    formats.describe(&f.frame)
                );
            }
        }
    }
    println!("\nPoll responses (status word, actual speed, analog input 2) as the drive ramps:");
    let mut next = 2500u64;
    while next <= 4000 {
        sim.run_until(at(next));
        let m = sim.node_mut::<Scanner>(scanner).context("scanner")?;
        let mut last = None;
        while let Some(ev) = m.poll_event() {
            if let ScannerEvent::PollResponse { data, .. } = ev {
                last = Some(data);
            }
        }
        if let Some(d) = last {
            let speed = d
                .get(2..4)
                .map(|b| i16::from_le_bytes([b[0], b[1]]))
                .unwrap_or(0);
            println!(
                "  {:>12}  input {}  speed {speed:>5} rpm",
                sim.now().to_string(),
                hex(&d)
            );
        }
        next += 500;
    }
    Ok(())
}
