//! One SDO client channel (CiA 301 §7.2.4): expedited, segmented and block transfers in
//! both directions, as a sans-IO state machine.
//!
//! The client talks to one server over a pair of COB-IDs (by default 0x600 + node-ID for
//! requests and 0x580 + node-ID for responses, §7.3.4 pre-defined connection set). A
//! transfer starts with [`SdoClient::start_upload`] or [`SdoClient::start_download`]; the
//! responses are fed to [`SdoClient::on_frame`], the timers to [`SdoClient::on_tick`], and
//! the outcome comes out of [`SdoClient::poll_event`] as [`SdoEvent`]s.
//!
//! Decisions where CiA 301 leaves room:
//! * [`Mode::Auto`] downloads 1..=4 bytes expedited, everything else segmented, or in
//!   block mode from [`ClientConfig::block_threshold`] bytes on; it uploads with a normal
//!   initiate (the server chooses expedited or segmented).
//! * Fallback: when the server answers a block initiate with abort 0x05040001 (command
//!   specifier not valid or unknown: it does not implement block transfer), 0x05040002
//!   (invalid block size) or 0x06010000 (unsupported access), and
//!   [`ClientConfig::fallback`] is on, the client reports [`SdoEvent::FellBack`] and
//!   repeats the transfer with the normal (segmented) protocol. Any other abort ends the
//!   transfer: the object is wrong, not the protocol.
//! * A response that is not the next step of the transfer aborts it with 0x05040001; a
//!   segment with the wrong toggle bit with 0x05030000; a CRC mismatch with 0x05040004; an
//!   uploaded length different from the indicated size with 0x06070010. The abort goes
//!   on the bus and is reported with `by_server: false`.
//! * A server that stays silent for [`ClientConfig::timeout`] (default 1 s) after a
//!   request is aborted with 0x05040000 on the bus (unless
//!   [`ClientConfig::abort_on_timeout`] is off, as for a network scan).
//!   [`SdoClient::next_deadline`] may be earlier than that timeout: transfers back to back
//!   keep the instant of an earlier request while it is ahead, so that the driver's timer
//!   moves once per timeout rather than at every request; the tick at that instant only
//!   moves it on.
//! * Block download sends a whole block into the outbox at once; the driver's transmit
//!   queue must hold it (the [`crate::master::Master`] paces its frames itself).
//! * Block upload acknowledges at the segment whose number is the block size or at the
//!   segment flagged last, with the number of the last segment received in order
//!   (§7.2.4.3.13); out-of-order segments are ignored and the server repeats them.

use std::collections::VecDeque;

use crate::abort::AbortCode;
use crate::sdo::crc::Crc16;
use crate::sdo::wire::{BlockSegment, Initiate, Mux, Request, Response};
use cantwin_can::{Duration, Frame, Id, Instant, Outbox};

/// The default SDO client timeout.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(1);

/// The largest number of segments in a block (CiA 301 §7.2.4.3.9).
pub const MAX_BLOCK_SIZE: u8 = 127;

/// The abort codes that make a refused block transfer fall back to segmented.
pub const FALLBACK_CODES: [AbortCode; 3] = [
    AbortCode::INVALID_COMMAND,
    AbortCode::INVALID_BLOCK_SIZE,
    AbortCode::UNSUPPORTED_ACCESS,
];

/// How a transfer is carried.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mode {
    /// Chosen by size (see the module documentation).
    #[default]
    Auto,
    /// Expedited (downloads of 1..=4 bytes; for uploads the server decides).
    Expedited,
    /// Segmented (for uploads: a normal initiate, the server may still answer expedited).
    Segmented,
    /// Block transfer with this many segments per block (1..=127).
    Block {
        /// Segments per block the client asks for (uploads) — downloads use the server's.
        blksize: u8,
    },
}

/// Settings of an SDO client.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClientConfig {
    /// How long to wait for each response.
    pub timeout: Duration,
    /// Send abort 0x05040000 when the server times out.
    pub abort_on_timeout: bool,
    /// Offer and check the block CRC.
    pub crc: bool,
    /// Protocol switch threshold for block uploads (0: the server must not switch).
    pub pst: u8,
    /// In [`Mode::Auto`], download in block mode from this many bytes on.
    pub block_threshold: Option<usize>,
    /// Retry a refused block transfer as segmented.
    pub fallback: bool,
    /// Report [`SdoEvent::Progress`] every time this many more bytes are through.
    pub progress_step: Option<u32>,
}

impl Default for ClientConfig {
    fn default() -> Self {
        ClientConfig {
            timeout: DEFAULT_TIMEOUT,
            abort_on_timeout: true,
            crc: true,
            pst: 0,
            block_threshold: None,
            fallback: true,
            progress_step: None,
        }
    }
}

/// What a transfer produced.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SdoEvent {
    /// Bytes transferred so far (and the total, if known).
    Progress {
        /// Bytes through.
        done: u32,
        /// Total size, if known.
        total: Option<u32>,
    },
    /// The server refused the block transfer with `code`; the transfer is repeated with
    /// the segmented protocol.
    FellBack {
        /// The server's abort code.
        code: AbortCode,
    },
    /// The transfer succeeded; `data` is the uploaded value (empty for a download).
    Completed {
        /// The object.
        mux: Mux,
        /// Uploaded data.
        data: Vec<u8>,
    },
    /// The transfer was aborted.
    Aborted {
        /// The object.
        mux: Mux,
        /// The reason.
        code: AbortCode,
        /// Whether the server sent the abort (else the client did).
        by_server: bool,
    },
}

