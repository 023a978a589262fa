//! The servo on a virtual bus with a scripted master: CiA 301 start-up, the CiA 402-3
//! pre-defined PDOs, the power drive state machine by RPDO, profile position by SDO and
//! cyclic synchronous position streamed at 1 ms SYNC, each frame checked as it is on the
//! wire.
#![allow(clippy::unwrap_used)]

use std::collections::VecDeque;

use cantwin_bus::{BusConfig, BusId, PortConfig, Recorder, Simulation, TapId};
use cantwin_can::{BitRate, Frame, Instant, Node, Outbox};
use cantwin_servo::{Servo, ServoConfig};

/// A master that sends frames at given times.
#[derive(Default)]
struct Script {
    frames: VecDeque<(Instant, Frame)>,
}

impl Script {
    fn at(&mut self, ms: f64, id: u16, data: &[u8]) {
        let t = Instant::from_nanos((ms * 1e6) as u64);
        self.frames.push_back((t, Frame::std(id, data).unwrap()));
    }
}

impl Node for Script {
    fn on_frame(&mut self, _frame: &Frame, _now: Instant, _out: &mut Outbox) {}
    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        while self.frames.front().is_some_and(|(t, _)| *t <= now) {
            let (_, f) = self.frames.pop_front().unwrap();
            out.push(f);
        }
    }
    fn next_deadline(&self) -> Option<Instant> {
        self.frames.front().map(|(t, _)| *t)
    }
}

fn run(script: Script, until_ms: u64) -> (Simulation, BusId, TapId) {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    sim.attach(
        bus,
        Servo::new(ServoConfig::new(5)).unwrap(),
        PortConfig::default(),
    )
    .unwrap();
    sim.attach(bus, script, PortConfig::default()).unwrap();
    sim.run_until(Instant::from_nanos(until_ms * 1_000_000));
    (sim, bus, tap)
}

fn frames(sim: &Simulation, bus: BusId, tap: TapId, id: u32) -> Vec<(f64, Vec<u8>)> {
    sim.bus(bus)
        .unwrap()
        .tap::<Recorder>(tap)
        .unwrap()
        .frames()
        .filter(|r| r.frame.id().as_raw() == id)
        .map(|r| (r.end.as_nanos() as f64 / 1e6, r.frame.data_bytes().to_vec()))
        .collect()
}

fn sdo_write(s: &mut Script, ms: f64, index: u16, sub: u8, value: &[u8]) {
    let cmd = match value.len() {
        1 => 0x2F,
        2 => 0x2B,
        _ => 0x23,
    };
    let mut d = vec![cmd, index as u8, (index >> 8) as u8, sub];
    d.extend_from_slice(value);
    d.resize(8, 0);
    s.at(ms, 0x605, &d);
}

#[test]
fn cia402_3_tpdo1_follows_the_state_machine_driven_by_rpdo1() {
    let mut s = Script::default();
    s.at(1.0, 0x000, &[0x01, 5]);
    s.at(2.0, 0x205, &[0x06, 0x00]);
    s.at(3.0, 0x205, &[0x0F, 0x00]);
    s.at(4.0, 0x205, &[0x0B, 0x00]);
    let (sim, bus, tap) = run(s, 10);
    assert_eq!(frames(&sim, bus, tap, 0x705)[0].1, [0x00], "boot-up");
    let sw: Vec<u16> = frames(&sim, bus, tap, 0x185)
        .iter()
        .map(|(_, d)| u16::from_le_bytes([d[0], d[1]]))
        .collect();
    // Entering OPERATIONAL sends the event-driven TPDO once; then each statusword change:
    // READY TO SWITCH ON, OPERATION ENABLED, QUICK STOP ACTIVE, SWITCH ON DISABLED.
    assert_eq!(sw.first(), Some(&0x0240));
    let states: Vec<u16> = sw.iter().map(|w| w & 0x6F).collect();
    for want in [0x21, 0x27, 0x07] {
        assert!(states.contains(&want), "{want:#04x} in {sw:04x?}");
    }
    assert_eq!(sw.last().map(|w| w & 0x4F), Some(0x40), "{sw:04x?}");
    // TPDO2 carries 0x6061 beside the statusword: no mode yet.
    let t2 = frames(&sim, bus, tap, 0x285);
    assert_eq!(t2[0].1.len(), 3);
    assert_eq!(t2[0].1[2], 0);
}

