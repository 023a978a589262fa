//! The generic CiA 301 device is a twin: its dictionary, its node-ID, writes through its
//! own checks.

use cantwin_canopen::device::Device;
use cantwin_canopen::od::{ObjectDictionary, OdHooks};
use cantwin_canopen::{AbortCode, ObjectAccess};

use crate::object::{Context, ObjectError};
use crate::twin::Twin;

/// Writes `data` to `index`/`sub` of `device` as [`Twin::write_object`] describes: a
/// fixed-size value must have its type's size, then the device's own download path checks
/// and stores it. For twins built around a [`Device`].
pub fn write_through<H: OdHooks>(
    device: &mut Device<H>,
    index: u16,
    sub: u8,
    data: &[u8],
) -> Result<(), ObjectError> {
    if let Some(n) = device.fixed_size(index, sub)
        && n != data.len()
    {
        return Err(ObjectError::Abort(AbortCode::TYPE_MISMATCH));
    }
    device.write(index, sub, data).map_err(ObjectError::Abort)
}

impl<H: OdHooks> Twin for Device<H> {
    fn dictionary(&self) -> Option<&ObjectDictionary> {
        Some(self.od())
    }

    fn write_object(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
        _cx: &mut Context<'_>,
    ) -> Result<(), ObjectError> {
        write_through(self, index, sub, data)
    }

    fn canopen_node_id(&self) -> Option<u8> {
        Some(self.node_id())
    }

    fn dictionary_heap_bytes(&self) -> Option<usize> {
        Some(self.heap_bytes())
    }
}
