//! SDO frames as typed messages (CiA 301 §7.2.4.3): decode and encode, nothing else.
//!
//! Every SDO frame is 8 bytes. Byte 0 is the command specifier; in the initiate and abort
//! frames bytes 1–2 carry the index (little-endian) and byte 3 the sub-index; reserved
//! bits and bytes are sent as zero. The segments of a block transfer carry no command
//! specifier (byte 0 is the last-segment bit and the sequence number), so they are decoded
//! separately with [`BlockSegment`] by whoever knows a block is in progress.

use crate::abort::AbortCode;

/// An index and sub-index (the "multiplexer" of CiA 301).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Mux {
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
}

impl Mux {
    /// A multiplexer.
    pub const fn new(index: u16, sub: u8) -> Self {
        Mux { index, sub }
    }

    /// Bytes 1–3 of a frame read as a multiplexer, whatever its command: what they carry
    /// in initiate and abort frames. A server answering a request it refuses before
    /// serving it (see [`super::server::SdoCapabilities`]) echoes them.
    #[inline]
    pub fn of_frame(b: &[u8; 8]) -> Self {
        Self::decode(b)
    }

    #[inline(always)]
    fn decode(b: &[u8; 8]) -> Self {
        Mux {
            index: u16::from_le_bytes([b[1], b[2]]),
            sub: b[3],
        }
    }

    #[inline]
    fn encode(self, b: &mut [u8; 8]) {
        let i = self.index.to_le_bytes();
        b[1] = i[0];
        b[2] = i[1];
        b[3] = self.sub;
    }
}

/// A frame that is not a valid SDO message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    /// The command specifier is unknown (the server answers 0x05040001).
    #[error("unknown SDO command specifier in byte 0 = {0:#04X}")]
    UnknownCommand(u8),
}

/// The data of an initiate download request or initiate upload response.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Initiate {
    /// Expedited: up to 4 bytes in the frame; `len` is `None` when the size is not indicated.
    Expedited {
        /// Bytes 4..8 of the frame.
        data: [u8; 4],
        /// The number of valid bytes (4 − n), if indicated.
        len: Option<u8>,
    },
    /// Segmented: the data follows in segments; `size` in bytes, if indicated.
    Segmented {
        /// Total size, if indicated.
        size: Option<u32>,
    },
}

/// A request from an SDO client to a server (everything but block segments).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request {
    /// Initiate SDO download (ccs = 1), §7.2.4.3.3.
    InitiateDownload {
        /// Object.
        mux: Mux,
        /// Expedited data or segmented size.
        init: Initiate,
    },
    /// Download SDO segment (ccs = 0), §7.2.4.3.4.
    DownloadSegment {
        /// Toggle bit.
        toggle: bool,
        /// No more segments (c).
        last: bool,
        /// Number of data bytes (7 − n).
        len: u8,
        /// Bytes 1..8.
        data: [u8; 7],
    },
    /// Initiate SDO upload (ccs = 2), §7.2.4.3.6.
    InitiateUpload {
        /// Object.
        mux: Mux,
    },
    /// Upload SDO segment (ccs = 3), §7.2.4.3.7.
    UploadSegment {
        /// Toggle bit.
        toggle: bool,
    },
    /// Initiate SDO block download (ccs = 6, cs = 0), §7.2.4.3.9.
    BlockDownloadInitiate {
        /// Object.
        mux: Mux,
        /// The client supports CRC (cc).
        crc: bool,
        /// Size, if indicated.
        size: Option<u32>,
    },
    /// End SDO block download (ccs = 6, cs = 1), §7.2.4.3.11.
    BlockDownloadEnd {
        /// Bytes of the last segment that carry no data (n).
        unused: u8,
        /// CRC of the data (zero when CRC is not used).
        crc: u16,
    },
    /// Initiate SDO block upload (ccs = 5, cs = 0), §7.2.4.3.12.
    BlockUploadInitiate {
        /// Object.
        mux: Mux,
        /// The client supports CRC (cc).
        crc: bool,
        /// Segments per block (1..=127 valid).
        blksize: u8,
        /// Protocol switch threshold: at or below this size the server may answer with a
        /// normal upload (0: no switch).
        pst: u8,
    },
    /// Start of the block upload data (ccs = 5, cs = 3), §7.2.4.3.12.
    BlockUploadStart,
    /// Block upload acknowledgement (ccs = 5, cs = 2), §7.2.4.3.13.
    BlockUploadAck {
        /// Sequence number of the last segment received in order.
        ackseq: u8,
        /// Segments per block for the next block.
        blksize: u8,
    },
    /// End SDO block upload response (ccs = 5, cs = 1), §7.2.4.3.14.
    BlockUploadEnd,
    /// Abort SDO transfer (cs = 4), §7.2.4.3.17.
    Abort {
        /// Object.
        mux: Mux,
        /// Reason.
        code: AbortCode,
    },
}

