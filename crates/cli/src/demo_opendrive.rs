//! `cantwin demo`, CAL part: the TDE MACNO OPEN DRIVE twin (application 003) driven by a CAL
//! master on its own 500 kbit/s bus, in virtual time.

use anyhow::{Context, Result};
use cantwin_bus::{PortConfig, PortId, Simulation};
use cantwin_cal::{ClientEvent, CmsClient, Payload, Request};
use cantwin_can::{Duration, Instant, Outbox};
use cantwin_opendrive::messages::{self, Code, CommandByte, message0_write};
use cantwin_opendrive::params::Params;
use cantwin_opendrive::{MESSAGE_0, MESSAGE_1};
use cantwin_scenario::{BuildEnv, Registry, Scenario};
use cantwin_twin::{SignalId, SignalValue};

const SCENARIO: &str = r#"
name = "demo: OPEN DRIVE"
seed = 3

[[bus]]
name = "cal"
bit_rate = "500k"

[[device]]
name = "drive"
kind = "opendrive"
bus = "cal"
params = { P21 = 2.0, P22 = 2.0, C48 = 1, C52 = 1 }
load_torque_pct = 20.0
"#;

/// Sends `req` on `object` from the CAL master on `port` now (CMS, CiA DS 202).
pub(crate) fn request(
    sim: &mut Simulation,
    port: PortId,
    object: cantwin_cal::ObjectIndex,
    req: Request,
) -> Result<()> {
    let now = sim.now();
    let mut out = Outbox::new();
    let client = sim.node_mut::<CmsClient>(port).context("the CAL master")?;
    client
        .request(object, req, now, &mut out)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    for f in out.drain() {
        sim.transmit(port, f)?;
    }
    Ok(())
}

/// Signal `name` of the drive on `port`.
fn read(sim: &Simulation, port: PortId, name: &str) -> Result<SignalValue> {
    sim.twin(port)
        .context("the drive")?
        .read_signal(&SignalId::new(name))
        .map_err(|e| anyhow::anyhow!("{e}"))
}

fn drive_state(sim: &Simulation, port: PortId) -> Result<(f64, f64, bool)> {
    let number = |name: &str| -> Result<f64> {
        read(sim, port, name)?
            .as_f64()
            .with_context(|| format!("the drive's {name} is not a number"))
    };
    let running = read(sim, port, "running")? == SignalValue::Bool(true);
    Ok((number("output_hz")?, number("current_pct")?, running))
}

pub fn run() -> Result<()> {
    let scenario = Scenario::parse(SCENARIO, "demo (embedded)")?;
    let mut built = scenario.build(&Registry::builtin(), &BuildEnv::default())?;
    let bus = built.bus("cal").context("bus")?;
    let drive = built.device("drive").context("drive")?.port;
    let params = Params::default();
    let client = messages::master(|p| params.get(p)).map_err(|e| anyhow::anyhow!("{e}"))?;
    let master = built.sim.attach(bus, client, PortConfig::default())?;
    let mut sim = built.sim;
    let ms = |v: u64| Instant::ZERO + Duration::from_millis(v);

    println!("CAL: a TDE MACNO OPEN DRIVE (application 003) and a CAL master on a 500 kbit/s bus.");
    println!("Ramps P21/P22 = 2 s to the maximum frequency, 20 % load torque.\n");
    sim.run_until(ms(10));
    request(&mut sim, master, MESSAGE_1, Request::ControlEvent(true))?;
    sim.run_until(ms(20));
    println!("Message 1: the master enables the alarm events. Message 0: reference 50.00 Hz");
    println!("(0x1388), reference remote, command remote and CAN-Start set:");
    let cmd = CommandByte {
        reference_remote: Code::Set,
        command_remote: Code::Set,
        can_start: Code::Set,
        can_reverse: Code::NoChange,
    };
    let payload = Payload::new(&message0_write(cmd, 5000)).context("message 0")?;
    request(&mut sim, master, MESSAGE_0, Request::WriteBasic(payload))?;
    let mut t = 20;
    let mut printed_header = false;
    while t <= 2600 {
        sim.run_until(ms(t));
        let client = sim
            .node_mut::<CmsClient>(master)
            .context("the CAL master")?;
        let events: Vec<ClientEvent> = std::iter::from_fn(|| client.poll_event()).collect();
        for ev in events {
            match ev {
                ClientEvent::Confirmed {
                    object, data, at, ..
                } if object == MESSAGE_0 => {
                    println!(
                        "  {:>12}  message 0 confirmed: {:02X?}",
                        at.to_string(),
                        data.as_slice()
                    )
                }
                ClientEvent::Notified { data, at, .. } => println!(
                    "  {:>12}  alarm notification {}: {}",
                    at.to_string(),
                    hex(data.as_slice()),
                    crate::cal::describe_flags(data.as_slice())
                ),
                _ => {}
            }
        }
        if t % 400 == 0 {
            if !printed_header {
                println!(
                    "  {:>12}  output frequency / motor current (the ramp to 50 Hz takes 2 s):",
                    ""
                );
                printed_header = true;
            }
            let (hz, current, running) = drive_state(&sim, drive)?;
            println!(
                "  {:>12}  {:6.2} Hz  {:5.1} % current  {}",
                sim.now().to_string(),
                hz,
                current,
                if running { "running" } else { "stopped" }
            );
        }
        t += 20;
    }

    println!("\nThe load rises to 150 % of the rated torque: the motor's I2t image heats up until");
    println!("the drive trips (A3) and notifies OVERLOAD; the motor coasts down:");
    sim.with_twin(drive, |t, cx| {
        t.set_signal(
            &SignalId::new("load_torque_pct"),
            &SignalValue::Real(150.0),
            cx,
        )
    })
    .context("the drive")?
    .map_err(|e| anyhow::anyhow!("{e}"))?;
    for step in 1..=6000 {
        if step % 500 == 0 {
            let (hz, current, _) = drive_state(&sim, drive)?;
            // The live value is the thermal image in %.
            let thermal = sim
                .twin(drive)
                .context("the drive")?
                .live_values()
                .into_iter()
                .find(|v| v.name == "motor thermal")
                .map(|v| v.value / 100.0)
                .context("the drive's motor thermal image")?;
            println!(
                "  {:>12}  {:6.2} Hz  {:5.1} % current  motor thermal image {:3.0} %",
                sim.now().to_string(),
                hz,
                current,
                thermal * 100.0
            );
        }
        let next = sim.now() + Duration::from_millis(20);
        sim.run_until(next);
        let client = sim
            .node_mut::<CmsClient>(master)
            .context("the CAL master")?;
        let mut done = false;
        while let Some(ev) = client.poll_event() {
            if let ClientEvent::Notified { data, at, .. } = ev {
                println!(
                    "  {:>12}  alarm notification {}: {}",
                    at.to_string(),
                    hex(data.as_slice()),
                    crate::cal::describe_flags(data.as_slice())
                );
                done = true;
            }
        }
        if done {
            break;
        }
    }
    let (hz, current, running) = drive_state(&sim, drive)?;
    println!(
        "  {:>12}  {:6.2} Hz  {:5.1} % current  {}",
        sim.now().to_string(),
        hz,
        current,
        if running {
            "running"
        } else {
            "stopped (alarm)"
        }
    );
    Ok(())
}

fn hex(data: &[u8]) -> String {
    data.iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}
