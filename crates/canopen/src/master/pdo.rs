//! Remote PDO configuration and decoding (CiA 301 §7.4.8, §7.5.2.35–38).
//!
//! A PDO is described by two objects on the node: its communication parameter
//! (RPDO 0x1400 + n − 1, TPDO 0x1800 + n − 1: sub 1 COB-ID, sub 2 transmission type, sub 3
//! inhibit time, sub 5 event timer) and its mapping parameter (RPDO 0x1600 + n − 1, TPDO
//! 0x1A00 + n − 1: sub 0 number of entries, subs 1.. the [`MapEntry`]s).
//!
//! [`Job`] is the sequence of SDO transfers that reads or writes them; the
//! [`super::Master`] runs it ([`super::Master::read_pdo`], [`super::Master::write_pdo`]).
//! Writing follows the CiA 301 §7.4.8.2 procedure for dynamic mapping: invalidate the PDO
//! (COB-ID bit 31), set the transmission parameters, clear the mapping (sub 0 = 0), write
//! the entries, enable the mapping (sub 0 = n), and write the COB-ID back as given.
//! [`decode`] turns a received PDO into named values from the node's object dictionary
//! description.

use std::collections::VecDeque;

use crate::abort::AbortCode;
use crate::od::{OdDescription, Value};
use crate::pdo::{Direction, MAX_PDO_BITS};
use crate::sdo::wire::Mux;

pub use crate::pdo::MapEntry;

/// One PDO of a node.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct PdoRef {
    /// RPDO or TPDO, from the node's point of view.
    pub dir: Direction,
    /// The PDO number, 1..=512.
    pub number: u16,
}

impl PdoRef {
    /// RPDO `number` (1..=512).
    pub const fn rpdo(number: u16) -> Self {
        PdoRef {
            dir: Direction::Rx,
            number,
        }
    }

    /// TPDO `number` (1..=512).
    pub const fn tpdo(number: u16) -> Self {
        PdoRef {
            dir: Direction::Tx,
            number,
        }
    }

    /// The communication parameter object.
    pub const fn comm_index(self) -> u16 {
        let base = match self.dir {
            Direction::Rx => 0x1400,
            Direction::Tx => 0x1800,
        };
        base + (self.number.saturating_sub(1) & 0x1FF)
    }

    /// The mapping parameter object.
    pub const fn map_index(self) -> u16 {
        let base = match self.dir {
            Direction::Rx => 0x1600,
            Direction::Tx => 0x1A00,
        };
        base + (self.number.saturating_sub(1) & 0x1FF)
    }
}

/// A PDO's communication and mapping parameters.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct PdoParams {
    /// Sub 1: COB-ID (bit 31: not valid, bit 30: no RTR, bit 29: 29-bit identifier).
    pub cob_id: u32,
    /// Sub 2: transmission type.
    pub transmission_type: u8,
    /// Sub 3: inhibit time in 100 µs (`None`: not present or not to be written).
    pub inhibit_time: Option<u16>,
    /// Sub 5: event timer in ms (`None`: not present or not to be written).
    pub event_timer: Option<u16>,
    /// The mapping entries, in order.
    pub mapping: Vec<MapEntry>,
}

/// What a PDO job produced.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PdoOutcome {
    /// The parameters read.
    Read(PdoParams),
    /// The parameters were written.
    Written,
}

/// Why a PDO job failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PdoError {
    /// A transfer was aborted.
    #[error("SDO transfer of {index:#06X}sub{sub} aborted: {code:?}")]
    Aborted {
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// Reason.
        code: AbortCode,
    },
    /// A value read has the wrong length or is out of range.
    #[error("unexpected value of {index:#06X}sub{sub}")]
    Malformed {
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
    },
}

/// One SDO transfer of a job.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum JobOp {
    /// Upload of index, sub-index.
    Read(u16, u8),
    /// Download of index, sub-index, data.
    Write(u16, u8, Vec<u8>),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Field {
    CobId,
    Type,
    Inhibit,
    Event,
    Count,
    Entry,
    Write,
}

/// A sequence of SDO transfers that reads or writes one PDO's parameters.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Job {
    pdo: PdoRef,
    reading: bool,
    ops: VecDeque<(JobOp, Field)>,
    current: Option<(u16, u8, Field)>,
    params: PdoParams,
    error: Option<PdoError>,
}