/// A response from an SDO server (everything but block segments).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Response {
    /// Initiate SDO download response (scs = 3).
    InitiateDownload {
        /// Object.
        mux: Mux,
    },
    /// Download SDO segment response (scs = 1).
    DownloadSegment {
        /// Toggle bit of the segment it confirms.
        toggle: bool,
    },
    /// Initiate SDO upload response (scs = 2).
    InitiateUpload {
        /// Object.
        mux: Mux,
        /// Expedited data or segmented size.
        init: Initiate,
    },
    /// Upload SDO segment response (scs = 0).
    UploadSegment {
        /// Toggle bit.
        toggle: bool,
        /// No more segments (c).
        last: bool,
        /// Number of data bytes (7 − n).
        len: u8,
        /// Bytes 1..8.
        data: [u8; 7],
    },
    /// Initiate SDO block download response (scs = 5, ss = 0).
    BlockDownloadInitiate {
        /// Object.
        mux: Mux,
        /// The server supports CRC (sc).
        crc: bool,
        /// Segments per block the server accepts.
        blksize: u8,
    },
    /// Block download acknowledgement (scs = 5, ss = 2).
    BlockDownloadAck {
        /// Sequence number of the last segment received in order.
        ackseq: u8,
        /// Segments per block for the next block.
        blksize: u8,
    },
    /// End SDO block download response (scs = 5, ss = 1).
    BlockDownloadEnd,
    /// Initiate SDO block upload response (scs = 6, ss = 0).
    BlockUploadInitiate {
        /// Object.
        mux: Mux,
        /// The server supports CRC (sc).
        crc: bool,
        /// Size, if indicated.
        size: Option<u32>,
    },
    /// End SDO block upload request (scs = 6, ss = 1).
    BlockUploadEnd {
        /// Bytes of the last segment that carry no data (n).
        unused: u8,
        /// CRC of the data.
        crc: u16,
    },
    /// Abort SDO transfer (cs = 4).
    Abort {
        /// Object.
        mux: Mux,
        /// Reason.
        code: AbortCode,
    },
}

/// One segment of a block transfer (either direction): byte 0 is `c | seqno`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BlockSegment {
    /// No more segments (c).
    pub last: bool,
    /// Sequence number, 1..=127 in a valid block.
    pub seqno: u8,
    /// Bytes 1..8.
    pub data: [u8; 7],
}

impl BlockSegment {
    /// Decodes a block segment.
    pub fn decode(b: &[u8; 8]) -> Self {
        let mut data = [0u8; 7];
        data.copy_from_slice(&b[1..]);
        BlockSegment {
            last: b[0] & 0x80 != 0,
            seqno: b[0] & 0x7F,
            data,
        }
    }

    /// Encodes a block segment.
    #[inline]
    pub fn encode(&self) -> [u8; 8] {
        let mut b = [0u8; 8];
        b[0] = (u8::from(self.last) << 7) | (self.seqno & 0x7F);
        b[1..].copy_from_slice(&self.data);
        b
    }
}

#[inline]
fn u32_at(b: &[u8; 8]) -> u32 {
    u32::from_le_bytes([b[4], b[5], b[6], b[7]])
}

#[inline]
fn put_u32(b: &mut [u8; 8], v: u32) {
    b[4..].copy_from_slice(&v.to_le_bytes());
}

