//! The values that cross between cantwin and SIL Kit, as plain Rust types (no pointers).

use cantwin_can::{Frame, Id};

/// `SilKit_CanFrameFlag_*` (`capi/Can.h`): identifier extension.
pub const FLAG_IDE: u32 = 1 << 9;
/// Remote transmission request.
pub const FLAG_RTR: u32 = 1 << 4;
/// CAN FD format.
pub const FLAG_FDF: u32 = 1 << 12;
/// CAN FD bit rate switch.
pub const FLAG_BRS: u32 = 1 << 13;
/// CAN FD error state indicator.
pub const FLAG_ESI: u32 = 1 << 14;
/// CAN XL format.
pub const FLAG_XLF: u32 = 1 << 15;
/// CAN XL simple extended content.
pub const FLAG_SEC: u32 = 1 << 16;

/// A CAN frame as SIL Kit carries it (`SilKit_CanFrame`): the identifier without format
/// bits, the format in `flags`, the DLC and the payload.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CanFrame {
    /// The identifier (11 or 29 bits; the format is [`FLAG_IDE`]).
    pub id: u32,
    /// `SilKit_CanFrameFlag_*` bits.
    pub flags: u32,
    /// The data length code.
    pub dlc: u16,
    /// The payload (empty for a remote frame).
    pub data: Vec<u8>,
}

/// Why a SIL Kit frame is not a classical CAN frame cantwin's bus can carry.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameConversionError {
    /// CAN FD and CAN XL frames are not simulated (cantwin's bus is classical CAN).
    #[error("CAN FD / CAN XL frames are not supported (flags {0:#x})")]
    NotClassical(u32),
    /// The identifier does not fit its format.
    #[error("identifier {id:#x} does not fit the {} format", if *.extended { "29-bit" } else { "11-bit" })]
    BadId {
        /// The identifier.
        id: u32,
        /// Whether the IDE flag was set.
        extended: bool,
    },
    /// More than 8 data bytes, or a DLC above 15.
    #[error("a classical CAN frame carries at most 8 bytes (DLC {dlc}, {len} bytes)")]
    BadLength {
        /// The DLC.
        dlc: u16,
        /// The payload length.
        len: usize,
    },
}

impl CanFrame {
    /// The SIL Kit form of a cantwin frame.
    pub fn from_frame(frame: &Frame) -> CanFrame {
        let mut flags = 0;
        if frame.is_extended() {
            flags |= FLAG_IDE;
        }
        if frame.is_remote() {
            flags |= FLAG_RTR;
        }
        CanFrame {
            id: frame.id().as_raw(),
            flags,
            dlc: u16::from(frame.dlc()),
            data: frame.data_bytes().to_vec(),
        }
    }

    /// The cantwin frame, or why it is not one. A data frame's DLC is the payload length
    /// (the DLC field SIL Kit carries is what a network simulator determines, `capi/Can.h`);
    /// a remote frame keeps its DLC.
    pub fn to_frame(&self) -> Result<Frame, FrameConversionError> {
        if self.flags & (FLAG_FDF | FLAG_XLF) != 0 {
            return Err(FrameConversionError::NotClassical(self.flags));
        }
        let extended = self.flags & FLAG_IDE != 0;
        let bad_id = FrameConversionError::BadId {
            id: self.id,
            extended,
        };
        let id = if extended {
            Id::extended(self.id).map_err(|_| bad_id)?
        } else {
            u16::try_from(self.id)
                .ok()
                .and_then(|raw| Id::standard(raw).ok())
                .ok_or(bad_id)?
        };
        let bad_length = FrameConversionError::BadLength {
            dlc: self.dlc,
            len: self.data.len(),
        };
        if self.flags & FLAG_RTR != 0 {
            let dlc = u8::try_from(self.dlc)
                .ok()
                .filter(|d| *d <= 15)
                .ok_or(bad_length.clone())?;
            Frame::remote(id, dlc.min(8)).map_err(|_| bad_length)
        } else {
            Frame::data(id, &self.data).map_err(|_| bad_length)
        }
    }
}

/// The direction of a frame event (`SilKit_Direction`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Sent by this controller (its own frame, reported back).
    Send,
    /// Received from another controller.
    Receive,
}

