//! A generic, table-driven Parameter object (class 0x0F, CIP Vol. 1 §5A-14, "stub"
//! parameter instances): each instance exposes a value with its descriptor, data type and
//! size. A device whose Parameter object has other semantics (the EXP-CAN/DN-ADV card
//! maps instance = drive PAR) serves class 0x0F from [`crate::Application::request`]
//! instead.

use super::{AttrDef, CipError, Reply, attribute_service, get, get_set};
use crate::wire::{Request, status};

/// Class 0x0F.
pub const CLASS: u16 = 0x0F;

/// Descriptor bit 4: the parameter is read-only.
pub const DESCRIPTOR_READ_ONLY: u16 = 0x0010;

/// CIP elementary data type codes (CIP Vol. 1 Appendix C).
pub mod data_type {
    /// BOOL.
    pub const BOOL: u8 = 0xC1;
    /// SINT.
    pub const SINT: u8 = 0xC2;
    /// INT.
    pub const INT: u8 = 0xC3;
    /// DINT.
    pub const DINT: u8 = 0xC4;
    /// USINT.
    pub const USINT: u8 = 0xC6;
    /// UINT.
    pub const UINT: u8 = 0xC7;
    /// UDINT.
    pub const UDINT: u8 = 0xC8;
    /// REAL.
    pub const REAL: u8 = 0xCA;
}

/// One parameter instance.
#[derive(Debug, Clone, PartialEq)]
pub struct Param {
    /// Instance ID (1…).
    pub instance: u16,
    /// Data type code ([`data_type`]).
    pub data_type: u8,
    /// Whether the value can be set.
    pub read_only: bool,
    /// Inclusive limits for integer types, checked on Set.
    pub limits: Option<(i64, i64)>,
    /// The current value, little-endian, [`Param::size`] bytes.
    pub value: Vec<u8>,
}

impl Param {
    /// The value's size in bytes.
    pub fn size(&self) -> usize {
        match self.data_type {
            data_type::BOOL | data_type::SINT | data_type::USINT => 1,
            data_type::INT | data_type::UINT => 2,
            _ => 4,
        }
    }

    fn as_integer(&self, v: &[u8]) -> Option<i64> {
        Some(match (self.data_type, v) {
            (data_type::SINT, [a]) => i64::from(*a as i8),
            (data_type::BOOL | data_type::USINT, [a]) => i64::from(*a),
            (data_type::INT, [a, b]) => i64::from(i16::from_le_bytes([*a, *b])),
            (data_type::UINT, [a, b]) => i64::from(u16::from_le_bytes([*a, *b])),
            (data_type::DINT, [a, b, c, d]) => i64::from(i32::from_le_bytes([*a, *b, *c, *d])),
            (data_type::UDINT, [a, b, c, d]) => i64::from(u32::from_le_bytes([*a, *b, *c, *d])),
            _ => return None,
        })
    }
}

/// The Parameter object: a table of [`Param`]s.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ParameterObject {
    params: Vec<Param>,
}

const INSTANCE_ATTRS: [AttrDef; 6] = [get_set(1), get(2), get(3), get(4), get(5), get(6)];
const CLASS_ATTRS: [AttrDef; 4] = [get(1), get(2), get(8), get(9)];

impl ParameterObject {
    /// A Parameter object over `params`; values shorter or longer than their type are
    /// resized (zero-filled).
    pub fn new(mut params: Vec<Param>) -> Self {
        for p in &mut params {
            let n = p.size();
            p.value.resize(n, 0);
        }
        params.sort_by_key(|p| p.instance);
        ParameterObject { params }
    }

    /// A parameter's current value.
    pub fn value(&self, instance: u16) -> Option<&[u8]> {
        self.param(instance).map(|p| p.value.as_slice())
    }

    fn param(&self, instance: u16) -> Option<&Param> {
        self.params.iter().find(|p| p.instance == instance)
    }

    fn set(&mut self, instance: u16, v: &[u8]) -> Result<Vec<u8>, CipError> {
        let p = self
            .params
            .iter_mut()
            .find(|p| p.instance == instance)
            .ok_or(CipError::new(status::OBJECT_DOES_NOT_EXIST))?;
        super::exact_len(v, p.size())?;
        if p.read_only {
            return Err(CipError::new(status::ATTRIBUTE_NOT_SETTABLE));
        }
        if let (Some((lo, hi)), Some(x)) = (p.limits, p.as_integer(v)) {
            if x < lo || x > hi {
                return Err(CipError::new(status::INVALID_ATTRIBUTE_VALUE));
            }
        }
        p.value = v.to_vec();
        Ok(Vec::new())
    }

