//! §1.6: the worked example on a 500 kbit/s virtual bus, with exact frames and times.
#![allow(clippy::unwrap_used)]

use cantwin_adv200::example;
use cantwin_adv200::params::par;
use cantwin_adv200::{Adv200, Leds};
use cantwin_bus::{BusConfig, PortConfig, Recorder, Simulation};
use cantwin_can::{BitRate, Frame, Instant, Node, Outbox};
use cantwin_canopen::nmt::State;

const MS: u64 = 1_000_000;

struct Master;

impl Node for Master {
    fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

fn f(s: &str) -> Frame {
    let (id, data) = s.split_once('#').unwrap();
    let bytes: Vec<u8> = (0..data.len() / 2)
        .map(|i| u8::from_str_radix(&data[2 * i..2 * i + 2], 16).unwrap())
        .collect();
    Frame::std(u16::from_str_radix(id, 16).unwrap(), &bytes).unwrap()
}

/// Number of 1 ms control steps in (from, to].
fn steps(from: u64, to: u64) -> u64 {
    to / MS - from / MS
}

#[test]
fn manual_1_6_worked_example_ramps_to_1500_rpm_on_the_wire() {
    let mut drive = example::drive().unwrap();
    drive.set_analog_input(2, 5.0);
    drive.set_digital_input(4, true);
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R500K));
    let d = sim.attach(bus, drive, PortConfig::default()).unwrap();
    let m = sim.attach(bus, Master, PortConfig::default()).unwrap();
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());

    sim.run_until(Instant::from_nanos(10 * MS));
    let node = sim.node::<Adv200>(d).unwrap();
    assert_eq!(node.nmt_state(), Some(State::PreOperational));
    assert_eq!(node.param(par::FIELDBUS_STATE), Ok(1));
    assert_eq!(
        node.leds(),
        Leds {
            al: true,
            op: false,
            pwr: true,
            vc5: true
        },
        "§1.6.2.1: pre-operational LEDs"
    );
    // NMT start node 12.
    sim.transmit(m, f("000#010C")).unwrap();
    sim.run_until(Instant::from_nanos(20 * MS));
    let node = sim.node::<Adv200>(d).unwrap();
    assert_eq!(node.param(par::FIELDBUS_STATE), Ok(2));
    assert_eq!(
        node.leds(),
        Leds {
            al: false,
            op: true,
            pwr: true,
            vc5: true
        }
    );
    // RPDO1: control word enable + start + digital output 3, Ramp ref 1 = 1500 rpm.
    sim.transmit(m, f("20C#0301DC05")).unwrap();
    sim.run_until(Instant::from_nanos(21 * MS));
    assert!(
        !sim.node::<Adv200>(d).unwrap().digital_output(3),
        "synchronous RPDO waits for SYNC"
    );
    // SYNC every 10 ms from 30 ms to 1.6 s.
    for k in 0..=157u64 {
        sim.run_until(Instant::from_nanos((30 + 10 * k) * MS));
        sim.transmit(m, f("080#")).unwrap();
    }
    sim.run_until(Instant::from_nanos(1_700 * MS));
    let node = sim.node::<Adv200>(d).unwrap();
    assert!(node.digital_output(3));
    assert!(!node.digital_output(4));
    assert_eq!(node.param(par::MOTOR_SPEED), Ok(1500));

    let rec = sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
    let frames: Vec<_> = rec.frames().collect();
    assert_eq!(frames[0].frame, f("70C#00"));
    assert_eq!(frames[0].start, Instant::ZERO);
    let syncs: Vec<_> = frames.iter().filter(|r| r.frame == f("080#")).collect();
    let tpdos: Vec<_> = frames
        .iter()
        .filter(|r| r.frame.id().as_raw() == 0x18C)
        .collect();
    assert_eq!(syncs.len(), 158);
    assert_eq!(tpdos.len(), 158, "one TPDO1 per SYNC (transmission type 1)");
    // CiA 301 §7.2.2.2: at a SYNC the synchronous TPDO samples first, then the synchronous
    // RPDO received before it is actuated; so TPDO1 of the first SYNC still shows the drive
    // disabled at zero speed (drive ok, speed is zero, digital input 4).
    assert_eq!(tpdos[0].frame, f("18C#060100000020"));
    // The ramp runs from the first SYNC at 1000 rpm/s in 1 ms steps.
    let t0 = syncs[0].end.as_nanos();
    for (s, t) in syncs.iter().zip(&tpdos).skip(1) {
        // Each TPDO1 starts as soon as its SYNC has left the bus.
        assert_eq!(t.start, s.idle_at);
        let speed = steps(t0, s.end.as_nanos()).min(1500) as i16;
        let zero = speed <= 10;
        // Status word: bit 0 enable state, bit 1 drive ok, bit 2 speed is zero, bit 8 DI 4.
        let status: u16 = 0x0103 | if zero { 0x0004 } else { 0 };
        let sp = speed.to_le_bytes();
        // Analog input 2 at 5 V = 8192 counts.
        let want = Frame::std(
            0x18C,
            &[status as u8, (status >> 8) as u8, sp[0], sp[1], 0x00, 0x20],
        )
        .unwrap();
        assert_eq!(t.frame, want, "TPDO1 after SYNC at {} ns", s.end.as_nanos());
    }
    assert_eq!(tpdos.last().unwrap().frame, f("18C#0301DC050020"));
}

