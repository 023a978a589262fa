//! One SDO server channel (CiA 301 §7.2.4): expedited, segmented and block transfers in
//! both directions, answered within the call that delivers the request.
//!
//! The server is sans-IO: [`SdoServer::on_frame`] takes a frame, the current time and the
//! device's [`ObjectAccess`], and queues its answer into the [`Outbox`];
//! [`SdoServer::on_tick`] enforces the SDO timeout. It keeps no copy of the data being
//! transferred: uploads read the value segment by segment from the device and downloads
//! stream into it ([`ObjectAccess::write_begin`] …). The expedited path does not allocate.
//!
//! Decisions where CiA 301 leaves room:
//!
//! * A frame whose command specifier is not the next step of the transfer in progress
//!   (including a new initiate) aborts that transfer with 0x05040001 and is not served;
//!   the client starts again. An abort from the client ends the transfer silently.
//! * A toggle bit that did not alternate aborts with 0x05030000 (as CANopenNode does;
//!   lely-core ignores the segment and lets the transfer time out).
//! * CiA 301 §7.2.4.3 gives every SDO frame 8 data bytes; a request with fewer is padded
//!   with zeros (some clients send short frames; lely-core does the same), a request with
//!   none is answered with 0x05040001, and remote frames are ignored.
//! * An expedited download without indicated size writes the type's size if it is below
//!   4 bytes, else 4 bytes.
//! * Block download: a segment out of sequence is ignored; at the end of the block (or at
//!   the segment flagged last) the acknowledgement carries the last sequence number
//!   received in order, so the client repeats the rest (§7.2.4.3.10). A sequence number of
//!   0 or above the block size aborts with 0x05040003.
//! * Block upload switches to a normal (expedited or segmented) upload when the client's
//!   protocol switch threshold is not 0 and the size is at or below it (§7.2.4.3.12).
//! * The server supports CRC; it is used when the client supports it too.
//!
//! On a new initiate during a transfer, implementations differ: CANopenNode v4 and
//! lely-core abort the running transfer with 0x05040001 (the frame is judged against the
//! state the transfer is in), python-canopen's server starts the new transfer and drops
//! the old one silently. This server does what the two embedded stacks do.

use super::crc::Crc16;
use super::wire::{BlockSegment, Initiate, Mux, Request, Response};
use crate::abort::AbortCode;
use crate::od::ObjectAccess;
use cantwin_can::{Duration, Frame, Id, Instant, Outbox};

/// The SDO services a server offers (CiA 301 §7.2.4.1: expedited transfer is the
/// minimum; segmented and block transfer are optional, and a minimum-capability device
/// such as a drive's fieldbus card offers expedited transfer only).
///
/// What a server without a service answers is chosen here, in one place, and each refusal
/// comes before the request is served (before the dictionary is asked):
///
/// * without segmented transfer, a download or upload segment (ccs 0 or 3) is aborted with
///   0x05040001 and index 0, sub-index 0 (as any segment that follows no initiate); an
///   initiate download without the expedited bit (e = 0) with 0x05040001 and the
///   request's index and sub-index; an upload of a value longer than 4 bytes with
///   0x06070012 (length too high) and the request's index and sub-index;
/// * without block transfer, every block request (ccs 5 or 6) is aborted with 0x05040001
///   and bytes 1–3 of the request as index and sub-index;
/// * with [`SdoCapabilities::sub_index_ff_refused`], every initiate request and block
///   request (ccs 1, 2, 5, 6) for sub-index 0xFF is aborted with 0x06090011 before any
///   other check: a device that does not offer the object-structure sub-index 0xFF of
///   CiA 301 §7.4.3 refuses it whether or not the object exists.
///
/// ```
/// use cantwin_can::{Frame, Id, Instant, Outbox};
/// use cantwin_canopen::od::{ObjectDictionary, OdBuilder};
/// use cantwin_canopen::sdo::{SdoCapabilities, SdoServer};
/// use std::sync::Arc;
///
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let mut od = ObjectDictionary::new(Arc::new(OdBuilder::new().build()?), 5);
/// let mut server = SdoServer::for_node(5);
/// server.set_capabilities(SdoCapabilities::EXPEDITED_ONLY);
/// let mut out = Outbox::new();
/// // A block upload of 0x1008:00 is refused: ccs 5 is not offered.
/// let request = Frame::data_array(Id::standard(0x605)?, [0xA4, 0x08, 0x10, 0x00, 0x7F, 0, 0, 0]);
/// server.on_frame(&request, Instant::ZERO, &mut od, &mut out);
/// assert_eq!(
///     out.frames(),
///     [Frame::data_array(Id::standard(0x585)?, [0x80, 0x08, 0x10, 0x00, 0x01, 0x00, 0x04, 0x05])]
/// );
/// # Ok(())
/// # }
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SdoCapabilities {
    /// Segmented download and upload (CiA 301 §7.2.4.3.4–8).
    pub segmented: bool,
    /// Block download and upload (CiA 301 §7.2.4.3.9–16).
    pub block: bool,
    /// Requests for sub-index 0xFF are refused with 0x06090011 before any other check.
    pub sub_index_ff_refused: bool,
}

