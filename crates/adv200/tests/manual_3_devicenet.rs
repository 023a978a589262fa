//! Chapter 3: the DeviceNet personality on a 500 kbit/s virtual bus with the stack's scanner.
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_adv200::alarms::CardFault;
use cantwin_adv200::params::par;
use cantwin_adv200::{Adv200, Adv200Config, example};
use cantwin_bus::{BusConfig, PortConfig, Recorder, Simulation};
use cantwin_can::{BitRate, Duration, Instant};
use cantwin_devicenet::scanner::ScannerConfig;
use cantwin_devicenet::wire::{BodyFormat, choice};
use cantwin_devicenet::{Led, MacId, Scanner, ScannerEvent};

const MS: u64 = 1_000_000;

fn at(ms: u64) -> Instant {
    Instant::from_nanos(ms * MS)
}

/// §3.9: the example of §1.6 with Fieldbus type DeviceNet.
fn drive() -> Adv200 {
    let mut d = Adv200::new(Adv200Config {
        bus_bit_rate: Some(500_000),
        ..Adv200Config::default()
    });
    example::configure(&mut d).unwrap();
    d.set_param_str(par::FIELDBUS_TYPE, "DeviceNet").unwrap();
    d
}

#[test]
fn manual_3_9_example_polls_4_bytes_out_6_bytes_in_and_runs_the_motor() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("dnet", BitRate::R500K));
    let mac = MacId::new(12).unwrap();
    let pm = sim
        .attach(
            bus,
            Scanner::new(ScannerConfig::new(MacId::new(0).unwrap(), 1, 2)),
            PortConfig::default(),
        )
        .unwrap();
    let pd = sim.attach(bus, drive(), PortConfig::default()).unwrap();
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    sim.run_until(at(2100));
    let node = sim.node::<Adv200>(pd).unwrap();
    assert_eq!(
        node.param(par::FIELDBUS_STATE),
        Ok(0),
        "Stop: no master yet"
    );
    assert_eq!(node.devicenet_leds(), Some((Led::Blink, Led::Off)));
    {
        let m = sim.node_mut::<Scanner>(pm).unwrap();
        assert_eq!(m.poll_event(), Some(ScannerEvent::Online));
        m.allocate(mac, choice::EXPLICIT | choice::POLLED).unwrap();
        m.set_expected_packet_rate(mac, 2, 100).unwrap();
        // Control word enable + start + digital output 3, Ramp ref 1 = 1500 rpm.
        m.start_polling(
            mac,
            Duration::from_millis(10),
            &[0x03, 0x01, 0xDC, 0x05],
            6,
            at(2110),
        );
    }
    sim.run_until(at(4000));
    let node = sim.node::<Adv200>(pd).unwrap();
    assert_eq!(
        node.param(par::FIELDBUS_STATE),
        Ok(2),
        "Operational: polled I/O"
    );
    assert_eq!(node.devicenet_leds(), Some((Led::On, Led::Off)));
    assert_eq!(node.param(par::MOTOR_SPEED), Ok(1500));
    assert!(node.digital_output(3));
    let rec = sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
    let frames: Vec<String> = rec.frames().map(|r| r.frame.to_string()).collect();
    // Poll command on group 2 message 5 (0x465), response on group 1 message 15 (0x3CC):
    // status word (enable, drive ok), speed 1500, analog input 2.
    assert_eq!(frames[frames.len() - 2], "465#0301DC05");
    assert_eq!(frames[frames.len() - 1], "3CC#0300DC050000");
    assert!(
        frames.contains(&"3CC#060000000000".to_string()),
        "first response: at rest"
    );
}

#[test]
fn manual_3_4_2_drive_parameter_access_over_ucmm() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("dnet", BitRate::R500K));
    let mac = MacId::new(12).unwrap();
    let pm = sim
        .attach(
            bus,
            Scanner::new(ScannerConfig::new(MacId::new(0).unwrap(), 1, 2)),
            PortConfig::default(),
        )
        .unwrap();
    sim.attach(bus, drive(), PortConfig::default()).unwrap();
    sim.run_until(at(2100));
    let m = sim.node_mut::<Scanner>(pm).unwrap();
    assert_eq!(m.poll_event(), Some(ScannerEvent::Online));
    // PAR 600 > 255 needs a 16-bit instance: a UCMM connection with body format 8/16.
    m.open_ucmm(mac, BodyFormat::F8_16).unwrap();
    m.request(mac, 0x33, 0x66, 600, &[0xE8, 0x03]).unwrap();
    m.request(mac, 0x32, 0x66, 600, &[]).unwrap();
    m.request(mac, 0x33, 0x66, 260, &[0x01, 0x00]).unwrap();
    sim.run_until(at(2300));
    let m = sim.node_mut::<Scanner>(pm).unwrap();
    let mut responses = Vec::new();
    while let Some(e) = m.poll_event() {
        if let ScannerEvent::Response { service, data, .. } = e {
            responses.push((service, data));
        }
    }
    assert_eq!(
        responses,
        [
            (0x33, vec![0x00, 0x00]),
            (0x32, vec![0x00, 0x00, 0xE8, 0x03]),
            (0x33, vec![12, 0x00]),
        ]
    );
}

