//! The DeviceNet personality (chapter 3): drive parameters through the Parameter object
//! (class 0x0F, instance = PAR, §3.4.1) and Drive Parameter Access (class 0x66, §3.4.2),
//! and the Process Data Channel as polled I/O (§3.5, §3.8), on the `cantwin-devicenet`
//! slave stack (Predefined Master/Slave Connection Set, UCMM, duplicate MAC ID check).
//!
//! Choices (each pinned by a test in `tests/manual_3_devicenet.rs`):
//!
//! * Parameter object: Get_Attribute_Single (0x0E) of attribute 1 answers 4 bytes (a DWORD,
//!   §3.4.1 "il drive risponde con 4 byte"); Set_Attribute_Single (0x10) takes 1–4 value
//!   bytes; a refused Set is not answered ("nel caso di errore il drive non risponde").
//! * Drive Parameter Access: replies `[Result WORD][value]`, the value as long as the
//!   parameter (2 or 4 bytes); a refused request answers its table 3.4.1 code in Result:
//!   1 no such parameter, 9 above the maximum, 10 below the minimum, 11 value not allowed
//!   (also a wrong length or data type), 12 read-only, 16 not writable while the drive is
//!   enabled. Typed access (0x34/0x35) converts to DB_T_INT 3, DB_T_LONG 4, DB_T_WORD 6,
//!   DB_T_DWORD 7, DB_T_FLOAT 8 (IEEE 754, rounded to the parameter's integer); DB_T_VOID 0
//!   is the parameter's own format.
//! * Polled I/O: the slave consumes the M2S channels and produces the S2M channels, each
//!   16 or 32 bits, little-endian, in channel order (the PDC of §1.3 without the PDO
//!   boundaries). An empty poll (master idle) changes nothing; `Fieldbus M->S enable` Off
//!   ignores the data.
//! * The identity object: vendor 0 (the manual gives no ODVA vendor ID), device type 0x02
//!   (AC drive), product code 4 (the card type code of PAR 534), product name
//!   "ADV200 EXP-CAN/DN-ADV".

use cantwin_can::Instant;
use cantwin_devicenet::wire::{Request, status};
use cantwin_devicenet::{Application, CipError, Identity, Reply, SlaveEvent};

use crate::fieldbus;
use crate::params::{ParamDb, ParamError, ParamType, def, par};
use crate::pdc::{self, Pdc};

/// Table 3.4.2 data types.
pub mod db_t {
    /// The parameter's own format.
    pub const VOID: u8 = 0;
    /// 16-bit signed.
    pub const INT: u8 = 3;
    /// 32-bit signed.
    pub const LONG: u8 = 4;
    /// 16-bit unsigned.
    pub const WORD: u8 = 6;
    /// 32-bit unsigned.
    pub const DWORD: u8 = 7;
    /// IEEE 754 single.
    pub const FLOAT: u8 = 8;
}

/// Table 3.4.1 code of a refused parameter access.
pub const fn error_code(e: ParamError) -> u16 {
    match e {
        ParamError::Missing => 1,
        ParamError::AboveMax => 9,
        ParamError::BelowMin => 10,
        ParamError::Invalid | ParamError::Length => 11,
        ParamError::ReadOnly => 12,
        ParamError::DeviceState => 16,
    }
}

/// Identity attribute 1 by default: the manual gives no ODVA vendor ID and none could be
/// sourced from public vendor lists or Gefran EDS files; the configuration may give one
/// ([`crate::Adv200Config::devicenet_vendor_id`], the scenario option
/// `devicenet_vendor_id`).
pub const VENDOR_ID: u16 = 0;

/// The Identity object (class 0x01) of the card with serial number `serial` and ODVA
/// vendor ID `vendor`.
pub fn identity(serial: u32, vendor: u16) -> Identity {
    Identity {
        vendor,
        device_type: 0x02,
        product_code: 4,
        revision: (1, 0),
        serial,
        product_name: "ADV200 EXP-CAN/DN-ADV".into(),
    }
}

/// The drive as the DeviceNet stack sees it. The parameters are lent to it for the length of
/// each call into the stack.
#[derive(Debug, Default)]
pub struct DnApp {
    pub(crate) params: ParamDb,
    pub(crate) pdc: Pdc,
    pub(crate) ms_enable: bool,
    pub(crate) events: Vec<SlaveEvent>,
}

