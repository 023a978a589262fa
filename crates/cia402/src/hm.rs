//! Homing mode (hm, CiA 402-2 homing mode): the homing methods of 0x6098, run with the
//! speeds of 0x6099 (1: search for switch, fast; 2: search for zero, slow) and 0x609A
//! homing acceleration. Controlword bit 4 starts homing on its rising edge and interrupts
//! it when it falls; bit 8 halts it (interrupted). At the home position the position actual
//! value becomes 0x607C home offset (the zero position is the home position shifted by the
//! home offset).
//!
//! | method | searches | home position |
//! |---|---|---|
//! | 1, 17 | negative (fast) for the negative limit switch, back (slow) until it is inactive | 1: the first index pulse beyond that transition; 17: the transition |
//! | 2, 18 | as 1 and 17, mirrored: the positive limit switch | as 1, 17 |
//! | 3, 19 | positive home switch: positive (fast) until it is active, back (slow) until it is inactive; started on the switch, only the second | 3: the first index pulse beyond the transition (on its negative side); 19: the transition |
//! | 4, 20 | positive home switch: started on it, negative (fast) until inactive; then positive (slow) until it is active | 4: the first index pulse beyond the transition (its positive side); 20: the transition |
//! | 5, 21 and 6, 22 | as 3, 19 and 4, 20 with the directions reversed (a negative home switch) | as 3, 4 |
//! | 7–10, 23–26 | a home switch that is a cam between the limit switches: positive (fast) until it is active, reversing at the positive limit switch if it is met first (the cam lies behind); then as below | 7, 23: the cam's negative edge, left moving negative; 8, 24: the negative edge, entered moving positive; 9, 25: the positive edge, entered moving negative; 10, 26: the positive edge, left moving positive |
//! | 11–14, 27–30 | as 7–10 and 23–26 mirrored: negative first, reversing at the negative limit switch | 11, 27: the positive edge, left moving positive; 12, 28: the positive edge, entered moving negative; 13, 29: the negative edge, entered moving positive; 14, 30: the negative edge, left moving negative |
//! | 33, 34 | negative (33) or positive (34), slow, to the first index pulse | the index pulse |
//! | 35, 37 | nothing: the drive does not move | the current position |
//!
//! In methods 7–14 the home position is the first index pulse beyond the edge in the
//! direction it is crossed, in 23–30 (no index pulse) the edge itself. A method started on
//! the cam first moves toward the edge it looks for (CiA 402-2, homing methods 7 to 14:
//! the initial direction depends on the edge sought when the home switch is active). To
//! leave the cam through an edge the drive moves off it slowly; to enter it through an
//! edge the drive stands beyond the edge and moves onto it slowly, except that with an
//! index pulse a search that has just entered the cam through that edge in that direction
//! goes on to the pulse (the edge is not the home position, the pulse is). Methods 23–30
//! always cross their edge at the search-for-zero speed, as 19–22 do, so the home
//! position is the same from either side of the cam.
//!
//! A limit switch met in the direction of a search that does not look for it (nor
//! reverses at it) is a homing error, and so is a method that needs a switch the drive has
//! not got wired. The manufacturer-specific negative methods, 0 and the reserved 15, 16,
//! 31, 32 and 36 are not supported: 0x6098 refuses them.
//!
//! Statusword bits 13, 12, 10 (CiA 402-2, homing mode statusword):
//!
//! | 13 | 12 | 10 | meaning |
//! |---|---|---|---|
//! | 0 | 0 | 0 | homing in progress |
//! | 0 | 0 | 1 | homing interrupted or not started |
//! | 0 | 1 | 0 | homing attained, target not reached (the axis is stopping) |
//! | 0 | 1 | 1 | homing completed successfully |
//! | 1 | 0 | 0 | homing error, velocity not 0 |
//! | 1 | 0 | 1 | homing error, velocity 0 |

use crate::physics::{HOME_SWITCH, NEGATIVE_LIMIT_SWITCH, POSITIVE_LIMIT_SWITCH};

/// What a search step waits for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Until {
    /// The 0x60FD input becomes active.
    Active(u32),
    /// The 0x60FD input becomes inactive.
    Inactive(u32),
    /// An index pulse.
    Index,
}