/// A transfer that cannot be started.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ClientError {
    /// Another transfer is in progress on this channel.
    #[error("an SDO transfer is already in progress")]
    Busy,
    /// An expedited download carries 1..=4 bytes.
    #[error("an expedited download carries 1 to 4 bytes, not {0}")]
    ExpeditedLength(usize),
    /// A block size outside 1..=127.
    #[error("block size {0} is outside 1..=127")]
    BlockSize(u8),
    /// The data does not fit the 32-bit size field.
    #[error("{0} bytes do not fit an SDO size")]
    TooLong(usize),
    /// A node-ID outside 1..=127.
    #[error("node-ID {0} is outside 1..=127")]
    NodeId(u8),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Idle,
    DlInitiate {
        expedited: bool,
    },
    DlSegment {
        toggle: bool,
        /// Bytes in the segment awaiting confirmation.
        len: usize,
        last: bool,
    },
    BlkDlInitiate,
    BlkDlBlock {
        /// Segments sent in this block.
        sent: u8,
        /// Data bytes of the last segment, if this block holds it.
        last_len: Option<u8>,
    },
    BlkDlEnd,
    UpInitiate,
    UpSegment {
        toggle: bool,
    },
    BlkUpInitiate {
        blksize: u8,
    },
    BlkUpBlock {
        blksize: u8,
        /// Next sequence number expected in order.
        expected: u8,
        got_last: bool,
    },
    BlkUpEnd,
}

/// One SDO client channel.
#[derive(Debug, Clone)]
pub struct SdoClient {
    tx: Id,
    rx: Id,
    config: ClientConfig,
    state: State,
    mux: Mux,
    /// Download: the data; upload: what arrived so far.
    data: Vec<u8>,
    /// A buffer handed back by [`Self::recycle`], for the next upload to fill.
    spare: Vec<u8>,
    /// Download: bytes confirmed by the server (start of the current block or segment).
    offset: usize,
    /// Upload: the size the server indicated.
    size: Option<u32>,
    crc_on: bool,
    /// The transfer may still fall back to segmented.
    may_fall_back: bool,
    /// When the server's response is due (the timeout).
    deadline: Option<Instant>,
    /// The instant [`Self::next_deadline`] reports while a transfer runs: never later than
    /// `deadline`, and kept from an earlier request when that is still ahead.
    wake: Option<Instant>,
    reported: u32,
    events: VecDeque<SdoEvent>,
}

impl SdoClient {
    /// A client sending requests on `tx` and receiving responses on `rx`.
    pub fn new(tx: Id, rx: Id) -> Self {
        SdoClient {
            tx,
            rx,
            config: ClientConfig::default(),
            state: State::Idle,
            mux: Mux::default(),
            data: Vec::new(),
            spare: Vec::new(),
            offset: 0,
            size: None,
            crc_on: false,
            may_fall_back: false,
            deadline: None,
            wake: None,
            reported: 0,
            events: VecDeque::new(),
        }
    }

    /// The client of node `node`'s default server (0x600 + node / 0x580 + node).
    pub fn for_node(node: u8) -> Result<Self, ClientError> {
        if !(1..=127).contains(&node) {
            return Err(ClientError::NodeId(node));
        }
        let n = u16::from(node);
        let tx =
            Id::standard(crate::wire::SDO_RX_BASE + n).map_err(|_| ClientError::NodeId(node))?;
        let rx =
            Id::standard(crate::wire::SDO_TX_BASE + n).map_err(|_| ClientError::NodeId(node))?;
        Ok(SdoClient::new(tx, rx))
    }

    /// The settings.
    pub fn config(&self) -> &ClientConfig {
        &self.config
    }

    /// Changes the settings (they apply from the next request).
    pub fn config_mut(&mut self) -> &mut ClientConfig {
        &mut self.config
    }

    /// The identifier requests go out on.
    pub fn tx_id(&self) -> Id {
        self.tx
    }

    /// The identifier responses arrive on.
    pub fn rx_id(&self) -> Id {
        self.rx
    }

    /// Whether no transfer is in progress.
    pub fn is_idle(&self) -> bool {
        self.state == State::Idle
    }

    /// When [`Self::on_tick`] must be called next: at the latest the response timeout,
    /// possibly earlier (see [`Self::on_tick`]); `None` when no transfer runs.
    pub fn next_deadline(&self) -> Option<Instant> {
        self.deadline.and(self.wake)
    }

    /// The next event, oldest first.
    pub fn poll_event(&mut self) -> Option<SdoEvent> {
        self.events.pop_front()
    }

    /// Hands back a buffer (typically the `data` of a [`SdoEvent::Completed`] that has
    /// been read) for the next upload to fill: a client that reads again and again then
    /// allocates once rather than at every transfer. Its contents are discarded; of two
    /// buffers the larger is kept.
    pub fn recycle(&mut self, buf: Vec<u8>) {
        if buf.capacity() > self.spare.capacity() {
            self.spare = buf;
        }
    }

