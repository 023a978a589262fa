//! PDOs of the coupler: the manual's default mappings per module set (objects 1600H and
//! 1A00H), CiA 401 input events on TPDOs with inhibit time and event timer (objects
//! 1800H–1837H), analog interrupt triggers (6421H) and the RPDO deadline (1400H sub 5).
#![allow(clippy::unwrap_used)]

mod harness;

use cantwin_bus::{BusConfig, PortConfig, Recorder, Simulation};
use cantwin_can::{BitRate, Frame, Instant, Node, Outbox};
use cantwin_canopen::nmt::State;
use cantwin_tm3::coupler::{CouplerConfig, Tm3Coupler};
use cantwin_tm3::island::Island;
use harness::*;

fn mapping(c: &mut Tm3Coupler, index: u16) -> Vec<u32> {
    let t = ms(1);
    let n = read_u32(c, t, index, 0).unwrap() as u8;
    (1..=n).map(|s| read_u32(c, t, index, s).unwrap()).collect()
}

#[test]
fn manual_1600_1a00_default_mapping_of_a_mixed_island() {
    let mut c = coupler(&["TM3DI16", "TM3DQ16T", "TM3AI4", "TM3AQ2"]);
    assert_eq!(mapping(&mut c, 0x1600), [0x6200_0108]);
    assert_eq!(mapping(&mut c, 0x1601), [0x6411_0110, 0x6411_0210]);
    assert_eq!(mapping(&mut c, 0x1602), Vec::<u32>::new());
    assert_eq!(mapping(&mut c, 0x1A00), [0x6000_0108]);
    assert_eq!(
        mapping(&mut c, 0x1A01),
        [0x6401_0110, 0x6401_0210, 0x6401_0310, 0x6401_0410]
    );
    assert_eq!(mapping(&mut c, 0x1A02), Vec::<u32>::new());
    assert_eq!(mapping(&mut c, 0x1A04), Vec::<u32>::new());
}

#[test]
fn manual_1600_1a00_default_mapping_stops_at_twelve_analog_channels() {
    let mut c = coupler(&["TM3AI8", "TM3AI8", "TM3AQ4", "TM3AQ4", "TM3AQ4", "TM3AQ4"]);
    assert_eq!(
        mapping(&mut c, 0x1600),
        Vec::<u32>::new(),
        "no digital outputs"
    );
    assert_eq!(
        mapping(&mut c, 0x1A00),
        Vec::<u32>::new(),
        "no digital inputs"
    );
    assert_eq!(read_u32(&mut c, ms(1), 0x1400, 1), Ok(0x8000_0203));
    assert_eq!(read_u32(&mut c, ms(1), 0x1800, 1), Ok(0x8000_0183));
    for k in 0..3u32 {
        let rx: Vec<u32> = (1..=4).map(|s| 0x6411_0010 | (4 * k + s) << 8).collect();
        let tx: Vec<u32> = (1..=4).map(|s| 0x6401_0010 | (4 * k + s) << 8).collect();
        assert_eq!(mapping(&mut c, 0x1601 + k as u16), rx);
        assert_eq!(mapping(&mut c, 0x1A01 + k as u16), tx);
    }
    // 16 inputs exist; 13..=16 are not mapped by default.
    assert_eq!(read_u32(&mut c, ms(1), 0x6401, 0), Ok(16));
    assert_eq!(mapping(&mut c, 0x1A04), Vec::<u32>::new());
}

#[test]
fn manual_1600_only_digital_modules() {
    let mut c = coupler(&["TM3DQ8R", "TM2DDI8DT", "TM3DM24R"]);
    assert_eq!(mapping(&mut c, 0x1600), [0x6200_0108]);
    assert_eq!(mapping(&mut c, 0x1A00), [0x6000_0108]);
    assert_eq!(read_u32(&mut c, ms(1), 0x6000, 0), Ok(3));
    assert_eq!(read_u32(&mut c, ms(1), 0x6200, 0), Ok(2));
    assert_eq!(read_u32(&mut c, ms(1), 0x1401, 1), Ok(0x8000_0303));
    assert_eq!(read_u32(&mut c, ms(1), 0x1801, 1), Ok(0x8000_0283));
}

