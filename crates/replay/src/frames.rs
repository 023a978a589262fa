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

/// A capture's frames on the scenario's buses (named `bus_names`, in scenario order), in
/// time order; a capture of one bus may name its channel otherwise.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CapturedFrames {
    /// The frames, times relative to the first.
    pub frames: Vec<Captured>,
    /// Error frames in the capture, which are not replayed.
    pub error_frames: u64,
}

impl CapturedFrames {
    /// Places `records` on the buses named `bus_names`.
    pub fn from_records(
        records: &[Record],
        bus_names: &[&str],
    ) -> Result<CapturedFrames, ReplayError> {
        let mut channels: BTreeSet<&str> = BTreeSet::new();
        let mut frames: Vec<(u64, usize, Frame)> = Vec::new();
        let mut error_frames = 0u64;
        for r in records {
            let Some(frame) = r.frame() else {
                error_frames += 1;
                continue;
            };
            channels.insert(r.channel.as_str());
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
            frames.push((r.timestamp_ns, bus, *frame));
        }
        if bus_names.len() == 1 && channels.len() > 1 {
            return Err(ReplayError::Channels {
                count: channels.len(),
                channels: channels.into_iter().collect::<Vec<_>>().join(", "),
            });
        }
        frames.sort_by_key(|f| f.0);
        let Some(t0) = frames.first().map(|f| f.0) else {
            return Err(ReplayError::NoFrames);
        };
        let frames = frames
            .iter()
            .map(|&(ts, bus, frame)| Captured {
                bus,
                t: i64::try_from(ts - t0).unwrap_or(i64::MAX),
                frame,
            })
            .collect();
        Ok(CapturedFrames {
            frames,
            error_frames,
        })
    }
}
