//! The one way a fieldbus writes a drive parameter, whichever personality carries it: an
//! SDO download or RPDO of the CANopen card (§1.4, §1.3), a Set_Attribute_Single or Drive
//! Parameter Access of the DeviceNet card (§3.4.1, §3.4.2).
//!
//! * the value arrives as 1–4 little-endian bytes, sign-extended for a signed parameter
//!   (§1.4: "a download of 1–4 bytes is accepted for any parameter"), or already decoded
//!   by a typed DeviceNet access;
//! * `Rated current` and `Full scale speed` (the motor data) cannot change while the drive
//!   is enabled (0x08000022, table 3.4.1 code 16);
//! * the access, limits and enumeration of the parameter database apply;
//! * naming `Dig Fieldbus S->Mn` as S2M channel n's `ipa` makes it an MDPLC channel: its
//!   format becomes Mdplc 16 or Mdplc 32 by the width it had (§1.3.3).

use crate::params::{ParamDb, ParamError, par};
use crate::pdc::Format;

/// Writes `v` to parameter `p` from a fieldbus, with the rules of the
/// [module documentation](self).
pub fn write(db: &mut ParamDb, p: u16, v: i64) -> Result<(), ParamError> {
    if matches!(p, par::RATED_CURRENT | par::FULL_SCALE_SPEED) && db.value(par::ENABLE_STATE) != 0 {
        return Err(ParamError::DeviceState);
    }
    db.check(p, v)?;
    if let Some(n) = (1..=crate::params::CHANNELS).find(|n| par::s2m_ipa(*n) == p)
        && v == i64::from(par::s2m_dig(n))
    {
        let f = Format::from_value(db.value(par::s2m_sys(n)));
        let mdplc = if f.bits() == 32 { 7 } else { 6 };
        let _ = db.force(par::s2m_sys(n), mdplc);
    }
    db.set(p, v)
}

/// Decodes 1–4 bytes for parameter `p` ([`ParamDb::decode`]) and writes them ([`write()`]).
pub fn write_bytes(db: &mut ParamDb, p: u16, data: &[u8]) -> Result<(), ParamError> {
    let v = ParamDb::decode(p, data)?;
    write(db, p, v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manual_1_3_3_naming_dig_fieldbus_s2m_makes_the_channel_mdplc() {
        let mut db = ParamDb::new();
        db.set(par::s2m_sys(2), 2).unwrap();
        write(&mut db, par::s2m_ipa(2), i64::from(par::s2m_dig(2))).unwrap();
        assert_eq!(db.value(par::s2m_sys(2)), 7, "Count 32 becomes Mdplc 32");
        write_bytes(&mut db, par::s2m_ipa(1), &par::s2m_dig(1).to_le_bytes()).unwrap();
        assert_eq!(
            db.value(par::s2m_sys(1)),
            6,
            "Not assigned becomes Mdplc 16"
        );
    }

    #[test]
    fn manual_1_4_motor_data_refused_while_enabled() {
        let mut db = ParamDb::new();
        db.force(par::ENABLE_STATE, 1).unwrap();
        assert_eq!(
            write(&mut db, par::FULL_SCALE_SPEED, 1000),
            Err(ParamError::DeviceState)
        );
        assert_eq!(write(&mut db, par::DIG_RAMP_REF_1, 1000), Ok(()));
        assert_eq!(
            write_bytes(&mut db, par::DIG_RAMP_REF_1, &[0x41, 0x23]),
            Err(ParamError::AboveMax)
        );
    }
}