#[test]
fn manual_3_4_1_par_600_example_over_the_predefined_explicit_connection() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("dnet", BitRate::R500K));
    let mac = MacId::new(12).unwrap();
    let pm = sim
        .attach(
            bus,
            Scanner::new(ScannerConfig::new(MacId::new(0).unwrap(), 1, 2)),
            PortConfig::default(),
        )
        .unwrap();
    let pd = sim.attach(bus, drive(), PortConfig::default()).unwrap();
    sim.run_until(at(2100));
    let m = sim.node_mut::<Scanner>(pm).unwrap();
    assert_eq!(m.poll_event(), Some(ScannerEvent::Online));
    m.allocate(mac, choice::EXPLICIT).unwrap();
    sim.run_until(at(2200));
    let m = sim.node_mut::<Scanner>(pm).unwrap();
    // The Allocate response announces 8/16.
    let allocated = std::iter::from_fn(|| m.poll_event()).find_map(|e| match e {
        ScannerEvent::Allocated { format, .. } => Some(format),
        _ => None,
    });
    assert_eq!(allocated, Some(BodyFormat::F8_16));
    // §3.4.1: Set_Attribute_Single class 0x0F instance 600 attribute 1 = 1000, then Get;
    // PAR 4006 (instance 0xFA6) read back.
    m.request(mac, 0x10, 0x0F, 600, &[1, 0xE8, 0x03]).unwrap();
    m.request(mac, 0x0E, 0x0F, 600, &[1]).unwrap();
    m.request(mac, 0x0E, 0x0F, 4006, &[1]).unwrap();
    sim.run_until(at(2400));
    let m = sim.node_mut::<Scanner>(pm).unwrap();
    let mut responses = Vec::new();
    while let Some(e) = m.poll_event() {
        if let ScannerEvent::Response { service, data, .. } = e {
            responses.push((service, data));
        }
    }
    assert_eq!(responses.len(), 3, "{responses:?}");
    assert_eq!(responses[0].0, 0x10);
    assert_eq!(responses[1], (0x0E, vec![0xE8, 0x03, 0, 0]));
    assert_eq!(responses[2], (0x0E, vec![12, 0, 0, 0]));
    let node = sim.node::<Adv200>(pd).unwrap();
    assert_eq!(node.param(par::DIG_RAMP_REF_1), Ok(1000));
}

#[test]
fn manual_3_7_1_configuration_faults() {
    let cfg = |baud: &str, addr: i64| {
        let h = common::H::new(Adv200Config::default(), |d| {
            d.set_param_str(par::FIELDBUS_TYPE, "DeviceNet").unwrap();
            d.set_param_str(par::FIELDBUS_BAUDRATE, baud).unwrap();
            d.set_param(par::FIELDBUS_ADDRESS, addr).unwrap();
        });
        (h.d.opt_bus_faults(), h.frames().len())
    };
    // DeviceNet has no 1 Mbit/s (FFC5) and MAC IDs 1–63 (FFC6).
    assert_eq!(cfg("1M", 12), (vec![0xFFC5], 0));
    assert_eq!(cfg("500k", 64), (vec![0xFFC6], 0));
    assert_eq!(cfg("500k", 0), (vec![0xFFC6], 0));
    // LED table: OP off, AL on, "Fault grave (errore di configurazione …)".
    let h = common::H::new(Adv200Config::default(), |d| {
        d.set_param_str(par::FIELDBUS_TYPE, "DeviceNet").unwrap();
        d.set_param_str(par::FIELDBUS_BAUDRATE, "1M").unwrap();
        d.set_param(par::FIELDBUS_ADDRESS, 12).unwrap();
    });
    assert_eq!(h.d.devicenet_leds(), Some((Led::Off, Led::On)));
    // Configured: the duplicate MAC ID check request goes out at power-up.
    let (faults, frames) = cfg("125k", 63);
    assert!(faults.is_empty());
    assert_eq!(frames, 1);
}