fn native(ty: ParamType) -> u8 {
    match ty {
        ParamType::I16 => db_t::INT,
        ParamType::I32 => db_t::LONG,
        ParamType::U32 => db_t::DWORD,
        _ => db_t::WORD,
    }
}

fn encode(v: i64, t: u8) -> Option<Vec<u8>> {
    Some(match t {
        db_t::INT | db_t::WORD => (v as u16).to_le_bytes().to_vec(),
        db_t::LONG | db_t::DWORD => (v as u32).to_le_bytes().to_vec(),
        db_t::FLOAT => (v as f32).to_le_bytes().to_vec(),
        _ => return None,
    })
}

fn decode(data: &[u8], t: u8) -> Option<i64> {
    Some(match (t, data) {
        (db_t::INT, [a, b]) => i64::from(i16::from_le_bytes([*a, *b])),
        (db_t::WORD, [a, b]) => i64::from(u16::from_le_bytes([*a, *b])),
        (db_t::LONG, [a, b, c, d]) => i64::from(i32::from_le_bytes([*a, *b, *c, *d])),
        (db_t::DWORD, [a, b, c, d]) => i64::from(u32::from_le_bytes([*a, *b, *c, *d])),
        (db_t::FLOAT, [a, b, c, d]) => {
            let f = f32::from_le_bytes([*a, *b, *c, *d]);
            if !f.is_finite() {
                return None;
            }
            f.round() as i64
        }
        _ => return None,
    })
}

impl DnApp {
    fn write(&mut self, p: u16, v: i64) -> Result<(), ParamError> {
        fieldbus::write(&mut self.params, p, v)
    }

    fn parameter_object(&mut self, req: &Request<'_>) -> Reply {
        use cantwin_devicenet::wire::service::{GET_ATTRIBUTE_SINGLE, SET_ATTRIBUTE_SINGLE};
        if req.instance == 0 {
            return match (req.service, req.data) {
                (GET_ATTRIBUTE_SINGLE, [1]) => Reply::Data(1u16.to_le_bytes().to_vec()),
                (GET_ATTRIBUTE_SINGLE, _) => CipError::new(status::ATTRIBUTE_NOT_SUPPORTED).into(),
                _ => CipError::new(status::SERVICE_NOT_SUPPORTED).into(),
            };
        }
        let p = req.instance;
        match req.service {
            GET_ATTRIBUTE_SINGLE => match (req.data, self.params.get(p)) {
                ([1], Ok(v)) => Reply::Data((v as u32).to_le_bytes().to_vec()),
                ([1], Err(_)) => CipError::new(status::OBJECT_DOES_NOT_EXIST).into(),
                _ => CipError::new(status::ATTRIBUTE_NOT_SUPPORTED).into(),
            },
            SET_ATTRIBUTE_SINGLE => {
                let Some((&1, value)) = req.data.split_first() else {
                    return Reply::Silent;
                };
                match fieldbus::write_bytes(&mut self.params, p, value) {
                    Ok(()) => Reply::Data(Vec::new()),
                    Err(_) => Reply::Silent,
                }
            }
            _ => CipError::new(status::SERVICE_NOT_SUPPORTED).into(),
        }
    }

