//! Frames of a capture placed on a scenario's buses, and identifiers as single numbers.

use std::collections::BTreeSet;

use cantwin_can::{Frame, Id};
use cantwin_capture::Record;

use crate::error::ReplayError;

/// A frame on a scenario bus, at a time relative to the capture's first frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Captured {
    /// The bus, as its position in the scenario.
    pub bus: usize,
    /// Nanoseconds after the capture's first frame (its end of frame).
    pub t: i64,
    /// The frame.
    pub frame: Frame,
}

/// An identifier as one number: the raw value, with bit 31 set for extended identifiers.
pub fn id_key(id: Id) -> u32 {
    if id.is_extended() {
        id.as_raw() | 1 << 31
    } else {
        id.as_raw()
    }
}

/// An identifier key as text: 3 hex digits for a standard identifier, 8 for an extended one.
pub fn key_text(key: u32) -> String {
    if key & 1 << 31 != 0 {
        format!("{:08X}", key & 0x1FFF_FFFF)
    } else {
        format!("{key:03X}")
    }
}

/// Nanoseconds as seconds with six decimals (`-0.000250`).
pub fn seconds(ns: i64) -> String {
    let sign = if ns < 0 { "-" } else { "" };
    let a = ns.unsigned_abs();
    format!(
        "{sign}{}.{:06}",
        a / 1_000_000_000,
        (a % 1_000_000_000) / 1000
    )
}

/// How long a gap between two consecutive frames (in time order) of a capture may be.
///
/// A replay runs the twins through every gap in virtual time, and what they send meanwhile
/// (heartbeats, cyclic PDOs) is kept to be compared: its memory and time grow with the
/// capture's time span, not with its size. One corrupt timestamp byte makes a capture of a
/// second span a thousand hours; the bound keeps a replay's cost a matter of the capture's
/// size and the scenario.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GapBound {
    /// The longest gap, in nanoseconds.
    pub max_ns: i64,
    /// Shorten longer gaps to the bound (moving every later frame earlier) instead of
    /// refusing the capture.
    pub clamp: bool,
}

impl GapBound {
    /// The default bound: 60 s, refused beyond.
    pub const DEFAULT: GapBound = GapBound {
        max_ns: 60_000_000_000,
        clamp: false,
    };
}

impl Default for GapBound {
    fn default() -> Self {
        GapBound::DEFAULT
    }
}

/// A gap shortened to the bound ([`GapBound::clamp`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClampedGap {
    /// The record before the gap (counted from 1, in the file's order).
    pub before: u64,
    /// The record after the gap.
    pub after: u64,
    /// How long the gap was, in nanoseconds.
    pub gap_ns: i64,
}

/// A capture's frames on the scenario's buses (named `bus_names`, in scenario order), in
/// time order; a capture of one bus may name its channel otherwise.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CapturedFrames {
    /// The frames, times relative to the first.
    pub frames: Vec<Captured>,
    /// Error frames in the capture, which are not replayed.
    pub error_frames: u64,
    /// Gaps shortened to the bound, in time order.
    pub clamped: Vec<ClampedGap>,
}

impl CapturedFrames {
    /// Places `records` on the buses named `bus_names`, with the default [`GapBound`].
    pub fn from_records(
        records: &[Record],
        bus_names: &[&str],
    ) -> Result<CapturedFrames, ReplayError> {
        Self::read(
            records.iter().cloned().map(Ok),
            bus_names,
            GapBound::DEFAULT,
        )
    }