    /// Starts reading `index`/`sub`.
    pub fn start_upload(
        &mut self,
        index: u16,
        sub: u8,
        mode: Mode,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), ClientError> {
        if !self.is_idle() {
            return Err(ClientError::Busy);
        }
        let mut buf = std::mem::take(&mut self.spare);
        buf.clear();
        self.begin(Mux::new(index, sub), buf);
        match mode {
            Mode::Block { blksize } => {
                if !(1..=127).contains(&blksize) {
                    return Err(ClientError::BlockSize(blksize));
                }
                self.may_fall_back = self.config.fallback;
                self.state = State::BlkUpInitiate { blksize };
                self.send(
                    Request::BlockUploadInitiate {
                        mux: self.mux,
                        crc: self.config.crc,
                        blksize,
                        pst: self.config.pst,
                    },
                    now,
                    out,
                );
            }
            Mode::Auto | Mode::Expedited | Mode::Segmented => self.initiate_upload(now, out),
        }
        Ok(())
    }

    /// Starts writing `data` to `index`/`sub`.
    pub fn start_download(
        &mut self,
        index: u16,
        sub: u8,
        data: Vec<u8>,
        mode: Mode,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), ClientError> {
        if !self.is_idle() {
            return Err(ClientError::Busy);
        }
        let len = data.len();
        if u32::try_from(len).is_err() {
            return Err(ClientError::TooLong(len));
        }
        let mode = match mode {
            Mode::Auto if (1..=4).contains(&len) => Mode::Expedited,
            Mode::Auto if self.config.block_threshold.is_some_and(|t| len >= t) => Mode::Block {
                blksize: MAX_BLOCK_SIZE,
            },
            Mode::Auto => Mode::Segmented,
            Mode::Expedited if !(1..=4).contains(&len) => {
                return Err(ClientError::ExpeditedLength(len));
            }
            Mode::Block { blksize } if !(1..=127).contains(&blksize) => {
                return Err(ClientError::BlockSize(blksize));
            }
            m => m,
        };
        self.begin(Mux::new(index, sub), data);
        match mode {
            Mode::Expedited => self.initiate_expedited_download(now, out),
            Mode::Block { .. } => {
                self.may_fall_back = self.config.fallback;
                self.state = State::BlkDlInitiate;
                self.send(
                    Request::BlockDownloadInitiate {
                        mux: self.mux,
                        crc: self.config.crc,
                        size: Some(self.len32()),
                    },
                    now,
                    out,
                );
            }
            Mode::Auto | Mode::Segmented => self.initiate_segmented_download(now, out),
        }
        Ok(())
    }

    /// Aborts the transfer in progress with `code` (sent on the bus and reported).
    pub fn abort(&mut self, code: AbortCode, out: &mut Outbox) {
        if !self.is_idle() {
            self.abort_local(code, true, out);
        }
    }