#[test]
fn cia402_6060h_refuses_an_unsupported_mode_by_sdo() {
    let mut s = Script::default();
    sdo_write(&mut s, 1.0, 0x6060, 0, &[5]);
    // 15 is reserved (CiA 402-2 homing methods).
    sdo_write(&mut s, 2.0, 0x6098, 0, &[15]);
    sdo_write(&mut s, 3.0, 0x6060, 0, &[1]);
    let (sim, bus, tap) = run(s, 5);
    let answers = frames(&sim, bus, tap, 0x585);
    assert_eq!(
        answers[0].1,
        [0x80, 0x60, 0x60, 0x00, 0x30, 0x00, 0x09, 0x06]
    );
    assert_eq!(
        answers[1].1,
        [0x80, 0x98, 0x60, 0x00, 0x30, 0x00, 0x09, 0x06]
    );
    assert_eq!(answers[2].1, [0x60, 0x60, 0x60, 0x00, 0, 0, 0, 0]);
}

#[test]
fn cia402_pp_profile_move_by_sdo_reports_target_reached_in_tpdo1() {
    let mut s = Script::default();
    s.at(1.0, 0x000, &[0x01, 5]);
    sdo_write(&mut s, 2.0, 0x6060, 0, &[1]);
    sdo_write(&mut s, 3.0, 0x6040, 0, &[0x06, 0x00]);
    sdo_write(&mut s, 4.0, 0x6040, 0, &[0x0F, 0x00]);
    sdo_write(&mut s, 5.0, 0x607A, 0, &8192i32.to_le_bytes());
    sdo_write(&mut s, 6.0, 0x6040, 0, &[0x1F, 0x00]);
    sdo_write(&mut s, 7.0, 0x6040, 0, &[0x0F, 0x00]);
    let (sim, bus, tap) = run(s, 600);
    let sw: Vec<(f64, u16)> = frames(&sim, bus, tap, 0x185)
        .iter()
        .map(|(t, d)| (*t, u16::from_le_bytes([d[0], d[1]])))
        .collect();
    // The set-point acknowledge answers the new set-point at once, in its SDO's millisecond.
    let ack = sw.iter().find(|(_, w)| w & 0x1000 != 0).unwrap();
    assert!(ack.0 >= 6.0 && ack.0 < 6.2, "{ack:?}");
    // Target reached once the move (8192 units at 40 960 units/s, 409 600 units/s²) is over.
    let (t, last) = *sw.last().unwrap();
    assert_eq!(last & 0x146F, 0x0427, "{sw:04x?}");
    assert!(t > 250.0 && t < 400.0, "{t}");
}

#[test]
fn cia402_csp_streamed_at_1_ms_sync_is_followed() {
    let mut s = Script::default();
    s.at(1.0, 0x000, &[0x01, 5]);
    // RPDO3 (controlword + target position) and TPDO3 (statusword + position) both at
    // every SYNC.
    sdo_write(&mut s, 2.0, 0x1402, 2, &[1]);
    sdo_write(&mut s, 3.0, 0x6060, 0, &[8]);
    s.at(4.0, 0x205, &[0x06, 0x00]);
    s.at(5.0, 0x205, &[0x0F, 0x00]);
    for k in 0..300u32 {
        let target = (k * 40) as i32;
        let mut d = vec![0x0F, 0x00];
        d.extend_from_slice(&target.to_le_bytes());
        let t = 10.0 + f64::from(k);
        s.at(t, 0x405, &d);
        s.at(t + 0.5, 0x080, &[]);
    }
    let (sim, bus, tap) = run(s, 320);
    let tpdo3 = frames(&sim, bus, tap, 0x385);
    assert!(tpdo3.len() >= 300, "{}", tpdo3.len());
    let last = &tpdo3.last().unwrap().1;
    let sw = u16::from_le_bytes([last[0], last[1]]);
    let pos = i32::from_le_bytes([last[2], last[3], last[4], last[5]]);
    assert_eq!(
        sw & 0x106F,
        0x1027,
        "operation enabled, drive follows: {sw:#06x}"
    );
    // The last set-point is 11 960; the axis follows it closely once the stream ends.
    assert!((pos - 11_960).abs() < 50, "{pos}");
    // While streaming, the TPDO at each SYNC shows the position a SYNC earlier, plus
    // the following error of a 40 000 units/s move.
    let mid = &tpdo3[tpdo3.len() / 2].1;
    let p = i32::from_le_bytes([mid[2], mid[3], mid[4], mid[5]]);
    assert!(p > 4000 && p < 8000, "{p}");
}