    /// Places the records a capture reader yields on the buses named `bus_names`, one at a
    /// time: only the frames are kept, never the records, and a capture whose gaps exceed
    /// `gaps` is refused (or its gaps shortened) before anything is replayed.
    pub fn read<I>(
        records: I,
        bus_names: &[&str],
        gaps: GapBound,
    ) -> Result<CapturedFrames, ReplayError>
    where
        I: IntoIterator<Item = Result<Record, cantwin_capture::Error>>,
    {
        let mut channels: BTreeSet<String> = BTreeSet::new();
        // Timestamp, record number (from 1), bus, frame.
        let mut frames: Vec<(u64, u64, usize, Frame)> = Vec::new();
        let mut error_frames = 0u64;
        for (n, r) in (1u64..).zip(records) {
            let r = r.map_err(|source| ReplayError::Read { record: n, source })?;
            let Some(frame) = r.frame() else {
                error_frames += 1;
                continue;
            };
            if !channels.contains(&r.channel) {
                channels.insert(r.channel.clone());
            }
            let bus = match bus_names.iter().position(|b| *b == r.channel) {
                Some(i) => i,
                // A capture of one bus may name it otherwise (pcap has no channel names).
                None if bus_names.len() == 1 => 0,
                None => {
                    return Err(ReplayError::UnknownChannel {
                        channel: r.channel.clone(),
                        buses: bus_names.join(", "),
                    });
                }
            };
            frames.push((r.timestamp_ns, n, bus, *frame));
        }
        if bus_names.len() == 1 && channels.len() > 1 {
            return Err(ReplayError::Channels {
                count: channels.len(),
                channels: channels.into_iter().collect::<Vec<_>>().join(", "),
            });
        }
        // Stable: frames with one timestamp keep the file's order.
        frames.sort_by_key(|f| f.0);
        let Some(t0) = frames.first().map(|f| f.0) else {
            return Err(ReplayError::NoFrames);
        };
        let max = gaps.max_ns.max(0);
        let mut clamped = Vec::new();
        // How much earlier every frame from here on is placed, for the gaps shortened so far.
        let mut shift: i64 = 0;
        let mut out = Vec::with_capacity(frames.len());
        let mut previous: Option<(u64, u64)> = None;
        for &(ts, n, bus, frame) in &frames {
            if let Some((before_ts, before)) = previous {
                let gap = i64::try_from(ts - before_ts).unwrap_or(i64::MAX);
                if gap > max {
                    if !gaps.clamp {
                        return Err(ReplayError::Gap {
                            before,
                            after: n,
                            gap: seconds(gap),
                            bound: seconds(max),
                        });
                    }
                    clamped.push(ClampedGap {
                        before,
                        after: n,
                        gap_ns: gap,
                    });
                    shift = shift.saturating_add(gap - max);
                }
            }
            previous = Some((ts, n));
            out.push(Captured {
                bus,
                t: i64::try_from(ts - t0)
                    .unwrap_or(i64::MAX)
                    .saturating_sub(shift),
                frame,
            });
        }
        Ok(CapturedFrames {
            frames: out,
            error_frames,
            clamped,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(n: u64, ts: u64) -> Record {
        Record::new(
            ts,
            "can0",
            Frame::std(0x700 + n as u16, &[5]).expect("a frame"),
        )
    }

    #[test]
    fn a_gap_beyond_the_bound_is_refused_with_its_records() {
        // Records 1 and 2 a millisecond apart, record 3 a thousand hours later.
        let late = 1_000 * 3_600 * 1_000_000_000u64;
        let records = [record(1, 10), record(2, 1_000_010), record(3, late)];
        let e = CapturedFrames::read(
            records.iter().cloned().map(Ok),
            &["can0"],
            GapBound::DEFAULT,
        )
        .expect_err("refused");
        assert!(
            matches!(
                e,
                ReplayError::Gap {
                    before: 2,
                    after: 3,
                    ..
                }
            ),
            "{e}"
        );
        assert_eq!(
            e.to_string(),
            "has a gap of 3599999.998999 s between record 2 and record 3 (counted from 1, \
             in time order), more than the bound of 60.000000 s"
        );
        // A flipped byte may also move a record far back: it sorts first.
        let records = [record(1, late), record(2, late + 5), record(3, 7)];
        let e = CapturedFrames::read(
            records.iter().cloned().map(Ok),
            &["can0"],
            GapBound::DEFAULT,
        )
        .expect_err("refused");
        assert!(
            matches!(
                e,
                ReplayError::Gap {
                    before: 3,
                    after: 1,
                    ..
                }
            ),
            "{e}"
        );
    }

    #[test]
    fn clamping_shortens_each_long_gap_to_the_bound() {
        let s = 1_000_000_000u64;
        let records = [
            record(1, 0),
            record(2, 100 * s),
            record(3, 101 * s),
            record(4, 500 * s),
        ];
        let gaps = GapBound {
            max_ns: 10 * s as i64,
            clamp: true,
        };
        let c = CapturedFrames::read(records.iter().cloned().map(Ok), &["can0"], gaps)
            .expect("clamped");
        let t: Vec<i64> = c.frames.iter().map(|f| f.t).collect();
        let s = s as i64;
        assert_eq!(t, [0, 10 * s, 11 * s, 21 * s]);
        assert_eq!(
            c.clamped,
            [
                ClampedGap {
                    before: 1,
                    after: 2,
                    gap_ns: 100 * s
                },
                ClampedGap {
                    before: 3,
                    after: 4,
                    gap_ns: 399 * s
                },
            ]
        );
    }
}