/// Which frames a frame handler gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DirectionMask {
    /// Only this controller's own frames.
    Send,
    /// Only other controllers' frames.
    Receive,
    /// Both.
    SendReceive,
}

impl DirectionMask {
    pub(crate) fn raw(self) -> u8 {
        match self {
            DirectionMask::Send => 1,
            DirectionMask::Receive => 2,
            DirectionMask::SendReceive => 3,
        }
    }
}

/// A frame seen by a controller (`SilKit_CanFrameEvent`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameEvent {
    /// Virtual time of the frame in nanoseconds (the sender's time, or the network
    /// simulator's).
    pub timestamp: u64,
    /// The frame.
    pub frame: CanFrame,
    /// Sent or received.
    pub direction: Direction,
    /// The tag given to [`crate::CanController::send`] for this controller's own frames, 0
    /// for received ones.
    pub user_context: usize,
}

/// The outcome of a transmit request (`SilKit_CanTransmitStatus`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TransmitStatus {
    /// The frame was sent and acknowledged.
    Transmitted,
    /// The request was cancelled (the transmit queue was reset).
    Canceled,
    /// The transmit queue was full.
    TransmitQueueFull,
    /// A status this binding does not know.
    Other(i32),
}

impl TransmitStatus {
    /// `SilKit_CanTransmitStatus_*` bits.
    pub fn raw(self) -> i32 {
        match self {
            TransmitStatus::Transmitted => 1,
            TransmitStatus::Canceled => 2,
            TransmitStatus::TransmitQueueFull => 4,
            TransmitStatus::Other(v) => v,
        }
    }

    pub(crate) fn from_raw(v: i32) -> Self {
        match v {
            1 => TransmitStatus::Transmitted,
            2 => TransmitStatus::Canceled,
            4 => TransmitStatus::TransmitQueueFull,
            v => TransmitStatus::Other(v),
        }
    }
}

/// A transmit acknowledgement (`SilKit_CanFrameTransmitEvent`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TransmitEvent {
    /// Virtual time in nanoseconds.
    pub timestamp: u64,
    /// The outcome.
    pub status: TransmitStatus,
    /// The identifier of the frame it answers.
    pub can_id: u32,
    /// The tag given to [`crate::CanController::send`].
    pub user_context: usize,
}

/// The controller state (`SilKit_CanControllerState`, after AUTOSAR's CAN driver).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerState {
    /// Not initialised.
    Uninit,
    /// Initialised, not on the bus.
    Stopped,
    /// On the bus.
    Started,
    /// Asleep.
    Sleep,
    /// A value this binding does not know.
    Other(i32),
}

impl ControllerState {
    /// The C value.
    pub fn raw(self) -> i32 {
        match self {
            ControllerState::Uninit => 0,
            ControllerState::Stopped => 1,
            ControllerState::Started => 2,
            ControllerState::Sleep => 3,
            ControllerState::Other(v) => v,
        }
    }

    /// From the C value.
    pub fn from_raw(v: i32) -> Self {
        match v {
            0 => ControllerState::Uninit,
            1 => ControllerState::Stopped,
            2 => ControllerState::Started,
            3 => ControllerState::Sleep,
            v => ControllerState::Other(v),
        }
    }
}

/// The fault confinement state (`SilKit_CanErrorState`, ISO 11898-1 §12.1.4).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorState {
    /// No state (controller uninitialised).
    NotAvailable,
    /// Error active.
    ErrorActive,
    /// Error passive.
    ErrorPassive,
    /// Bus-off.
    BusOff,
    /// A value this binding does not know.
    Other(i32),
}

impl ErrorState {
    /// The C value.
    pub fn raw(self) -> i32 {
        match self {
            ErrorState::NotAvailable => 0,
            ErrorState::ErrorActive => 1,
            ErrorState::ErrorPassive => 2,
            ErrorState::BusOff => 3,
            ErrorState::Other(v) => v,
        }
    }

    /// From the C value.
    pub fn from_raw(v: i32) -> Self {
        match v {
            0 => ErrorState::NotAvailable,
            1 => ErrorState::ErrorActive,
            2 => ErrorState::ErrorPassive,
            3 => ErrorState::BusOff,
            v => ErrorState::Other(v),
        }
    }
}