/// One step of a homing method: move in `direction` at the fast or slow speed until.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Search {
    /// +1 or −1.
    pub direction: i8,
    /// Speed during search for switch (0x6099 sub 1) rather than for zero (sub 2).
    pub fast: bool,
    /// The event that ends the step.
    pub until: Until,
    /// The limit switch (0x60FD bit, 0: none) at which the step reverses once: the home
    /// switch of methods 7–14 and 23–30 lies behind the start when it is met first.
    pub reverse_at: u32,
    /// Skip the step when the step before ended on a transition met moving in this
    /// direction (the edge it crossed is the one sought, crossed the way it is sought).
    pub skip_after: Option<i8>,
}

const fn s(direction: i8, fast: bool, until: Until) -> Search {
    Search {
        direction,
        fast,
        until,
        reverse_at: 0,
        skip_after: None,
    }
}

/// Methods 7–14 and 23–30 (CiA 402-2 homing on the home switch, a cam, with reversal at
/// the limit switch): search `d` first; the edge sought is on the `w` side of the cam,
/// crossed moving `a`; `index`: home on the first index pulse beyond it.
fn cam(d: i8, w: i8, a: i8, index: bool) -> Vec<Search> {
    use Until::*;
    let limit = if d > 0 {
        POSITIVE_LIMIT_SWITCH
    } else {
        NEGATIVE_LIMIT_SWITCH
    };
    let mut v = vec![Search {
        reverse_at: limit,
        ..s(d, true, Active(HOME_SWITCH))
    }];
    if a == w {
        // Leave the cam through the edge (slowly: it is the home position of 23–30).
        v.push(s(w, false, Inactive(HOME_SWITCH)));
    } else {
        // Stand beyond the edge, then move onto the cam through it.
        let skip = index.then_some(a);
        v.push(Search {
            skip_after: skip,
            ..s(w, true, Inactive(HOME_SWITCH))
        });
        v.push(Search {
            skip_after: skip,
            ..s(a, false, Active(HOME_SWITCH))
        });
    }
    if index {
        v.push(s(a, false, Index));
    }
    v
}

/// The steps of homing `method`; `None` for a method not supported. The event ending the
/// last step is the home position; no steps: the current position is.
pub fn plan(method: i8) -> Option<Vec<Search>> {
    use Until::*;
    let limit = |d: i8, bit: u32, index: bool| {
        let mut v = vec![s(d, true, Active(bit)), s(-d, false, Inactive(bit))];
        if index {
            v.push(s(-d, false, Index));
        }
        v
    };
    // Methods 3 and 5: toward the switch (fast) until it is active, back (slow) until it
    // is inactive; home beyond that transition.
    let away = |d: i8, index: bool| {
        let mut v = vec![
            s(d, true, Active(HOME_SWITCH)),
            s(-d, false, Inactive(HOME_SWITCH)),
        ];
        if index {
            v.push(s(-d, false, Index));
        }
        v
    };
    // Methods 4 and 6: off the switch (fast) if on it, then onto it (slow); home beyond.
    let onto = |d: i8, index: bool| {
        let mut v = vec![
            s(-d, true, Inactive(HOME_SWITCH)),
            s(d, false, Active(HOME_SWITCH)),
        ];
        if index {
            v.push(s(d, false, Index));
        }
        v
    };
    Some(match method {
        1 => limit(-1, NEGATIVE_LIMIT_SWITCH, true),
        2 => limit(1, POSITIVE_LIMIT_SWITCH, true),
        3 => away(1, true),
        4 => onto(1, true),
        5 => away(-1, true),
        6 => onto(-1, true),
        17 => limit(-1, NEGATIVE_LIMIT_SWITCH, false),
        18 => limit(1, POSITIVE_LIMIT_SWITCH, false),
        19 => away(1, false),
        20 => onto(1, false),
        21 => away(-1, false),
        22 => onto(-1, false),
        7..=14 | 23..=30 => {
            let index = method <= 14;
            let k = (method - if index { 7 } else { 23 }) as usize;
            // (first direction, side of the edge, direction it is crossed), in the order
            // of the methods.
            const CAM: [(i8, i8, i8); 8] = [
                (1, -1, -1),
                (1, -1, 1),
                (1, 1, -1),
                (1, 1, 1),
                (-1, 1, 1),
                (-1, 1, -1),
                (-1, -1, 1),
                (-1, -1, -1),
            ];
            let (d, w, a) = CAM[k];
            cam(d, w, a, index)
        }
        33 => vec![s(-1, false, Index)],
        34 => vec![s(1, false, Index)],
        35 | 37 => Vec::new(),
        _ => return None,
    })
}