fn seg_data(b: &[u8; 8]) -> [u8; 7] {
    let mut d = [0u8; 7];
    d.copy_from_slice(&b[1..]);
    d
}

/// Decodes the `x n e s` bits and bytes 4..8 of an initiate frame.
#[inline(always)]
fn decode_initiate(b: &[u8; 8]) -> Initiate {
    let (e, s, n) = (b[0] & 0x02 != 0, b[0] & 0x01 != 0, (b[0] >> 2) & 0x03);
    if e {
        Initiate::Expedited {
            data: [b[4], b[5], b[6], b[7]],
            len: s.then_some(4 - n),
        }
    } else {
        Initiate::Segmented {
            size: s.then(|| u32_at(b)),
        }
    }
}

#[inline]
fn encode_initiate(init: Initiate, b: &mut [u8; 8]) {
    match init {
        Initiate::Expedited { data, len } => {
            b[0] |= 0x02;
            if let Some(len) = len {
                b[0] |= 0x01 | ((4 - len.clamp(1, 4)) << 2);
            }
            b[4..].copy_from_slice(&data);
        }
        Initiate::Segmented { size } => {
            if let Some(size) = size {
                b[0] |= 0x01;
                put_u32(b, size);
            }
        }
    }
}

impl Request {
    /// Decodes a client request (not a block segment).
    #[inline(always)]
    pub fn decode(b: &[u8; 8]) -> Result<Request, WireError> {
        let cmd = b[0];
        // The two most frequent requests (initiate upload and download) first, as plain
        // tests a caller's own test of the result folds into: no jump table between them.
        match cmd >> 5 {
            2 => {
                return Ok(Request::InitiateUpload {
                    mux: Mux::decode(b),
                });
            }
            1 => {
                return Ok(Request::InitiateDownload {
                    mux: Mux::decode(b),
                    init: decode_initiate(b),
                });
            }
            _ => {}
        }
        Ok(match cmd >> 5 {
            0 => Request::DownloadSegment {
                toggle: cmd & 0x10 != 0,
                last: cmd & 0x01 != 0,
                len: 7 - ((cmd >> 1) & 0x07),
                data: seg_data(b),
            },
            3 => Request::UploadSegment {
                toggle: cmd & 0x10 != 0,
            },
            4 => Request::Abort {
                mux: Mux::decode(b),
                code: AbortCode::from_u32(u32_at(b)),
            },
            5 => match cmd & 0x03 {
                0 => Request::BlockUploadInitiate {
                    mux: Mux::decode(b),
                    crc: cmd & 0x04 != 0,
                    blksize: b[4],
                    pst: b[5],
                },
                1 => Request::BlockUploadEnd,
                2 => Request::BlockUploadAck {
                    ackseq: b[1],
                    blksize: b[2],
                },
                _ => Request::BlockUploadStart,
            },
            6 => {
                if cmd & 0x01 == 0 {
                    Request::BlockDownloadInitiate {
                        mux: Mux::decode(b),
                        crc: cmd & 0x04 != 0,
                        size: (cmd & 0x02 != 0).then(|| u32_at(b)),
                    }
                } else {
                    Request::BlockDownloadEnd {
                        unused: (cmd >> 2) & 0x07,
                        crc: u16::from_le_bytes([b[1], b[2]]),
                    }
                }
            }
            _ => return Err(WireError::UnknownCommand(cmd)),
        })
    }

