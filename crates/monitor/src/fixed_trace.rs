//! The fixed (overwrite) trace: one row per identifier, overwritten by each new frame of
//! that identifier, as the default views of CANalyzer's trace window and PCAN-View's receive
//! list show a bus. Each row keeps how often the identifier was seen, its cycle time (the
//! last, shortest and longest gap between two of its frames), which data bytes changed with
//! the last frame (the *delta*) and the last frame with its decoding.
//!
//! The model is pure: [`FixedTrace::record`] takes each decoded frame (a [`FrameEntry`], as
//! [`crate::NetworkView`] makes them) and front ends read [`FixedTrace::rows`]. It is
//! bounded: past [`FixedTrace::capacity`] identifiers, frames of new identifiers are only
//! counted ([`FixedTrace::overflow`]), so that a flood of distinct extended identifiers
//! cannot grow it without limit.
//!
//! ```
//! use cantwin_can::{Frame, Id, Instant};
//! use cantwin_monitor::{Config, NetworkView};
//!
//! let mut view = NetworkView::new(Config::default());
//! let f = |id: u16, data: &[u8]| Frame::data(Id::standard(id).unwrap(), data).unwrap();
//! let ms = |v: u64| Instant::from_nanos(v * 1_000_000);
//! view.push(ms(0), &f(0x70C, &[0x05]));
//! view.push(ms(100), &f(0x70C, &[0x05]));
//! view.push(ms(150), &f(0x18C, &[0x01, 0x02]));
//! view.push(ms(300), &f(0x70C, &[0x7F]));
//!
//! let rows: Vec<_> = view.fixed_trace().rows().collect();
//! assert_eq!(rows.len(), 2);
//! let hb = rows.iter().find(|r| r.key.id == 0x70C).unwrap();
//! assert_eq!(hb.count, 3);
//! assert_eq!(hb.cycle.last.unwrap().as_millis(), 200);
//! assert_eq!(hb.cycle.min.unwrap().as_millis(), 100);
//! assert_eq!(hb.cycle.max.unwrap().as_millis(), 200);
//! assert_eq!(hb.changed, 0b1); // byte 0 went from 0x05 to 0x7F
//! ```

use std::collections::BTreeMap;

use cantwin_can::{Duration, Frame, Instant};

use crate::FrameEntry;
use crate::filter::{Filter, Service};

/// What a row stands for: an identifier, of its format, data or remote. A remote request
/// and the data frame answering it (node guarding, CiA 301 §7.2.8.3.2.1) have the same
/// identifier and get rows of their own, as CANalyzer shows them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct RowKey {
    /// The raw identifier (11 or 29 bits).
    pub id: u32,
    /// Whether the identifier is an extended (29-bit) one.
    pub extended: bool,
    /// Whether the frames are remote requests.
    pub remote: bool,
}

impl RowKey {
    /// The key of `frame`.
    pub fn of(frame: &Frame) -> RowKey {
        RowKey {
            id: frame.id().as_raw(),
            extended: frame.is_extended(),
            remote: frame.is_remote(),
        }
    }
}

/// The gaps between consecutive frames of one row.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CycleTime {
    /// The gap before the last frame (CANalyzer's Δt).
    pub last: Option<Duration>,
    /// The shortest gap seen.
    pub min: Option<Duration>,
    /// The longest gap seen.
    pub max: Option<Duration>,
}

impl CycleTime {
    fn add(&mut self, gap: Duration) {
        self.last = Some(gap);
        self.min = Some(self.min.map_or(gap, |m| m.min(gap)));
        self.max = Some(self.max.map_or(gap, |m| m.max(gap)));
    }
}

/// One row of the fixed trace.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Row {
    /// What the row stands for.
    pub key: RowKey,
    /// Frames seen with this key.
    pub count: u64,
    /// Bus time of the first frame.
    pub first: Instant,
    /// Cycle time statistics.
    pub cycle: CycleTime,
    /// The data bytes that changed with the last frame, bit `i` for byte `i`; a byte the
    /// frame before did not have counts as changed. 0 for the first frame of the row and for
    /// remote frames.
    pub changed: u8,
    /// The last frame, decoded (its time, service, node and one-line text).
    pub last: FrameEntry,
}

impl Row {
    /// Bus time since the last frame, at `now`.
    pub fn age(&self, now: Instant) -> Duration {
        now.saturating_duration_since(self.last.at)
    }

    /// Whether the row passes `filter` (by its last frame).
    pub fn matches(&self, filter: &Filter) -> bool {
        self.last.matches(filter)
    }

