//! LSS frames (CiA 305 §4): the master's requests on 0x7E5 and the slaves' answers on
//! 0x7E4, decoded into typed messages and encoded back. Stateless.
//!
//! Every LSS frame carries 8 data bytes: byte 0 is the command specifier, 32-bit values
//! are little-endian in bytes 1–4 and unused bytes are 0 (CiA 305 §4.2). A frame with
//! another length is not an LSS message.

use cantwin_can::{BitRate, Frame, Id};

/// The identifier of the master's requests (CiA 305 §4.2: "LSS master message").
pub const MASTER_ID: u16 = 0x7E5;
/// The identifier of the slaves' answers (CiA 305 §4.2: "LSS slave message").
pub const SLAVE_ID: u16 = 0x7E4;

/// The node-ID of a node that has none (CiA 305 §3.3: "not configured").
pub const UNCONFIGURED: u8 = 0xFF;

/// Command specifiers (CiA 305 §4.3 to §4.8).
pub mod cs {
    /// Switch state global (§4.3.1).
    pub const SWITCH_GLOBAL: u8 = 0x04;
    /// Configure node-ID (§4.4.1).
    pub const CONFIGURE_NODE_ID: u8 = 0x11;
    /// Configure bit timing parameters (§4.4.2).
    pub const CONFIGURE_BIT_TIMING: u8 = 0x13;
    /// Activate bit timing parameters (§4.4.3).
    pub const ACTIVATE_BIT_TIMING: u8 = 0x15;
    /// Store configuration (§4.4.4).
    pub const STORE_CONFIGURATION: u8 = 0x17;
    /// Switch state selective, vendor-ID (§4.3.2); 0x41–0x43 follow for the other parts.
    pub const SWITCH_SELECTIVE_VENDOR: u8 = 0x40;
    /// Switch state selective, serial number: the last request of the sequence.
    pub const SWITCH_SELECTIVE_SERIAL: u8 = 0x43;
    /// The answer to a complete switch state selective sequence.
    pub const SWITCH_SELECTIVE_RESPONSE: u8 = 0x44;
    /// Identify remote slave, vendor-ID (§4.6.1); 0x47–0x4B follow.
    pub const IDENTIFY_REMOTE_VENDOR: u8 = 0x46;
    /// Identify remote slave, serial number high: the last request of the sequence.
    pub const IDENTIFY_REMOTE_SERIAL_HIGH: u8 = 0x4B;
    /// Identify non-configured remote slave (§4.6.3).
    pub const IDENTIFY_NON_CONFIGURED: u8 = 0x4C;
    /// Identify slave: the answer to identify remote slave and fastscan.
    pub const IDENTIFY_SLAVE: u8 = 0x4F;
    /// Identify non-configured slave: the answer to 0x4C.
    pub const NON_CONFIGURED_SLAVE: u8 = 0x50;
    /// Fastscan (§4.7).
    pub const FASTSCAN: u8 = 0x51;
    /// Inquire identity vendor-ID (§4.5.1); 0x5B–0x5D follow.
    pub const INQUIRE_VENDOR: u8 = 0x5A;
    /// Inquire identity serial number.
    pub const INQUIRE_SERIAL: u8 = 0x5D;
    /// Inquire node-ID (§4.5.2).
    pub const INQUIRE_NODE_ID: u8 = 0x5E;
}

/// The fastscan `BitCheck` that restarts a scan (CiA 305 §4.7: all non-configured slaves
/// answer and go back to the vendor-ID).
pub const FASTSCAN_CONFIRM: u8 = 0x80;

/// The LSS state of a slave (CiA 305 §3.4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mode {
    /// LSS waiting: only the switch and identification services are answered.
    Waiting,
    /// LSS configuration: node-ID and bit timing may be configured and inquired.
    Configuration,
}

/// One of the four parts of an LSS address (CiA 305 §3.2, object 0x1018 sub 1–4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Part {
    /// Vendor-ID, 0x1018 sub 1.
    Vendor,
    /// Product code, 0x1018 sub 2.
    Product,
    /// Revision number, 0x1018 sub 3.
    Revision,
    /// Serial number, 0x1018 sub 4.
    Serial,
}

