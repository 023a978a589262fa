//! Why a replay could not run.

use cantwin_scenario::ScenarioError;

/// Why a replay could not run. Errors about the capture read as the rest of a sentence
/// that starts with the capture's name.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// A frame of the capture is on a channel none of the scenario's buses has.
    #[error("channel {channel:?} is none of the scenario's buses ({buses})")]
    UnknownChannel {
        /// The capture's channel.
        channel: String,
        /// The scenario's buses, comma-separated.
        buses: String,
    },
    /// The capture holds several channels but the scenario one bus.
    #[error("holds {count} channels ({channels}) but the scenario has one bus")]
    Channels {
        /// How many channels the capture holds.
        count: usize,
        /// The channels, comma-separated.
        channels: String,
    },
    /// A captured frame is placed on a bus the scenario does not have.
    #[error("places a frame on bus {bus}, but the scenario has {buses} buses")]
    NoSuchBus {
        /// The frame's bus, as a position in the scenario.
        bus: usize,
        /// How many buses the scenario has.
        buses: usize,
    },
    /// A record of the capture could not be read.
    #[error("record {record}: {source}")]
    Read {
        /// The record, counted from 1.
        record: u64,
        /// Why it could not be read.
        source: cantwin_capture::Error,
    },
    /// Two consecutive frames (in time order) are further apart than the bound allows.
    #[error(
        "has a gap of {gap} s between record {before} and record {after} (counted from 1, in \
         time order), more than the bound of {bound} s"
    )]
    Gap {
        /// The record before the gap.
        before: u64,
        /// The record after it.
        after: u64,
        /// The gap, in seconds.
        gap: String,
        /// The bound, in seconds.
        bound: String,
    },
    /// The twins sent more frames than a capture of this size can be compared with: its
    /// time span is out of proportion to its frames.
    #[error(
        "spans more time than its frames account for: the twins sent more than {budget} \
         frames by {at} s of its time"
    )]
    TooManyFrames {
        /// The most twin frames a run keeps.
        budget: usize,
        /// The capture time the budget ran out at, in seconds.
        at: String,
    },
    /// The capture holds no frames.
    #[error("holds no frames to replay")]
    NoFrames,
    /// The scenario did not build.
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    /// A bus of the scenario was gone after building it.
    #[error("a bus of the scenario is gone")]
    BusGone,
    /// A master frame could not be put on the bus.
    #[error("injecting {frame} at {at}: {reason}")]
    Inject {
        /// The frame, as text.
        frame: String,
        /// Its time in the capture, in seconds.
        at: String,
        /// Why the bus refused it.
        reason: String,
    },
    /// Learning the master's identifiers did not reach a fixed point.
    #[error("the master's identifiers did not settle")]
    Unsettled,
}