    /// Handles a frame if it is this channel's response; returns whether it was.
    pub fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) -> bool {
        if frame.is_remote() || frame.id() != self.rx {
            return false;
        }
        // CiA 301 §7.2.4.3: SDO frames carry 8 bytes; anything else is not a response.
        let Ok(b) = <&[u8; 8]>::try_from(frame.data_bytes()) else {
            return true;
        };
        if self.is_idle() {
            return true;
        }
        self.arm(now);
        // The answer a client reading small objects gets most: an expedited initiate
        // upload response (scs = 2, e = 1; CiA 301 §7.2.4.3.6) to the request in flight,
        // taken here as `step` takes it, without building a `Response` first.
        if self.state == State::UpInitiate && b[0] & 0xE2 == 0x42 && Mux::of_frame(b) == self.mux {
            // s = 1: n bytes of the 4 do not contain data; s = 0: the size is not given.
            let len = if b[0] & 0x01 != 0 {
                4 - usize::from((b[0] >> 2) & 0x03)
            } else {
                4
            };
            self.data.clear();
            self.data.extend_from_slice(&b[4..4 + len]);
            self.complete();
            return true;
        }
        if let State::BlkUpBlock { .. } = self.state {
            // Sequence number 0 with c = 1 cannot be a segment: it is the abort (0x80).
            if b[0] != 0x80 {
                self.upload_segment_in_block(BlockSegment::decode(b), now, out);
                return true;
            }
        }
        let resp = match Response::decode(b) {
            Ok(r) => r,
            Err(_) => {
                self.abort_local(AbortCode::INVALID_COMMAND, true, out);
                return true;
            }
        };
        if let Response::Abort { code, .. } = resp {
            self.server_abort(code, now, out);
            return true;
        }
        if let Err(code) = self.step(resp, now, out) {
            self.abort_local(code, true, out);
        }
        true
    }

    /// The response timeout. A tick before it only moves [`Self::next_deadline`] on to it.
    pub fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        if self.deadline.is_some_and(|d| now >= d) && !self.is_idle() {
            let send = self.config.abort_on_timeout;
            self.abort_local(AbortCode::TIMEOUT, send, out);
        } else if self.wake.is_some_and(|w| now >= w) {
            self.wake = self.deadline;
        }
    }

    /// Starts the response timeout at `now`. Transfers back to back keep the instant
    /// reported to the driver while it is still ahead: the driver then re-schedules its
    /// timer once per timeout rather than at every request, and the early tick at that
    /// instant re-arms to the real timeout.
    fn arm(&mut self, now: Instant) {
        let due = now.checked_add(self.config.timeout);
        self.deadline = due;
        self.wake = match (self.wake, due) {
            (Some(w), Some(d)) if w > now && w <= d => Some(w),
            _ => due,
        };
    }

    fn begin(&mut self, mux: Mux, data: Vec<u8>) {
        self.mux = mux;
        self.data = data;
        self.offset = 0;
        self.size = None;
        self.crc_on = false;
        self.may_fall_back = false;
        self.reported = 0;
    }

    fn len32(&self) -> u32 {
        // Checked at the start of the download.
        u32::try_from(self.data.len()).unwrap_or(u32::MAX)
    }

    fn send(&mut self, req: Request, now: Instant, out: &mut Outbox) {
        out.push(Frame::data_array(self.tx, req.encode()));
        self.arm(now);
    }

    fn finish(&mut self, event: SdoEvent) {
        self.state = State::Idle;
        self.deadline = None;
        self.events.push_back(event);
    }

    fn complete(&mut self) {
        let data = std::mem::take(&mut self.data);
        let total = u32::try_from(data.len()).unwrap_or(u32::MAX);
        if self.config.progress_step.is_some() && self.reported != total {
            self.events.push_back(SdoEvent::Progress {
                done: total,
                total: Some(total),
            });
        }
        let mux = self.mux;
        let data = if self.is_upload() { data } else { Vec::new() };
        self.finish(SdoEvent::Completed { mux, data });
    }

    fn is_upload(&self) -> bool {
        matches!(
            self.state,
            State::UpInitiate
                | State::UpSegment { .. }
                | State::BlkUpInitiate { .. }
                | State::BlkUpBlock { .. }
                | State::BlkUpEnd
        )
    }

    fn progress(&mut self, done: usize, total: Option<u32>) {
        let Some(step) = self.config.progress_step else {
            return;
        };
        let done = u32::try_from(done).unwrap_or(u32::MAX);
        if done.saturating_sub(self.reported) >= step.max(1) {
            self.reported = done;
            self.events.push_back(SdoEvent::Progress { done, total });
        }
    }

    fn abort_local(&mut self, code: AbortCode, send: bool, out: &mut Outbox) {
        if send {
            out.push(Frame::data_array(
                self.tx,
                Request::Abort {
                    mux: self.mux,
                    code,
                }
                .encode(),
            ));
        }
        self.data = Vec::new();
        let mux = self.mux;
        self.finish(SdoEvent::Aborted {
            mux,
            code,
            by_server: false,
        });
    }

    fn server_abort(&mut self, code: AbortCode, now: Instant, out: &mut Outbox) {
        let refused_block = matches!(
            self.state,
            State::BlkDlInitiate | State::BlkUpInitiate { .. }
        );
        if refused_block && self.may_fall_back && FALLBACK_CODES.contains(&code) {
            self.events.push_back(SdoEvent::FellBack { code });
            self.may_fall_back = false;
            if self.state == State::BlkDlInitiate {
                if (1..=4).contains(&self.data.len()) {
                    self.initiate_expedited_download(now, out);
                } else {
                    self.initiate_segmented_download(now, out);
                }
            } else {
                self.initiate_upload(now, out);
            }
            return;
        }
        self.data = Vec::new();
        let mux = self.mux;
        self.finish(SdoEvent::Aborted {
            mux,
            code,
            by_server: true,
        });
    }

    fn initiate_upload(&mut self, now: Instant, out: &mut Outbox) {
        self.state = State::UpInitiate;
        self.send(Request::InitiateUpload { mux: self.mux }, now, out);
    }

    /// The whole of `data` in the initiate request; the callers have checked that it holds
    /// 1 to 4 bytes.
    fn initiate_expedited_download(&mut self, now: Instant, out: &mut Outbox) {
        let len = self.data.len();
        let mut d = [0u8; 4];
        d[..len].copy_from_slice(&self.data);
        self.state = State::DlInitiate { expedited: true };
        let init = Initiate::Expedited {
            data: d,
            len: u8::try_from(len).ok(),
        };
        self.send(
            Request::InitiateDownload {
                mux: self.mux,
                init,
            },
            now,
            out,
        );
    }

    fn initiate_segmented_download(&mut self, now: Instant, out: &mut Outbox) {
        self.state = State::DlInitiate { expedited: false };
        let init = Initiate::Segmented {
            size: Some(self.len32()),
        };
        self.send(
            Request::InitiateDownload {
                mux: self.mux,
                init,
            },
            now,
            out,
        );
    }

    fn check_mux(&self, mux: Mux) -> Result<(), AbortCode> {
        if mux == self.mux {
            Ok(())
        } else {
            Err(AbortCode::INVALID_COMMAND)
        }
    }

    /// The next step of the transfer after response `resp`.
    fn step(&mut self, resp: Response, now: Instant, out: &mut Outbox) -> Result<(), AbortCode> {
        match (self.state, resp) {
            // ---- expedited / segmented download (§7.2.4.3.3–4) ----
            (State::DlInitiate { expedited }, Response::InitiateDownload { mux }) => {
                self.check_mux(mux)?;
                if expedited {
                    self.complete();
                } else {
                    self.send_download_segment(false, now, out);
                }
                Ok(())
            }
            (State::DlSegment { toggle, len, last }, Response::DownloadSegment { toggle: t }) => {
                if t != toggle {
                    return Err(AbortCode::TOGGLE_BIT_NOT_ALTERNATED);
                }
                self.offset += len;
                if last {
                    self.complete();
                } else {
                    self.progress(self.offset, Some(self.len32()));
                    self.send_download_segment(!toggle, now, out);
                }
                Ok(())
            }
            // ---- block download (§7.2.4.3.9–11) ----
            (State::BlkDlInitiate, Response::BlockDownloadInitiate { mux, crc, blksize }) => {
                self.check_mux(mux)?;
                self.crc_on = crc && self.config.crc;
                self.send_download_block(blksize, out)?;
                self.arm(now);
                Ok(())
            }
            (
                State::BlkDlBlock { sent, last_len },
                Response::BlockDownloadAck { ackseq, blksize },
            ) => {
                if ackseq > sent {
                    return Err(AbortCode::INVALID_SEQUENCE_NUMBER);
                }
                let acked = usize::from(ackseq) * 7;
                match last_len {
                    Some(n) if ackseq == sent => {
                        // Everything is through: end with the unused byte count and CRC.
                        self.offset = self.data.len();
                        let crc = if self.crc_on {
                            Crc16::of(&self.data)
                        } else {
                            0
                        };
                        self.state = State::BlkDlEnd;
                        self.send(Request::BlockDownloadEnd { unused: 7 - n, crc }, now, out);
                    }
                    _ => {
                        // §7.2.4.3.10: the next block starts after the last segment the
                        // server received in order.
                        self.offset = (self.offset + acked).min(self.data.len());
                        self.progress(self.offset, Some(self.len32()));
                        self.send_download_block(blksize, out)?;
                        self.arm(now);
                    }
                }
                Ok(())
            }
            (State::BlkDlEnd, Response::BlockDownloadEnd) => {
                self.complete();
                Ok(())
            }
            // ---- expedited / segmented upload (§7.2.4.3.6–7) ----
            (
                State::UpInitiate | State::BlkUpInitiate { .. },
                Response::InitiateUpload { mux, init },
            ) => {
                // From a block initiate this is the protocol switch (§7.2.4.3.12, pst).
                self.check_mux(mux)?;
                match init {
                    Initiate::Expedited { data, len } => {
                        let n = usize::from(len.unwrap_or(4).min(4));
                        // Into the buffer the upload started with (see `recycle`).
                        self.data.clear();
                        self.data.extend_from_slice(&data[..n]);
                        self.state = State::UpInitiate;
                        self.complete();
                    }
                    Initiate::Segmented { size } => {
                        self.size = size;
                        self.state = State::UpSegment { toggle: false };
                        self.send(Request::UploadSegment { toggle: false }, now, out);
                    }
                }
                Ok(())
            }
            (
                State::UpSegment { toggle },
                Response::UploadSegment {
                    toggle: t,
                    last,
                    len,
                    data,
                },
            ) => {
                if t != toggle {
                    return Err(AbortCode::TOGGLE_BIT_NOT_ALTERNATED);
                }
                self.data
                    .extend_from_slice(&data[..usize::from(len.min(7))]);
                if last {
                    self.check_size()?;
                    self.complete();
                } else {
                    if self.size.is_some_and(|s| self.data.len() > s as usize) {
                        return Err(AbortCode::TYPE_MISMATCH);
                    }
                    self.progress(self.data.len(), self.size);
                    self.state = State::UpSegment { toggle: !toggle };
                    self.send(Request::UploadSegment { toggle: !toggle }, now, out);
                }
                Ok(())
            }
            // ---- block upload (§7.2.4.3.12–14) ----
            (
                State::BlkUpInitiate { blksize },
                Response::BlockUploadInitiate { mux, crc, size },
            ) => {
                self.check_mux(mux)?;
                self.crc_on = crc && self.config.crc;
                self.size = size;
                if let Some(s) = size {
                    // Bounded: the size comes from the bus.
                    self.data.reserve((s as usize).min(1 << 20));
                }
                self.state = State::BlkUpBlock {
                    blksize,
                    expected: 1,
                    got_last: false,
                };
                self.send(Request::BlockUploadStart, now, out);
                Ok(())
            }
            (State::BlkUpEnd, Response::BlockUploadEnd { unused, crc }) => {
                let unused = usize::from(unused);
                // The last segment was kept whole: drop the bytes the server did not use.
                if unused > 7 || unused > self.data.len() {
                    return Err(AbortCode::INVALID_COMMAND);
                }
                self.data.truncate(self.data.len() - unused);
                self.check_size()?;
                if self.crc_on && Crc16::of(&self.data) != crc {
                    return Err(AbortCode::CRC_ERROR);
                }
                out.push(Frame::data_array(self.tx, Request::BlockUploadEnd.encode()));
                self.complete();
                Ok(())
            }
            _ => Err(AbortCode::INVALID_COMMAND),
        }
    }

    fn check_size(&self) -> Result<(), AbortCode> {
        match self.size {
            Some(s) if s as usize != self.data.len() => Err(AbortCode::TYPE_MISMATCH),
            _ => Ok(()),
        }
    }

    fn send_download_segment(&mut self, toggle: bool, now: Instant, out: &mut Outbox) {
        let rest = &self.data[self.offset.min(self.data.len())..];
        let len = rest.len().min(7);
        let last = rest.len() <= 7;
        let mut d = [0u8; 7];
        d[..len].copy_from_slice(&rest[..len]);
        self.state = State::DlSegment { toggle, len, last };
        self.send(
            Request::DownloadSegment {
                toggle,
                last,
                // len ≤ 7.
                len: u8::try_from(len).unwrap_or(7),
                data: d,
            },
            now,
            out,
        );
    }

    /// Sends the segments of one block from `self.offset`.
    fn send_download_block(&mut self, blksize: u8, out: &mut Outbox) -> Result<(), AbortCode> {
        if !(1..=127).contains(&blksize) {
            return Err(AbortCode::INVALID_BLOCK_SIZE);
        }
        let mut sent = 0u8;
        let mut last_len = None;
        let mut pos = self.offset;
        while sent < blksize {
            sent += 1;
            let rest = &self.data[pos.min(self.data.len())..];
            let len = rest.len().min(7);
            let last = rest.len() <= 7;
            let mut d = [0u8; 7];
            d[..len].copy_from_slice(&rest[..len]);
            let seg = BlockSegment {
                last,
                seqno: sent,
                data: d,
            };
            out.push(Frame::data_array(self.tx, seg.encode()));
            pos += len;
            if last {
                last_len = u8::try_from(len).ok();
                break;
            }
        }
        self.state = State::BlkDlBlock { sent, last_len };
        Ok(())
    }

    fn upload_segment_in_block(&mut self, seg: BlockSegment, now: Instant, out: &mut Outbox) {
        let State::BlkUpBlock {
            blksize,
            mut expected,
            mut got_last,
        } = self.state
        else {
            return;
        };
        if seg.seqno == 0 || seg.seqno > blksize {
            self.abort_local(AbortCode::INVALID_SEQUENCE_NUMBER, true, out);
            return;
        }
        if seg.seqno == expected && !got_last {
            self.data.extend_from_slice(&seg.data);
            expected += 1;
            got_last = seg.last;
            if self.size.is_some_and(|s| self.data.len() > s as usize + 7) {
                self.abort_local(AbortCode::TYPE_MISMATCH, true, out);
                return;
            }
        }
        if seg.seqno == blksize || seg.last {
            // End of the block: acknowledge the last segment received in order.
            let ackseq = expected - 1;
            let next = blksize;
            self.send(
                Request::BlockUploadAck {
                    ackseq,
                    blksize: next,
                },
                now,
                out,
            );
            if got_last {
                self.state = State::BlkUpEnd;
            } else {
                self.progress(self.data.len(), self.size);
                self.state = State::BlkUpBlock {
                    blksize: next,
                    expected: 1,
                    got_last: false,
                };
            }
        } else {
            self.state = State::BlkUpBlock {
                blksize,
                expected,
                got_last,
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const T0: Instant = Instant::ZERO;

    fn client() -> (SdoClient, Outbox) {
        (SdoClient::for_node(5).unwrap(), Outbox::new())
    }

    /// A client whose upload of 0x2003 sub 0 in `mode` started at `T0`, its request sent.
    fn uploading(mode: Mode) -> (SdoClient, Outbox) {
        let (mut c, mut out) = client();
        c.start_upload(0x2003, 0, mode, T0, &mut out).unwrap();
        out.clear();
        (c, out)
    }

    /// A client whose download of `data` to 0x2003 sub 0 in `mode` started at `T0`, its
    /// request sent.
    fn downloading(data: Vec<u8>, mode: Mode) -> (SdoClient, Outbox) {
        let (mut c, mut out) = client();
        c.start_download(0x2003, 0, data, mode, T0, &mut out)
            .unwrap();
        out.clear();
        (c, out)
    }

    fn resp(c: &mut SdoClient, b: [u8; 8], out: &mut Outbox) -> Vec<[u8; 8]> {
        assert!(c.on_frame(&Frame::std(0x585, &b).unwrap(), T0, out));
        out.drain()
            .map(|f| {
                assert_eq!(f.id().as_raw(), 0x605);
                <[u8; 8]>::try_from(f.data_bytes()).unwrap()
            })
            .collect()
    }

    fn events(c: &mut SdoClient) -> Vec<SdoEvent> {
        std::iter::from_fn(|| c.poll_event()).collect()
    }

    const MUX: Mux = Mux::new(0x2003, 0);

    fn aborted(code: AbortCode, by_server: bool) -> SdoEvent {
        SdoEvent::Aborted {
            mux: MUX,
            code,
            by_server,
        }
    }

    #[test]
    fn cia301_7_2_4_3_7_upload_segment_with_wrong_toggle_aborts_0x05030000() {
        let (mut c, mut out) = uploading(Mode::Segmented);
        let r = resp(&mut c, [0x41, 0x03, 0x20, 0, 10, 0, 0, 0], &mut out);
        assert_eq!(r, [[0x60, 0, 0, 0, 0, 0, 0, 0]]);
        // Toggle 1 where 0 is expected.
        let r = resp(&mut c, [0x10, 1, 2, 3, 4, 5, 6, 7], &mut out);
        assert_eq!(r, [[0x80, 0x03, 0x20, 0, 0x00, 0x00, 0x03, 0x05]]);
        assert_eq!(
            events(&mut c),
            [aborted(AbortCode::TOGGLE_BIT_NOT_ALTERNATED, false)]
        );
        assert!(c.is_idle());
    }

    #[test]
    fn cia301_7_2_4_3_14_block_upload_crc_mismatch_aborts_0x05040004() {
        let (mut c, mut out) = client();
        c.start_upload(0x2003, 0, Mode::Block { blksize: 4 }, T0, &mut out)
            .unwrap();
        assert_eq!(
            out.drain().next().unwrap().data_bytes(),
            [0xA4, 0x03, 0x20, 0, 4, 0, 0, 0]
        );
        let r = resp(&mut c, [0xC6, 0x03, 0x20, 0, 3, 0, 0, 0], &mut out);
        assert_eq!(r, [[0xA3, 0, 0, 0, 0, 0, 0, 0]]);
        let r = resp(&mut c, [0x81, 1, 2, 3, 0, 0, 0, 0], &mut out);
        assert_eq!(r, [[0xA2, 1, 4, 0, 0, 0, 0, 0]]);
        // n = 4 unused bytes, wrong CRC.
        let r = resp(&mut c, [0xD1, 0x12, 0x34, 0, 0, 0, 0, 0], &mut out);
        assert_eq!(r, [[0x80, 0x03, 0x20, 0, 0x04, 0x00, 0x04, 0x05]]);
        assert_eq!(events(&mut c), [aborted(AbortCode::CRC_ERROR, false)]);
    }

    #[test]
    fn cia301_7_2_4_3_13_block_upload_sequence_number_above_block_size_aborts_0x05040003() {
        let (mut c, mut out) = uploading(Mode::Block { blksize: 2 });
        resp(&mut c, [0xC4, 0x03, 0x20, 0, 0, 0, 0, 0], &mut out);
        let r = resp(&mut c, [0x03, 0, 0, 0, 0, 0, 0, 0], &mut out);
        assert_eq!(r, [[0x80, 0x03, 0x20, 0, 0x03, 0x00, 0x04, 0x05]]);
        assert_eq!(
            events(&mut c),
            [aborted(AbortCode::INVALID_SEQUENCE_NUMBER, false)]
        );
    }

    #[test]
    fn cia301_7_2_4_3_10_block_download_ack_beyond_the_block_aborts_0x05040003() {
        let (mut c, mut out) = downloading(vec![0; 20], Mode::Block { blksize: 127 });
        let r = resp(&mut c, [0xA4, 0x03, 0x20, 0, 2, 0, 0, 0], &mut out);
        assert_eq!(r.len(), 2, "a block of 2 segments");
        let r = resp(&mut c, [0xA2, 3, 2, 0, 0, 0, 0, 0], &mut out);
        assert_eq!(r, [[0x80, 0x03, 0x20, 0, 0x03, 0x00, 0x04, 0x05]]);
    }

    #[test]
    fn cia301_7_2_4_3_9_block_download_with_server_block_size_0_aborts_0x05040002() {
        let (mut c, mut out) = downloading(vec![0; 20], Mode::Block { blksize: 127 });
        let r = resp(&mut c, [0xA4, 0x03, 0x20, 0, 0, 0, 0, 0], &mut out);
        assert_eq!(r, [[0x80, 0x03, 0x20, 0, 0x02, 0x00, 0x04, 0x05]]);
    }

    #[test]
    fn cia301_7_2_4_3_17_unexpected_response_aborts_0x05040001() {
        let (mut c, mut out) = uploading(Mode::Auto);
        // A download response to an upload request.
        let r = resp(&mut c, [0x60, 0x03, 0x20, 0, 0, 0, 0, 0], &mut out);
        assert_eq!(r, [[0x80, 0x03, 0x20, 0, 0x01, 0x00, 0x04, 0x05]]);
        assert_eq!(events(&mut c), [aborted(AbortCode::INVALID_COMMAND, false)]);
    }

    #[test]
    fn cia301_7_2_4_3_3_uploaded_length_differs_from_indicated_size() {
        let (mut c, mut out) = uploading(Mode::Auto);
        resp(&mut c, [0x41, 0x03, 0x20, 0, 3, 0, 0, 0], &mut out);
        // The last segment brings 2 bytes instead of 3 (n = 5).
        let r = resp(&mut c, [0x0B, 1, 2, 0, 0, 0, 0, 0], &mut out);
        assert_eq!(r, [[0x80, 0x03, 0x20, 0, 0x10, 0x00, 0x07, 0x06]]);
        assert_eq!(events(&mut c), [aborted(AbortCode::TYPE_MISMATCH, false)]);
    }

    #[test]
    fn cia301_7_2_4_3_9_refused_block_download_of_3_bytes_falls_back_to_expedited() {
        let (mut c, mut out) = downloading(vec![1, 2, 3], Mode::Block { blksize: 127 });
        // Abort 0x0504 0001 (command specifier not valid): the server knows no block
        // transfer, so the 3 bytes go in one expedited initiate (n = 1, e = 1, s = 1).
        let r = resp(
            &mut c,
            [0x80, 0x03, 0x20, 0, 0x01, 0x00, 0x04, 0x05],
            &mut out,
        );
        assert_eq!(r, [[0x27, 0x03, 0x20, 0, 1, 2, 3, 0]]);
        assert_eq!(
            events(&mut c),
            [SdoEvent::FellBack {
                code: AbortCode::INVALID_COMMAND
            }]
        );
    }

    #[test]
    fn timeout_is_configurable_and_can_be_silent() {
        let (mut c, mut out) = client();
        c.config_mut().timeout = Duration::from_millis(20);
        c.config_mut().abort_on_timeout = false;
        c.start_upload(0x2003, 0, Mode::Auto, T0, &mut out).unwrap();
        out.clear();
        assert_eq!(c.next_deadline(), Some(Instant::from_nanos(20_000_000)));
        c.on_tick(Instant::from_nanos(19_999_999), &mut out);
        assert!(events(&mut c).is_empty());
        c.on_tick(Instant::from_nanos(20_000_000), &mut out);
        assert!(out.is_empty());
        assert_eq!(events(&mut c), [aborted(AbortCode::TIMEOUT, false)]);
        assert_eq!(c.next_deadline(), None);
    }

    #[test]
    fn back_to_back_transfers_keep_the_wake_up_and_time_out_on_time() {
        let ms = |n: u64| Instant::from_nanos(n * 1_000_000);
        let (mut c, mut out) = client();
        c.start_upload(0x2003, 0, Mode::Auto, T0, &mut out).unwrap();
        // The expedited answer at 10 ms (CiA 301 §7.2.4.3.6), the next request at once.
        let answer = Frame::std(0x585, &[0x4F, 0x03, 0x20, 0, 7, 0, 0, 0]).unwrap();
        assert!(c.on_frame(&answer, ms(10), &mut out));
        let Some(SdoEvent::Completed { data, .. }) = c.poll_event() else {
            panic!("not completed");
        };
        assert_eq!(data, [7]);
        c.recycle(data);
        c.start_upload(0x2003, 0, Mode::Auto, ms(10), &mut out)
            .unwrap();
        // The wake-up of the first request stays; the tick there moves it to the timeout.
        assert_eq!(c.next_deadline(), Some(ms(1000)));
        c.on_tick(ms(1000), &mut out);
        assert!(events(&mut c).is_empty());
        assert_eq!(c.next_deadline(), Some(ms(1010)));
        out.clear();
        c.on_tick(ms(1010), &mut out);
        assert_eq!(events(&mut c), [aborted(AbortCode::TIMEOUT, false)]);
        assert_eq!(c.next_deadline(), None);
    }

    #[test]
    fn start_errors() {
        let (mut c, mut out) = client();
        assert_eq!(
            c.start_download(1, 0, vec![0; 5], Mode::Expedited, T0, &mut out),
            Err(ClientError::ExpeditedLength(5))
        );
        assert_eq!(
            c.start_upload(1, 0, Mode::Block { blksize: 0 }, T0, &mut out),
            Err(ClientError::BlockSize(0))
        );
        c.start_upload(1, 0, Mode::Auto, T0, &mut out).unwrap();
        assert_eq!(
            c.start_upload(1, 0, Mode::Auto, T0, &mut out),
            Err(ClientError::Busy)
        );
        assert!(matches!(
            SdoClient::for_node(0),
            Err(ClientError::NodeId(0))
        ));
        assert!(matches!(
            SdoClient::for_node(128),
            Err(ClientError::NodeId(128))
        ));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]
        /// Whatever a server answers, the client never panics, and every transfer ends
        /// (completed or aborted) within the frames given or at its timeout.
        #[test]
        fn any_server_answers_end_every_transfer(
            mode in 0u8..4,
            upload in any::<bool>(),
            frames in proptest::collection::vec(any::<[u8; 8]>(), 0..40),
        ) {
            let (mut c, mut out) = client();
            let mode = [Mode::Auto, Mode::Expedited, Mode::Segmented, Mode::Block { blksize: 3 }][usize::from(mode)];
            let started = if upload {
                c.start_upload(0x2003, 0, mode, T0, &mut out)
            } else {
                c.start_download(0x2003, 0, vec![7; 3], mode, T0, &mut out)
            };
            prop_assert!(started.is_ok());
            for b in frames {
                c.on_frame(&Frame::std(0x585, &b).unwrap(), T0, &mut out);
            }
            c.on_tick(Instant::from_nanos(2_000_000_000), &mut out);
            prop_assert!(c.is_idle());
            let ends = events(&mut c)
                .into_iter()
                .filter(|e| matches!(e, SdoEvent::Completed { .. } | SdoEvent::Aborted { .. }))
                .count();
            prop_assert_eq!(ends, 1);
        }
    }
}
