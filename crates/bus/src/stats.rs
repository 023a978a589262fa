//! Bus statistics: load, per-identifier counts, error frames.

use std::collections::{HashMap, VecDeque};
use std::hash::{BuildHasherDefault, Hasher};

use cantwin_can::{Duration, Id, Instant, StandardId};

/// A fast hasher for identifiers (multiply-rotate, as in rustc's FxHash): the per-frame
/// maps are keyed by [`Id`], which needs no protection against crafted collisions.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct IdHasher(u64);

impl IdHasher {
    #[inline]
    fn mix(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x51_7C_C1_B7_27_22_0A_95);
    }
}

impl Hasher for IdHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.mix(u64::from(b));
        }
    }
    fn write_u8(&mut self, v: u8) {
        self.mix(u64::from(v));
    }
    fn write_u16(&mut self, v: u16) {
        self.mix(u64::from(v));
    }
    fn write_u32(&mut self, v: u32) {
        self.mix(u64::from(v));
    }
    fn write_u64(&mut self, v: u64) {
        self.mix(v);
    }
    fn write_usize(&mut self, v: usize) {
        self.mix(v as u64);
    }
    fn write_isize(&mut self, v: isize) {
        self.mix(v as u64);
    }
    fn finish(&self) -> u64 {
        self.0
    }
}

pub(crate) type BuildIdHasher = BuildHasherDefault<IdHasher>;

/// A dense numbering of the identifiers seen on a bus, so that per-identifier tables are
/// plain vectors: standard identifiers (all a CANopen or DeviceNet bus uses) through a table
/// indexed by the 11-bit identifier, with no hashing; extended ones through a map.
#[derive(Debug, Clone, Default)]
pub(crate) struct IdIndex {
    /// Per standard identifier: its number + 1, or 0 while unseen. Allocated at the first.
    standard: Vec<u32>,
    extended: HashMap<u32, u32, BuildIdHasher>,
    /// The identifiers in the order numbered.
    ids: Vec<Id>,
}

impl IdIndex {
    /// The number of `id`, if it has one.
    #[inline]
    pub fn get(&self, id: Id) -> Option<usize> {
        match id {
            Id::Standard(s) => match self.standard.get(usize::from(s.as_raw())) {
                Some(&n) if n > 0 => Some(n as usize - 1),
                _ => None,
            },
            Id::Extended(e) => self.extended.get(&e.as_raw()).map(|&n| n as usize),
        }
    }

    /// The number of `id`, numbering it now if it had none.
    #[inline]
    pub fn number(&mut self, id: Id) -> usize {
        match self.get(id) {
            Some(n) => n,
            None => self.add(id),
        }
    }

    /// Number `id`, which has no number yet.
    #[cold]
    fn add(&mut self, id: Id) -> usize {
        let n = self.ids.len();
        self.ids.push(id);
        match id {
            Id::Standard(s) => {
                if self.standard.is_empty() {
                    self.standard = vec![0; usize::from(StandardId::MAX.as_raw()) + 1];
                }
                self.standard[usize::from(s.as_raw())] = n as u32 + 1;
            }
            Id::Extended(e) => {
                self.extended.insert(e.as_raw(), n as u32);
            }
        }
        n
    }

    /// The identifiers numbered so far, in number order.
    pub fn ids(&self) -> &[Id] {
        &self.ids
    }
}

/// Frames and bits seen for one identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct IdStats {
    /// Frames that completed (dropped ones included: they took bus time).
    pub frames: u64,
    /// Bits those frames occupied, intermission included.
    pub bits: u64,
    /// Transmissions of this identifier that ended in an error frame.
    pub errors: u64,
}

/// What a bus has counted since it was created (or [`BusStats::reset`]).
#[derive(Debug, Clone)]
pub struct BusStats {
    since: Instant,
    frames: u64,
    dropped_frames: u64,
    error_frames: u64,
    busy: Duration,
    bits: u64,
    /// Numbers the identifiers of `per_id`.
    index: IdIndex,
    /// Per identifier number.
    per_id: Vec<IdStats>,
    window: Duration,
    /// Busy intervals before the latest, oldest first, as far back as the window reaches.
    recent: VecDeque<(Instant, Instant)>,
    /// The latest busy interval, which back-to-back frames extend: kept apart so that a
    /// loaded bus extends it without touching the allocation behind `recent`.
    open: Option<(Instant, Instant)>,
}

impl BusStats {
    pub(crate) fn new(since: Instant, window: Duration) -> Self {
        BusStats {
            since,
            frames: 0,
            dropped_frames: 0,
            error_frames: 0,
            busy: Duration::ZERO,
            bits: 0,
            index: IdIndex::default(),
            per_id: Vec::new(),
            window,
            recent: VecDeque::new(),
            open: None,
        }
    }

    /// Forget everything counted so far; counting restarts at `now`.
    pub fn reset(&mut self, now: Instant) {
        *self = BusStats::new(now, self.window);
    }

    #[inline]
    fn busy_interval(&mut self, start: Instant, end: Instant) {
        self.busy += end - start;
        // Back-to-back transmissions (a loaded bus) extend one interval: the window's sums
        // are the same, and the window holds a few intervals rather than one per frame.
        match &mut self.open {
            Some(last) if last.1 == start => last.1 = end,
            open => {
                if let Some(before) = open.replace((start, end)) {
                    self.recent.push_back(before);
                }
            }
        }
        let horizon = end - self.window;
        while let Some(&(_, e)) = self.recent.front() {
            if e <= horizon {
                self.recent.pop_front();
            } else {
                break;
            }
        }
        // The latest interval ends at `end`: only a window of zero leaves it behind.
        if self.recent.is_empty() && self.open.is_some_and(|(_, e)| e <= horizon) {
            self.open = None;
        }
    }