/// Whether 0x6098 takes `method`.
pub fn supported(method: i8) -> bool {
    plan(method).is_some()
}

/// The 0x60FD inputs a method needs wired.
pub fn needs(method: i8) -> u32 {
    plan(method).map_or(0, |p| {
        p.iter()
            .map(|s| match s.until {
                Until::Active(b) | Until::Inactive(b) => b | s.reverse_at,
                Until::Index => s.reverse_at,
            })
            .fold(0, |a, b| a | b)
    })
}

/// Where a homing procedure is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Not started since the mode was entered, or interrupted (bit 4 fell, halt).
    Idle,
    /// Searching: at step `step` of the plan.
    Searching {
        /// The step.
        step: usize,
    },
    /// The home position was found; the axis is stopping.
    Attained,
    /// Homing completed.
    Done,
    /// A homing error.
    Error,
}

/// What one cycle of a search saw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// 0x60FD before the cycle.
    pub inputs_before: u32,
    /// 0x60FD after it.
    pub inputs: u32,
    /// The actual position after it, position units.
    pub position: f64,
    /// The position of an index pulse passed in the cycle, position units.
    pub index: Option<f64>,
}

/// What the drive must do after a cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Outcome {
    /// Keep moving in `direction` (±1) at the fast or slow speed.
    Move {
        /// The direction.
        direction: f64,
        /// Search for switch speed.
        fast: bool,
    },
    /// The home position is `home` (position units, in the present coordinates): shift
    /// the positions so that it reads the home offset, and stop.
    Home(f64),
    /// Stop (error, interrupted, completed).
    Stop,
}

/// The state of homing mode.
#[derive(Debug, Clone, PartialEq)]
pub struct Homing {
    plan: Vec<Search>,
    /// The phase.
    pub phase: Phase,
    bit4: bool,
    /// The present step has reversed at its limit switch.
    reversed: bool,
    /// The direction the last step ended moving in, when a transition ended it.
    arrived: Option<i8>,
}

impl Default for Homing {
    fn default() -> Self {
        Homing {
            plan: Vec::new(),
            phase: Phase::Idle,
            bit4: false,
            reversed: false,
            arrived: None,
        }
    }
}

/// Controlword bit 4: homing operation start.
pub const HOMING_OPERATION_START: u16 = 1 << 4;

impl Homing {
    /// Enters the mode with controlword bit 4 at `bit4` (a level already set does not
    /// start homing). A completed homing stays reported as attained.
    pub fn enter(&mut self, bit4: bool) {
        self.bit4 = bit4;
        if !matches!(self.phase, Phase::Done) {
            self.phase = Phase::Idle;
        }
    }

    /// Evaluates controlword `cw` with homing `method`, the `wired` 0x60FD inputs, and
    /// whether the drive follows its mode (`run`: OPERATION ENABLED, no halt). Returns
    /// `true` when a method that homes on the current position (35, 37) has just
    /// completed: the current position is the home position.
    pub fn controlword(&mut self, cw: u16, method: i8, wired: u32, run: bool) -> bool {
        let bit4 = cw & HOMING_OPERATION_START != 0;
        let edge = bit4 && !self.bit4;
        let fell = !bit4 && self.bit4;
        self.bit4 = bit4;
        if fell && matches!(self.phase, Phase::Searching { .. } | Phase::Attained) {
            self.phase = Phase::Idle;
        }
        if !(edge && run) {
            return false;
        }
        match plan(method) {
            None => self.phase = Phase::Error,
            Some(_) if needs(method) & !wired != 0 => self.phase = Phase::Error,
            Some(p) if p.is_empty() => {
                self.phase = Phase::Done;
                return true;
            }
            Some(p) => {
                self.plan = p;
                self.reversed = false;
                self.arrived = None;
                self.phase = Phase::Searching { step: 0 };
            }
        }
        false
    }

