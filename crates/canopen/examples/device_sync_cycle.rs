//! Measures one SYNC cycle of a whole CiA 301 device (SYNC received, 4 synchronous TPDOs of
//! 8 bytes sent) and reports the per-device heap.
//!
//! `cargo run --release -p cantwin-canopen --example device_sync_cycle`

use cantwin_can::{Frame, Instant, Node, Outbox};
use cantwin_canopen::device::{Device, DeviceConfig};
use cantwin_canopen::objects::{Cia301Options, cia301_defaults};
use cantwin_canopen::od::{Access, DataType, OdBuilder, SubObject};
use cantwin_canopen::pdo::PdoObjects;
use std::sync::Arc;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let word = SubObject::new("Input", DataType::Unsigned16, Access::Ro).mappable();
    let b = cia301_defaults(OdBuilder::new(), &Cia301Options::default())
        .array_of(0x6000, "Inputs", 16, word);
    let mut pdos = PdoObjects::new(4, 4).max_entries(4);
    for n in 0..4u16 {
        let m: Vec<u32> = (0..4u32)
            .map(|k| 0x6000_0010 | ((u32::from(n) * 4 + k + 1) << 8))
            .collect();
        pdos = pdos.tpdo(n, 1, &m);
    }
    let desc = Arc::new(pdos.add_to(b).build()?);
    let mut dev = Device::new(Arc::clone(&desc), DeviceConfig::new(1))?;
    let mut out = Outbox::new();
    dev.on_power_up(Instant::ZERO, &mut out);
    dev.on_frame(&Frame::std(0, &[1, 1])?, Instant::ZERO, &mut out);
    out.clear();
    let sync = Frame::std(0x80, &[])?;
    let cycles: u64 = 1_000_000;
    let mut now = Instant::ZERO;
    let started = std::time::Instant::now();
    for _ in 0..cycles {
        now += cantwin_can::Duration::from_millis(1);
        dev.on_frame(&sync, now, &mut out);
        assert_eq!(out.len(), 4);
        out.clear();
    }
    let elapsed = started.elapsed();
    println!(
        "SYNC cycle, 4 TPDOs x 8 bytes: {:.0} ns per node per cycle",
        elapsed.as_nanos() as f64 / cycles as f64
    );
    let fresh = Device::new(
        Arc::new(cia301_defaults(OdBuilder::new(), &Cia301Options::default()).build()?),
        DeviceConfig::new(1),
    )?;
    println!(
        "default CiA 301 device: {} bytes inline + {} bytes heap (description shared)",
        core::mem::size_of::<Device>(),
        fresh.heap_bytes()
    );
    println!(
        "device above (4 RPDO + 4 TPDO): {} bytes heap",
        dev.heap_bytes()
    );
    Ok(())
}