    fn drive_parameter_access(&mut self, req: &Request<'_>) -> Reply {
        let result = |e: Result<(), ParamError>| {
            let code = e.err().map_or(0, error_code);
            Reply::Data(code.to_le_bytes().to_vec())
        };
        let value = |v: Vec<u8>| {
            let mut d = vec![0, 0];
            d.extend(v);
            Reply::Data(d)
        };
        if req.instance == 0 {
            return match (req.service, req.data) {
                (0x0E, [1]) => Reply::Data(1u16.to_le_bytes().to_vec()),
                _ => CipError::new(status::SERVICE_NOT_SUPPORTED).into(),
            };
        }
        let p = req.instance;
        let Some(d) = def(p) else {
            return match req.service {
                0x32..=0x35 => result(Err(ParamError::Missing)),
                _ => CipError::new(status::SERVICE_NOT_SUPPORTED).into(),
            };
        };
        let own = native(d.ty);
        let v = self.params.value(p);
        match req.service {
            0x32 if req.data.is_empty() => value(encode(v, own).unwrap_or_default()),
            0x32 => CipError::new(status::TOO_MUCH_DATA).into(),
            0x33 => result(fieldbus::write_bytes(&mut self.params, p, req.data)),
            0x34 => match req.data {
                [t] => {
                    let t = if *t == db_t::VOID { own } else { *t };
                    match encode(v, t) {
                        Some(bytes) => value(bytes),
                        None => result(Err(ParamError::Invalid)),
                    }
                }
                _ => result(Err(ParamError::Invalid)),
            },
            0x35 => {
                let Some((&t, data)) = req.data.split_first() else {
                    return result(Err(ParamError::Invalid));
                };
                let t = if t == db_t::VOID { own } else { t };
                match decode(data, t) {
                    Some(v) => result(self.write(p, v)),
                    None => result(Err(ParamError::Invalid)),
                }
            }
            _ => CipError::new(status::SERVICE_NOT_SUPPORTED).into(),
        }
    }
}

impl Application for DnApp {
    fn poll_sizes(&self) -> (u16, u16) {
        let bytes = |l: &pdc::Layout| l.items().map(|i| u16::from(i.bits) / 8).sum::<u16>();
        (bytes(&self.pdc.s2m), bytes(&self.pdc.m2s))
    }

    fn produce(&mut self, _now: Instant) -> Vec<u8> {
        let mut out = Vec::new();
        for item in self.pdc.s2m.items() {
            let v = pdc::s2m_value(&self.params, item.channel);
            let _ = self.params.force(par::s2m_mon(item.channel), v);
            let b = (v as u32).to_le_bytes();
            out.extend_from_slice(&b[..usize::from(item.bits / 8)]);
        }
        out
    }

