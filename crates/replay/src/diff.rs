//! Pairing the captured twin frames with the replayed ones.

use std::collections::BTreeMap;

use cantwin_can::Frame;

use crate::frames::{Captured, id_key};

/// How a captured frame and a replayed one compare.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// The same data within the tolerance.
    Matching,
    /// Captured, not replayed.
    Missing,
    /// Replayed, not captured.
    Unexpected,
    /// The same data at another time, or other data within the tolerance.
    Different,
}

impl Kind {
    /// The kind's name in reports: `matching`, `missing`, `unexpected`, `different`.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Matching => "matching",
            Kind::Missing => "missing",
            Kind::Unexpected => "unexpected",
            Kind::Different => "different",
        }
    }
}

/// One line of the diff: the captured frame, the replayed one, or both, each with its time
/// in nanoseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Entry {
    /// How they compare.
    pub kind: Kind,
    /// The bus, as its position in the scenario.
    pub bus: usize,
    /// The captured frame.
    pub captured: Option<(i64, Frame)>,
    /// The replayed frame.
    pub replayed: Option<(i64, Frame)>,
}

impl Entry {
    /// The captured frame's time, else the replayed one's.
    pub fn time(&self) -> i64 {
        self.captured.or(self.replayed).map(|(t, _)| t).unwrap_or(0)
    }
}

/// Pairs the captured twin frames with the replayed ones, per bus and identifier in time
/// order: first the same data within the tolerance (in nanoseconds), then the same data at
/// any time (a timing difference), then other data within the tolerance (a data
/// difference). What is left is missing (captured only) or unexpected (replayed only).
pub fn diff(captured: &[Captured], replayed: &[Captured], tolerance: i64) -> Vec<Entry> {
    type Group = (Vec<(i64, Frame)>, Vec<(i64, Frame)>);
    let mut groups: BTreeMap<(usize, u32), Group> = BTreeMap::new();
    for c in captured {
        groups
            .entry((c.bus, id_key(c.frame.id())))
            .or_default()
            .0
            .push((c.t, c.frame));
    }
    for r in replayed {
        groups
            .entry((r.bus, id_key(r.frame.id())))
            .or_default()
            .1
            .push((r.t, r.frame));
    }
    let mut entries = Vec::new();
    for ((bus, _), (mut cap, mut rep)) in groups {
        cap.sort_by_key(|(t, _)| *t);
        rep.sort_by_key(|(t, _)| *t);
        let mut used = vec![false; rep.len()];
        let mut done = vec![false; cap.len()];
        let passes: [(Kind, bool, bool); 3] = [
            (Kind::Matching, true, true),
            (Kind::Different, true, false),
            (Kind::Different, false, true),
        ];
        for (kind, same_data, within) in passes {
            for (ci, (ct, cf)) in cap.iter().enumerate() {
                if done[ci] {
                    continue;
                }
                // Both lists are in time order: within the tolerance only a window of the
                // replayed frames can pair.
                let range = if within {
                    rep.partition_point(|(rt, _)| *rt < ct.saturating_sub(tolerance))
                        ..rep.partition_point(|(rt, _)| *rt <= ct.saturating_add(tolerance))
                } else {
                    0..rep.len()
                };
                let best = range
                    .filter(|ri| !used[*ri] && ((rep[*ri].1 == *cf) == same_data))
                    .min_by_key(|ri| rep[*ri].0.abs_diff(*ct));
                if let Some(ri) = best {
                    used[ri] = true;
                    done[ci] = true;
                    entries.push(Entry {
                        kind,
                        bus,
                        captured: Some((*ct, *cf)),
                        replayed: Some(rep[ri]),
                    });
                }
            }
        }
        for (ci, c) in cap.iter().enumerate() {
            if !done[ci] {
                entries.push(Entry {
                    kind: Kind::Missing,
                    bus,
                    captured: Some(*c),
                    replayed: None,
                });
            }
        }
        for (ri, r) in rep.iter().enumerate() {
            if !used[ri] {
                entries.push(Entry {
                    kind: Kind::Unexpected,
                    bus,
                    captured: None,
                    replayed: Some(*r),
                });
            }
        }
    }
    entries.sort_by_key(|e| (e.time(), e.bus));
    entries
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c(t_ms: i64, text: &str) -> Captured {
        Captured {
            bus: 0,
            t: t_ms * 1_000_000,
            frame: cantwin_scenario::script::parse_frame(text).expect("frame"),
        }
    }

    #[test]
    fn diff_pairs_by_identifier_data_and_time() {
        let captured = [
            c(10, "585#4B17100064000000"),
            c(20, "701#05"),
            c(30, "181#01"),
            c(40, "181#02"),
        ];
        let replayed = [
            c(10, "585#4B17100065000000"),
            c(25, "701#05"),
            c(40, "181#02"),
            c(50, "182#00"),
        ];
        let e = diff(&captured, &replayed, 1_000_000);
        let kinds: Vec<(&str, i64)> = e.iter().map(|e| (e.kind.name(), e.time())).collect();
        assert_eq!(
            kinds,
            [
                ("different", 10_000_000),
                ("different", 20_000_000),
                ("missing", 30_000_000),
                ("matching", 40_000_000),
                ("unexpected", 50_000_000),
            ]
        );
    }

    #[test]
    fn extreme_times_and_tolerances_saturate() {
        let at = |t| Captured {
            t,
            ..c(0, "181#01")
        };
        let e = diff(&[at(i64::MAX)], &[at(i64::MAX - 10)], i64::MAX);
        assert_eq!(e.len(), 1);
        assert_eq!(e[0].kind, Kind::Matching);
        // Further apart than any tolerance: the same data at another time.
        let e = diff(&[at(i64::MAX)], &[at(-5)], i64::MAX);
        assert_eq!(e.len(), 1);
        assert_eq!(e[0].kind, Kind::Different);
    }
}