    #[inline]
    pub(crate) fn frame(
        &mut self,
        id: Id,
        bits: u32,
        start: Instant,
        idle_at: Instant,
        dropped: bool,
    ) {
        self.frames += 1;
        self.dropped_frames += u64::from(dropped);
        self.bits += u64::from(bits);
        let s = self.entry(id);
        s.frames += 1;
        s.bits += u64::from(bits);
        self.busy_interval(start, idle_at);
    }

    pub(crate) fn error(&mut self, id: Id, bits: u32, start: Instant, idle_at: Instant) {
        self.error_frames += 1;
        self.bits += u64::from(bits);
        self.entry(id).errors += 1;
        self.busy_interval(start, idle_at);
    }

    #[inline]
    fn entry(&mut self, id: Id) -> &mut IdStats {
        let n = self.index.number(id);
        if n == self.per_id.len() {
            self.per_id.push(IdStats::default());
        }
        &mut self.per_id[n]
    }

    /// When counting started.
    pub fn since(&self) -> Instant {
        self.since
    }

    /// Frames that completed successfully (dropped ones included).
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Completed frames that fault injection dropped.
    pub fn dropped_frames(&self) -> u64 {
        self.dropped_frames
    }

    /// Transmissions that ended in an error frame.
    pub fn error_frames(&self) -> u64 {
        self.error_frames
    }

    /// Bits the bus was busy: frames and error frames, intermission included.
    pub fn bits(&self) -> u64 {
        self.bits
    }

    /// Time the bus was busy.
    pub fn busy_time(&self) -> Duration {
        self.busy
    }

    /// Bus load in percent from [`BusStats::since`] to `now`: busy time over elapsed time.
    /// Transmissions still in progress at `now` are not counted.
    pub fn load_percent(&self, now: Instant) -> f64 {
        let elapsed = now - self.since;
        if elapsed.is_zero() {
            return 0.0;
        }
        100.0 * self.busy.as_nanos() as f64 / elapsed.as_nanos() as f64
    }

    /// The sliding window [`BusStats::window_load_percent`] uses.
    pub fn window(&self) -> Duration {
        self.window
    }

    /// Bus load in percent over the last [`BusStats::window`] before `now` (or since counting
    /// started, if that is shorter). Busy time that lies partly in the window counts with its
    /// part in it.
    pub fn window_load_percent(&self, now: Instant) -> f64 {
        let from = (now - self.window).max(self.since);
        let span = now - from;
        if span.is_zero() {
            return 0.0;
        }
        let busy: u64 = self
            .recent
            .iter()
            .chain(self.open.iter())
            .map(|&(s, e)| (e.min(now) - s.max(from)).as_nanos())
            .sum();
        100.0 * busy as f64 / span.as_nanos() as f64
    }

    /// The counts for one identifier.
    pub fn id(&self, id: Id) -> IdStats {
        self.index
            .get(id)
            .and_then(|n| self.per_id.get(n))
            .copied()
            .unwrap_or_default()
    }

    /// Per-identifier counts, in arbitration order (highest priority first).
    pub fn per_id(&self) -> Vec<(Id, IdStats)> {
        let mut v: Vec<(Id, IdStats)> = self
            .index
            .ids()
            .iter()
            .copied()
            .zip(self.per_id.iter().copied())
            .collect();
        v.sort_by_key(|(id, _)| id.arbitration_key(false));
        v
    }
}

/// What a port has counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PortStats {
    /// Frames the port sent successfully (its own, babble not included).
    pub tx_frames: u64,
    /// Frames passed up to the node (`on_frame`), echo included.
    pub rx_frames: u64,
    /// Transmissions of this port that ended in an error frame.
    pub tx_errors: u64,
    /// Frames dropped before transmission: queue full, or cleared by bus-off.
    pub tx_dropped: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn load_over_run_and_window() {
        let mut s = BusStats::new(Instant::ZERO, Duration::from_millis(1));
        let id = Id::standard(1).unwrap();
        let t = |us: u64| Instant::from_nanos(us * 1000);
        s.frame(id, 100, t(0), t(100), false);
        s.frame(id, 100, t(1500), t(1600), true);
        assert_eq!(s.load_percent(t(2000)), 10.0);
        // Window (1000, 2000]: only the second frame.
        assert_eq!(s.window_load_percent(t(2000)), 10.0);
        // Window (600, 1600]: the second frame fully.
        assert_eq!(s.window_load_percent(t(1600)), 10.0);
        // Window (550, 1550]: half of the second.
        assert_eq!(s.window_load_percent(t(1550)), 5.0);
        assert_eq!(
            s.id(id),
            IdStats {
                frames: 2,
                bits: 200,
                errors: 0
            }
        );
        assert_eq!((s.frames(), s.dropped_frames()), (2, 1));
    }

    #[test]
    fn back_to_back_frames_share_one_interval_with_the_same_window_load() {
        let mut s = BusStats::new(Instant::ZERO, Duration::from_millis(1));
        let id = Id::standard(1).unwrap();
        let t = |us: u64| Instant::from_nanos(us * 1000);
        for k in 0..10 {
            s.frame(id, 100, t(100 * k), t(100 * (k + 1)), false);
        }
        s.frame(id, 100, t(1500), t(1600), false);
        assert_eq!(s.recent.len() + usize::from(s.open.is_some()), 2);
        // Window (600, 1600]: 400 µs of the run of ten frames and the last frame.
        assert_eq!(s.window_load_percent(t(1600)), 50.0);
        // Window (50, 1050]: 950 µs of the run.
        assert_eq!(s.window_load_percent(t(1050)), 95.0);
        assert_eq!(s.load_percent(t(2000)), 55.0);
    }
}