impl SdoCapabilities {
    /// Every transfer CiA 301 defines; sub-index 0xFF is looked up like any other.
    pub const FULL: SdoCapabilities = SdoCapabilities {
        segmented: true,
        block: true,
        sub_index_ff_refused: false,
    };

    /// Expedited transfers only (a CiA 301 minimum-capability device).
    pub const EXPEDITED_ONLY: SdoCapabilities = SdoCapabilities {
        segmented: false,
        block: false,
        sub_index_ff_refused: false,
    };

    /// The same services, refusing sub-index 0xFF before any other check.
    pub const fn with_sub_index_ff_refused(self) -> Self {
        SdoCapabilities {
            sub_index_ff_refused: true,
            ..self
        }
    }

    /// The abort a request gets before it is served (see the type's documentation), with
    /// the multiplexer the abort frame carries; `None` if the request is offered. `b` is
    /// the request frame, `req` its decoding.
    #[inline]
    pub fn refusal(&self, b: &[u8; 8], req: &Request) -> Option<(Mux, AbortCode)> {
        let block = matches!(
            req,
            Request::BlockDownloadInitiate { .. }
                | Request::BlockDownloadEnd { .. }
                | Request::BlockUploadInitiate { .. }
                | Request::BlockUploadStart
                | Request::BlockUploadAck { .. }
                | Request::BlockUploadEnd
        );
        let initiate = matches!(
            req,
            Request::InitiateDownload { .. } | Request::InitiateUpload { .. }
        );
        let mux = Mux::of_frame(b);
        if self.sub_index_ff_refused && (initiate || block) && mux.sub == 0xFF {
            return Some((mux, AbortCode::NO_SUB_INDEX));
        }
        if !self.segmented {
            match req {
                Request::DownloadSegment { .. } | Request::UploadSegment { .. } => {
                    return Some((Mux::default(), AbortCode::INVALID_COMMAND));
                }
                Request::InitiateDownload {
                    init: Initiate::Segmented { .. },
                    ..
                } => return Some((mux, AbortCode::INVALID_COMMAND)),
                _ => {}
            }
        }
        if !self.block && block {
            return Some((mux, AbortCode::INVALID_COMMAND));
        }
        None
    }

    /// The abort an upload of a value of `size` bytes gets: a server without segmented
    /// transfer can only send up to 4 bytes (0x06070012).
    #[inline]
    pub fn upload_refusal(&self, size: usize) -> Option<AbortCode> {
        (!self.segmented && size > 4).then_some(AbortCode::LENGTH_TOO_HIGH)
    }
}

impl Default for SdoCapabilities {
    fn default() -> Self {
        SdoCapabilities::FULL
    }
}

/// The default SDO timeout.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(1);

/// The largest number of segments in a block (CiA 301 §7.2.4.3.9).
pub const MAX_BLOCK_SIZE: u8 = 127;

