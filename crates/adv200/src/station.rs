//! The drive as the card's object dictionary reaches it: the [`OdHooks`] of the CANopen and
//! DS402 personalities.
//!
//! The dictionary holds no copy of a drive parameter. Every parameter PAR is the ARRAY
//! 0x2000 + PAR (§1.4) whose sub-index 0 (1, read-only) the dictionary stores and whose
//! sub-index 1 the hooks serve from the parameter database:
//!
//! * **reads** (SDO uploads, TPDOs) encode the parameter at its size; a channel the Process
//!   Data Channel placed reads at its width (§1.3: a 16-bit channel's `mon` is 16 bits wide
//!   in the PDOs and in the dictionary, so that the EDS types it as the PDOs map it);
//! * **writes** (SDO downloads, RPDOs) go through [`fieldbus::write_bytes`], the path the
//!   DeviceNet card uses too; RPDO data for M2S channel n lands in `Fieldbus M->Sn mon`,
//!   sign-extended from the channel's width, while `Fieldbus M->S enable` is On (§1.2).
//!
//! DS402 (chapter 2): the controlword, the target velocity and the vl limits and ramps are
//! the dictionary's own values, written by the master; the statusword (0x6041), vl velocity
//! demand (0x6043) and vl control effort (0x6044) are computed from the power state machine
//! and the drive: the statusword as the drive's last evaluation left it (a TPDO sampled at
//! the SYNC that also applies a new target shows the state before the drive saw it), the
//! speeds when they are read.

use cantwin_canopen::AbortCode;
use cantwin_canopen::od::{DataType, ObjectDictionary, OdHooks, ReadInfo, Value};
use cantwin_cia402::objects as cia402;

use crate::drive::Drive;
use crate::ds402::{Ds402, State as PowerState};
use crate::fieldbus;
use crate::params::{CHANNELS, ParamDb, par};
use crate::pdc::Pdc;

/// First index of the §1.4 parameter window (0x2000 + PAR).
pub const PARAMS_FIRST: u16 = 0x2000;
/// Last index of the parameter window.
pub const PARAMS_LAST: u16 = 0x5FFF;

/// The drive, its parameters and its CiA 402 state, as the card's dictionary hooks.
#[derive(Debug, Clone, Default)]
pub struct Station {
    pub(crate) params: ParamDb,
    pub(crate) drive: Drive,
    pub(crate) ds402: Ds402,
    /// Bytes each placed PDC channel's `mon` has in the dictionary: (PAR, bytes).
    widths: Vec<(u16, usize)>,
    /// `Fieldbus M->S enable` as latched at the drive reset.
    ms_enable: bool,
    /// A write reached the drive since it was last evaluated.
    pub(crate) touched: bool,
    /// The statusword (0x6041) as the drive's last evaluation made it.
    pub(crate) statusword: u16,
    /// A TPDO's communication or mapping parameters were written: which objects the
    /// event-driven TPDOs map must be found again.
    pub(crate) remapped: bool,
}

/// The integer the dictionary stores at `index`/`sub`.
pub(crate) fn od_i64(od: &ObjectDictionary, index: u16, sub: u8) -> Option<i64> {
    Some(match od.get(index, sub).ok()? {
        Value::Integer8(v) => i64::from(v),
        Value::Integer16(v) => i64::from(v),
        Value::Integer32(v) => i64::from(v),
        Value::Unsigned8(v) => i64::from(v),
        Value::Unsigned16(v) => i64::from(v),
        Value::Unsigned32(v) => i64::from(v),
        _ => return None,
    })
}

/// The M2S channel whose `mon` parameter is `p`.
fn m2s_channel(p: u16) -> Option<u16> {
    let first = par::m2s_mon(1);
    let n = p.checked_sub(first)?;
    (n % 10 == 0 && n / 10 < CHANNELS).then_some(n / 10 + 1)
}

impl Station {
    /// The fieldbus settings of a drive reset: the PDC placed, `Fieldbus M->S enable`.
    pub(crate) fn configure(&mut self, pdc: &Pdc, ms_enable: bool) {
        self.ms_enable = ms_enable;
        self.widths.clear();
        self.widths.extend(
            pdc.m2s
                .items()
                .filter(|i| !i.fill)
                .map(|i| (par::m2s_mon(i.channel), usize::from(i.bits / 8))),
        );
        self.widths.extend(
            pdc.s2m
                .items()
                .map(|i| (par::s2m_mon(i.channel), usize::from(i.bits / 8))),
        );
    }