    /// The drive stopped homing from outside (halt, a stop ramp, the drive disabled).
    pub fn interrupt(&mut self) {
        if matches!(self.phase, Phase::Searching { .. } | Phase::Attained) {
            self.phase = Phase::Idle;
        }
    }

    /// One cycle of a search: what the axis saw, and what to do next.
    pub fn step(&mut self, sample: &Sample) -> Outcome {
        let Phase::Searching { mut step } = self.phase else {
            return Outcome::Stop;
        };
        // Steps whose event holds at their start are done at once (a method started on
        // its switch skips the move onto it).
        loop {
            let Some(search) = self.plan.get(step).copied() else {
                self.phase = Phase::Error;
                return Outcome::Stop;
            };
            let now = sample.inputs;
            let last = step + 1 == self.plan.len();
            let direction = if self.reversed {
                -search.direction
            } else {
                search.direction
            };
            let holds = |inputs: u32| match search.until {
                Until::Active(b) => inputs & b != 0,
                Until::Inactive(b) => inputs & b == 0,
                Until::Index => false,
            };
            let skip = search.skip_after.is_some() && search.skip_after == self.arrived;
            let hit = holds(now);
            let index = match search.until {
                Until::Index => sample.index,
                _ => None,
            };
            if skip || hit || index.is_some() {
                if last {
                    self.phase = Phase::Attained;
                    return Outcome::Home(index.unwrap_or(sample.position));
                }
                if !skip {
                    // A transition seen in this cycle, not an event that held before.
                    self.arrived =
                        (index.is_some() || !holds(sample.inputs_before)).then_some(direction);
                }
                self.reversed = false;
                step += 1;
                self.phase = Phase::Searching { step };
                continue;
            }
            // A limit switch in the direction of the search that it does not look for:
            // the step reverses at it once if it may, else a homing error.
            let ahead = if direction > 0 {
                POSITIVE_LIMIT_SWITCH
            } else {
                NEGATIVE_LIMIT_SWITCH
            };
            let looked_for = self
                .plan
                .iter()
                .any(|s| matches!(s.until, Until::Active(b) | Until::Inactive(b) if b == ahead));
            if now & ahead != 0 && !looked_for {
                if search.reverse_at & ahead != 0 && !self.reversed {
                    self.reversed = true;
                    return Outcome::Move {
                        direction: f64::from(-direction),
                        fast: search.fast,
                    };
                }
                self.phase = Phase::Error;
                return Outcome::Stop;
            }
            return Outcome::Move {
                direction: f64::from(direction),
                fast: search.fast,
            };
        }
    }

    /// The axis has stopped after the home position was found.
    pub fn stopped(&mut self) {
        if self.phase == Phase::Attained {
            self.phase = Phase::Done;
        }
    }

    /// Statusword bits 10, 12 and 13 given whether the axis is at rest.
    pub fn status(&self, at_rest: bool) -> (bool, bool, bool) {
        match self.phase {
            Phase::Idle => (at_rest, false, false),
            Phase::Searching { .. } => (false, false, false),
            Phase::Attained => (false, true, false),
            Phase::Done => (at_rest, true, false),
            Phase::Error => (at_rest, false, true),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia402_6098h_supported_methods() {
        for m in (1..=14).chain(17..=30).chain([33, 34, 35, 37]) {
            assert!(supported(m), "{m}");
        }
        for m in [15, 16, 31, 32, 0, 36, -1, 38] {
            assert!(!supported(m), "{m}");
        }
        assert_eq!(needs(1), NEGATIVE_LIMIT_SWITCH);
        assert_eq!(needs(20), HOME_SWITCH);
        assert_eq!(needs(7), HOME_SWITCH | POSITIVE_LIMIT_SWITCH);
        assert_eq!(needs(30), HOME_SWITCH | NEGATIVE_LIMIT_SWITCH);
        assert_eq!(needs(34), 0);
    }
}