impl Part {
    /// The parts in address order.
    pub const ALL: [Part; 4] = [Part::Vendor, Part::Product, Part::Revision, Part::Serial];

    /// The part's position: 0 vendor … 3 serial (the fastscan `LSSSub`).
    pub const fn position(self) -> u8 {
        match self {
            Part::Vendor => 0,
            Part::Product => 1,
            Part::Revision => 2,
            Part::Serial => 3,
        }
    }

    /// The part at `position` 0–3.
    pub const fn at(position: u8) -> Option<Part> {
        match position {
            0 => Some(Part::Vendor),
            1 => Some(Part::Product),
            2 => Some(Part::Revision),
            3 => Some(Part::Serial),
            _ => None,
        }
    }
}

/// An LSS address: the identity object 0x1018 sub 1–4 (CiA 305 §3.2).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct Address {
    /// Vendor-ID.
    pub vendor: u32,
    /// Product code.
    pub product: u32,
    /// Revision number.
    pub revision: u32,
    /// Serial number.
    pub serial: u32,
}

impl Address {
    /// The value of `part`.
    pub const fn part(&self, part: Part) -> u32 {
        match part {
            Part::Vendor => self.vendor,
            Part::Product => self.product,
            Part::Revision => self.revision,
            Part::Serial => self.serial,
        }
    }

    /// Sets `part` to `value`.
    pub fn set_part(&mut self, part: Part, value: u32) {
        match part {
            Part::Vendor => self.vendor = value,
            Part::Product => self.product = value,
            Part::Revision => self.revision = value,
            Part::Serial => self.serial = value,
        }
    }
}

/// One request of identify remote slave (CiA 305 §4.6.1): the vendor-ID and product code
/// must match, the revision and serial number lie in inclusive bounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum IdentifyField {
    /// 0x46: vendor-ID.
    Vendor,
    /// 0x47: product code.
    Product,
    /// 0x48: revision number, low bound.
    RevisionLow,
    /// 0x49: revision number, high bound.
    RevisionHigh,
    /// 0x4A: serial number, low bound.
    SerialLow,
    /// 0x4B: serial number, high bound.
    SerialHigh,
}

impl IdentifyField {
    /// The fields in the order the master sends them.
    pub const ALL: [IdentifyField; 6] = [
        IdentifyField::Vendor,
        IdentifyField::Product,
        IdentifyField::RevisionLow,
        IdentifyField::RevisionHigh,
        IdentifyField::SerialLow,
        IdentifyField::SerialHigh,
    ];

    /// The position in the sequence, 0–5 (the command specifier minus 0x46).
    pub const fn position(self) -> u8 {
        match self {
            IdentifyField::Vendor => 0,
            IdentifyField::Product => 1,
            IdentifyField::RevisionLow => 2,
            IdentifyField::RevisionHigh => 3,
            IdentifyField::SerialLow => 4,
            IdentifyField::SerialHigh => 5,
        }
    }
}

/// A request of the LSS master (on [`MASTER_ID`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Request {
    /// 0x04: every slave to `mode` (CiA 305 §4.3.1). No answer.
    SwitchGlobal(Mode),
    /// 0x40–0x43: one part of the address of the slave to switch to configuration
    /// (§4.3.2); the slave whose four parts matched in order answers 0x44.
    SwitchSelective(Part, u32),
    /// 0x11: the pending node-ID, 1–127 or 0xFF (§4.4.1).
    ConfigureNodeId(u8),
    /// 0x13: the pending bit timing, table selector and table index (§4.4.2).
    ConfigureBitTiming {
        /// 0: the CiA 301 table ([`bit_rate_of`]); 1–127 reserved; 128–255 manufacturer.
        table: u8,
        /// The entry of the table.
        index: u8,
    },
    /// 0x15: switch to the pending bit timing after `delay_ms`, and stay silent for
    /// another `delay_ms` (§4.4.3). No answer.
    ActivateBitTiming {
        /// The switch delay in milliseconds.
        delay_ms: u16,
    },
    /// 0x17: store the pending node-ID and bit timing (§4.4.4).
    StoreConfiguration,
    /// 0x46–0x4B: one field of identify remote slave (§4.6.1).
    IdentifyRemote(IdentifyField, u32),
    /// 0x4C: every non-configured slave answers 0x50 (§4.6.3).
    IdentifyNonConfigured,
    /// 0x51: one step of a fastscan (§4.7).
    Fastscan {
        /// The bits of the address part found so far.
        id_number: u32,
        /// The lowest bit compared, 0–31, or [`FASTSCAN_CONFIRM`].
        bit_check: u8,
        /// The address part compared, 0–3.
        sub: u8,
        /// The address part a matching slave compares next, 0–3.
        next: u8,
    },
    /// 0x5A–0x5D: the slave in configuration answers with this part of its address
    /// (§4.5.1).
    Inquire(Part),
    /// 0x5E: the slave in configuration answers with its node-ID (§4.5.2).
    InquireNodeId,
}

