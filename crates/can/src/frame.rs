//! Classic CAN data and remote frames (ISO 11898-1 §10.4).

use crate::id::{Id, IdError};
use core::fmt;

/// A frame that cannot exist on a classic CAN bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// More than 8 data bytes.
    #[error("a classic CAN frame carries at most 8 data bytes, not {0}")]
    TooLong(usize),
    /// A remote frame's DLC above 8.
    #[error("a remote frame's DLC is at most 8, not {0}")]
    BadDlc(u8),
    /// The identifier is out of range.
    #[error(transparent)]
    Id(#[from] IdError),
}

/// A classic CAN frame: a data frame with 0–8 bytes or a remote frame with a DLC of 0–8.
///
/// Frames are small `Copy` values (16 bytes): protocol code passes them around freely.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct Frame {
    id: Id,
    remote: bool,
    dlc: u8,
    data: [u8; 8],
}

impl Frame {
    /// A data frame carrying `data` (0–8 bytes).
    pub fn data(id: impl Into<Id>, data: &[u8]) -> Result<Frame, FrameError> {
        if data.len() > 8 {
            return Err(FrameError::TooLong(data.len()));
        }
        let mut buf = [0u8; 8];
        buf[..data.len()].copy_from_slice(data);
        Ok(Frame {
            id: id.into(),
            remote: false,
            dlc: data.len() as u8,
            data: buf,
        })
    }

    /// A data frame from a fixed-size payload; the length is checked at compile time.
    pub fn data_array<const N: usize>(id: impl Into<Id>, data: [u8; N]) -> Frame {
        const { assert!(N <= 8, "a classic CAN frame carries at most 8 bytes") };
        let mut buf = [0u8; 8];
        buf[..N].copy_from_slice(&data);
        Frame {
            id: id.into(),
            remote: false,
            dlc: N as u8,
            data: buf,
        }
    }

    /// A remote frame requesting `dlc` (0–8) bytes.
    pub fn remote(id: impl Into<Id>, dlc: u8) -> Result<Frame, FrameError> {
        if dlc > 8 {
            return Err(FrameError::BadDlc(dlc));
        }
        Ok(Frame {
            id: id.into(),
            remote: true,
            dlc,
            data: [0; 8],
        })
    }

    /// A standard-format data frame from a raw 11-bit identifier.
    pub fn std(raw_id: u16, data: &[u8]) -> Result<Frame, FrameError> {
        Frame::data(Id::standard(raw_id)?, data)
    }

    /// The identifier.
    pub const fn id(&self) -> Id {
        self.id
    }

    /// Whether this is a remote (RTR) frame.
    pub const fn is_remote(&self) -> bool {
        self.remote
    }

    /// Whether this is an extended-format frame.
    pub const fn is_extended(&self) -> bool {
        self.id.is_extended()
    }

    /// The data length code: the number of data bytes, or the length a remote frame requests.
    pub const fn dlc(&self) -> u8 {
        self.dlc
    }

    /// The data bytes (empty for a remote frame).
    pub fn data_bytes(&self) -> &[u8] {
        if self.remote {
            &[]
        } else {
            &self.data[..usize::from(self.dlc)]
        }
    }

    /// The number of data bytes (0 for a remote frame).
    pub fn len(&self) -> usize {
        if self.remote {
            0
        } else {
            usize::from(self.dlc)
        }
    }

    /// Whether the frame carries no data bytes.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The arbitration key: lower wins (see [`Id::arbitration_key`]).
    pub const fn arbitration_key(&self) -> u32 {
        self.id.arbitration_key(self.remote)
    }
}

impl fmt::Debug for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

impl fmt::Display for Frame {
    /// candump's compact form: `123#DEADBEEF`, `12345678#`, `123#R`, `123#R4`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}#", self.id)?;
        if self.remote {
            f.write_str("R")?;
            if self.dlc > 0 {
                write!(f, "{}", self.dlc)?;
            }
        } else {
            for b in self.data_bytes() {
                write!(f, "{b:02X}")?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constructors_validate() {
        assert_eq!(Frame::std(0x123, &[0; 9]), Err(FrameError::TooLong(9)));
        assert_eq!(
            Frame::remote(Id::standard(1).unwrap(), 9),
            Err(FrameError::BadDlc(9))
        );
        assert!(matches!(Frame::std(0x800, &[]), Err(FrameError::Id(_))));
        let f = Frame::std(0x7FF, &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
        assert_eq!(f.data_bytes(), &[1, 2, 3, 4, 5, 6, 7, 8]);
    }

    #[test]
    fn remote_frames_have_dlc_but_no_data() {
        let f = Frame::remote(Id::standard(0x705).unwrap(), 1).unwrap();
        assert!(f.is_remote());
        assert_eq!(f.dlc(), 1);
        assert!(f.data_bytes().is_empty());
        assert_eq!(f.to_string(), "705#R1");
        assert_eq!(
            Frame::remote(Id::standard(0x705).unwrap(), 0)
                .unwrap()
                .to_string(),
            "705#R"
        );
    }

    #[test]
    fn display_is_candump_style() {
        let f = Frame::data_array(Id::extended(0x1234).unwrap(), [0xDE, 0xAD]);
        assert_eq!(f.to_string(), "00001234#DEAD");
        assert_eq!(Frame::std(0x80, &[]).unwrap().to_string(), "080#");
    }
}
