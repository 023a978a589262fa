//! Reading and writing a device's objects from above, and what a change made from above
//! may do on the bus.

use cantwin_can::{Instant, Outbox};
use cantwin_canopen::AbortCode;

/// Why an object could not be read or written.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ObjectError {
    /// The device has no object dictionary (at least not in its present personality).
    #[error("no object dictionary")]
    NoDictionary,
    /// The device answered as it would an SDO client (CiA 301 table 22).
    #[error("abort {0}")]
    Abort(AbortCode),
    /// The device takes no writes this way; `reason` says how to change it instead.
    #[error("{0}")]
    Refused(String),
}

impl From<AbortCode> for ObjectError {
    fn from(code: AbortCode) -> Self {
        ObjectError::Abort(code)
    }
}

/// The moment a host changes a device, and where the frames the device sends at once go
/// (a module pulled out of a coupler raises an EMCY now).
#[derive(Debug)]
pub struct Context<'a> {
    /// The bus time now.
    pub now: Instant,
    /// Frames to queue for transmission on the device's port.
    pub out: &'a mut Outbox,
}

impl<'a> Context<'a> {
    /// A context at `now` writing into `out`.
    pub fn new(now: Instant, out: &'a mut Outbox) -> Self {
        Context { now, out }
    }
}