/// An answer of an LSS slave (on [`SLAVE_ID`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Response {
    /// 0x44: switch state selective done, the slave is in configuration.
    SwitchSelective,
    /// 0x11: configure node-ID; error 0 success, 1 out of range, 0xFF manufacturer (then
    /// `spec` says which).
    ConfigureNodeId {
        /// The error code.
        error: u8,
        /// The manufacturer-specific error, when `error` is 0xFF.
        spec: u8,
    },
    /// 0x13: configure bit timing; error 0 success, 1 not supported, 0xFF manufacturer.
    ConfigureBitTiming {
        /// The error code.
        error: u8,
        /// The manufacturer-specific error, when `error` is 0xFF.
        spec: u8,
    },
    /// 0x17: store configuration; error 0 success, 1 not supported, 2 storage media
    /// access error, 0xFF manufacturer.
    StoreConfiguration {
        /// The error code.
        error: u8,
        /// The manufacturer-specific error, when `error` is 0xFF.
        spec: u8,
    },
    /// 0x4F: identify slave (the answer to identify remote slave and to fastscan).
    IdentifySlave,
    /// 0x50: identify non-configured slave.
    NonConfiguredSlave,
    /// 0x5A–0x5D: a part of the slave's address.
    Address(Part, u32),
    /// 0x5E: the slave's node-ID, 0xFF when it has none.
    NodeId(u8),
}

/// Why a frame is not an LSS message of the expected direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// Another identifier, an extended or a remote frame.
    #[error("not an LSS frame of this direction")]
    NotLss,
    /// LSS frames carry 8 data bytes (CiA 305 §4.2).
    #[error("LSS frames carry 8 data bytes, not {0}")]
    Length(usize),
    /// A command specifier this direction does not know.
    #[error("unknown LSS command specifier {0:#04X}")]
    Command(u8),
    /// A field outside its range (a switch mode other than 0 or 1, a fastscan position
    /// above 3 or a bit check above 31 other than 0x80).
    #[error("LSS command {0:#04X} with a field out of range")]
    Field(u8),
}

fn u32_at(d: &[u8]) -> u32 {
    u32::from_le_bytes([d[1], d[2], d[3], d[4]])
}

/// The 8 data bytes of an LSS frame with `cs` and `payload` after it.
fn frame(id: u16, cs: u8, payload: &[u8]) -> Frame {
    let mut d = [0u8; 8];
    d[0] = cs;
    d[1..1 + payload.len()].copy_from_slice(payload);
    let Ok(id) = Id::standard(id) else {
        unreachable!("0x7E4 and 0x7E5 are standard identifiers")
    };
    Frame::data_array(id, d)
}

/// The data bytes of `f` if it is an 8-byte data frame on standard identifier `id`.
fn bytes_of(f: &Frame, id: u16) -> Result<&[u8], DecodeError> {
    if f.is_remote() || f.is_extended() || f.id().as_raw() != u32::from(id) {
        return Err(DecodeError::NotLss);
    }
    let d = f.data_bytes();
    if d.len() != 8 {
        return Err(DecodeError::Length(d.len()));
    }
    Ok(d)
}

