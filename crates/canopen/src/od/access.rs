//! The SDO server's view of a device ([`ObjectAccess`]) and device hooks ([`OdHooks`]).

use super::{EntryId, ObjectDictionary};
use crate::abort::AbortCode;

/// The result of a read: the value's whole size and how many bytes were copied.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadInfo {
    /// The size of the whole value in bytes.
    pub size: usize,
    /// Bytes copied into the buffer (from the requested offset).
    pub copied: usize,
}

impl ReadInfo {
    /// Serves a read of `value` from `offset` into `buf`, as the dictionary serves its
    /// stored values: for a hook that holds the value itself ([`OdHooks::read`]).
    #[inline]
    pub fn serve(value: &[u8], offset: usize, buf: &mut [u8]) -> ReadInfo {
        read_from(value, offset, buf)
    }
}

/// What an SDO server needs from a device: reads by offset (so that a large DOMAIN is
/// uploaded segment by segment without a copy), whole writes for expedited downloads, and
/// streamed writes for segmented and block downloads.
///
/// [`ObjectDictionary`] implements it with the CiA 301 checks; a device wraps its
/// dictionary and adds its own rules (communication objects, NMT state, hooks).
/// Every error is the abort code the SDO server sends.
pub trait ObjectAccess {
    /// Copies the value of `index`/`sub` from byte `offset` into `buf` (as much as fits)
    /// and tells its whole size. An upload calls it with offset 0 first, then with
    /// increasing offsets (and again from an earlier offset when a block is repeated);
    /// a device computing values on the fly should take its snapshot at offset 0.
    /// Errors: 0x06020000, 0x06090011, 0x06010001, or the device's own.
    fn read(
        &mut self,
        index: u16,
        sub: u8,
        offset: usize,
        buf: &mut [u8],
    ) -> Result<ReadInfo, AbortCode>;

    /// The size of the value's type if it is fixed (used for an expedited download that
    /// does not indicate its size, CiA 301 §7.2.4.3.3: e = 1, s = 0). `None` by default.
    fn fixed_size(&mut self, index: u16, sub: u8) -> Option<usize> {
        let _ = (index, sub);
        None
    }

    /// Writes a whole value (expedited download).
    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode>;

    /// Starts a streamed write of `size` bytes (if the client indicated it). Existence,
    /// writability and the indicated length are checked here.
    fn write_begin(&mut self, index: u16, sub: u8, size: Option<usize>) -> Result<(), AbortCode>;

    /// The next bytes of a streamed write.
    fn write_segment(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode>;

    /// The streamed write is complete: validate and store it.
    fn write_end(&mut self, index: u16, sub: u8) -> Result<(), AbortCode>;

    /// The streamed write was aborted: drop what was received.
    fn write_cancel(&mut self, index: u16, sub: u8);
}

#[inline]
fn read_from(raw: &[u8], offset: usize, buf: &mut [u8]) -> ReadInfo {
    let size = raw.len();
    let start = offset.min(size);
    let copied = (size - start).min(buf.len());
    super::copy_small(&mut buf[..copied], &raw[start..start + copied]);
    ReadInfo { size, copied }
}

impl ObjectDictionary {
    #[inline]
    fn readable(&self, index: u16, sub: u8) -> Result<EntryId, AbortCode> {
        let id = self.locate(index, sub)?;
        if !self.desc_access(id).readable() {
            return Err(AbortCode::WRITE_ONLY);
        }
        Ok(id)
    }
}

impl ObjectAccess for ObjectDictionary {
    #[inline]
    fn read(
        &mut self,
        index: u16,
        sub: u8,
        offset: usize,
        buf: &mut [u8],
    ) -> Result<ReadInfo, AbortCode> {
        let id = self.readable(index, sub)?;
        Ok(read_from(self.raw(id), offset, buf))
    }

    fn fixed_size(&mut self, index: u16, sub: u8) -> Option<usize> {
        let id = self.locate(index, sub).ok()?;
        self.sub_object(id).data_type.fixed_size()
    }

    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode> {
        self.download(index, sub, data)
    }

    fn write_begin(&mut self, index: u16, sub: u8, size: Option<usize>) -> Result<(), AbortCode> {
        self.stage_begin(index, sub, size).map(|_| ())
    }

    fn write_segment(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode> {
        let id = self.locate(index, sub)?;
        self.stage_append(id, data)
    }

    fn write_end(&mut self, index: u16, sub: u8) -> Result<(), AbortCode> {
        let id = self.locate(index, sub)?;
        self.stage_commit(id)
    }

    fn write_cancel(&mut self, _index: u16, _sub: u8) {
        self.stage_cancel();
    }
}

/// Device code behind the objects an [`OdBuilder::hook`](super::OdBuilder::hook) range
/// marks: validates writes before they land, learns of writes after they land, and may
/// serve reads and take writes itself (a drive parameter held by the model, with no
/// stored copy in the dictionary). The dictionary's own checks (existence, access,
/// length, limits) run first.
///
/// A write of a hooked object goes, in this order, through the dictionary's checks
/// ([`ObjectDictionary::check_download`]), [`OdHooks::validate`], [`OdHooks::write`]
/// (or the stored value when it answers `None`) and [`OdHooks::written`]; whatever step
/// refuses ends the write with its abort code and nothing after it runs. SDO downloads of
/// every kind and RPDO data take this same path.
pub trait OdHooks {
    /// Serves a read of a hooked object, or `None` to read the stored value.
    fn read(
        &mut self,
        od: &ObjectDictionary,
        index: u16,
        sub: u8,
        offset: usize,
        buf: &mut [u8],
    ) -> Option<Result<ReadInfo, AbortCode>> {
        let _ = (od, index, sub, offset, buf);
        None
    }