/// A controller state change (`SilKit_CanStateChangeEvent`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StateChangeEvent {
    /// Virtual time in nanoseconds.
    pub timestamp: u64,
    /// The new state.
    pub state: ControllerState,
}

/// An error state change (`SilKit_CanErrorStateChangeEvent`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ErrorStateChangeEvent {
    /// Virtual time in nanoseconds.
    pub timestamp: u64,
    /// The new state.
    pub error_state: ErrorState,
}

/// How a participant's lifecycle follows the others (`SilKit_OperationMode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OperationMode {
    /// Follows the system state set by a system controller; starts and stops with the
    /// required participants.
    Coordinated,
    /// Runs on its own and stops itself.
    Autonomous,
}

/// A participant's state (`SilKit_ParticipantState`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParticipantState {
    /// Invalid or unknown.
    Invalid,
    /// Services created.
    ServicesCreated,
    /// Communication initialising.
    CommunicationInitializing,
    /// Communication initialised.
    CommunicationInitialized,
    /// Ready to run.
    ReadyToRun,
    /// Running.
    Running,
    /// Paused.
    Paused,
    /// Stopping.
    Stopping,
    /// Stopped.
    Stopped,
    /// Error.
    Error,
    /// Shutting down.
    ShuttingDown,
    /// Shut down.
    Shutdown,
    /// Aborting.
    Aborting,
    /// A value this binding does not know.
    Other(i16),
}

impl ParticipantState {
    /// From the C value.
    pub fn from_raw(v: i16) -> Self {
        match v {
            0 => ParticipantState::Invalid,
            10 => ParticipantState::ServicesCreated,
            20 => ParticipantState::CommunicationInitializing,
            30 => ParticipantState::CommunicationInitialized,
            40 => ParticipantState::ReadyToRun,
            50 => ParticipantState::Running,
            60 => ParticipantState::Paused,
            70 => ParticipantState::Stopping,
            80 => ParticipantState::Stopped,
            90 => ParticipantState::Error,
            100 => ParticipantState::ShuttingDown,
            110 => ParticipantState::Shutdown,
            120 => ParticipantState::Aborting,
            v => ParticipantState::Other(v),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_convert_both_ways_with_format_flags() {
        let std = Frame::std(0x123, &[1, 2, 3]).expect("frame");
        let sk = CanFrame::from_frame(&std);
        assert_eq!((sk.id, sk.flags, sk.dlc), (0x123, 0, 3));
        assert_eq!(sk.to_frame(), Ok(std));
        let ext = Frame::data(Id::extended(0x1ABC_DEF0).expect("id"), &[9]).expect("frame");
        let sk = CanFrame::from_frame(&ext);
        assert_eq!((sk.id, sk.flags), (0x1ABC_DEF0, FLAG_IDE));
        assert_eq!(sk.to_frame(), Ok(ext));
        let rtr = Frame::remote(Id::standard(0x701).expect("id"), 1).expect("frame");
        let sk = CanFrame::from_frame(&rtr);
        assert_eq!((sk.flags, sk.dlc, sk.data.len()), (FLAG_RTR, 1, 0));
        assert_eq!(sk.to_frame(), Ok(rtr));
    }

    #[test]
    fn frames_cantwin_cannot_carry_are_refused() {
        let f = |id, flags, data: &[u8]| CanFrame {
            id,
            flags,
            dlc: data.len() as u16,
            data: data.to_vec(),
        };
        assert_eq!(
            f(0x800, 0, &[]).to_frame(),
            Err(FrameConversionError::BadId {
                id: 0x800,
                extended: false
            })
        );
        assert!(matches!(
            f(0x2000_0000, FLAG_IDE, &[]).to_frame(),
            Err(FrameConversionError::BadId { .. })
        ));
        assert!(matches!(
            f(1, 0, &[0; 9]).to_frame(),
            Err(FrameConversionError::BadLength { .. })
        ));
        assert!(matches!(
            f(1, FLAG_FDF, &[0; 12]).to_frame(),
            Err(FrameConversionError::NotClassical(_))
        ));
    }
}
