//! The fully loaded island that benchmarks measure: a coupler carrying 14 modules (the most
//! a TM3BCCO takes) with all 56 TPDOs valid, and a process whose inputs change every
//! millisecond.
//!
//! At power-up the coupler is configured by SDO writes through its own dictionary (as a
//! master's DCF download would): every TPDO made event-driven with a 10 ms event timer,
//! 4 of them mapping the 18 digital input bytes and 52 mapping four of the 50 analog inputs
//! each, 0x6423 (analog input global interrupt enable) TRUE, then NMT start. Every
//! millisecond one digital input toggles and one analog channel moves along a ramp.
//! At 1 Mbit/s this loads the bus to about 85 %.

use cantwin_can::{ControllerEvent, Duration, Frame, Instant, Node, Outbox};
use cantwin_canopen::{AbortCode, ObjectAccess};

use crate::coupler::{CouplerConfig, CouplerError, Tm3Coupler};
use crate::island::Island;

/// The 14 modules, in bus order: 18 digital input bytes, 50 analog inputs.
pub const MODULES: [&str; 14] = [
    "TM3DI32K",
    "TM3DI32K",
    "TM3DI32K",
    "TM3DI32K",
    "TM3DQ32TK",
    "TM3DM24R",
    "TM3AI8",
    "TM3AI8",
    "TM3AI8",
    "TM3AI8",
    "TM3AI8",
    "TM3AI8",
    "TM3AQ4",
    "TM2AMI2HT",
];

/// The TPDOs made valid: all of the coupler's.
pub const TPDOS: u16 = 56;

/// The event timer of every TPDO (0x1800 + n sub 5), in ms.
pub const EVENT_TIMER_MS: u16 = 10;

/// The identifier of TPDO n (0-based): 0x1C0 + n, clear of every predefined identifier of
/// node 3 and of the restricted ones (CiA 301 §7.3.5).
pub const fn tpdo_cob_id(n: u16) -> u32 {
    0x1C0 + n as u32
}

/// The coupler with [`MODULES`] and a process driving its inputs. See the [module
/// documentation](self).
pub struct FullIsland {
    coupler: Tm3Coupler,
    next: Instant,
    step: u32,
}

impl FullIsland {
    /// An unpowered coupler at `node_id` carrying [`MODULES`].
    pub fn new(node_id: u8) -> Result<Self, CouplerError> {
        // The references are in the catalogue and there are 14 of them.
        let island = Island::from_references(&MODULES).unwrap_or_else(|_| unreachable!());
        Ok(FullIsland {
            coupler: Tm3Coupler::new(CouplerConfig::new(node_id, island))?,
            next: Instant::ZERO,
            step: 0,
        })
    }

    /// The coupler.
    pub fn coupler(&self) -> &Tm3Coupler {
        &self.coupler
    }

    /// Every TPDO event-driven on the 10 ms timer, mapped as the [module
    /// documentation](self) says; CiA 301 §7.3.3's procedure: invalidate, map, validate.
    fn configure(&mut self) -> Result<(), AbortCode> {
        let d = self.coupler.device_mut();
        for n in 0..TPDOS {
            let comm = 0x1800 + n;
            let map = 0x1A00 + n;
            d.write(comm, 1, &(0x8000_0000 | tpdo_cob_id(n)).to_le_bytes())?;
            d.write(map, 0, &[0])?;
            let entries: Vec<u32> = if n < 4 {
                (0..8)
                    .map(|k| 0x6000_0008 | (u32::from((n * 8 + k) % 18 + 1) << 8))
                    .collect()
            } else {
                (0..4)
                    .map(|k| 0x6401_0010 | (u32::from(((n - 4) * 4 + k) % 50 + 1) << 8))
                    .collect()
            };
            for (k, e) in (1u8..).zip(&entries) {
                d.write(map, k, &e.to_le_bytes())?;
            }
            d.write(map, 0, &[entries.len() as u8])?;
            d.write(comm, 5, &EVENT_TIMER_MS.to_le_bytes())?;
            d.write(comm, 1, &tpdo_cob_id(n).to_le_bytes())?;
        }
        d.write(0x6423, 0, &[1])
    }
}

impl Node for FullIsland {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.coupler.on_power_up(now, out);
        // The writes are within the dictionary the coupler was built with: a refusal would
        // leave TPDOs invalid, which the benchmark sees as missing frames.
        let _ = self.configure();
        if let Ok(start) = Frame::std(0, &[1, self.coupler.device().node_id()]) {
            self.coupler.on_frame(&start, now, out);
        }
        self.next = now + Duration::from_millis(1);
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.coupler.on_frame(frame, now, out);
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        if now >= self.next {
            self.step += 1;
            let s = self.step;
            // One digital input toggles, one analog channel moves along a ramp; both are
            // in range by construction.
            let _ =
                self.coupler
                    .set_digital_input((s % 4) as usize + 1, (s % 32) as u8, s % 2 == 0);
            let _ = self.coupler.set_analog_input(
                (s % 6) as usize + 7,
                (s % 8) as u8,
                (s * 37 % 20_000) as i16,
            );
            self.next = now + Duration::from_millis(1);
        }
        self.coupler.on_tick(now, out);
    }

    fn next_deadline(&self) -> Option<Instant> {
        Some(match self.coupler.next_deadline() {
            Some(t) => t.min(self.next),
            None => self.next,
        })
    }

    fn on_sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.coupler.on_sent(frame, now, out);
    }

    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        self.coupler.on_controller_event(event, now, out);
    }
}