/// Drives input changes of a coupler on the bus at given instants.
struct Scripted {
    coupler: Tm3Coupler,
    script: Vec<(Instant, usize, u8, bool)>,
}

impl Node for Scripted {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.coupler.on_power_up(now, out);
    }
    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.coupler.on_frame(frame, now, out);
    }
    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        while let Some(&(t, m, ch, on)) = self.script.first() {
            if t > now {
                break;
            }
            self.script.remove(0);
            self.coupler.set_digital_input(m, ch, on).unwrap();
        }
        self.coupler.on_tick(now, out);
    }
    fn next_deadline(&self) -> Option<Instant> {
        let s = self.script.first().map(|e| e.0);
        match (s, self.coupler.next_deadline()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
    fn on_sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.coupler.on_sent(frame, now, out);
    }
}

/// The master side: sends what the test queues.
struct Master;

impl Node for Master {
    fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

/// (start ns, frame) of every frame the coupler sent on a 1 Mbit/s bus until `until`,
/// after SDO downloads `setup` (at 1 ms, 2 ms, ...) and NMT start at 10 ms.
fn run_on_bus(
    refs: &[&str],
    setup: &[(u16, u8, &[u8])],
    script: Vec<(Instant, usize, u8, bool)>,
    until: Instant,
) -> Vec<(u64, String)> {
    let coupler = Tm3Coupler::new(CouplerConfig::new(
        NODE,
        Island::from_references(refs).unwrap(),
    ))
    .unwrap();
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    let port = sim
        .attach(bus, Scripted { coupler, script }, PortConfig::default())
        .unwrap();
    let master = sim.attach(bus, Master, PortConfig::default()).unwrap();
    for (k, (index, sub, data)) in setup.iter().enumerate() {
        sim.run_until(ms(k as u64 + 1));
        let [lo, hi] = index.to_le_bytes();
        let mut f = [0u8; 8];
        f[0] = 0x23 | ((4 - data.len() as u8) << 2);
        f[1..4].copy_from_slice(&[lo, hi, *sub]);
        f[4..4 + data.len()].copy_from_slice(data);
        sim.transmit(master, Frame::std(0x603, &f).unwrap())
            .unwrap();
    }
    sim.run_until(ms(10));
    sim.transmit(master, Frame::std(0, &[1, NODE]).unwrap())
        .unwrap();
    sim.run_until(until);
    let rec = sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
    rec.frames()
        .filter(|f| f.sender == port)
        .filter(|f| {
            !f.frame.to_string().starts_with("583#") && !f.frame.to_string().starts_with("703#")
        })
        .map(|f| (f.start.as_nanos(), f.frame.to_string()))
        .collect()
}

/// The end of the NMT start frame's EOF at 1 Mbit/s (the coupler starts then).
fn nmt_start_end() -> u64 {
    10_000_000 + (u64::from(Frame::std(0, &[1, NODE]).unwrap().bit_length()) - 3) * 1_000
}

/// When the bus is idle again after the NMT start (3 bits of intermission later): the
/// first TPDO starts then.
fn first_tpdo() -> u64 {
    nmt_start_end() + 3_000
}

#[test]
fn cia401_digital_input_change_sends_tpdo1_after_the_inhibit_time() {
    // Inhibit 10 × 100 µs = 1 ms. Changes at 20 ms, 20.2 ms and 20.5 ms: the first goes out at
    // once, the next two as one TPDO 1 ms after the end of the first.
    let script = vec![
        (us(20_000), 1, 0, true),
        (us(20_200), 1, 1, true),
        (us(20_500), 1, 2, true),
        (us(30_000), 1, 2, false),
    ];
    let trace = run_on_bus(
        &["TM3DI8"],
        // The inhibit time changes only while the PDO is invalid (CiA 301 §7.5.2.35).
        &[
            (0x1800, 1, &0x8000_0183u32.to_le_bytes()),
            (0x1800, 3, &10u16.to_le_bytes()),
            (0x1800, 1, &0x183u32.to_le_bytes()),
        ],
        script,
        ms(40),
    );
    let first_end =
        20_000_000 + (u64::from(Frame::std(0x183, &[1]).unwrap().bit_length()) - 3) * 1_000;
    assert_eq!(
        trace,
        [
            (first_tpdo(), "183#00".to_string()),
            (20_000_000, "183#01".to_string()),
            (first_end + 1_000_000, "183#07".to_string()),
            (30_000_000, "183#03".to_string()),
        ]
    );
}

#[test]
fn cia401_event_timer_repeats_tpdo1() {
    // Event timer 5 ms (manual: 1800H sub 5, multiples of 1 ms).
    let trace = run_on_bus(
        &["TM3DI8"],
        &[(0x1800, 5, &5u16.to_le_bytes())],
        vec![(ms(17), 1, 7, true)],
        ms(30),
    );
    // The timer runs from the start of OPERATIONAL, when the first TPDO was queued.
    let start = nmt_start_end();
    assert_eq!(
        trace,
        [
            (first_tpdo(), "183#00".to_string()),
            (start + 5_000_000, "183#00".to_string()),
            (17_000_000, "183#80".to_string()),
            (22_000_000, "183#80".to_string()),
            (27_000_000, "183#80".to_string()),
        ]
    );
}

#[test]
fn cia401_6005_disabled_digital_interrupts_send_nothing() {
    let trace = run_on_bus(
        &["TM3DI8"],
        &[(0x6005, 0, &[0])],
        vec![(ms(20), 1, 0, true)],
        ms(30),
    );
    assert_eq!(trace, [(first_tpdo(), "183#00".to_string())]);
}

#[test]
fn cia401_6421_analog_triggers_send_tpdo2() {
    let mut c = coupler(&["TM3AI2H"]);
    assert_eq!(write(&mut c, ms(1), 0x6423, 0, &[1]), Ok(()));
    assert_eq!(write(&mut c, ms(1), 0x6421, 1, &[0x01]), Ok(()));
    assert_eq!(
        write(&mut c, ms(1), 0x6424, 1, &1000i32.to_le_bytes()),
        Ok(())
    );
    assert_eq!(write(&mut c, ms(1), 0x6421, 2, &[0x04]), Ok(()));
    assert_eq!(
        write(&mut c, ms(1), 0x6426, 2, &50u32.to_le_bytes()),
        Ok(())
    );
    assert_eq!(start(&mut c, ms(2)), ["283#00000000"]);
    c.set_analog_input(1, 0, 900).unwrap();
    assert_eq!(
        tick(&mut c, ms(3)),
        Vec::<String>::new(),
        "below the upper limit"
    );
    c.set_analog_input(1, 0, 1001).unwrap();
    assert_eq!(tick(&mut c, ms(4)), ["283#E9030000"]);
    c.set_analog_input(1, 0, 2000).unwrap();
    assert_eq!(tick(&mut c, ms(5)), Vec::<String>::new(), "still above");
    c.set_analog_input(1, 1, 50).unwrap();
    assert_eq!(
        tick(&mut c, ms(6)),
        Vec::<String>::new(),
        "delta not exceeded"
    );
    c.set_analog_input(1, 1, -51).unwrap();
    assert_eq!(tick(&mut c, ms(7)), ["283#D007CDFF"]);
    assert!(c.set_analog_input(1, 2, 0).is_err());
}

#[test]
fn manual_0080_analog_interrupts_disabled_on_start() {
    let mut c = coupler(&["TM3AI2H"]);
    // 0x6423 is FALSE by default: EMCY 0x0080 with the error register's generic and
    // device profile bits (0x21),
    // after the TPDOs sent on entering OPERATIONAL.
    assert_eq!(
        start(&mut c, ms(2)),
        ["283#00000000", "083#8000210000000000"]
    );
    c.set_analog_input(1, 0, 5000).unwrap();
    assert_eq!(tick(&mut c, ms(3)), Vec::<String>::new());
    // Enabling the interrupts corrects it: error reset, with the SDO response.
    assert_eq!(
        send(&mut c, ms(4), 0x603, &[0x2F, 0x23, 0x64, 0, 1, 0, 0, 0]),
        ["583#6023640000000000", "083#0000000000000000"]
    );
    assert_eq!(read_u32(&mut c, ms(5), 0x1003, 1), Ok(0x0021_0080));
}

#[test]
fn cia301_rpdo_deadline_is_armed_by_the_first_reception() {
    let mut c = coupler(&["TM3DQ8T"]);
    assert_eq!(
        write(&mut c, ms(1), 0x1400, 5, &100u16.to_le_bytes()),
        Ok(())
    );
    assert_eq!(write(&mut c, ms(1), 0x6206, 1, &[0x0F]), Ok(()));
    assert_eq!(write(&mut c, ms(1), 0x6207, 1, &[0x05]), Ok(()));
    start(&mut c, ms(2));
    assert_eq!(c.next_deadline(), None, "not armed before the first RPDO");
    assert_eq!(send(&mut c, ms(10), 0x203, &[0xF0]), Vec::<String>::new());
    assert_eq!(c.digital_output(1, 4), Ok(true));
    assert_eq!(c.next_deadline(), Some(ms(110)));
    // The deadline passes: EMCY 0x8250, outputs 0..3 take the error value 0b0101, the
    // others keep their value; 0x1029 = 0 makes the coupler pre-operational.
    assert_eq!(tick(&mut c, ms(110)), ["083#5082110000000000"]);
    let outs: Vec<bool> = (0..8).map(|ch| c.digital_output(1, ch).unwrap()).collect();
    assert_eq!(outs, [true, false, true, false, true, true, true, true]);
    assert!(c.in_failure_state());
    assert_eq!(c.state(), State::PreOperational);
    assert_eq!(read_u32(&mut c, ms(111), 0x1003, 1), Ok(0x0011_8250));
    // Back to OPERATIONAL and a new RPDO: the outputs follow the master again.
    start(&mut c, ms(120));
    assert!(!c.in_failure_state());
    assert_eq!(
        send(&mut c, ms(121), 0x203, &[0x01]),
        ["083#0000000000000000"]
    );
    assert_eq!(c.digital_output(1, 0), Ok(true));
    assert_eq!(c.digital_output(1, 4), Ok(false));
}

#[test]
fn manual_1800_type_0_sends_after_sync_following_an_event() {
    let mut c = coupler(&["TM3DI8"]);
    assert_eq!(write(&mut c, ms(1), 0x1800, 2, &[0]), Ok(()));
    assert_eq!(
        start(&mut c, ms(2)),
        Vec::<String>::new(),
        "synchronous: nothing on start"
    );
    c.set_digital_input(1, 3, true).unwrap();
    assert_eq!(tick(&mut c, ms(3)), Vec::<String>::new());
    assert_eq!(send(&mut c, ms(4), 0x080, &[]), ["183#08"]);
    assert_eq!(
        send(&mut c, ms(5), 0x080, &[]),
        Vec::<String>::new(),
        "no new event"
    );
}

#[test]
fn manual_1800_type_2_sends_every_second_sync() {
    let mut c = coupler(&["TM3DI8"]);
    assert_eq!(write(&mut c, ms(1), 0x1800, 2, &[2]), Ok(()));
    start(&mut c, ms(2));
    let sent: Vec<Vec<String>> = (0..4)
        .map(|k| send(&mut c, ms(10 + k), 0x080, &[]))
        .collect();
    assert_eq!(
        sent,
        [
            vec![],
            vec!["183#00".to_string()],
            vec![],
            vec!["183#00".to_string()]
        ]
    );
}

#[test]
fn manual_1400_synchronous_rpdo_applies_at_the_next_sync() {
    let mut c = coupler(&["TM3DQ8T"]);
    assert_eq!(write(&mut c, ms(1), 0x1400, 2, &[0]), Ok(()));
    start(&mut c, ms(2));
    send(&mut c, ms(3), 0x203, &[0x81]);
    assert_eq!(c.digital_output(1, 0), Ok(false), "held until SYNC");
    send(&mut c, ms(4), 0x080, &[]);
    assert_eq!(c.digital_output(1, 0), Ok(true));
    assert_eq!(c.digital_output(1, 7), Ok(true));
}