impl Job {
    /// Reads COB-ID, transmission type, inhibit time and event timer (both optional: a
    /// missing sub-index leaves them `None`), the number of entries and each entry.
    pub fn read(pdo: PdoRef) -> Self {
        let c = pdo.comm_index();
        let m = pdo.map_index();
        let ops = [
            (c, 1, Field::CobId),
            (c, 2, Field::Type),
            (c, 3, Field::Inhibit),
            (c, 5, Field::Event),
            (m, 0, Field::Count),
        ]
        .into_iter()
        .map(|(i, s, f)| (JobOp::Read(i, s), f))
        .collect();
        Job {
            pdo,
            reading: true,
            ops,
            current: None,
            params: PdoParams::default(),
            error: None,
        }
    }

    /// Writes `params` with the CiA 301 §7.4.8.2 sequence (see the module documentation).
    pub fn write(pdo: PdoRef, params: &PdoParams) -> Self {
        let c = pdo.comm_index();
        let m = pdo.map_index();
        let mut ops = VecDeque::new();
        let mut w =
            |i: u16, s: u8, d: Vec<u8>| ops.push_back((JobOp::Write(i, s, d), Field::Write));
        w(c, 1, (params.cob_id | 0x8000_0000).to_le_bytes().to_vec());
        w(c, 2, vec![params.transmission_type]);
        if let Some(t) = params.inhibit_time {
            w(c, 3, t.to_le_bytes().to_vec());
        }
        if let Some(t) = params.event_timer {
            w(c, 5, t.to_le_bytes().to_vec());
        }
        w(m, 0, vec![0]);
        for (k, e) in params.mapping.iter().enumerate() {
            // At most 64 entries are written (CiA 301 §7.5.2.36); k < 64 fits a u8.
            let sub = u8::try_from(k + 1).unwrap_or(u8::MAX);
            w(m, sub, e.to_u32().to_le_bytes().to_vec());
        }
        let n = u8::try_from(params.mapping.len()).unwrap_or(u8::MAX);
        w(m, 0, vec![n]);
        w(c, 1, params.cob_id.to_le_bytes().to_vec());
        Job {
            pdo,
            reading: false,
            ops,
            current: None,
            params: params.clone(),
            error: None,
        }
    }

    /// The PDO the job is about.
    pub fn pdo(&self) -> PdoRef {
        self.pdo
    }

    /// The next transfer, or `None` when the job is over.
    pub fn next_op(&mut self) -> Option<JobOp> {
        if self.error.is_some() {
            return None;
        }
        let (op, field) = self.ops.pop_front()?;
        let (i, s) = match &op {
            JobOp::Read(i, s) | JobOp::Write(i, s, _) => (*i, *s),
        };
        self.current = Some((i, s, field));
        Some(op)
    }

    /// The result of the transfer last returned by [`Self::next_op`].
    pub fn on_result(&mut self, result: Result<Vec<u8>, (Mux, AbortCode)>) {
        let Some((index, sub, field)) = self.current.take() else {
            return;
        };
        let data = match result {
            Ok(d) => d,
            // Inhibit time and event timer are optional sub-indices (CiA 301 §7.5.2.35).
            Err((_, AbortCode::NO_SUB_INDEX)) if matches!(field, Field::Inhibit | Field::Event) => {
                return;
            }
            Err((_, code)) => {
                self.error = Some(PdoError::Aborted { index, sub, code });
                return;
            }
        };
        let malformed = PdoError::Malformed { index, sub };
        let le = |n: usize| -> Option<u32> {
            (data.len() == n).then(|| {
                let mut b = [0u8; 4];
                b[..n].copy_from_slice(&data);
                u32::from_le_bytes(b)
            })
        };
        let ok = match field {
            Field::CobId => le(4).map(|v| self.params.cob_id = v),
            Field::Type => le(1).map(|v| self.params.transmission_type = v as u8),
            Field::Inhibit => le(2).map(|v| self.params.inhibit_time = Some(v as u16)),
            Field::Event => le(2).map(|v| self.params.event_timer = Some(v as u16)),
            Field::Count => le(1).filter(|n| *n <= 64).map(|n| {
                let m = self.pdo.map_index();
                for s in 1..=n as u8 {
                    self.ops.push_back((JobOp::Read(m, s), Field::Entry));
                }
            }),
            Field::Entry => le(4).map(|v| self.params.mapping.push(MapEntry::from_u32(v))),
            Field::Write => Some(()),
        };
        if ok.is_none() {
            self.error = Some(malformed);
        }
    }

    /// The outcome, once [`Self::next_op`] has returned `None`.
    pub fn finish(self) -> Result<PdoOutcome, PdoError> {
        match self.error {
            Some(e) => Err(e),
            None if self.reading => Ok(PdoOutcome::Read(self.params)),
            None => Ok(PdoOutcome::Written),
        }
    }
}