    /// Serve a request to class 0x0F.
    pub fn serve(&mut self, req: &Request<'_>) -> Reply {
        if req.instance == 0 {
            let max = self.params.last().map_or(0, |p| p.instance);
            return attribute_service(
                req,
                &CLASS_ATTRS,
                |a| match a {
                    1 => 1u16.to_le_bytes().to_vec(),
                    2 => max.to_le_bytes().to_vec(),
                    // Parameter class descriptor: parameters are supported individually.
                    8 => 0x0001u16.to_le_bytes().to_vec(),
                    _ => 0u16.to_le_bytes().to_vec(),
                },
                |_, _| Err(CipError::new(status::ATTRIBUTE_NOT_SETTABLE)),
            );
        }
        let Some(p) = self.param(req.instance).cloned() else {
            return CipError::new(status::OBJECT_DOES_NOT_EXIST).into();
        };
        let instance = req.instance;
        let table: &[AttrDef] = if p.read_only {
            &[get(1), get(2), get(3), get(4), get(5), get(6)]
        } else {
            &INSTANCE_ATTRS
        };
        attribute_service(
            req,
            table,
            |a| match a {
                1 => p.value.clone(),
                2 => vec![0],
                3 => Vec::new(),
                4 => {
                    let d = if p.read_only { DESCRIPTOR_READ_ONLY } else { 0 };
                    d.to_le_bytes().to_vec()
                }
                5 => vec![p.data_type],
                _ => vec![p.size() as u8],
            },
            |_, v| self.set(instance, v),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::BodyFormat;

    fn obj() -> ParameterObject {
        ParameterObject::new(vec![
            Param {
                instance: 1,
                data_type: data_type::INT,
                read_only: false,
                limits: Some((-100, 100)),
                value: vec![5, 0],
            },
            Param {
                instance: 2,
                data_type: data_type::UDINT,
                read_only: true,
                limits: None,
                value: vec![1, 2, 3, 4],
            },
        ])
    }

    fn call(o: &mut ParameterObject, body: &[u8]) -> Reply {
        o.serve(&Request::decode(body, BodyFormat::F8_8).unwrap())
    }

    #[test]
    fn get_set_with_limits_types_and_access() {
        let mut o = obj();
        assert_eq!(call(&mut o, &[0x0E, 0x0F, 1, 1]), Reply::Data(vec![5, 0]));
        assert_eq!(call(&mut o, &[0x0E, 0x0F, 1, 5]), Reply::Data(vec![0xC3]));
        assert_eq!(call(&mut o, &[0x0E, 0x0F, 1, 6]), Reply::Data(vec![2]));
        assert_eq!(
            call(&mut o, &[0x0E, 0x0F, 2, 4]),
            Reply::Data(vec![0x10, 0])
        );
        assert_eq!(
            call(&mut o, &[0x10, 0x0F, 1, 1, 0x9C, 0xFF]),
            Reply::Data(vec![])
        );
        assert_eq!(o.value(1), Some(&[0x9C, 0xFF][..]));
        let err = |g| Reply::Error(CipError::new(g));
        assert_eq!(call(&mut o, &[0x10, 0x0F, 1, 1, 0x65, 0]), err(0x09));
        assert_eq!(call(&mut o, &[0x10, 0x0F, 1, 1, 0x65]), err(0x13));
        assert_eq!(call(&mut o, &[0x10, 0x0F, 1, 1, 0, 0, 0]), err(0x15));
        assert_eq!(call(&mut o, &[0x10, 0x0F, 2, 1, 0, 0, 0, 0]), err(0x0E));
        assert_eq!(call(&mut o, &[0x10, 0x0F, 1, 5, 0xC4]), err(0x0E));
        assert_eq!(call(&mut o, &[0x0E, 0x0F, 3, 1]), err(0x16));
        assert_eq!(call(&mut o, &[0x0E, 0x0F, 1, 7]), err(0x14));
        assert_eq!(call(&mut o, &[0x05, 0x0F, 1]), err(0x08));
        assert_eq!(call(&mut o, &[0x0E, 0x0F, 0, 2]), Reply::Data(vec![2, 0]));
    }
}