impl Request {
    /// Decodes a master request.
    pub fn decode(f: &Frame) -> Result<Request, DecodeError> {
        let d = bytes_of(f, MASTER_ID)?;
        let c = d[0];
        Ok(match c {
            cs::SWITCH_GLOBAL => match d[1] {
                0 => Request::SwitchGlobal(Mode::Waiting),
                1 => Request::SwitchGlobal(Mode::Configuration),
                _ => return Err(DecodeError::Field(c)),
            },
            0x40..=0x43 => match Part::at(c - 0x40) {
                Some(p) => Request::SwitchSelective(p, u32_at(d)),
                None => return Err(DecodeError::Command(c)),
            },
            cs::CONFIGURE_NODE_ID => Request::ConfigureNodeId(d[1]),
            cs::CONFIGURE_BIT_TIMING => Request::ConfigureBitTiming {
                table: d[1],
                index: d[2],
            },
            cs::ACTIVATE_BIT_TIMING => Request::ActivateBitTiming {
                delay_ms: u16::from_le_bytes([d[1], d[2]]),
            },
            cs::STORE_CONFIGURATION => Request::StoreConfiguration,
            0x46..=0x4B => {
                let field = IdentifyField::ALL[usize::from(c - 0x46)];
                Request::IdentifyRemote(field, u32_at(d))
            }
            cs::IDENTIFY_NON_CONFIGURED => Request::IdentifyNonConfigured,
            cs::FASTSCAN => {
                let (bit_check, sub, next) = (d[5], d[6], d[7]);
                if (bit_check > 31 && bit_check != FASTSCAN_CONFIRM) || sub > 3 || next > 3 {
                    return Err(DecodeError::Field(c));
                }
                Request::Fastscan {
                    id_number: u32_at(d),
                    bit_check,
                    sub,
                    next,
                }
            }
            0x5A..=0x5D => match Part::at(c - 0x5A) {
                Some(p) => Request::Inquire(p),
                None => return Err(DecodeError::Command(c)),
            },
            cs::INQUIRE_NODE_ID => Request::InquireNodeId,
            _ => return Err(DecodeError::Command(c)),
        })
    }

    /// The request's frame.
    pub fn encode(&self) -> Frame {
        let id = MASTER_ID;
        match *self {
            Request::SwitchGlobal(m) => {
                frame(id, cs::SWITCH_GLOBAL, &[u8::from(m == Mode::Configuration)])
            }
            Request::SwitchSelective(p, v) => frame(id, 0x40 + p.position(), &v.to_le_bytes()),
            Request::ConfigureNodeId(n) => frame(id, cs::CONFIGURE_NODE_ID, &[n]),
            Request::ConfigureBitTiming { table, index } => {
                frame(id, cs::CONFIGURE_BIT_TIMING, &[table, index])
            }
            Request::ActivateBitTiming { delay_ms } => {
                frame(id, cs::ACTIVATE_BIT_TIMING, &delay_ms.to_le_bytes())
            }
            Request::StoreConfiguration => frame(id, cs::STORE_CONFIGURATION, &[]),
            Request::IdentifyRemote(f, v) => frame(id, 0x46 + f.position(), &v.to_le_bytes()),
            Request::IdentifyNonConfigured => frame(id, cs::IDENTIFY_NON_CONFIGURED, &[]),
            Request::Fastscan {
                id_number,
                bit_check,
                sub,
                next,
            } => {
                let v = id_number.to_le_bytes();
                frame(
                    id,
                    cs::FASTSCAN,
                    &[v[0], v[1], v[2], v[3], bit_check, sub, next],
                )
            }
            Request::Inquire(p) => frame(id, 0x5A + p.position(), &[]),
            Request::InquireNodeId => frame(id, cs::INQUIRE_NODE_ID, &[]),
        }
    }
}

impl Response {
    /// Decodes a slave answer.
    pub fn decode(f: &Frame) -> Result<Response, DecodeError> {
        let d = bytes_of(f, SLAVE_ID)?;
        let c = d[0];
        Ok(match c {
            cs::SWITCH_SELECTIVE_RESPONSE => Response::SwitchSelective,
            cs::CONFIGURE_NODE_ID => Response::ConfigureNodeId {
                error: d[1],
                spec: d[2],
            },
            cs::CONFIGURE_BIT_TIMING => Response::ConfigureBitTiming {
                error: d[1],
                spec: d[2],
            },
            cs::STORE_CONFIGURATION => Response::StoreConfiguration {
                error: d[1],
                spec: d[2],
            },
            cs::IDENTIFY_SLAVE => Response::IdentifySlave,
            cs::NON_CONFIGURED_SLAVE => Response::NonConfiguredSlave,
            0x5A..=0x5D => match Part::at(c - 0x5A) {
                Some(p) => Response::Address(p, u32_at(d)),
                None => return Err(DecodeError::Command(c)),
            },
            cs::INQUIRE_NODE_ID => Response::NodeId(d[1]),
            _ => return Err(DecodeError::Command(c)),
        })
    }