    /// Encodes the request (reserved bits and bytes zero).
    #[inline]
    pub fn encode(&self) -> [u8; 8] {
        let mut b = [0u8; 8];
        match *self {
            Request::InitiateDownload { mux, init } => {
                b[0] = 0x20;
                mux.encode(&mut b);
                encode_initiate(init, &mut b);
            }
            Request::DownloadSegment {
                toggle,
                last,
                len,
                data,
            } => {
                b[0] = (u8::from(toggle) << 4) | ((7 - len.min(7)) << 1) | u8::from(last);
                b[1..].copy_from_slice(&data);
            }
            Request::InitiateUpload { mux } => {
                b[0] = 0x40;
                mux.encode(&mut b);
            }
            Request::UploadSegment { toggle } => b[0] = 0x60 | (u8::from(toggle) << 4),
            Request::BlockDownloadInitiate { mux, crc, size } => {
                b[0] = 0xC0 | (u8::from(crc) << 2);
                mux.encode(&mut b);
                if let Some(size) = size {
                    b[0] |= 0x02;
                    put_u32(&mut b, size);
                }
            }
            Request::BlockDownloadEnd { unused, crc } => {
                b[0] = 0xC1 | ((unused & 0x07) << 2);
                b[1..3].copy_from_slice(&crc.to_le_bytes());
            }
            Request::BlockUploadInitiate {
                mux,
                crc,
                blksize,
                pst,
            } => {
                b[0] = 0xA0 | (u8::from(crc) << 2);
                mux.encode(&mut b);
                b[4] = blksize;
                b[5] = pst;
            }
            Request::BlockUploadStart => b[0] = 0xA3,
            Request::BlockUploadAck { ackseq, blksize } => {
                b[0] = 0xA2;
                b[1] = ackseq;
                b[2] = blksize;
            }
            Request::BlockUploadEnd => b[0] = 0xA1,
            Request::Abort { mux, code } => {
                b[0] = 0x80;
                mux.encode(&mut b);
                put_u32(&mut b, code.to_u32());
            }
        }
        b
    }
}

impl Response {
    /// Decodes a server response (not a block segment).
    #[inline]
    pub fn decode(b: &[u8; 8]) -> Result<Response, WireError> {
        let cmd = b[0];
        Ok(match cmd >> 5 {
            0 => Response::UploadSegment {
                toggle: cmd & 0x10 != 0,
                last: cmd & 0x01 != 0,
                len: 7 - ((cmd >> 1) & 0x07),
                data: seg_data(b),
            },
            1 => Response::DownloadSegment {
                toggle: cmd & 0x10 != 0,
            },
            2 => Response::InitiateUpload {
                mux: Mux::decode(b),
                init: decode_initiate(b),
            },
            3 => Response::InitiateDownload {
                mux: Mux::decode(b),
            },
            4 => Response::Abort {
                mux: Mux::decode(b),
                code: AbortCode::from_u32(u32_at(b)),
            },
            5 => match cmd & 0x03 {
                0 => Response::BlockDownloadInitiate {
                    mux: Mux::decode(b),
                    crc: cmd & 0x04 != 0,
                    blksize: b[4],
                },
                1 => Response::BlockDownloadEnd,
                2 => Response::BlockDownloadAck {
                    ackseq: b[1],
                    blksize: b[2],
                },
                _ => return Err(WireError::UnknownCommand(cmd)),
            },
            6 => {
                if cmd & 0x01 == 0 {
                    Response::BlockUploadInitiate {
                        mux: Mux::decode(b),
                        crc: cmd & 0x04 != 0,
                        size: (cmd & 0x02 != 0).then(|| u32_at(b)),
                    }
                } else {
                    Response::BlockUploadEnd {
                        unused: (cmd >> 2) & 0x07,
                        crc: u16::from_le_bytes([b[1], b[2]]),
                    }
                }
            }
            _ => return Err(WireError::UnknownCommand(cmd)),
        })
    }