    /// Updates the statusword after an evaluation of the drive: the power state, and target
    /// reached (bit 10) when the speed equals the target velocity the drive was given.
    pub(crate) fn update_statusword(&mut self, target: i64) {
        let speed = self.params.value(par::MOTOR_SPEED);
        let reached = self.ds402.state() == PowerState::OperationEnabled && speed == target;
        self.statusword = self.ds402.publish(reached);
    }

    /// The bytes of parameter `p` as the dictionary gives them.
    fn encode(&self, p: u16) -> Result<([u8; 4], usize), AbortCode> {
        let (bytes, len) = self.params.encode(p).map_err(|e| e.abort_code())?;
        let len = self
            .widths
            .iter()
            .find(|(q, _)| *q == p)
            .map_or(len, |(_, w)| *w);
        Ok((bytes, len))
    }

    /// The value of a hooked object as the dictionary gives it, or `None` for one the
    /// dictionary stores itself.
    pub(crate) fn serve(&self, index: u16, sub: u8) -> Option<Result<([u8; 4], usize), AbortCode>> {
        let word = |v: i64| Some(Ok(((v as u32).to_le_bytes(), 2)));
        match (index, sub) {
            (PARAMS_FIRST..=PARAMS_LAST, 1) => Some(self.encode(index - PARAMS_FIRST)),
            (cia402::STATUSWORD, 0) => word(i64::from(self.statusword)),
            (cia402::VL_VELOCITY_DEMAND, 0) => word(self.params.value(par::RAMP_OUTPUT)),
            (cia402::VL_VELOCITY_ACTUAL_VALUE, 0) => word(self.params.value(par::MOTOR_SPEED)),
            _ => None,
        }
    }

    fn take(&mut self, p: u16, data: &[u8]) -> Result<(), AbortCode> {
        if m2s_channel(p).is_some() {
            // Process data of the master (§1.3): the channel's mon shows it while the
            // M->S direction is enabled; the drive takes it from there through the srcs.
            let v = ParamDb::decode(p, data).map_err(|e| e.abort_code())?;
            if self.ms_enable {
                let _ = self.params.force(p, v);
            }
            return Ok(());
        }
        fieldbus::write_bytes(&mut self.params, p, data).map_err(|e| e.abort_code())
    }
}

impl OdHooks for Station {
    fn read(
        &mut self,
        od: &ObjectDictionary,
        index: u16,
        sub: u8,
        offset: usize,
        buf: &mut [u8],
    ) -> Option<Result<ReadInfo, AbortCode>> {
        let _ = od;
        let served = self.serve(index, sub)?;
        Some(
            served
                .map(|(bytes, size)| ReadInfo::serve(&bytes[..size.min(bytes.len())], offset, buf)),
        )
    }

    fn write(
        &mut self,
        _od: &mut ObjectDictionary,
        index: u16,
        sub: u8,
        data: &[u8],
    ) -> Option<Result<(), AbortCode>> {
        if !(PARAMS_FIRST..=PARAMS_LAST).contains(&index) || sub != 1 {
            return None;
        }
        Some(self.take(index - PARAMS_FIRST, data))
    }

    /// §1.4: a download of 1–4 bytes is accepted for any parameter and read as its value
    /// (sign-extended for signed parameters); it stands for that value in the object's own
    /// size. A value the object's size cannot hold is refused as the parameter's limits
    /// refuse it, never cut to fit.
    fn download_bytes(
        &mut self,
        od: &ObjectDictionary,
        index: u16,
        sub: u8,
        data: &[u8],
        buf: &mut [u8; 8],
    ) -> Option<Result<usize, AbortCode>> {
        if !(PARAMS_FIRST..=PARAMS_LAST).contains(&index) || sub != 1 {
            return None;
        }
        let p = index - PARAMS_FIRST;
        let ty = od
            .locate(index, sub)
            .ok()
            .map(|id| od.sub_object(id).data_type)?;
        let width = ty.fixed_size().filter(|w| (1..=4).contains(w))?;
        Some((|| {
            let v = ParamDb::decode(p, data).map_err(|e| e.abort_code())?;
            // A value an enumeration or a src does not have is "invalid value" before the
            // dictionary's limits would call it too high or too low (§1.4 table).
            if let Err(e @ crate::params::ParamError::Invalid) = self.params.check(p, v) {
                return Err(e.abort_code());
            }
            let bits = 8 * width as u32;
            let signed = matches!(
                ty,
                DataType::Integer8 | DataType::Integer16 | DataType::Integer32
            );
            let (min, max) = if signed {
                (-(1i64 << (bits - 1)), (1i64 << (bits - 1)) - 1)
            } else {
                (0, (1i64 << bits) - 1)
            };
            if !(min..=max).contains(&v) {
                return Err(match self.params.check(p, v) {
                    Err(e) => e.abort_code(),
                    Ok(()) if v > max => AbortCode::VALUE_TOO_HIGH,
                    Ok(()) => AbortCode::VALUE_TOO_LOW,
                });
            }
            buf[..width].copy_from_slice(&v.to_le_bytes()[..width]);
            Ok(width)
        })())
    }