#[test]
fn manual_3_7_1_connection_timeout_is_bus_loss() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("dnet", BitRate::R500K));
    let mac = MacId::new(12).unwrap();
    let pm = sim
        .attach(
            bus,
            Scanner::new(ScannerConfig::new(MacId::new(0).unwrap(), 1, 2)),
            PortConfig::default(),
        )
        .unwrap();
    let mut d = drive();
    d.set_param(par::FIELDBUS_ALARM_MODE, 1).unwrap();
    let pd = sim.attach(bus, d, PortConfig::default()).unwrap();
    sim.run_until(at(2100));
    {
        let m = sim.node_mut::<Scanner>(pm).unwrap();
        m.allocate(mac, choice::EXPLICIT | choice::POLLED).unwrap();
        m.set_expected_packet_rate(mac, 2, 50).unwrap();
        m.start_polling(mac, Duration::from_millis(10), &[0, 0, 0, 0], 6, at(2110));
    }
    sim.run_until(at(2500));
    assert_eq!(
        sim.node::<Adv200>(pd).unwrap().param(par::FIELDBUS_STATE),
        Ok(2)
    );
    assert!(sim.node::<Adv200>(pd).unwrap().opt_bus_faults().is_empty());
    sim.node_mut::<Scanner>(pm).unwrap().stop_polling(mac);
    // The polled connection's watchdog (4 × 50 ms) expires: Opt Bus Fault 0 (bus loss).
    sim.run_until(at(2800));
    let node = sim.node::<Adv200>(pd).unwrap();
    assert_eq!(node.opt_bus_faults(), [0x0000]);
    assert_eq!(node.param(par::FIELDBUS_STATE), Ok(1));
    assert_eq!(node.devicenet_leds(), Some((Led::Off, Led::Blink)));
}

#[test]
fn manual_3_3_2_identity_reset_restarts_the_link_and_keeps_the_parameters() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("dnet", BitRate::R500K));
    let mac = MacId::new(12).unwrap();
    let pm = sim
        .attach(
            bus,
            Scanner::new(ScannerConfig::new(MacId::new(0).unwrap(), 1, 2)),
            PortConfig::default(),
        )
        .unwrap();
    let pd = sim.attach(bus, drive(), PortConfig::default()).unwrap();
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    sim.run_until(at(2100));
    {
        let m = sim.node_mut::<Scanner>(pm).unwrap();
        m.allocate(mac, choice::EXPLICIT).unwrap();
        // Identity (class 1, instance 1) Reset, type 0.
        m.request(mac, 0x05, 0x01, 0x01, &[0]).unwrap();
    }
    sim.run_until(at(2200));
    let rec = sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
    let dup: Vec<Instant> = rec
        .frames()
        .filter(|r| r.frame.id().as_raw() == 0x467)
        .map(|r| r.start)
        .collect();
    // Two duplicate MAC ID checks after power-up; the Reset restarts the link (a third
    // check) while the drive keeps its parameters.
    assert_eq!(dup.len(), 3, "{dup:?}");
    assert!(dup[2] > at(2100));
    let node = sim.node::<Adv200>(pd).unwrap();
    assert_eq!(node.param(par::FIELDBUS_ADDRESS), Ok(12), "parameters kept");
}

/// A scanner (MAC 0) and the §3.9 drive (MAC 12, alarm mode 1 so that the faults show
/// while the drive is disabled), both on-line at 2.1 s.
fn online() -> (
    Simulation,
    cantwin_bus::BusId,
    cantwin_bus::PortId,
    cantwin_bus::PortId,
) {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("dnet", BitRate::R500K));
    let pm = sim
        .attach(
            bus,
            Scanner::new(ScannerConfig::new(MacId::new(0).unwrap(), 1, 2)),
            PortConfig::default(),
        )
        .unwrap();
    let mut d = drive();
    d.set_param(par::FIELDBUS_ALARM_MODE, 1).unwrap();
    let pd = sim.attach(bus, d, PortConfig::default()).unwrap();
    sim.run_until(at(2100));
    (sim, bus, pm, pd)
}