    /// Encodes the response (reserved bits and bytes zero).
    #[inline(always)]
    pub fn encode(&self) -> [u8; 8] {
        let mut b = [0u8; 8];
        match *self {
            Response::InitiateDownload { mux } => {
                b[0] = 0x60;
                mux.encode(&mut b);
            }
            Response::DownloadSegment { toggle } => b[0] = 0x20 | (u8::from(toggle) << 4),
            Response::InitiateUpload { mux, init } => {
                b[0] = 0x40;
                mux.encode(&mut b);
                encode_initiate(init, &mut b);
            }
            Response::UploadSegment {
                toggle,
                last,
                len,
                data,
            } => {
                b[0] = (u8::from(toggle) << 4) | ((7 - len.min(7)) << 1) | u8::from(last);
                b[1..].copy_from_slice(&data);
            }
            Response::BlockDownloadInitiate { mux, crc, blksize } => {
                b[0] = 0xA0 | (u8::from(crc) << 2);
                mux.encode(&mut b);
                b[4] = blksize;
            }
            Response::BlockDownloadAck { ackseq, blksize } => {
                b[0] = 0xA2;
                b[1] = ackseq;
                b[2] = blksize;
            }
            Response::BlockDownloadEnd => b[0] = 0xA1,
            Response::BlockUploadInitiate { mux, crc, size } => {
                b[0] = 0xC0 | (u8::from(crc) << 2);
                mux.encode(&mut b);
                if let Some(size) = size {
                    b[0] |= 0x02;
                    put_u32(&mut b, size);
                }
            }
            Response::BlockUploadEnd { unused, crc } => {
                b[0] = 0xC1 | ((unused & 0x07) << 2);
                b[1..3].copy_from_slice(&crc.to_le_bytes());
            }
            Response::Abort { mux, code } => {
                b[0] = 0x80;
                mux.encode(&mut b);
                put_u32(&mut b, code.to_u32());
            }
        }
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn cia301_7_2_4_3_3_expedited_download_of_two_bytes() {
        let b = [0x2B, 0x17, 0x10, 0x00, 0xE8, 0x03, 0, 0];
        let r = Request::decode(&b).unwrap();
        assert_eq!(
            r,
            Request::InitiateDownload {
                mux: Mux::new(0x1017, 0),
                init: Initiate::Expedited {
                    data: [0xE8, 0x03, 0, 0],
                    len: Some(2)
                }
            }
        );
        assert_eq!(r.encode(), b);
    }

    #[test]
    fn cia301_7_2_4_3_17_abort_frame() {
        let r = Response::Abort {
            mux: Mux::new(0x1018, 5),
            code: AbortCode::NO_SUB_INDEX,
        };
        assert_eq!(r.encode(), [0x80, 0x18, 0x10, 0x05, 0x11, 0x00, 0x09, 0x06]);
    }

    #[test]
    fn ccs_7_is_unknown() {
        assert_eq!(
            Request::decode(&[0xE0; 8]),
            Err(WireError::UnknownCommand(0xE0))
        );
        assert_eq!(
            Response::decode(&[0xA3, 0, 0, 0, 0, 0, 0, 0]),
            Err(WireError::UnknownCommand(0xA3))
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]
        /// Every decodable frame whose reserved bits are zero encodes back to itself.
        #[test]
        fn request_decode_encode_is_stable(b in any::<[u8; 8]>()) {
            if let Ok(r) = Request::decode(&b) {
                prop_assert_eq!(Request::decode(&r.encode()), Ok(r));
            }
        }

        #[test]
        fn response_decode_encode_is_stable(b in any::<[u8; 8]>()) {
            if let Ok(r) = Response::decode(&b) {
                prop_assert_eq!(Response::decode(&r.encode()), Ok(r));
            }
        }
    }
}

fn hex(data: &[u8]) -> String {
    data.iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

impl core::fmt::Display for Mux {
    /// `0x1018sub1`, as traces and CiA 306 section names write it.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "0x{:04X}sub{}", self.index, self.sub)
    }
}

impl core::fmt::Display for Initiate {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Initiate::Expedited { data, len: Some(n) } => {
                write!(f, "expedited [{}]", hex(&data[..usize::from(*n).min(4)]))
            }
            Initiate::Expedited { data, len: None } => {
                write!(f, "expedited [{}] (size not indicated)", hex(data))
            }
            Initiate::Segmented { size: Some(n) } => write!(f, "segmented, {n} bytes"),
            Initiate::Segmented { size: None } => f.write_str("segmented, size not indicated"),
        }
    }
}