/// One value of a decoded PDO.
#[derive(Debug, Clone, PartialEq)]
pub struct PdoValue {
    /// Object.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Its name in the dictionary description.
    pub name: String,
    /// The value.
    pub value: Value,
}

/// Why a PDO could not be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// The frame is shorter than the mapping (CiA 301 §7.2.2.2: EMCY 0x8210 on a device).
    #[error("the PDO carries {have} bits, the mapping needs {need}")]
    TooShort {
        /// Bits the mapping needs.
        need: u32,
        /// Bits the frame carries.
        have: u32,
    },
    /// A mapped object the description does not have.
    #[error("{index:#06X}sub{sub} is not in the dictionary")]
    Unknown {
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
    },
    /// A length that does not fit the mapped object's type.
    #[error("{bits} bits do not fit {index:#06X}sub{sub}")]
    Length {
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// The mapped length.
        bits: u8,
    },
}

/// Reads `bits` bits from bit `pos` of `data`, little-endian (CiA 301 §7.1.2).
fn bits_at(data: &[u8], pos: u32, bits: u32) -> u64 {
    let mut v = 0u64;
    for k in 0..bits {
        let p = pos + k;
        let byte = data.get((p / 8) as usize).copied().unwrap_or(0);
        if byte >> (p % 8) & 1 != 0 {
            v |= 1 << k;
        }
    }
    v
}

/// Decodes a received PDO's `data` with `mapping` into named values of `od`. Dummy
/// entries are skipped; bytes beyond the mapping are ignored (CiA 301 §7.2.2.2).
pub fn decode(
    mapping: &[MapEntry],
    od: &OdDescription,
    data: &[u8],
) -> Result<Vec<PdoValue>, DecodeError> {
    let need: u32 = mapping.iter().map(|e| u32::from(e.bits)).sum();
    let have = u32::try_from(data.len())
        .unwrap_or(u32::MAX)
        .saturating_mul(8)
        .min(MAX_PDO_BITS);
    if need > have {
        return Err(DecodeError::TooShort { need, have });
    }
    let mut pos = 0u32;
    let mut values = Vec::with_capacity(mapping.len());
    for e in mapping {
        let bits = u32::from(e.bits);
        let at = pos;
        pos += bits;
        if e.is_dummy() {
            continue;
        }
        let (index, sub) = (e.index, e.sub);
        let so = od
            .get(index, sub)
            .ok_or(DecodeError::Unknown { index, sub })?;
        let length = DecodeError::Length {
            index,
            sub,
            bits: e.bits,
        };
        let ty = so.data_type;
        let raw = bits_at(data, at, bits).to_le_bytes();
        let value = match ty.fixed_size() {
            // A fixed-size value may be mapped with fewer bits (BOOLEAN as 1 bit).
            Some(size) if bits <= size as u32 * 8 => Value::from_le_bytes(ty, &raw[..size]),
            Some(_) => return Err(length),
            None if bits % 8 == 0 => Value::from_le_bytes(ty, &raw[..(bits / 8) as usize]),
            None => return Err(length),
        }
        .map_err(|_| length)?;
        values.push(PdoValue {
            index,
            sub,
            name: so.name.clone(),
            value,
        });
    }
    Ok(values)
}

/// Decodes the PDOs of several nodes, each by the COB-ID and mapping read from the node
/// (a [`PdoOutcome::Read`]) and the node's dictionary description.
#[derive(Debug, Clone, Default)]
pub struct PdoDecoder {
    pdos: Vec<(u32, Vec<MapEntry>, std::sync::Arc<OdDescription>)>,
}

impl PdoDecoder {
    /// An empty decoder.
    pub fn new() -> Self {
        PdoDecoder::default()
    }

    /// Decodes frames on `params.cob_id` with `params.mapping` and `od` (replacing an earlier
    /// PDO on the same identifier). A PDO whose COB-ID is not valid (bit 31) is not added.
    pub fn add(&mut self, params: &PdoParams, od: std::sync::Arc<OdDescription>) {
        if params.cob_id & 0x8000_0000 != 0 {
            return;
        }
        // Bit 30 (RTR) does not change the identifier; bit 29 marks a 29-bit one.
        let id = params.cob_id & 0x3FFF_FFFF;
        self.pdos.retain(|p| p.0 != id);
        self.pdos.push((id, params.mapping.clone(), od));
    }