#[test]
fn manual_3_7_1_ffc8_system_error_on_connection_when_the_master_polls_the_wrong_size() {
    let (mut sim, bus, pm, pd) = online();
    let mac = MacId::new(12).unwrap();
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    {
        let m = sim.node_mut::<Scanner>(pm).unwrap();
        m.allocate(mac, choice::EXPLICIT | choice::POLLED).unwrap();
        m.set_expected_packet_rate(mac, 2, 100).unwrap();
        // The PDC's Master→Slave area is 4 bytes (§3.9); this master's scan list says 2.
        m.start_polling(mac, Duration::from_millis(10), &[0x03, 0x00], 6, at(2110));
    }
    sim.run_until(at(2200));
    let node = sim.node::<Adv200>(pd).unwrap();
    assert_eq!(node.opt_bus_faults(), [0xFFC8]);
    assert_eq!(node.param(par::ACTIVE_ALARM), Ok(0xFF11));
    assert_eq!(node.param(par::m2s_mon(1)), Ok(0), "nothing consumed");
    let rec = sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
    assert!(
        rec.frames().all(|r| r.frame.id().as_raw() != 0x3CC),
        "no poll response to a command of the wrong size"
    );
    // The right size is consumed and answered; the alarm stays until it is reset.
    sim.node_mut::<Scanner>(pm).unwrap().stop_polling(mac);
    sim.node_mut::<Scanner>(pm).unwrap().start_polling(
        mac,
        Duration::from_millis(10),
        &[0x00, 0x00, 0xDC, 0x05],
        6,
        at(2210),
    );
    sim.run_until(at(2300));
    let node = sim.node::<Adv200>(pd).unwrap();
    assert_eq!(node.param(par::m2s_mon(2)), Ok(1500));
    assert_eq!(node.opt_bus_faults(), [0xFFC8]);
    let rec = sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
    assert!(rec.frames().any(|r| r.frame.id().as_raw() == 0x3CC));
}

#[test]
fn manual_3_7_1_ffc7_bus_off_and_no_8100_in_devicenet() {
    let (mut sim, bus, _pm, pd) = online();
    // Bus-off twice within a second: DeviceNet's table has FFC7 only.
    sim.bus_mut(bus).unwrap().force_bus_off(pd).unwrap();
    sim.run_until(at(2200));
    sim.bus_mut(bus).unwrap().force_bus_off(pd).unwrap();
    sim.run_until(at(2300));
    let node = sim.node::<Adv200>(pd).unwrap();
    assert_eq!(node.opt_bus_faults(), [0xFFC7]);
    assert_eq!(node.param(par::ACTIVE_ALARM), Ok(0xFF11));
}

#[test]
fn manual_3_7_1_ffc9_duplicate_mac_id_check_failed() {
    let (mut sim, bus, _pm, pd) = online();
    // A second drive configured with the same MAC ID 12 is powered later: the first, on-line,
    // answers its duplicate MAC ID check request.
    let mut second = drive();
    second.set_param(par::FIELDBUS_ALARM_MODE, 1).unwrap();
    let p2 = sim.attach(bus, second, PortConfig::default()).unwrap();
    sim.run_until(at(3500));
    let late = sim.node::<Adv200>(p2).unwrap();
    assert_eq!(late.opt_bus_faults(), [0xFFC9]);
    // LED table: OP off, AL blinking, "Fault recuperabile (DUP MAC-ID fail, …)".
    assert_eq!(late.devicenet_leds(), Some((Led::Off, Led::Blink)));
    assert!(sim.node::<Adv200>(pd).unwrap().opt_bus_faults().is_empty());
}

#[test]
fn manual_3_7_1_internal_errors_ff04_and_ffb4_in_devicenet() {
    let cfg = |fault: CardFault| {
        let h = common::H::new(Adv200Config::default(), |d| {
            d.set_param_str(par::FIELDBUS_TYPE, "DeviceNet").unwrap();
            d.set_param_str(par::FIELDBUS_BAUDRATE, "500k").unwrap();
            d.set_param(par::FIELDBUS_ADDRESS, 12).unwrap();
            d.inject_card_fault(fault);
        });
        (
            h.d.opt_bus_faults(),
            h.frames().len(),
            h.d.devicenet().is_some(),
        )
    };
    // FF04: the CAN interface does not start, nothing on the bus.
    assert_eq!(cfg(CardFault::CanInit), (vec![0xFF04], 0, false));
    // LED table: OP off, AL on, "Fault grave (… errore interno)".
    let h = common::H::new(Adv200Config::default(), |d| {
        d.set_param_str(par::FIELDBUS_TYPE, "DeviceNet").unwrap();
        d.set_param_str(par::FIELDBUS_BAUDRATE, "500k").unwrap();
        d.set_param(par::FIELDBUS_ADDRESS, 12).unwrap();
        d.inject_card_fault(CardFault::CanInit);
    });
    assert_eq!(h.d.devicenet_leds(), Some((Led::Off, Led::On)));
    // FFB4+n−1: the card runs (its duplicate MAC ID check goes out) in Opt Bus Fault.
    assert_eq!(cfg(CardFault::Database(2)), (vec![0xFFB5], 1, true));
}
