//! Identity object (class 0x01, CIP Vol. 1 §5-2): who the device is, and Reset.

use super::{AttrDef, CipError, Reply, attribute_service, get};
use crate::wire::{Request, service, status};

/// Class 0x01.
pub const CLASS: u16 = 0x01;

/// The identity values of a device (instance 1, attributes 1–7).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Identity {
    /// Vendor ID (ODVA-assigned).
    pub vendor: u16,
    /// Device type (0x02 AC drive, 0x0C communications adapter …).
    pub device_type: u16,
    /// Product code.
    pub product_code: u16,
    /// Revision: major, minor.
    pub revision: (u8, u8),
    /// Serial number.
    pub serial: u32,
    /// Product name (SHORT_STRING, at most 32 characters).
    pub product_name: String,
}

const INSTANCE_ATTRS: [AttrDef; 7] = [get(1), get(2), get(3), get(4), get(5), get(6), get(7)];

/// Status word bit 0: the device has an owner (a master allocated it).
pub const STATUS_OWNED: u16 = 0x0001;
/// Extended device status: at least one faulted I/O connection.
pub const EXT_IO_FAULTED: u16 = 0x0020;
/// Extended device status: no I/O connection established.
pub const EXT_NO_IO: u16 = 0x0030;
/// Extended device status: at least one I/O connection in run mode.
pub const EXT_IO_RUN: u16 = 0x0060;
/// Extended device status: I/O connections established, all idle.
pub const EXT_IO_IDLE: u16 = 0x0070;

impl Identity {
    fn attribute(&self, attr: u8, status_word: u16) -> Vec<u8> {
        match attr {
            1 => self.vendor.to_le_bytes().to_vec(),
            2 => self.device_type.to_le_bytes().to_vec(),
            3 => self.product_code.to_le_bytes().to_vec(),
            4 => vec![self.revision.0, self.revision.1],
            5 => status_word.to_le_bytes().to_vec(),
            6 => self.serial.to_le_bytes().to_vec(),
            _ => {
                let name = self.product_name.as_bytes();
                let n = name.len().min(32);
                let mut v = Vec::with_capacity(1 + n);
                v.push(n as u8);
                v.extend_from_slice(&name[..n]);
                v
            }
        }
    }

    /// Get_Attributes_All: attributes 1–7 in order.
    pub fn all(&self, status_word: u16) -> Vec<u8> {
        (1..=7)
            .flat_map(|a| self.attribute(a, status_word))
            .collect()
    }
}

/// What an Identity request asks the slave to do besides replying.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum IdentityAction {
    /// Nothing more.
    None,
    /// Reset after the reply is sent (0 = emulate power cycle, 1 = factory defaults).
    Reset(u8),
}

/// Serve a request to class 0x01.
pub fn serve(id: &Identity, status_word: u16, req: &Request<'_>) -> (Reply, IdentityAction) {
    let none = IdentityAction::None;
    match req.instance {
        0 => (
            attribute_service(
                req,
                &[get(1), get(2)],
                |_| 1u16.to_le_bytes().to_vec(),
                |_, _| Err(CipError::new(status::ATTRIBUTE_NOT_SETTABLE)),
            ),
            none,
        ),
        1 => match req.service {
            service::GET_ATTRIBUTES_ALL => (Reply::Data(id.all(status_word)), none),
            service::RESET => match req.data {
                [] => (Reply::Data(Vec::new()), IdentityAction::Reset(0)),
                [kind @ (0 | 1)] => (Reply::Data(Vec::new()), IdentityAction::Reset(*kind)),
                [_] => (
                    CipError::new(status::INVALID_PARAMETER).into(),
                    IdentityAction::None,
                ),
                _ => (CipError::new(status::TOO_MUCH_DATA).into(), none),
            },
            _ => (
                attribute_service(
                    req,
                    &INSTANCE_ATTRS,
                    |a| id.attribute(a, status_word),
                    |_, _| Err(CipError::new(status::ATTRIBUTE_NOT_SETTABLE)),
                ),
                none,
            ),
        },
        _ => (CipError::new(status::OBJECT_DOES_NOT_EXIST).into(), none),
    }
}
