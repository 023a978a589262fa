//! The worked example of §1.6 (node 12 at 500 kbit/s): the parameter settings, and a small
//! network with a master that runs the motor to 1500 rpm and reports what it sees.
//!
//! Wiring (§1.6.1, §1.6.2):
//!
//! * M2S word 1 = control word into WordDecomp (`Fieldbus M->S1 ipa` = 4452, Count 16): bit 0
//!   → `Dig enable src`, bit 1 → `Dig start src`, bit 8 → digital output 3, bit 9 → digital
//!   output 4; `Commands remote sel` = Digital.
//! * M2S word 2 = Ramp ref 1 in rpm (`Fieldbus M->S2 ipa` = 610, Eu).
//! * S2M word 1 = status word from WordComp (4432): bit 0 Enable state, bit 1 Drive ok, bit 2
//!   Speed is zero, bit 8 digital input 4, bit 9 digital input 5; word 2 = Motor speed (260);
//!   word 3 = Analog input 2 (1550).

use cantwin_bus::{BusConfig, BusError, PortConfig, Recorder, Simulation};
use cantwin_can::{BitRate, Duration, Frame, Instant, Node, Outbox};

use crate::card::{Adv200, Adv200Config};
use crate::params::{ParamError, par};

/// Why the example could not run.
#[derive(Debug, thiserror::Error)]
pub enum ExampleError {
    /// A parameter setting was refused (a defect of the example).
    #[error("parameter: {0}")]
    Param(#[from] ParamError),
    /// The virtual bus refused something.
    #[error("bus: {0}")]
    Bus(#[from] BusError),
    /// A frame could not be built.
    #[error("frame: {0}")]
    Frame(#[from] cantwin_can::FrameError),
}

/// A node that only acknowledges frames: the master's port on the example's bus.
#[derive(Debug, Clone, Copy, Default)]
pub struct Master;

impl Node for Master {
    fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

/// The example's node-ID.
pub const NODE: u8 = 12;

/// Applies the parameter settings of §1.6.2 to a drive with factory parameters (they take
/// effect at the next drive reset).
pub fn configure(drive: &mut Adv200) -> Result<(), ParamError> {
    drive.set_param_str(par::FIELDBUS_TYPE, "CANopen")?;
    drive.set_param_str(par::FIELDBUS_BAUDRATE, "500k")?;
    drive.set_param(par::FIELDBUS_ADDRESS, i64::from(NODE))?;
    drive.set_param_str(par::m2s_sys(1), "Count 16")?;
    drive.set_param(par::m2s_ipa(1), i64::from(par::WORD_DECOMP_SRC))?;
    drive.set_param_str(par::m2s_sys(2), "Eu")?;
    drive.set_param(par::m2s_ipa(2), i64::from(par::RAMP_REF_1_SRC))?;
    drive.set_param_str(par::COMMANDS_REMOTE_SEL, "Digital")?;
    drive.set_param(par::DIG_ENABLE_SRC, i64::from(par::word_decomp_bit(0)))?;
    drive.set_param(par::DIG_START_SRC, i64::from(par::word_decomp_bit(1)))?;
    drive.set_param(
        par::digital_output_src(3),
        i64::from(par::word_decomp_bit(8)),
    )?;
    drive.set_param(
        par::digital_output_src(4),
        i64::from(par::word_decomp_bit(9)),
    )?;
    drive.set_param(par::word_comp_bit_src(0), i64::from(par::ENABLE_STATE))?;
    drive.set_param(par::word_comp_bit_src(1), i64::from(par::DRIVE_OK))?;
    drive.set_param(par::word_comp_bit_src(2), i64::from(par::SPEED_IS_ZERO))?;
    drive.set_param(par::word_comp_bit_src(8), i64::from(par::digital_input(4)))?;
    drive.set_param(par::word_comp_bit_src(9), i64::from(par::digital_input(5)))?;
    drive.set_param_str(par::s2m_sys(1), "Count 16")?;
    drive.set_param(par::s2m_ipa(1), i64::from(par::WORD_COMP_MON))?;
    drive.set_param_str(par::s2m_sys(2), "Eu")?;
    drive.set_param(par::s2m_ipa(2), i64::from(par::MOTOR_SPEED))?;
    drive.set_param_str(par::s2m_sys(3), "Count 16")?;
    drive.set_param(par::s2m_ipa(3), i64::from(par::ANALOG_INPUT_2))?;
    Ok(())
}

/// A drive configured as in §1.6, already reset (powered up) at time zero.
pub fn drive() -> Result<Adv200, ParamError> {
    let mut d = Adv200::new(Adv200Config {
        bus_bit_rate: Some(500_000),
        ..Adv200Config::default()
    });
    configure(&mut d)?;
    Ok(d)
}

/// One sample of [`run`]: what the master read from TPDO1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sample {
    /// Bus time.
    pub time: Instant,
    /// The status word (S2M word 1).
    pub status: u16,
    /// The actual speed, rpm (S2M word 2).
    pub speed: i16,
    /// Analog input 2, counts (S2M word 3).
    pub analog_input_2: i16,
}

/// Runs the example on a 500 kbit/s virtual bus with exact frame timing: the drive boots at
/// 0, the master starts it at 1 ms, sends RPDO1 (enable + start, `speed` rpm) at 2 ms and a
/// SYNC every `period` from `period` on, until `duration`. Returns TPDO1 as the master
/// received it (its time is the end of the frame).
pub fn simulate(
    speed: i16,
    period: Duration,
    duration: Duration,
) -> Result<Vec<Sample>, ExampleError> {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R500K));
    sim.attach(bus, drive()?, PortConfig::default())?;
    let m = sim.attach(bus, Master, PortConfig::default())?;
    let tap = sim
        .bus_mut(bus)
        .ok_or(BusError::NoSuchBus(bus))?
        .add_tap(Recorder::new());
    let ms = Duration::from_millis(1);
    sim.run_until(Instant::ZERO + ms);
    sim.transmit(m, Frame::std(0x000, &[0x01, NODE])?)?;
    sim.run_until(Instant::ZERO + ms + ms);
    let s = speed.to_le_bytes();
    sim.transmit(
        m,
        Frame::std(0x200 + u16::from(NODE), &[0x03, 0x00, s[0], s[1]])?,
    )?;
    let end = Instant::ZERO + duration;
    let mut t = Instant::ZERO + period.max(ms + ms + ms);
    while t <= end {
        sim.run_until(t);
        sim.transmit(m, Frame::std(0x080, &[])?)?;
        t += period.max(ms);
    }
    sim.run_until(end + ms);
    let rec = sim
        .bus(bus)
        .ok_or(BusError::NoSuchBus(bus))?
        .tap::<Recorder>(tap)
        .ok_or(BusError::NoSuchBus(bus))?;
    Ok(rec
        .frames()
        .filter(|r| r.frame.id().as_raw() == 0x180 + u32::from(NODE) && r.frame.len() >= 6)
        .map(|r| {
            let b = r.frame.data_bytes();
            Sample {
                time: r.end,
                status: u16::from_le_bytes([b[0], b[1]]),
                speed: i16::from_le_bytes([b[2], b[3]]),
                analog_input_2: i16::from_le_bytes([b[4], b[5]]),
            }
        })
        .collect())
}

/// Runs the example without a bus (frames handed straight to the drive): NMT start, then
/// every `period` a SYNC and an RPDO1 with enable + start and `speed` rpm, for `duration`.
/// Returns TPDO1 as the master sees it after each SYNC.
pub fn run(speed: i16, period: Duration, duration: Duration) -> Result<Vec<Sample>, ExampleError> {
    let mut d = drive()?;
    let mut out = Outbox::new();
    let mut now = Instant::ZERO;
    d.on_power_up(now, &mut out);
    let start = Frame::std(0x000, &[0x01, NODE])?;
    d.on_frame(&start, now, &mut out);
    let s = speed.to_le_bytes();
    let rpdo = Frame::std(0x200 + u16::from(NODE), &[0x03, 0x00, s[0], s[1]])?;
    let sync = Frame::std(0x080, &[])?;
    let mut samples = Vec::new();
    let end = Instant::ZERO + duration;
    while now <= end {
        out.clear();
        d.on_frame(&rpdo, now, &mut out);
        d.on_frame(&sync, now, &mut out);
        for f in out.frames() {
            if f.id().as_raw() == 0x180 + u32::from(NODE) && f.len() >= 6 {
                let b = f.data_bytes();
                samples.push(Sample {
                    time: now,
                    status: u16::from_le_bytes([b[0], b[1]]),
                    speed: i16::from_le_bytes([b[2], b[3]]),
                    analog_input_2: i16::from_le_bytes([b[4], b[5]]),
                });
            }
        }
        let next = now + period;
        while let Some(t) = d.next_deadline().filter(|t| *t < next) {
            d.on_tick(t, &mut out);
        }
        now = next;
    }
    Ok(samples)
}