    /// The answer's frame.
    pub fn encode(&self) -> Frame {
        let id = SLAVE_ID;
        match *self {
            Response::SwitchSelective => frame(id, cs::SWITCH_SELECTIVE_RESPONSE, &[]),
            Response::ConfigureNodeId { error, spec } => {
                frame(id, cs::CONFIGURE_NODE_ID, &[error, spec])
            }
            Response::ConfigureBitTiming { error, spec } => {
                frame(id, cs::CONFIGURE_BIT_TIMING, &[error, spec])
            }
            Response::StoreConfiguration { error, spec } => {
                frame(id, cs::STORE_CONFIGURATION, &[error, spec])
            }
            Response::IdentifySlave => frame(id, cs::IDENTIFY_SLAVE, &[]),
            Response::NonConfiguredSlave => frame(id, cs::NON_CONFIGURED_SLAVE, &[]),
            Response::Address(p, v) => frame(id, 0x5A + p.position(), &v.to_le_bytes()),
            Response::NodeId(n) => frame(id, cs::INQUIRE_NODE_ID, &[n]),
        }
    }
}

/// The bit rate of entry `index` of the CiA 301 bit timing table (table selector 0, CiA
/// 305 §4.4.2 table 4): 0 1 Mbit/s, 1 800 k, 2 500 k, 3 250 k, 4 125 k, 5 reserved, 6 50 k,
/// 7 20 k, 8 10 k, 9 automatic bit rate detection (no fixed rate, so `None` here too).
pub const fn bit_rate_of(index: u8) -> Option<BitRate> {
    match index {
        0 => Some(BitRate::R1M),
        1 => Some(BitRate::R800K),
        2 => Some(BitRate::R500K),
        3 => Some(BitRate::R250K),
        4 => Some(BitRate::R125K),
        6 => Some(BitRate::R50K),
        7 => Some(BitRate::R20K),
        8 => Some(BitRate::R10K),
        _ => None,
    }
}