    /// The values of `frame` if it is one of the PDOs added (`None` otherwise).
    pub fn decode(&self, frame: &cantwin_can::Frame) -> Option<Result<Vec<PdoValue>, DecodeError>> {
        if frame.is_remote() {
            return None;
        }
        let key = match frame.id() {
            cantwin_can::Id::Standard(s) => u32::from(s.as_raw()),
            cantwin_can::Id::Extended(e) => e.as_raw() | 0x2000_0000,
        };
        let (_, mapping, od) = self.pdos.iter().find(|p| p.0 == key)?;
        Some(decode(mapping, od, frame.data_bytes()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::od::{Access, DataType, OdBuilder, SubObject};

    #[test]
    fn cia301_7_5_2_35_object_indices() {
        assert_eq!(PdoRef::rpdo(1).comm_index(), 0x1400);
        assert_eq!(PdoRef::rpdo(1).map_index(), 0x1600);
        assert_eq!(PdoRef::tpdo(4).comm_index(), 0x1803);
        assert_eq!(PdoRef::tpdo(4).map_index(), 0x1A03);
    }

    #[test]
    fn cia301_7_4_8_2_dynamic_mapping_write_sequence() {
        let params = PdoParams {
            cob_id: 0x185,
            transmission_type: 0xFE,
            inhibit_time: None,
            event_timer: Some(100),
            mapping: vec![
                MapEntry::from_u32(0x6041_0010),
                MapEntry::from_u32(0x6064_0020),
            ],
        };
        let mut job = Job::write(PdoRef::tpdo(1), &params);
        let mut ops = Vec::new();
        while let Some(op) = job.next_op() {
            ops.push(op);
            job.on_result(Ok(vec![]));
        }
        assert_eq!(
            ops,
            [
                JobOp::Write(0x1800, 1, vec![0x85, 0x01, 0, 0x80]),
                JobOp::Write(0x1800, 2, vec![0xFE]),
                JobOp::Write(0x1800, 5, vec![100, 0]),
                JobOp::Write(0x1A00, 0, vec![0]),
                JobOp::Write(0x1A00, 1, vec![0x10, 0, 0x41, 0x60]),
                JobOp::Write(0x1A00, 2, vec![0x20, 0, 0x64, 0x60]),
                JobOp::Write(0x1A00, 0, vec![2]),
                JobOp::Write(0x1800, 1, vec![0x85, 0x01, 0, 0]),
            ]
        );
        assert_eq!(job.finish(), Ok(PdoOutcome::Written));
    }

    #[test]
    fn cia301_7_4_8_2_write_stops_at_the_first_abort() {
        let mut job = Job::write(PdoRef::rpdo(1), &PdoParams::default());
        assert!(job.next_op().is_some());
        job.on_result(Err((Mux::new(0x1400, 1), AbortCode::READ_ONLY)));
        assert_eq!(job.next_op(), None);
        assert_eq!(
            job.finish(),
            Err(PdoError::Aborted {
                index: 0x1400,
                sub: 1,
                code: AbortCode::READ_ONLY
            })
        );
    }

    #[test]
    fn cia301_7_1_2_decode_packs_little_endian_bits() {
        let od = OdBuilder::new()
            .var(
                0x2000,
                SubObject::new("Flag", DataType::Boolean, Access::Rw),
            )
            .var(
                0x2001,
                SubObject::new("Speed", DataType::Integer16, Access::Rw),
            )
            .build()
            .unwrap();
        let mapping = [
            MapEntry::from_u32(0x2000_0001),
            MapEntry::from_u32(0x0001_0007), // dummy: 7 bits
            MapEntry::from_u32(0x2001_0010),
        ];
        let v = decode(&mapping, &od, &[0x01, 0x18, 0xFC]).unwrap();
        assert_eq!(v.len(), 2);
        assert_eq!(
            (v[0].name.as_str(), &v[0].value),
            ("Flag", &Value::Boolean(true))
        );
        assert_eq!(
            (v[1].name.as_str(), &v[1].value),
            ("Speed", &Value::Integer16(-1000))
        );
        assert_eq!(
            decode(&mapping, &od, &[0x01, 0x18]),
            Err(DecodeError::TooShort { need: 24, have: 16 })
        );

        let mut d = PdoDecoder::new();
        let od = std::sync::Arc::new(od);
        let params = PdoParams {
            cob_id: 0x4000_0185,
            mapping: mapping.to_vec(),
            ..PdoParams::default()
        };
        d.add(&params, od.clone());
        d.add(
            &PdoParams {
                cob_id: 0x8000_0186,
                ..params.clone()
            },
            od,
        );
        let f = cantwin_can::Frame::std(0x185, &[0x00, 0xE8, 0x03]).unwrap();
        let v = d.decode(&f).unwrap().unwrap();
        assert_eq!(v[1].value, Value::Integer16(1000));
        assert!(
            d.decode(&cantwin_can::Frame::std(0x186, &[0; 3]).unwrap())
                .is_none()
        );
    }
}