    /// §1.1.6, §1.1.7: the PDOs' transmission types are 1 (with SYNC), 254 and 255
    /// (asynchronous); a TPDO's COB-ID keeps bit 30 set, CiA 301's "no RTR allowed" (the
    /// manual's "= 0 because RTR is not supported" states the meaning, the standard's bit
    /// value says it with 1), so transmission types 252 and 253 (on RTR only) are refused
    /// too. Any other value is 0x06090030 "invalid value".
    fn validate(
        &mut self,
        _od: &ObjectDictionary,
        index: u16,
        sub: u8,
        data: &[u8],
    ) -> Result<(), AbortCode> {
        let pdo = matches!(index, 0x1400..=0x1403 | 0x1800..=0x1803);
        match (pdo, sub, data) {
            (true, 2, [ty]) if !matches!(ty, 1 | 254 | 255) => Err(AbortCode::INVALID_VALUE),
            (true, 1, [_, _, _, b3]) if index >= 0x1800 && b3 & 0x40 == 0 => {
                Err(AbortCode::INVALID_VALUE)
            }
            _ => Ok(()),
        }
    }

    fn written(&mut self, _od: &mut ObjectDictionary, index: u16, _sub: u8) {
        // A parameter or a CiA 402 command object: the drive evaluates its inputs after
        // the event that wrote it.
        if index >= PARAMS_FIRST {
            self.touched = true;
        } else if (0x1800..=0x1BFF).contains(&index) {
            self.remapped = true;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manual_1_3_m2s_mon_parameters_are_their_channels() {
        assert_eq!(m2s_channel(par::m2s_mon(1)), Some(1));
        assert_eq!(m2s_channel(par::m2s_mon(16)), Some(16));
        assert_eq!(m2s_channel(par::m2s_sys(2)), None);
        assert_eq!(m2s_channel(par::m2s_mon(16) + 10), None);
        assert_eq!(m2s_channel(par::DIG_RAMP_REF_1), None);
    }

    #[test]
    fn manual_1_4_the_write_hook_takes_one_to_four_bytes_for_any_parameter() {
        let mut st = Station::default();
        assert_eq!(st.take(par::DIG_RAMP_REF_1, &[0xE8, 0x03, 0, 0]), Ok(()));
        assert_eq!(st.params.value(par::DIG_RAMP_REF_1), 1000);
        assert_eq!(st.take(par::DIG_RAMP_REF_1, &[0xF6, 0xFF]), Ok(()));
        assert_eq!(st.params.value(par::DIG_RAMP_REF_1), -10);
        assert_eq!(st.take(par::ALARM_RESET, &[1]), Ok(()));
        assert_eq!(st.params.value(par::ALARM_RESET), 1);
        assert_eq!(
            st.take(par::DIG_RAMP_REF_1, &[0x41, 0x23]),
            Err(AbortCode::from_u32(0x0609_0031))
        );
        assert_eq!(
            st.take(par::MOTOR_SPEED, &[1, 0]),
            Err(AbortCode::from_u32(0x0601_0002))
        );
        // Process data: the M2S mon takes it, sign-extended, while M->S is enabled.
        st.ms_enable = true;
        assert_eq!(st.take(par::m2s_mon(2), &[0xDC, 0x05]), Ok(()));
        assert_eq!(st.params.value(par::m2s_mon(2)), 1500);
        assert_eq!(st.take(par::m2s_mon(2), &[0xFF, 0xFF]), Ok(()));
        assert_eq!(st.params.value(par::m2s_mon(2)), -1);
    }
}