    /// The row's service.
    pub fn service(&self) -> Service {
        self.last.service
    }
}

/// The bytes of `new` that differ from `old` (bit `i` for byte `i`).
fn changed_bytes(old: &[u8], new: &[u8]) -> u8 {
    new.iter().enumerate().fold(0u8, |mask, (i, b)| {
        if old.get(i) == Some(b) {
            mask
        } else {
            mask | (1 << i)
        }
    })
}

/// Rows by identifier, bounded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FixedTrace {
    rows: BTreeMap<RowKey, Row>,
    capacity: usize,
    overflow: u64,
}

impl FixedTrace {
    /// Identifiers kept by default: more than every standard identifier a CANopen network
    /// uses, far fewer than a flood of distinct extended identifiers could make.
    pub const DEFAULT_CAPACITY: usize = 4096;

    /// An empty trace keeping at most `capacity` rows (at least one).
    pub fn new(capacity: usize) -> FixedTrace {
        FixedTrace {
            rows: BTreeMap::new(),
            capacity: capacity.max(1),
            overflow: 0,
        }
    }

    /// The most rows it keeps.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Frames of identifiers that found no row because the trace was full.
    pub fn overflow(&self) -> u64 {
        self.overflow
    }

    /// Take a decoded frame: it overwrites its identifier's row, or opens one.
    pub fn record(&mut self, entry: &FrameEntry) {
        let key = RowKey::of(&entry.frame);
        if let Some(row) = self.rows.get_mut(&key) {
            let gap = entry.at.saturating_duration_since(row.last.at);
            row.cycle.add(gap);
            row.count += 1;
            row.changed = if entry.frame.is_remote() {
                0
            } else {
                changed_bytes(row.last.frame.data_bytes(), entry.frame.data_bytes())
            };
            row.last = entry.clone();
            return;
        }
        if self.rows.len() >= self.capacity {
            self.overflow += 1;
            return;
        }
        self.rows.insert(
            key,
            Row {
                key,
                count: 1,
                first: entry.at,
                cycle: CycleTime::default(),
                changed: 0,
                last: entry.clone(),
            },
        );
    }

    /// The rows in identifier order (standard before extended, data before remote for the
    /// same identifier).
    pub fn rows(&self) -> impl DoubleEndedIterator<Item = &Row> + ExactSizeIterator {
        self.rows.values()
    }

    /// The rows passing `filter`, in identifier order.
    pub fn filtered<'a>(&'a self, filter: &'a Filter) -> impl DoubleEndedIterator<Item = &'a Row> {
        self.rows.values().filter(move |r| r.matches(filter))
    }

    /// The row of `key`, if any.
    pub fn row(&self, key: &RowKey) -> Option<&Row> {
        self.rows.get(key)
    }

    /// Forget every row (a user's "clear").
    pub fn clear(&mut self) {
        self.rows.clear();
        self.overflow = 0;
    }
}

impl Default for FixedTrace {
    fn default() -> Self {
        FixedTrace::new(FixedTrace::DEFAULT_CAPACITY)
    }
}

#[cfg(test)]
mod tests {
    use cantwin_can::Id;

    use super::*;

    fn entry(seq: u64, ms: u64, frame: Frame) -> FrameEntry {
        FrameEntry {
            seq,
            at: Instant::from_nanos(ms * 1_000_000),
            frame,
            service: Service::Other,
            node: None,
            text: format!("frame {seq}"),
        }
    }

    fn data(id: u16, bytes: &[u8]) -> Frame {
        Frame::data(Id::standard(id).unwrap(), bytes).unwrap()
    }

    #[test]
    fn a_row_per_identifier_overwritten_by_the_last_frame() {
        let mut t = FixedTrace::default();
        t.record(&entry(0, 0, data(0x181, &[1, 2, 3])));
        t.record(&entry(1, 5, data(0x080, &[])));
        t.record(&entry(2, 10, data(0x181, &[1, 9, 3, 4])));
        t.record(&entry(3, 40, data(0x181, &[1, 9, 3, 4])));
        let rows: Vec<&Row> = t.rows().collect();
        assert_eq!(
            rows.iter().map(|r| r.key.id).collect::<Vec<_>>(),
            [0x080, 0x181]
        );
        let pdo = rows[1];
        assert_eq!(pdo.count, 3);
        assert_eq!(pdo.first, Instant::from_nanos(0));
        assert_eq!(pdo.last.text, "frame 3");
        assert_eq!(pdo.cycle.last, Some(Duration::from_millis(30)));
        assert_eq!(pdo.cycle.min, Some(Duration::from_millis(10)));
        assert_eq!(pdo.cycle.max, Some(Duration::from_millis(30)));
        // Unchanged data: no delta.
        assert_eq!(pdo.changed, 0);
        assert_eq!(
            pdo.age(Instant::from_nanos(50_000_000)),
            Duration::from_millis(10)
        );
        let sync = rows[0];
        assert_eq!(sync.count, 1);
        assert_eq!(sync.cycle, CycleTime::default());
    }