impl core::fmt::Display for Request {
    /// One line for traces: the service and its fields, with the multiplexer as
    /// `0xINDEXsubN` and data in hex.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let t = |toggle: &bool| u8::from(*toggle);
        match self {
            Request::InitiateDownload { mux, init } => write!(f, "download {mux}: {init}"),
            Request::DownloadSegment {
                toggle,
                last,
                len,
                data,
            } => write!(
                f,
                "download segment t={} [{}]{}",
                t(toggle),
                hex(&data[..usize::from(*len).min(7)]),
                if *last { " last" } else { "" }
            ),
            Request::InitiateUpload { mux } => write!(f, "upload {mux}"),
            Request::UploadSegment { toggle } => write!(f, "upload segment t={}", t(toggle)),
            Request::BlockDownloadInitiate { mux, crc, size } => write!(
                f,
                "block download {mux}{}{}",
                size.map(|s| format!(", {s} bytes")).unwrap_or_default(),
                if *crc { ", CRC" } else { "" }
            ),
            Request::BlockDownloadEnd { unused, crc } => {
                write!(
                    f,
                    "block download end, {unused} unused bytes, CRC 0x{crc:04X}"
                )
            }
            Request::BlockUploadInitiate {
                mux,
                crc,
                blksize,
                pst,
            } => write!(
                f,
                "block upload {mux}, blksize {blksize}, pst {pst}{}",
                if *crc { ", CRC" } else { "" }
            ),
            Request::BlockUploadStart => f.write_str("block upload start"),
            Request::BlockUploadAck { ackseq, blksize } => {
                write!(f, "block upload ack seq {ackseq}, next blksize {blksize}")
            }
            Request::BlockUploadEnd => f.write_str("block upload end"),
            Request::Abort { mux, code } => write!(f, "abort {mux}: {code}"),
        }
    }
}

impl core::fmt::Display for Response {
    /// One line for traces (see [`Request`]'s `Display`).
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let t = |toggle: &bool| u8::from(*toggle);
        match self {
            Response::InitiateDownload { mux } => write!(f, "download {mux} accepted"),
            Response::DownloadSegment { toggle } => {
                write!(f, "download segment t={} accepted", t(toggle))
            }
            Response::InitiateUpload { mux, init } => write!(f, "upload {mux}: {init}"),
            Response::UploadSegment {
                toggle,
                last,
                len,
                data,
            } => write!(
                f,
                "upload segment t={} [{}]{}",
                t(toggle),
                hex(&data[..usize::from(*len).min(7)]),
                if *last { " last" } else { "" }
            ),
            Response::BlockDownloadInitiate { mux, crc, blksize } => write!(
                f,
                "block download {mux} accepted, blksize {blksize}{}",
                if *crc { ", CRC" } else { "" }
            ),
            Response::BlockDownloadAck { ackseq, blksize } => {
                write!(f, "block download ack seq {ackseq}, next blksize {blksize}")
            }
            Response::BlockDownloadEnd => f.write_str("block download end accepted"),
            Response::BlockUploadInitiate { mux, crc, size } => write!(
                f,
                "block upload {mux}{}{}",
                size.map(|s| format!(", {s} bytes")).unwrap_or_default(),
                if *crc { ", CRC" } else { "" }
            ),
            Response::BlockUploadEnd { unused, crc } => {
                write!(
                    f,
                    "block upload end, {unused} unused bytes, CRC 0x{crc:04X}"
                )
            }
            Response::Abort { mux, code } => write!(f, "ABORT {mux}: {code}"),
        }
    }
}

#[cfg(test)]
mod display_tests {
    use super::*;

    #[test]
    fn trace_lines_name_the_object_and_the_data() {
        let r = Request::decode(&[0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0]).unwrap();
        assert_eq!(r.to_string(), "upload 0x1008sub0");
        let r = Response::decode(&[0x43, 0x18, 0x10, 0x01, 0xA7, 0x0C, 0, 0]).unwrap();
        assert_eq!(r.to_string(), "upload 0x1018sub1: expedited [A7 0C 00 00]");
        let r = Response::decode(&[0x80, 0x00, 0x60, 0x00, 0x00, 0x00, 0x02, 0x06]).unwrap();
        assert_eq!(
            r.to_string(),
            "ABORT 0x6000sub0: 0x06020000 (Object does not exist in the object dictionary)"
        );
    }
}