/// The entry of the CiA 301 bit timing table for `rate`; 100 kbit/s has none (index 5 is
/// reserved).
pub fn table_index_of(rate: BitRate) -> Option<u8> {
    (0..=8).find(|i| bit_rate_of(*i) == Some(rate))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bytes(f: &Frame) -> (u32, Vec<u8>) {
        (f.id().as_raw(), f.data_bytes().to_vec())
    }

    /// Each request as python-canopen and CANopenNode put it on the wire, and back.
    #[test]
    fn cia305_4_requests_on_the_wire() {
        let cases: &[(Request, [u8; 8])] = &[
            (
                Request::SwitchGlobal(Mode::Configuration),
                [0x04, 1, 0, 0, 0, 0, 0, 0],
            ),
            (
                Request::SwitchGlobal(Mode::Waiting),
                [0x04, 0, 0, 0, 0, 0, 0, 0],
            ),
            (
                Request::SwitchSelective(Part::Vendor, 0x1234_5678),
                [0x40, 0x78, 0x56, 0x34, 0x12, 0, 0, 0],
            ),
            (
                Request::SwitchSelective(Part::Serial, 1),
                [0x43, 1, 0, 0, 0, 0, 0, 0],
            ),
            (
                Request::ConfigureNodeId(0x2A),
                [0x11, 0x2A, 0, 0, 0, 0, 0, 0],
            ),
            (
                Request::ConfigureBitTiming { table: 0, index: 3 },
                [0x13, 0, 3, 0, 0, 0, 0, 0],
            ),
            (
                Request::ActivateBitTiming { delay_ms: 0x0102 },
                [0x15, 0x02, 0x01, 0, 0, 0, 0, 0],
            ),
            (Request::StoreConfiguration, [0x17, 0, 0, 0, 0, 0, 0, 0]),
            (
                Request::IdentifyRemote(IdentifyField::SerialHigh, 0xFF),
                [0x4B, 0xFF, 0, 0, 0, 0, 0, 0],
            ),
            (Request::IdentifyNonConfigured, [0x4C, 0, 0, 0, 0, 0, 0, 0]),
            (
                Request::Fastscan {
                    id_number: 0x8000_0000,
                    bit_check: 31,
                    sub: 2,
                    next: 3,
                },
                [0x51, 0, 0, 0, 0x80, 31, 2, 3],
            ),
            (
                Request::Inquire(Part::Revision),
                [0x5C, 0, 0, 0, 0, 0, 0, 0],
            ),
            (Request::InquireNodeId, [0x5E, 0, 0, 0, 0, 0, 0, 0]),
        ];
        for (req, data) in cases {
            let f = req.encode();
            assert_eq!(bytes(&f), (0x7E5, data.to_vec()), "{req:?}");
            assert_eq!(Request::decode(&f), Ok(*req));
        }
    }

    #[test]
    fn cia305_4_answers_on_the_wire() {
        let cases: &[(Response, [u8; 8])] = &[
            (Response::SwitchSelective, [0x44, 0, 0, 0, 0, 0, 0, 0]),
            (
                Response::ConfigureNodeId { error: 1, spec: 0 },
                [0x11, 1, 0, 0, 0, 0, 0, 0],
            ),
            (
                Response::ConfigureBitTiming {
                    error: 0xFF,
                    spec: 7,
                },
                [0x13, 0xFF, 7, 0, 0, 0, 0, 0],
            ),
            (
                Response::StoreConfiguration { error: 2, spec: 0 },
                [0x17, 2, 0, 0, 0, 0, 0, 0],
            ),
            (Response::IdentifySlave, [0x4F, 0, 0, 0, 0, 0, 0, 0]),
            (Response::NonConfiguredSlave, [0x50, 0, 0, 0, 0, 0, 0, 0]),
            (
                Response::Address(Part::Serial, 0xDEAD_BEEF),
                [0x5D, 0xEF, 0xBE, 0xAD, 0xDE, 0, 0, 0],
            ),
            (Response::NodeId(0xFF), [0x5E, 0xFF, 0, 0, 0, 0, 0, 0]),
        ];
        for (resp, data) in cases {
            let f = resp.encode();
            assert_eq!(bytes(&f), (0x7E4, data.to_vec()), "{resp:?}");
            assert_eq!(Response::decode(&f), Ok(*resp));
        }
    }

    #[test]
    fn cia305_4_2_other_frames_are_not_lss_messages() {
        let short = Frame::std(0x7E5, &[0x5E, 0, 0, 0]).unwrap();
        assert_eq!(Request::decode(&short), Err(DecodeError::Length(4)));
        let other = Frame::std(0x7E6, &[0x5E, 0, 0, 0, 0, 0, 0, 0]).unwrap();
        assert_eq!(Request::decode(&other), Err(DecodeError::NotLss));
        let answer_as_request = Response::NodeId(3).encode();
        assert_eq!(
            Request::decode(&answer_as_request),
            Err(DecodeError::NotLss)
        );
        let bad_mode = Frame::std(0x7E5, &[0x04, 2, 0, 0, 0, 0, 0, 0]).unwrap();
        assert_eq!(Request::decode(&bad_mode), Err(DecodeError::Field(0x04)));
        let bad_scan = Frame::std(0x7E5, &[0x51, 0, 0, 0, 0, 32, 0, 0]).unwrap();
        assert_eq!(Request::decode(&bad_scan), Err(DecodeError::Field(0x51)));
        let unknown = Frame::std(0x7E5, &[0x99, 0, 0, 0, 0, 0, 0, 0]).unwrap();
        assert_eq!(Request::decode(&unknown), Err(DecodeError::Command(0x99)));
    }

    #[test]
    fn cia305_4_4_2_bit_timing_table() {
        assert_eq!(bit_rate_of(0), Some(BitRate::R1M));
        assert_eq!(bit_rate_of(2), Some(BitRate::R500K));
        assert_eq!(bit_rate_of(5), None);
        assert_eq!(bit_rate_of(9), None);
        assert_eq!(table_index_of(BitRate::R10K), Some(8));
        assert_eq!(table_index_of(BitRate::R100K), None);
    }
}