    #[test]
    fn the_delta_marks_changed_and_new_bytes() {
        let mut t = FixedTrace::default();
        t.record(&entry(0, 0, data(0x201, &[1, 2, 3])));
        t.record(&entry(1, 1, data(0x201, &[1, 7, 3, 0])));
        let key = RowKey::of(&data(0x201, &[]));
        // Byte 1 changed, byte 3 is new.
        assert_eq!(t.row(&key).unwrap().changed, 0b1010);
    }

    #[test]
    fn remote_requests_have_rows_of_their_own() {
        let mut t = FixedTrace::default();
        let rtr = Frame::remote(Id::standard(0x70C).unwrap(), 1).unwrap();
        t.record(&entry(0, 0, rtr));
        t.record(&entry(1, 1, data(0x70C, &[0x85])));
        t.record(&entry(2, 100, rtr));
        let rows: Vec<&Row> = t.rows().collect();
        assert_eq!(rows.len(), 2);
        assert!(!rows[0].key.remote && rows[0].count == 1);
        assert!(rows[1].key.remote && rows[1].count == 2);
        assert_eq!(rows[1].changed, 0);
    }

    #[test]
    fn a_full_trace_counts_new_identifiers_instead_of_growing() {
        let mut t = FixedTrace::new(2);
        for (i, id) in [0x100, 0x200, 0x300, 0x400, 0x100].into_iter().enumerate() {
            t.record(&entry(i as u64, i as u64, data(id, &[0])));
        }
        assert_eq!(t.rows().len(), 2);
        assert_eq!(t.overflow(), 2);
        assert_eq!(t.row(&RowKey::of(&data(0x100, &[]))).unwrap().count, 2);
        t.clear();
        assert_eq!((t.rows().len(), t.overflow()), (0, 0));
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(128))]

        /// Any frames: rows stay within the capacity, every frame is counted in a row or in
        /// the overflow, a row's cycle times order as min ≤ last ≤ max and its last frame is
        /// the newest of its key.
        #[test]
        fn rows_count_every_frame_and_stay_bounded(
            frames in proptest::collection::vec(
                (0u16..0x20, proptest::collection::vec(proptest::prelude::any::<u8>(), 0..=8),
                 0u64..50, proptest::prelude::any::<bool>()),
                0..300,
            ),
            capacity in 1usize..12,
        ) {
            let mut t = FixedTrace::new(capacity);
            let mut at = 0;
            for (i, (id, data, gap, remote)) in frames.iter().enumerate() {
                at += gap;
                let id = Id::standard(*id).unwrap();
                let frame = if *remote {
                    Frame::remote(id, data.len() as u8).unwrap()
                } else {
                    Frame::data(id, data).unwrap()
                };
                t.record(&entry(i as u64, at, frame));
            }
            proptest::prop_assert!(t.rows().len() <= capacity);
            let counted: u64 = t.rows().map(|r| r.count).sum();
            proptest::prop_assert_eq!(counted + t.overflow(), frames.len() as u64);
            for r in t.rows() {
                match (r.cycle.min, r.cycle.last, r.cycle.max) {
                    (Some(min), Some(last), Some(max)) => {
                        proptest::prop_assert!(min <= last && last <= max);
                        proptest::prop_assert!(r.count > 1);
                    }
                    (None, None, None) => proptest::prop_assert_eq!(r.count, 1),
                    other => proptest::prop_assert!(false, "{:?}", other),
                }
                proptest::prop_assert_eq!(RowKey::of(&r.last.frame), r.key);
                proptest::prop_assert!(r.first <= r.last.at);
            }
        }
    }

    #[test]
    fn the_filter_applies_to_rows() {
        let mut t = FixedTrace::default();
        let mut e = entry(0, 0, data(0x70C, &[5]));
        e.service = Service::Heartbeat;
        e.node = Some(12);
        t.record(&e);
        t.record(&entry(1, 0, data(0x181, &[0])));
        let f = Filter::parse("svc=hb").unwrap();
        let shown: Vec<u32> = t.filtered(&f).map(|r| r.key.id).collect();
        assert_eq!(shown, [0x70C]);
    }
}