    fn consume(&mut self, data: &[u8], _now: Instant) {
        if data.is_empty() || !self.ms_enable {
            return;
        }
        let mut at = 0;
        for item in self.pdc.m2s.items() {
            let n = usize::from(item.bits / 8);
            let Some(bytes) = data.get(at..at + n) else {
                return;
            };
            at += n;
            let v = if n == 2 {
                i64::from(i16::from_le_bytes([bytes[0], bytes[1]]))
            } else {
                i64::from(i32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]))
            };
            let _ = self.params.force(par::m2s_mon(item.channel), v);
        }
    }

    fn request(&mut self, req: &Request<'_>, _now: Instant) -> Option<Reply> {
        match req.class {
            0x0F => Some(self.parameter_object(req)),
            0x66 => Some(self.drive_parameter_access(req)),
            _ => None,
        }
    }

    fn event(&mut self, event: SlaveEvent, _now: Instant) {
        self.events.push(event);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_devicenet::wire::service::{GET_ATTRIBUTE_SINGLE, SET_ATTRIBUTE_SINGLE};

    fn app() -> DnApp {
        DnApp {
            params: ParamDb::new(),
            ms_enable: true,
            ..DnApp::default()
        }
    }

    fn req(app: &mut DnApp, service: u8, class: u16, instance: u16, data: &[u8]) -> Option<Reply> {
        let r = Request {
            service,
            class,
            instance,
            data,
        };
        app.request(&r, Instant::ZERO)
    }

    #[test]
    fn manual_3_4_1_parameter_object_instance_is_the_par() {
        let mut a = app();
        // Set PAR 600 = 1000 with a 2-byte value (INT), then Get answers a DWORD.
        let set = req(&mut a, SET_ATTRIBUTE_SINGLE, 0x0F, 600, &[1, 0xE8, 0x03]);
        assert_eq!(set, Some(Reply::Data(vec![])));
        let get = req(&mut a, GET_ATTRIBUTE_SINGLE, 0x0F, 600, &[1]);
        assert_eq!(get, Some(Reply::Data(vec![0xE8, 0x03, 0, 0])));
        // A refused Set is not answered (read-only Motor speed; above the maximum).
        assert_eq!(
            req(&mut a, SET_ATTRIBUTE_SINGLE, 0x0F, 260, &[1, 1, 0]),
            Some(Reply::Silent)
        );
        assert_eq!(
            req(&mut a, SET_ATTRIBUTE_SINGLE, 0x0F, 600, &[1, 0x41, 0x23]),
            Some(Reply::Silent)
        );
        assert_eq!(
            req(&mut a, GET_ATTRIBUTE_SINGLE, 0x0F, 1, &[1]),
            Some(Reply::Error(CipError::new(status::OBJECT_DOES_NOT_EXIST)))
        );
        // Class attribute 1: revision 1.
        assert_eq!(
            req(&mut a, GET_ATTRIBUTE_SINGLE, 0x0F, 0, &[1]),
            Some(Reply::Data(vec![1, 0]))
        );
        // Other classes go to the stack.
        assert_eq!(req(&mut a, GET_ATTRIBUTE_SINGLE, 0x01, 1, &[1]), None);
    }

    #[test]
    fn manual_3_4_2_drive_parameter_access_and_table_3_4_1_codes() {
        let mut a = app();
        assert_eq!(
            req(&mut a, 0x33, 0x66, 600, &[0xE8, 0x03]),
            Some(Reply::Data(vec![0, 0]))
        );
        assert_eq!(
            req(&mut a, 0x32, 0x66, 600, &[]),
            Some(Reply::Data(vec![0, 0, 0xE8, 0x03]))
        );
        // A 32-bit parameter answers 4 value bytes.
        assert_eq!(
            req(&mut a, 0x32, 0x66, 4184, &[]),
            Some(Reply::Data(vec![0, 0, 0, 0, 0, 0]))
        );
        let code = |c: u16| Some(Reply::Data(c.to_le_bytes().to_vec()));
        assert_eq!(req(&mut a, 0x32, 0x66, 1, &[]), code(1));
        assert_eq!(req(&mut a, 0x33, 0x66, 600, &[0x41, 0x23]), code(9));
        assert_eq!(req(&mut a, 0x33, 0x66, 600, &[0xBF, 0xDC]), code(10));
        assert_eq!(req(&mut a, 0x33, 0x66, 610, &[3, 0]), code(11));
        assert_eq!(req(&mut a, 0x33, 0x66, 260, &[1, 0]), code(12));
        a.params.force(par::ENABLE_STATE, 1).unwrap();
        assert_eq!(req(&mut a, 0x33, 0x66, 680, &[0xDC, 0x05]), code(16));
        // Typed access: DB_T_LONG read of a 16-bit parameter, DB_T_FLOAT write.
        assert_eq!(
            req(&mut a, 0x34, 0x66, 600, &[db_t::LONG]),
            Some(Reply::Data(vec![0, 0, 0xE8, 0x03, 0, 0]))
        );
        let f = 250.4f32.to_le_bytes();
        assert_eq!(
            req(
                &mut a,
                0x35,
                0x66,
                600,
                &[db_t::FLOAT, f[0], f[1], f[2], f[3]]
            ),
            code(0)
        );
        assert_eq!(a.params.value(600), 250);
        assert_eq!(
            req(&mut a, 0x35, 0x66, 600, &[db_t::VOID, 0x10, 0x00]),
            code(0)
        );
        assert_eq!(a.params.value(600), 16);
        assert_eq!(req(&mut a, 0x35, 0x66, 600, &[db_t::INT, 0x10]), code(11));
        assert_eq!(req(&mut a, 0x34, 0x66, 600, &[9]), code(11));
    }

    #[test]
    fn manual_3_4_2_enumeration_values_outside_the_list_are_code_11() {
        let mut a = app();
        let code = |c: u16| Some(Reply::Data(c.to_le_bytes().to_vec()));
        // PAR 4000 = 9, PAR 4004 = 7: "valore non ammesso" (11), not "maximum exceeded".
        assert_eq!(req(&mut a, 0x33, 0x66, 4000, &[9, 0]), code(11));
        assert_eq!(req(&mut a, 0x33, 0x66, 4004, &[7, 0]), code(11));
        // PAR 4006 above 127 (§1.2): maximum exceeded.
        assert_eq!(req(&mut a, 0x33, 0x66, 4006, &[200, 0]), code(9));
        assert_eq!(req(&mut a, 0x33, 0x66, 4006, &[63, 0]), code(0));
    }
}
