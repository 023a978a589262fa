//! `cantwin demo`, I/O part: the Schneider TM3 bus coupler twin with an I/O island under
//! cantwin's CANopen master, in virtual time.

use anyhow::{Context, Result};
use cantwin_can::{Duration, Frame, Instant};
use cantwin_canopen::master::{MasterEvent, Mode};
use cantwin_canopen::sdo::wire::Mux;
use cantwin_canopen::wire::NmtCs;
use cantwin_scenario::{BuildEnv, Registry, Scenario};
use cantwin_twin::{SignalId, SignalValue};

use crate::canopen::emcy_meaning;
use crate::demo_canopen::Net;

/// The island of `scenarios/tm3-island.toml`, at node 3.
const SCENARIO: &str = r#"
name = "demo: TM3 island"
seed = 401

[[bus]]
name = "io"
bit_rate = "500k"

[[device]]
name = "island"
kind = "tm3"
bus = "io"
node_id = 3
modules = ["TM3DI16", "TM3DQ16T", "TM3DM24R", "TM3AI4", "TM3AQ2", "TM3TI4", "TM2DDI8DT"]
"#;

/// Sets signal `name` of the coupler on `port` to `value` now, as a script's `set` would.
fn set_signal(
    net: &mut Net,
    port: cantwin_bus::PortId,
    name: &str,
    value: SignalValue,
) -> Result<()> {
    net.sim
        .with_twin(port, |t, cx| t.set_signal(&SignalId::new(name), &value, cx))
        .context("the coupler")?
        .map_err(|e| anyhow::anyhow!("{e}"))
}

/// The frames since the last call (at most `limit`) and the EMCYs the master received, in
/// bus time order.
fn frames_and_emcys(net: &mut Net, limit: usize) -> Result<()> {
    net.frames_with(limit, |ev| match ev {
        MasterEvent::Emcy { node, emcy } => Some(format!(
            "EMCY from node {node}: 0x{:04X} {} (register 0x{:02X}, manufacturer bytes {})",
            emcy.code,
            emcy_meaning(emcy.code),
            emcy.register,
            emcy.manufacturer
                .iter()
                .map(|b| format!("{b:02X}"))
                .collect::<Vec<_>>()
                .join(" ")
        )),
        _ => None,
    })
}

pub fn run() -> Result<()> {
    let scenario = Scenario::parse(SCENARIO, "demo (embedded)")?;
    let built = scenario.build(&Registry::builtin(), &BuildEnv::default())?;
    let bus = built.bus("io").context("bus")?;
    let island = built.device("island").context("island")?.port;
    let mut net = Net::new(built.sim, bus)?;
    let ms = |v: u64| Instant::ZERO + Duration::from_millis(v);

    println!("CiA 401 I/O: a Schneider TM3BCCO coupler (node 3) with 7 modules (16 DI, 16 DQ,");
    println!(
        "16 DI + 8 relays, 4 AI, 2 AQ, 4 temperature inputs, 8 TM2 DI) and cantwin's master.\n"
    );
    net.sim.run_until(ms(5));
    net.frames(4)?;

    println!("\nNMT start: the coupler sends its event-driven TPDOs with the inputs once:");
    net.master(|m, _, out| m.nmt(NmtCs::Start, 3, out))??;
    net.sim.run_until(ms(20));
    frames_and_emcys(&mut net, 8)?;
    println!(
        "  {:>12}  (0x0080 is the manual's \"analog interrupts disabled\": 0x6423 is FALSE)",
        ""
    );

    println!("\nRPDO1 0x203#05 switches outputs 0 and 2 of module 2 (TM3DQ16T):");
    net.sim
        .transmit(net_master_port(&net)?, Frame::std(0x203, &[0x05])?)?;
    net.sim.run_until(ms(30));
    net.frames(2)?;
    let outputs: Vec<bool> = (0..4)
        .map(|ch| {
            net.sim.twin(island).map(|c| {
                c.read_signal(&SignalId::indexed("digital_output", &[2, ch]))
                    .is_ok_and(|v| v == SignalValue::Bool(true))
            })
        })
        .collect::<Option<_>>()
        .context("the coupler")?;
    println!("  {:>12}  module 2 outputs 0..3: {outputs:?}", "");

    println!("\nInput 3 of module 1 switches on: TPDO1 follows within the inhibit time:");
    set_signal(
        &mut net,
        island,
        "digital_input.1.3",
        SignalValue::Bool(true),
    )?;
    net.sim.run_until(ms(40));
    net.frames(2)?;

    println!("\nModule 5 (TM3AQ2) is pulled out at runtime: EMCY, and 0x1002 shows it:");
    set_signal(&mut net, island, "module.5", SignalValue::from("pulled"))?;
    net.sim.run_until(ms(50));
    frames_and_emcys(&mut net, 3)?;
    net.master(|m, now, out| m.upload(3, Mux::new(0x1002, 0), Mode::Expedited, now, out))??;
    match net.sdo(Duration::from_secs(1))? {
        Ok(data) if data.len() == 4 => {
            let v = u32::from_le_bytes([data[0], data[1], data[2], data[3]]);
            println!(
                "  {:>12}  0x1002 manufacturer status = 0x{v:08X} (2 bits per module; module 5 in bits 8-9)",
                ""
            );
        }
        Ok(data) => println!("  0x1002 = {data:02X?}"),
        Err(e) => println!("  0x1002 read aborted: {e}"),
    }
    Ok(())
}

fn net_master_port(net: &Net) -> Result<cantwin_bus::PortId> {
    net.master_port().context("the master")
}