    /// Accepts or refuses a segmented or block download as it starts (e.g. 0x08000022 when
    /// the device state does not allow it), before any data is sent. `size` is the size
    /// the client indicated, if it did.
    fn validate_begin(
        &mut self,
        od: &ObjectDictionary,
        index: u16,
        sub: u8,
        size: Option<usize>,
    ) -> Result<(), AbortCode> {
        let _ = (od, index, sub, size);
        Ok(())
    }

    /// Accepts or refuses (with the abort code to send) a write that passed the
    /// dictionary's checks.
    fn validate(
        &mut self,
        od: &ObjectDictionary,
        index: u16,
        sub: u8,
        data: &[u8],
    ) -> Result<(), AbortCode> {
        let _ = (od, index, sub, data);
        Ok(())
    }

    /// Takes a write of a hooked object that passed the dictionary's checks and
    /// [`OdHooks::validate`]: `Some` when the hook took it (the device's model holds the
    /// value and the dictionary keeps no copy; `Some(Err)` refuses it with that abort code),
    /// `None` to store it in the dictionary as usual. Asked for application objects
    /// (0x2000 and up): the communication objects are the stack's and always stored.
    fn write(
        &mut self,
        od: &mut ObjectDictionary,
        index: u16,
        sub: u8,
        data: &[u8],
    ) -> Option<Result<(), AbortCode>> {
        let _ = (od, index, sub, data);
        None
    }

    /// The bytes an expedited download of `data` to the hooked application object
    /// `index`/`sub` stands for, re-encoded into `buf` in the object's own size before the
    /// dictionary checks them; `Some(Ok(len))` gives their length, `Some(Err(code))` refuses
    /// the download with that abort code. CiA 301 aborts a length other than the object's
    /// (0x06070010, 0x06070012, 0x06070013); a device whose manual accepts other lengths
    /// decodes them here — the ADV200 card takes 1–4 bytes for any parameter and reads them
    /// as the parameter's value (seed 000 §1.4). The default, `None`, checks `data` as it
    /// came.
    fn download_bytes(
        &mut self,
        od: &ObjectDictionary,
        index: u16,
        sub: u8,
        data: &[u8],
        buf: &mut [u8; 8],
    ) -> Option<Result<usize, AbortCode>> {
        let _ = (od, index, sub, data, buf);
        None
    }

    /// A write landed (stored in the dictionary, or taken by [`OdHooks::write`]).
    fn written(&mut self, od: &mut ObjectDictionary, index: u16, sub: u8) {
        let _ = (od, index, sub);
    }

    /// The five manufacturer-specific bytes (bytes 3–7, CiA 301 §7.2.7.3.1) of an EMCY
    /// the device sends now: error `code` (0x0000 for an error reset) with error register
    /// `register`, raised or cleared with `info`. Asked for every EMCY as it goes to the
    /// bus, so the bytes may carry the device's state at that moment (a status register,
    /// the failing module). The default sends `info`.
    fn emcy_manufacturer(
        &mut self,
        od: &ObjectDictionary,
        code: u16,
        register: u8,
        info: [u8; 5],
    ) -> [u8; 5] {
        let _ = (od, code, register);
        info
    }

    /// The 32-bit entry the pre-defined error field (0x1003, CiA 301 §7.5.2.4) records for
    /// error `code` raised with `info`, the error register being `register` after it: bits
    /// 0–15 are the code, bits 16–31 manufacturer-specific additional information. Asked
    /// once per recorded error, as CANopenNode's `CO_errorReport` takes an info code. The
    /// default records the code alone.
    fn error_entry(
        &mut self,
        od: &ObjectDictionary,
        code: u16,
        register: u8,
        info: [u8; 5],
    ) -> u32 {
        let _ = (od, register, info);
        u32::from(code)
    }
}

/// A dictionary together with the device's hooks, as one [`ObjectAccess`]. Built on the
/// fly (`Hooked::new(&mut self.od, &mut self.model)`) so the hooks reach device state
/// through a plain `&mut`.
///
/// ```
/// use std::sync::Arc;
/// use cantwin_canopen::{AbortCode, ObjectAccess};
/// use cantwin_canopen::od::*;
///
/// struct Drive { speed_limit: u16 }
/// impl OdHooks for Drive {
///     fn validate(&mut self, _: &ObjectDictionary, _: u16, _: u8, data: &[u8]) -> Result<(), AbortCode> {
///         let v = u16::from_le_bytes([data[0], data[1]]);
///         if v > self.speed_limit { Err(AbortCode::DEVICE_STATE) } else { Ok(()) }
///     }
/// }
/// let desc = OdBuilder::new()
///     .var(0x2000, SubObject::new("Speed", DataType::Unsigned16, Access::Rw))
///     .hook(0x2000..=0x2FFF)
///     .build().unwrap();
/// let mut od = ObjectDictionary::new(Arc::new(desc), 1);
/// let mut drive = Drive { speed_limit: 3000 };
/// let mut access = Hooked::new(&mut od, &mut drive);
/// assert_eq!(access.write(0x2000, 0, &4000u16.to_le_bytes()), Err(AbortCode::DEVICE_STATE));
/// assert_eq!(access.write(0x2000, 0, &1500u16.to_le_bytes()), Ok(()));
/// ```
pub struct Hooked<'a, H: ?Sized> {
    od: &'a mut ObjectDictionary,
    hooks: &'a mut H,
}

impl<'a, H: OdHooks + ?Sized> Hooked<'a, H> {
    /// Joins a dictionary and its hooks.
    pub fn new(od: &'a mut ObjectDictionary, hooks: &'a mut H) -> Self {
        Hooked { od, hooks }
    }

