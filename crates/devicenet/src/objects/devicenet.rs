//! DeviceNet object (class 0x03, DeviceNet Vol. 1 §5): the port's MAC ID, baud rate,
//! bus-off interrupt (BOI), bus-off counter and allocation information. Allocate and
//! Release (services 0x4B/0x4C) are served by the slave, which owns the connections.

use super::{AttrDef, CipError, Reply, attribute_service, exact_len, get, get_set};
use crate::wire::{MacId, Request, status};

/// Class 0x03.
pub const CLASS: u16 = 0x03;

/// The DeviceNet object's instance attributes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceNetObject {
    /// Attribute 1: MAC ID.
    pub mac: MacId,
    /// Attribute 2: baud rate code (0 = 125, 1 = 250, 2 = 500 kbit/s).
    pub baud: u8,
    /// Attribute 3: bus-off interrupt: false = stay off the bus after bus-off, true =
    /// reset the controller and come back (re-running the duplicate MAC ID check).
    pub boi: bool,
    /// Attribute 4: bus-off counter, saturating at 255; a Set of 0 clears it.
    pub bus_off_count: u8,
    /// Attribute 5: allocation choice.
    pub choice: u8,
    /// Attribute 5: master's MAC ID, `None` (255 on the wire) when not allocated.
    pub master: Option<MacId>,
}

const ATTRS: [AttrDef; 5] = [get(1), get(2), get_set(3), get_set(4), get(5)];

impl DeviceNetObject {
    fn attribute(&self, attr: u8) -> Vec<u8> {
        match attr {
            1 => vec![self.mac.get()],
            2 => vec![self.baud],
            3 => vec![u8::from(self.boi)],
            4 => vec![self.bus_off_count],
            _ => vec![self.choice, self.master.map_or(255, MacId::get)],
        }
    }

    fn set(&mut self, attr: u8, data: &[u8]) -> Result<Vec<u8>, CipError> {
        exact_len(data, 1)?;
        match (attr, data[0]) {
            (3, v @ (0 | 1)) => self.boi = v == 1,
            (4, 0) => self.bus_off_count = 0,
            _ => return Err(CipError::new(status::INVALID_ATTRIBUTE_VALUE)),
        }
        Ok(Vec::new())
    }

    /// Serve an attribute request to class 0x03.
    pub fn serve(&mut self, req: &Request<'_>) -> Reply {
        match req.instance {
            0 => attribute_service(
                req,
                &[get(1)],
                |_| 2u16.to_le_bytes().to_vec(),
                |_, _| Err(CipError::new(status::ATTRIBUTE_NOT_SETTABLE)),
            ),
            1 => {
                let snapshot = *self;
                attribute_service(
                    req,
                    &ATTRS,
                    |a| snapshot.attribute(a),
                    |a, d| self.set(a, d),
                )
            }
            _ => CipError::new(status::OBJECT_DOES_NOT_EXIST).into(),
        }
    }
}