/// Decodes a CiA 301 COB-ID entry (e.g. 0x1200 sub-indices 1 and 2, §7.5.2.33): bit 31 set
/// means not valid, bit 29 selects a 29-bit identifier. `None` if not valid or out of range.
pub fn cob_id(raw: u32) -> Option<Id> {
    if raw & 0x8000_0000 != 0 {
        return None;
    }
    if raw & 0x2000_0000 != 0 {
        Id::extended(raw & 0x1FFF_FFFF).ok()
    } else {
        u16::try_from(raw & 0x1FFF_FFFF)
            .ok()
            .and_then(|r| Id::standard(r).ok())
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Idle,
    Download {
        toggle: bool,
        size: Option<u32>,
        received: u32,
    },
    Upload {
        toggle: bool,
        size: u32,
        offset: u32,
    },
    BlockDownload {
        crc_on: bool,
        size: Option<u32>,
        /// Bytes handed to the device so far (the held-back segment not included).
        flushed: u32,
        /// Sequence number of the last segment received in order in this block.
        seq: u8,
        /// The last segment received in order is held back until it is known how many of
        /// its bytes are data (the end frame says so for the last one).
        pending: Option<[u8; 7]>,
        /// The segment flagged last was received and acknowledged: the end frame is next.
        finished: bool,
    },
    BlockUploadInitiated {
        crc_on: bool,
        size: u32,
        blksize: u8,
    },
    BlockUpload {
        crc_on: bool,
        size: u32,
        blksize: u8,
        /// Offset of the first byte of the current block.
        block_start: u32,
        /// Segments sent in the current block.
        sent: u8,
        /// Data bytes in the last segment sent, when the block holds the last segment.
        last_len: Option<u8>,
    },
    BlockUploadEnding,
}

/// One SDO server channel.
///
/// ```
/// use std::sync::Arc;
/// use cantwin_can::{Frame, Id, Instant, Outbox};
/// use cantwin_canopen::od::{Access, DataType, ObjectDictionary, OdBuilder, SubObject, Value};
/// use cantwin_canopen::sdo::SdoServer;
///
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let desc = OdBuilder::new()
///     .var(0x1000, SubObject::new("Device type", DataType::Unsigned32, Access::Ro)
///         .default(Value::Unsigned32(0x0004_0191)))
///     .build()?;
/// let mut od = ObjectDictionary::new(Arc::new(desc), 5);
/// let mut server = SdoServer::for_node(5);
/// let mut out = Outbox::new();
/// // Upload 0x1000:00 from node 5 (request on 0x605, answer on 0x585).
/// let request = Frame::data_array(Id::standard(0x605)?, [0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]);
/// assert!(server.on_frame(&request, Instant::ZERO, &mut od, &mut out));
/// assert_eq!(
///     out.frames(),
///     [Frame::data_array(Id::standard(0x585)?, [0x43, 0x00, 0x10, 0x00, 0x91, 0x01, 0x04, 0x00])]
/// );
/// # Ok(())
/// # }
/// ```
#[derive(Debug, Clone)]
pub struct SdoServer {
    rx: Option<Id>,
    tx: Option<Id>,
    timeout: Duration,
    block_size: u8,
    caps: SdoCapabilities,
    state: State,
    mux: Mux,
    deadline: Option<Instant>,
    crc: Crc16,
    /// CRC after each segment of the current upload block (index = sequence number), so a
    /// repeated block resumes the CRC where the acknowledged data ends.
    block_crcs: [u16; 128],
}

impl SdoServer {
    /// A server receiving requests on `rx` and answering on `tx`.
    pub fn new(rx: Id, tx: Id) -> Self {
        SdoServer {
            rx: Some(rx),
            tx: Some(tx),
            timeout: DEFAULT_TIMEOUT,
            block_size: MAX_BLOCK_SIZE,
            caps: SdoCapabilities::FULL,
            state: State::Idle,
            mux: Mux::default(),
            deadline: None,
            crc: Crc16::new(),
            block_crcs: [0; 128],
        }
    }

    /// The default server of a node (0x1200: 0x600 + node-ID / 0x580 + node-ID, CiA 301
    /// §7.3.3 pre-defined connection set). Node-IDs outside 1..=127 give an invalid server.
    pub fn for_node(node_id: u8) -> Self {
        let id = u32::from(node_id);
        let (rx, tx) = if (1..=127).contains(&node_id) {
            (0x600 + id, 0x580 + id)
        } else {
            (0x8000_0000, 0x8000_0000)
        };
        let mut s = SdoServer::new(
            Id::Standard(cantwin_can::StandardId::MAX),
            Id::Standard(cantwin_can::StandardId::MAX),
        );
        s.set_cob_ids(rx, tx);
        s
    }

    /// Sets the COB-IDs from their CiA 301 object dictionary form (0x1200..0x127F
    /// sub-indices 1 and 2). The channel works only while both are valid. A transfer in
    /// progress ends without a frame.
    pub fn set_cob_ids(&mut self, client_to_server: u32, server_to_client: u32) {
        self.rx = cob_id(client_to_server);
        self.tx = cob_id(server_to_client);
        self.state = State::Idle;
        self.deadline = None;
    }

    /// The identifier requests arrive on, if the channel is valid.
    pub fn rx_id(&self) -> Option<Id> {
        self.rx.filter(|_| self.tx.is_some())
    }

    /// The identifier answers are sent on, if the channel is valid.
    pub fn tx_id(&self) -> Option<Id> {
        self.tx.filter(|_| self.rx.is_some())
    }

    /// Sets the SDO timeout (default 1 s): a transfer with no request for this long is
    /// aborted with 0x05040000.
    pub fn set_timeout(&mut self, timeout: Duration) {
        self.timeout = timeout;
    }

    /// The SDO timeout.
    pub fn timeout(&self) -> Duration {
        self.timeout
    }

    /// Sets the block size the server offers for block downloads (clamped to 1..=127).
    pub fn set_block_size(&mut self, blksize: u8) {
        self.block_size = blksize.clamp(1, MAX_BLOCK_SIZE);
    }

    /// Sets the services the server offers (default [`SdoCapabilities::FULL`]).
    pub fn set_capabilities(&mut self, caps: SdoCapabilities) {
        self.caps = caps;
    }

    /// The services the server offers.
    pub fn capabilities(&self) -> SdoCapabilities {
        self.caps
    }

    /// Whether no transfer is in progress.
    pub fn is_idle(&self) -> bool {
        self.state == State::Idle
    }

    /// When [`Self::on_tick`] must be called next (the SDO timeout of the transfer in
    /// progress).
    pub fn next_deadline(&self) -> Option<Instant> {
        self.deadline
    }

    /// Ends any transfer without a frame (NMT reset, channel disabled).
    pub fn reset(&mut self, access: &mut dyn ObjectAccess) {
        self.cancel(access);
    }

    /// Handles a frame if it is addressed to this server; returns whether it was.
    #[inline]
    pub fn on_frame(
        &mut self,
        frame: &Frame,
        now: Instant,
        access: &mut dyn ObjectAccess,
        out: &mut Outbox,
    ) -> bool {
        if frame.is_remote() || Some(frame.id()) != self.rx_id() {
            return false;
        }
        let bytes = frame.data_bytes();
        if let Ok(data) = <&[u8; 8]>::try_from(bytes) {
            self.on_request(data, now, access, out);
        } else if bytes.is_empty() {
            // No command specifier at all.
            if self.state == State::Idle {
                self.mux = Mux::default();
            }
            self.abort(AbortCode::INVALID_COMMAND, access, out);
        } else {
            let mut data = [0u8; 8];
            data[..bytes.len()].copy_from_slice(bytes);
            self.on_request(&data, now, access, out);
        }
        true
    }

    /// The SDO timeout: aborts a transfer that has waited too long.
    pub fn on_tick(&mut self, now: Instant, access: &mut dyn ObjectAccess, out: &mut Outbox) {
        if self.deadline.is_some_and(|d| now >= d) {
            self.abort(AbortCode::TIMEOUT, access, out);
        }
    }

    /// Handles the 8 data bytes of a request.
    pub fn on_request(
        &mut self,
        b: &[u8; 8],
        now: Instant,
        access: &mut dyn ObjectAccess,
        out: &mut Outbox,
    ) {
        let Some(tx) = self.tx_id() else { return };
        // Block download segments carry no command specifier; 0x80 cannot be a segment
        // (sequence number 0), so it is the client's abort.
        if let State::BlockDownload {
            finished: false, ..
        } = self.state
            && b[0] != 0x80
        {
            self.deadline = now.checked_add(self.timeout);
            self.block_segment(BlockSegment::decode(b), tx, access, out);
            return;
        }
        let req = match Request::decode(b) {
            Ok(r) => r,
            Err(_) => {
                if self.state == State::Idle {
                    self.mux = Mux::default();
                }
                self.abort(AbortCode::INVALID_COMMAND, access, out);
                return;
            }
        };
        if self.state == State::Idle && !(self.caps.sub_index_ff_refused && b[3] == 0xFF) {
            // The most frequent requests first, served without a transfer state: no
            // capability refuses them but the sub-index 0xFF rule.
            match req {
                // Initiate upload (§7.2.4.3.6).
                Request::InitiateUpload { mux } => {
                    self.mux = mux;
                    match self.start_upload(mux, tx, access, out) {
                        Err(code) => self.abort(code, access, out),
                        Ok(()) if self.state != State::Idle => {
                            self.deadline = now.checked_add(self.timeout);
                        }
                        Ok(()) => {}
                    }
                    return;
                }
                // Expedited download (§7.2.4.3.3).
                Request::InitiateDownload {
                    mux,
                    init: Initiate::Expedited { data, len },
                } => {
                    self.mux = mux;
                    match Self::expedited_download(mux, &data, len, access) {
                        Ok(()) => Self::send(out, tx, Response::InitiateDownload { mux }),
                        Err(code) => self.abort(code, access, out),
                    }
                    return;
                }
                _ => {}
            }
        }
        if self.caps != SdoCapabilities::FULL
            && let Some((mux, code)) = self.caps.refusal(b, &req)
        {
            self.cancel(access);
            self.mux = mux;
            self.abort(code, access, out);
            return;
        }
        let result = match self.state {
            State::Idle => match req {
                Request::Abort { .. } => return self.cancel(access),
                _ => self.initiate(req, tx, access, out),
            },
            _ if matches!(req, Request::Abort { .. }) => return self.cancel(access),
            State::Download { .. } => self.download_segment(req, tx, access, out),
            State::Upload { .. } => self.upload_segment(req, tx, access, out),
            State::BlockDownload { .. } => self.block_download_end(req, tx, access, out),
            State::BlockUploadInitiated { .. } => match req {
                Request::BlockUploadStart => self.send_block(tx, access, out),
                _ => Err(AbortCode::INVALID_COMMAND),
            },
            State::BlockUpload { .. } => self.block_upload_ack(req, tx, access, out),
            State::BlockUploadEnding => match req {
                Request::BlockUploadEnd => {
                    self.finish();
                    Ok(())
                }
                _ => Err(AbortCode::INVALID_COMMAND),
            },
        };
        match result {
            Err(code) => self.abort(code, access, out),
            // A transfer in progress waits at most the SDO timeout for the next request.
            Ok(()) if self.state != State::Idle => self.deadline = now.checked_add(self.timeout),
            Ok(()) => self.deadline = None,
        }
    }

    #[inline]
    fn send(out: &mut Outbox, tx: Id, r: Response) {
        out.push(Frame::data_array(tx, r.encode()));
    }

    fn finish(&mut self) {
        self.state = State::Idle;
        self.deadline = None;
    }

    /// Ends the transfer without a frame, dropping a partial download.
    fn cancel(&mut self, access: &mut dyn ObjectAccess) {
        if matches!(
            self.state,
            State::Download { .. } | State::BlockDownload { .. }
        ) {
            access.write_cancel(self.mux.index, self.mux.sub);
        }
        self.finish();
    }

    /// Sends an abort for the current multiplexer and ends the transfer.
    fn abort(&mut self, code: AbortCode, access: &mut dyn ObjectAccess, out: &mut Outbox) {
        self.cancel(access);
        if let Some(tx) = self.tx_id() {
            Self::send(
                out,
                tx,
                Response::Abort {
                    mux: self.mux,
                    code,
                },
            );
        }
    }

    fn initiate(
        &mut self,
        req: Request,
        tx: Id,
        access: &mut dyn ObjectAccess,
        out: &mut Outbox,
    ) -> Result<(), AbortCode> {
        match req {
            Request::InitiateUpload { mux } => {
                self.mux = mux;
                self.start_upload(mux, tx, access, out)
            }
            Request::InitiateDownload { mux, init } => {
                self.mux = mux;
                match init {
                    Initiate::Expedited { data, len } => {
                        Self::expedited_download(mux, &data, len, access)?;
                    }
                    Initiate::Segmented { size } => {
                        access.write_begin(mux.index, mux.sub, size.map(|s| s as usize))?;
                        self.state = State::Download {
                            toggle: false,
                            size,
                            received: 0,
                        };
                    }
                }
                Self::send(out, tx, Response::InitiateDownload { mux });
                Ok(())
            }
            Request::BlockDownloadInitiate { mux, crc, size } => {
                self.mux = mux;
                access.write_begin(mux.index, mux.sub, size.map(|s| s as usize))?;
                self.crc = Crc16::new();
                self.state = State::BlockDownload {
                    crc_on: crc,
                    size,
                    flushed: 0,
                    seq: 0,
                    pending: None,
                    finished: false,
                };
                Self::send(
                    out,
                    tx,
                    Response::BlockDownloadInitiate {
                        mux,
                        crc: true,
                        blksize: self.block_size,
                    },
                );
                Ok(())
            }
            Request::BlockUploadInitiate {
                mux,
                crc,
                blksize,
                pst,
            } => {
                self.mux = mux;
                if blksize == 0 || blksize > MAX_BLOCK_SIZE {
                    return Err(AbortCode::INVALID_BLOCK_SIZE);
                }
                let info = access.read(mux.index, mux.sub, 0, &mut [])?;
                let size = u32::try_from(info.size).map_err(|_| AbortCode::LENGTH_TOO_HIGH)?;
                if pst != 0 && size <= u32::from(pst) {
                    return self.start_upload(mux, tx, access, out);
                }
                self.state = State::BlockUploadInitiated {
                    crc_on: crc,
                    size,
                    blksize,
                };
                Self::send(
                    out,
                    tx,
                    Response::BlockUploadInitiate {
                        mux,
                        crc: true,
                        size: Some(size),
                    },
                );
                Ok(())
            }
            _ => {
                self.mux = Mux::default();
                Err(AbortCode::INVALID_COMMAND)
            }
        }
    }

    /// Writes the data of an expedited download; without an indicated size, the type's size
    /// if it is below 4 bytes, else 4 bytes.
    #[inline]
    fn expedited_download(
        mux: Mux,
        data: &[u8; 4],
        len: Option<u8>,
        access: &mut dyn ObjectAccess,
    ) -> Result<(), AbortCode> {
        let len = match len {
            Some(l) => usize::from(l.min(4)),
            None => access
                .fixed_size(mux.index, mux.sub)
                .filter(|s| *s < 4)
                .unwrap_or(4),
        };
        access.write(mux.index, mux.sub, &data[..len])
    }

    /// Initiate upload response: expedited up to 4 bytes, otherwise segmented with size.
    #[inline]
    fn start_upload(
        &mut self,
        mux: Mux,
        tx: Id,
        access: &mut dyn ObjectAccess,
        out: &mut Outbox,
    ) -> Result<(), AbortCode> {
        let mut data = [0u8; 4];
        let info = access.read(mux.index, mux.sub, 0, &mut data)?;
        if (1..=4).contains(&info.size) {
            // Expedited, size indicated: scs = 2, n = 4 - size, e = 1, s = 1. The frame is
            // composed in a register: building it byte by byte in memory and loading it
            // whole stalls store forwarding on the hottest path.
            let cmd = 0x43 | ((4 - info.size as u32) << 2);
            let head = cmd | u32::from(mux.index) << 8 | u32::from(mux.sub) << 24;
            let word = u64::from(head) | u64::from(u32::from_le_bytes(data)) << 32;
            out.push(Frame::data_array(tx, word.to_le_bytes()));
            return Ok(());
        }
        if let Some(code) = self.caps.upload_refusal(info.size) {
            return Err(code);
        }
        let size = u32::try_from(info.size).map_err(|_| AbortCode::LENGTH_TOO_HIGH)?;
        self.state = State::Upload {
            toggle: false,
            size,
            offset: 0,
        };
        let init = Initiate::Segmented { size: Some(size) };
        Self::send(out, tx, Response::InitiateUpload { mux, init });
        Ok(())
    }

    fn download_segment(
        &mut self,
        req: Request,
        tx: Id,
        access: &mut dyn ObjectAccess,
        out: &mut Outbox,
    ) -> Result<(), AbortCode> {
        let (
            State::Download {
                toggle: expected,
                size,
                received,
            },
            Request::DownloadSegment {
                toggle,
                last,
                len,
                data,
            },
        ) = (self.state, req)
        else {
            return Err(AbortCode::INVALID_COMMAND);
        };
        if toggle != expected {
            return Err(AbortCode::TOGGLE_BIT_NOT_ALTERNATED);
        }
        let received = received.saturating_add(u32::from(len));
        if size.is_some_and(|s| received > s) {
            return Err(AbortCode::LENGTH_TOO_HIGH);
        }
        access.write_segment(self.mux.index, self.mux.sub, &data[..usize::from(len)])?;
        if last {
            if size.is_some_and(|s| received < s) {
                return Err(AbortCode::LENGTH_TOO_LOW);
            }
            access.write_end(self.mux.index, self.mux.sub)?;
            self.finish();
        } else {
            self.state = State::Download {
                toggle: !toggle,
                size,
                received,
            };
        }
        Self::send(out, tx, Response::DownloadSegment { toggle });
        Ok(())
    }

    fn upload_segment(
        &mut self,
        req: Request,
        tx: Id,
        access: &mut dyn ObjectAccess,
        out: &mut Outbox,
    ) -> Result<(), AbortCode> {
        let (
            State::Upload {
                toggle: expected,
                size,
                offset,
            },
            Request::UploadSegment { toggle },
        ) = (self.state, req)
        else {
            return Err(AbortCode::INVALID_COMMAND);
        };
        if toggle != expected {
            return Err(AbortCode::TOGGLE_BIT_NOT_ALTERNATED);
        }
        let (data, len) = self.read_segment(access, offset, size)?;
        let offset = offset + u32::from(len);
        let last = offset >= size;
        if last {
            self.finish();
        } else {
            self.state = State::Upload {
                toggle: !toggle,
                size,
                offset,
            };
        }
        Self::send(
            out,
            tx,
            Response::UploadSegment {
                toggle,
                last,
                len,
                data,
            },
        );
        Ok(())
    }

    /// Reads up to 7 bytes at `offset` of a value announced as `size` bytes long. A value
    /// that shrank under the transfer aborts it (0x08000024, no data available).
    fn read_segment(
        &self,
        access: &mut dyn ObjectAccess,
        offset: u32,
        size: u32,
    ) -> Result<([u8; 7], u8), AbortCode> {
        let mut data = [0u8; 7];
        let want = (size - offset.min(size)).min(7) as usize;
        let info = access.read(
            self.mux.index,
            self.mux.sub,
            offset as usize,
            &mut data[..want],
        )?;
        if info.copied < want {
            return Err(AbortCode::NO_DATA);
        }
        Ok((data, want as u8))
    }

    fn block_segment(
        &mut self,
        seg: BlockSegment,
        tx: Id,
        access: &mut dyn ObjectAccess,
        out: &mut Outbox,
    ) {
        let State::BlockDownload {
            crc_on,
            size,
            mut flushed,
            seq,
            mut pending,
            ..
        } = self.state
        else {
            return;
        };
        if seg.seqno == 0 || seg.seqno > self.block_size {
            self.abort(AbortCode::INVALID_SEQUENCE_NUMBER, access, out);
            return;
        }
        let end_of_block = seg.last || seg.seqno == self.block_size;
        if seg.seqno != seq + 1 {
            // Out of sequence (a segment was lost, or this one is repeated): ignore it, and
            // at the end of the block acknowledge what arrived in order.
            if end_of_block {
                Self::send(
                    out,
                    tx,
                    Response::BlockDownloadAck {
                        ackseq: seq,
                        blksize: self.block_size,
                    },
                );
                self.set_block_seq(0);
            }
            return;
        }
        if let Some(prev) = pending {
            flushed = flushed.saturating_add(7);
            if size.is_some_and(|s| flushed > s) {
                self.abort(AbortCode::LENGTH_TOO_HIGH, access, out);
                return;
            }
            if let Err(code) = access.write_segment(self.mux.index, self.mux.sub, &prev) {
                self.abort(code, access, out);
                return;
            }
            self.crc.update(&prev);
        }
        pending = Some(seg.data);
        self.state = State::BlockDownload {
            crc_on,
            size,
            flushed,
            seq: if end_of_block { 0 } else { seg.seqno },
            pending,
            finished: seg.last,
        };
        if end_of_block {
            Self::send(
                out,
                tx,
                Response::BlockDownloadAck {
                    ackseq: seg.seqno,
                    blksize: self.block_size,
                },
            );
        }
    }

    fn set_block_seq(&mut self, new: u8) {
        if let State::BlockDownload { seq, .. } = &mut self.state {
            *seq = new;
        }
    }

    fn block_download_end(
        &mut self,
        req: Request,
        tx: Id,
        access: &mut dyn ObjectAccess,
        out: &mut Outbox,
    ) -> Result<(), AbortCode> {
        let (
            State::BlockDownload {
                crc_on,
                size,
                flushed,
                pending,
                ..
            },
            Request::BlockDownloadEnd { unused, crc },
        ) = (self.state, req)
        else {
            return Err(AbortCode::INVALID_COMMAND);
        };
        let last = pending.unwrap_or_default();
        let len = 7 - usize::from(unused.min(7));
        let total = flushed.saturating_add(len as u32);
        if let Some(s) = size {
            if total > s {
                return Err(AbortCode::LENGTH_TOO_HIGH);
            }
            if total < s {
                return Err(AbortCode::LENGTH_TOO_LOW);
            }
        }
        access.write_segment(self.mux.index, self.mux.sub, &last[..len])?;
        self.crc.update(&last[..len]);
        if crc_on && self.crc.value() != crc {
            return Err(AbortCode::CRC_ERROR);
        }
        access.write_end(self.mux.index, self.mux.sub)?;
        self.finish();
        Self::send(out, tx, Response::BlockDownloadEnd);
        Ok(())
    }

    /// Sends the segments of one upload block, from the current block start.
    fn send_block(
        &mut self,
        tx: Id,
        access: &mut dyn ObjectAccess,
        out: &mut Outbox,
    ) -> Result<(), AbortCode> {
        let (crc_on, size, blksize, block_start) = match self.state {
            State::BlockUploadInitiated {
                crc_on,
                size,
                blksize,
            } => {
                self.crc = Crc16::new();
                (crc_on, size, blksize, 0)
            }
            State::BlockUpload {
                crc_on,
                size,
                blksize,
                block_start,
                ..
            } => (crc_on, size, blksize, block_start),
            _ => return Err(AbortCode::INVALID_COMMAND),
        };
        let mut crc = self.crc;
        self.block_crcs[0] = crc.value();
        let mut offset = block_start;
        let mut sent = 0u8;
        let mut last_len = None;
        while sent < blksize {
            sent += 1;
            let (data, len) = self.read_segment(access, offset, size)?;
            offset += u32::from(len);
            crc.update(&data[..usize::from(len)]);
            self.block_crcs[usize::from(sent)] = crc.value();
            let last = offset >= size;
            Self::send_segment(
                out,
                tx,
                BlockSegment {
                    last,
                    seqno: sent,
                    data,
                },
            );
            if last {
                last_len = Some(len);
                break;
            }
        }
        self.state = State::BlockUpload {
            crc_on,
            size,
            blksize,
            block_start,
            sent,
            last_len,
        };
        Ok(())
    }

    fn send_segment(out: &mut Outbox, tx: Id, seg: BlockSegment) {
        out.push(Frame::data_array(tx, seg.encode()));
    }

    fn block_upload_ack(
        &mut self,
        req: Request,
        tx: Id,
        access: &mut dyn ObjectAccess,
        out: &mut Outbox,
    ) -> Result<(), AbortCode> {
        let (
            State::BlockUpload {
                crc_on,
                size,
                block_start,
                sent,
                last_len,
                ..
            },
            Request::BlockUploadAck { ackseq, blksize },
        ) = (self.state, req)
        else {
            return Err(AbortCode::INVALID_COMMAND);
        };
        if blksize == 0 || blksize > MAX_BLOCK_SIZE {
            return Err(AbortCode::INVALID_BLOCK_SIZE);
        }
        if ackseq > sent {
            return Err(AbortCode::INVALID_SEQUENCE_NUMBER);
        }
        // CRC of the data acknowledged so far.
        self.crc = Crc16::from_value(self.block_crcs[usize::from(ackseq)]);
        if ackseq == sent
            && let Some(len) = last_len
        {
            self.state = State::BlockUploadEnding;
            let crc = if crc_on { self.crc.value() } else { 0 };
            Self::send(
                out,
                tx,
                Response::BlockUploadEnd {
                    unused: 7 - len,
                    crc,
                },
            );
            return Ok(());
        }
        // Segments 1..=ackseq were full (the last one is never followed by more); the next
        // block starts after them, repeating whatever was not acknowledged.
        let block_start = block_start + 7 * u32::from(ackseq);
        self.state = State::BlockUpload {
            crc_on,
            size,
            blksize,
            block_start,
            sent: 0,
            last_len: None,
        };
        self.send_block(tx, access, out)
    }
}