    /// The dictionary.
    pub fn od(&mut self) -> &mut ObjectDictionary {
        self.od
    }

    /// Offers a download of a hooked application object to [`OdHooks::download_bytes`];
    /// communication objects keep CiA 301's lengths.
    fn download_bytes(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
        buf: &mut [u8; 8],
    ) -> Option<Result<usize, AbortCode>> {
        if index < 0x2000 {
            return None;
        }
        self.hooks.download_bytes(self.od, index, sub, data, buf)
    }

    /// Offers a checked write of a hooked object to [`OdHooks::write`]; communication
    /// objects are the stack's and always stored.
    fn take_write(&mut self, index: u16, sub: u8, data: &[u8]) -> Option<Result<(), AbortCode>> {
        if index < 0x2000 {
            return None;
        }
        self.hooks.write(self.od, index, sub, data)
    }
}

impl<H: OdHooks + ?Sized> ObjectAccess for Hooked<'_, H> {
    #[inline]
    fn read(
        &mut self,
        index: u16,
        sub: u8,
        offset: usize,
        buf: &mut [u8],
    ) -> Result<ReadInfo, AbortCode> {
        let (id, hooked) = self.od.description().locate_hooked(index, sub)?;
        if !self.od.desc_access(id).readable() {
            return Err(AbortCode::WRITE_ONLY);
        }
        if hooked && let Some(r) = self.hooks.read(self.od, index, sub, offset, buf) {
            return r;
        }
        Ok(read_from(self.od.raw(id), offset, buf))
    }

    fn fixed_size(&mut self, index: u16, sub: u8) -> Option<usize> {
        self.od.fixed_size(index, sub)
    }

    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode> {
        let (id, hooked) = self.od.description().locate_hooked(index, sub)?;
        if !hooked {
            return self.od.download(index, sub, data);
        }
        let mut buf = [0u8; 8];
        let data = match self.download_bytes(index, sub, data, &mut buf) {
            // A length beyond the buffer is a hook's mistake: refused, never read past.
            Some(len) => buf.get(..len?).ok_or(AbortCode::LENGTH_TOO_HIGH)?,
            None => data,
        };
        self.od.check_download(id, data)?;
        self.hooks.validate(self.od, index, sub, data)?;
        match self.take_write(index, sub, data) {
            Some(r) => r?,
            None => self.od.set_raw(id, data)?,
        }
        self.hooks.written(self.od, index, sub);
        Ok(())
    }

    fn write_begin(&mut self, index: u16, sub: u8, size: Option<usize>) -> Result<(), AbortCode> {
        self.od.stage_begin(index, sub, size)?;
        if self.od.description().is_hooked(index)
            && let Err(code) = self.hooks.validate_begin(self.od, index, sub, size)
        {
            self.od.stage_cancel();
            return Err(code);
        }
        Ok(())
    }

    fn write_segment(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode> {
        let id = self.od.locate(index, sub)?;
        self.od.stage_append(id, data)
    }

    fn write_end(&mut self, index: u16, sub: u8) -> Result<(), AbortCode> {
        let id = self.od.locate(index, sub)?;
        self.od.stage_check(id)?;
        if !self.od.description().is_hooked(index) {
            return self.od.stage_commit(id);
        }
        self.hooks.validate(self.od, index, sub, self.od.staged())?;
        // The hook may take the staged bytes; the buffer is lent to it and given back, so
        // its allocation serves the next download.
        let staged = core::mem::take(&mut self.od.staging);
        let taken = self.take_write(index, sub, &staged);
        self.od.staging = staged;
        match taken {
            Some(r) => {
                self.od.stage_cancel();
                r?;
            }
            None => self.od.stage_commit(id)?,
        }
        self.hooks.written(self.od, index, sub);
        Ok(())
    }

    fn write_cancel(&mut self, _index: u16, _sub: u8) {
        self.od.stage_cancel();
    }
}