#[test]
fn manual_1_6_run_reports_speed_and_status_over_time() {
    let samples = example::run(
        1500,
        cantwin_can::Duration::from_millis(100),
        cantwin_can::Duration::from_millis(2000),
    )
    .unwrap();
    assert_eq!(samples.len(), 21);
    // The first SYNC applies the RPDO; each following one sees 100 more rpm.
    let speeds: Vec<i16> = samples.iter().map(|s| s.speed).collect();
    let want: Vec<i16> = (0..21).map(|k| (k * 100).min(1500)).collect();
    assert_eq!(speeds, want);
    assert_eq!(samples[0].status, 0x0006);
    assert_eq!(samples[1].status, 0x0003);
    assert_eq!(samples[20].status, 0x0003);
}

#[test]
fn manual_1_6_simulate_on_the_bus_reports_tpdo1_with_exact_times() {
    let samples = example::simulate(
        1000,
        cantwin_can::Duration::from_millis(100),
        cantwin_can::Duration::from_millis(1500),
    )
    .unwrap();
    assert_eq!(samples.len(), 15);
    // SYNC (0 data bytes) at 100 ms takes 47 bits + 3 intermission at 2 µs; TPDO1 (6 bytes)
    // follows: its end is the sample time.
    let sync_bits = u64::from(f("080#").bit_length());
    let tpdo_bits = u64::from(f("18C#060000000000").bit_length());
    assert_eq!(
        samples[0].time.as_nanos(),
        100 * MS + sync_bits * 2_000 + (tpdo_bits - 3) * 2_000
    );
    let speeds: Vec<i16> = samples.iter().map(|s| s.speed).collect();
    // The RPDO is applied at the first SYNC (its end, a little after 100 ms): each later
    // SYNC sees 100 more rpm.
    let want: Vec<i16> = (0..15).map(|k| (k * 100).min(1000)).collect();
    assert_eq!(speeds, want);
    assert_eq!(samples[14].status, 0x0003);
}

#[test]
fn manual_1_2_m2s_enable_off_ignores_rpdo_data() {
    let mut drive = example::drive().unwrap();
    drive.set_param_str(par::FIELDBUS_MS_ENABLE, "Off").unwrap();
    let mut out = Outbox::new();
    drive.on_power_up(Instant::ZERO, &mut out);
    let t = Instant::from_nanos(MS);
    drive.on_frame(&f("000#010C"), t, &mut out);
    drive.on_frame(&f("20C#0300DC05"), t, &mut out);
    drive.on_frame(&f("080#"), t, &mut out);
    assert_eq!(drive.param(par::m2s_mon(1)), Ok(0));
    assert_eq!(drive.param(par::ENABLE_STATE), Ok(0));
}

#[test]
fn manual_1_5_a_drive_reset_forgets_the_process_data_and_boots_without_alarm() {
    let mut drive = example::drive().unwrap();
    let mut out = Outbox::new();
    drive.on_power_up(Instant::ZERO, &mut out);
    let t = Instant::from_nanos(MS);
    drive.on_frame(&f("000#010C"), t, &mut out);
    drive.on_frame(&f("20C#0300DC05"), t, &mut out);
    drive.on_frame(&f("080#"), t, &mut out);
    assert_eq!(drive.param(par::m2s_mon(1)), Ok(3));
    assert_eq!(drive.param(par::ENABLE_STATE), Ok(1));
    // Power cycle: the enable received before it must not enable the drive in
    // Pre-Operational (that would be bus loss by §1.5) nor send an EMCY before the boot-up.
    let mut out = Outbox::new();
    drive.on_power_up(Instant::from_nanos(2 * MS), &mut out);
    let sent: Vec<String> = out.drain().map(|fr| fr.to_string()).collect();
    assert_eq!(sent, ["70C#00"]);
    assert_eq!(drive.param(par::m2s_mon(1)), Ok(0));
    assert_eq!(drive.param(par::m2s_mon(2)), Ok(0));
    assert_eq!(drive.param(par::ENABLE_STATE), Ok(0));
    assert!(drive.opt_bus_faults().is_empty());
}
