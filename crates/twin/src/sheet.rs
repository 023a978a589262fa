//! A device's own data sheet: the electronic data sheet a personality without an object
//! dictionary describes itself with (a DeviceNet EDS).

/// When a generated data sheet says it was written (its `[File]` dates), in UTC. The twin
/// never reads a clock: the host passes the date in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FileDate {
    /// The year.
    pub year: u16,
    /// 1–12.
    pub month: u8,
    /// 1–31.
    pub day: u8,
    /// 0–23.
    pub hour: u8,
    /// 0–59.
    pub minute: u8,
    /// 0–59.
    pub second: u8,
}

/// Why a device gives no data sheet.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DataSheetError {
    /// The device has no data sheet of its own (a CANopen twin's EDS comes from its
    /// dictionary).
    #[error("has no data sheet of its own")]
    None,
    /// The device has one, but not in its present state; the message says what is missing.
    #[error("{0}")]
    Unavailable(String),
}
