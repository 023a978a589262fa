//! Reassembly of SDO transfers from the frames of a capture (CiA 301 §7.2.4.3): expedited,
//! segmented and block transfers, in either direction, one transfer per server node at a
//! time (the default SDO channel, 0x600/0x580 + node-ID).

use cantwin_canopen::abort::AbortCode;
use cantwin_canopen::sdo::wire::{BlockSegment, Initiate, Request, Response};

/// Bytes of a transfer's data the report keeps for display; the size counts all of them.
pub const KEPT_BYTES: usize = 256;

/// Which way the data of a transfer goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// Client → server (a write).
    Download,
    /// Server → client (a read).
    Upload,
}

/// The SDO protocol a transfer used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mode {
    /// Up to 4 bytes in the initiate frames.
    Expedited,
    /// 7 bytes per confirmed segment.
    Segmented,
    /// Blocks of up to 127 unconfirmed segments.
    Block,
}

/// How a transfer ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Completed: the last confirmation was seen.
    Done,
    /// Aborted; `by_server` tells who sent the abort.
    Aborted {
        /// The abort code on the wire.
        code: AbortCode,
        /// The server (0x580 + node) sent it, not the client.
        by_server: bool,
    },
    /// A request got no answer before the next request or the end of the capture.
    NoResponse,
    /// The server had answered the last request, but the transfer did not finish before
    /// the next one started or the capture ended.
    Incomplete,
}

/// One SDO transfer, reassembled.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Transfer {
    /// When the first request was seen (capture time, ns).
    pub start_ns: u64,
    /// When the transfer ended (its last frame).
    pub end_ns: u64,
    /// The capture channel.
    pub channel: String,
    /// The server's node-ID.
    pub node: u8,
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Read or write; `None` when only an abort was seen.
    pub direction: Option<Direction>,
    /// Expedited, segmented or block; `None` when only an abort was seen.
    pub mode: Option<Mode>,
    /// Bytes transferred.
    pub size: usize,
    /// The first [`KEPT_BYTES`] of the data.
    pub data: Vec<u8>,
    /// How it ended.
    pub outcome: Outcome,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// Waiting for the server's answer to an initiate or segment request.
    Confirmed,
    /// Segmented download: the client sent the segment marked last.
    SegDownLast,
    /// Block download: client requests are block segments.
    BlockDownData,
    /// Block download: the last segment was sent; next request is the end.
    BlockDownEnd,
    /// Block upload: server responses are block segments.
    BlockUpData,
    /// Block upload: the last segment was received; next response is the end.
    BlockUpEnd,
}

#[derive(Debug)]
struct Open {
    t: Transfer,
    phase: Phase,
    /// Segments of the current block, not yet acknowledged.
    block: Vec<[u8; 7]>,
    /// The last frame of the transfer came from the server.
    answered: bool,
}

impl Open {
    /// How a transfer ends that is cut short.
    fn cut_short(&self) -> Outcome {
        if self.answered {
            Outcome::Incomplete
        } else {
            Outcome::NoResponse
        }
    }

    fn push(&mut self, bytes: &[u8]) {
        let room = KEPT_BYTES.saturating_sub(self.t.data.len());
        self.t
            .data
            .extend_from_slice(&bytes[..bytes.len().min(room)]);
        self.t.size += bytes.len();
    }

    /// Commits the first `ackseq` segments of the block (§7.2.4.3.10: the receiver
    /// confirms the last segment it received in sequence).
    fn commit_block(&mut self, ackseq: u8) {
        let block = std::mem::take(&mut self.block);
        for seg in block.iter().take(usize::from(ackseq)) {
            self.push(seg);
        }
    }

    /// Drops the `unused` padding bytes of the last segment (§7.2.4.3.11, n).
    fn trim(&mut self, unused: u8) {
        let n = usize::from(unused.min(7));
        self.t.size = self.t.size.saturating_sub(n);
        if self.t.data.len() > self.t.size {
            self.t.data.truncate(self.t.size);
        }
    }
}

/// Reassembles the transfers of one server node on one channel.
#[derive(Debug, Default)]
pub struct Tracker {
    open: Option<Open>,
}

fn new_transfer(start_ns: u64, channel: &str, node: u8, index: u16, sub: u8) -> Transfer {
    Transfer {
        start_ns,
        end_ns: start_ns,
        channel: channel.to_string(),
        node,
        index,
        sub,
        direction: None,
        mode: None,
        size: 0,
        data: Vec::new(),
        outcome: Outcome::Done,
    }
}

impl Tracker {
    /// A client request frame (0x600 + node, 8 bytes) at `t`; returns the transfers it ended.
    pub fn on_request(&mut self, t: u64, channel: &str, node: u8, b: &[u8; 8]) -> Vec<Transfer> {
        let done = self.request(t, channel, node, b);
        if let Some(open) = &mut self.open {
            open.answered = false;
        }
        done
    }

    /// A server response frame (0x580 + node, 8 bytes) at `t`; returns the transfers it
    /// ended.
    pub fn on_response(&mut self, t: u64, channel: &str, node: u8, b: &[u8; 8]) -> Vec<Transfer> {
        let done = self.response(t, channel, node, b);
        if let Some(open) = &mut self.open {
            open.answered = true;
        }
        done
    }

    fn request(&mut self, t: u64, channel: &str, node: u8, b: &[u8; 8]) -> Vec<Transfer> {
        let mut done = Vec::new();
        if let Some(open) = &mut self.open {
            match open.phase {
                Phase::BlockDownData if b[0] != 0x80 => {
                    let seg = BlockSegment::decode(b);
                    open.block.push(seg.data);
                    open.t.end_ns = t;
                    if seg.last {
                        open.phase = Phase::BlockDownEnd;
                    }
                    return done;
                }
                Phase::BlockUpData | Phase::BlockUpEnd => {
                    if let Ok(Request::BlockUploadAck { ackseq, .. }) = Request::decode(b) {
                        open.commit_block(ackseq);
                        open.t.end_ns = t;
                        return done;
                    }
                }
                _ => {}
            }
        }
        let Ok(req) = Request::decode(b) else {
            return done;
        };
        // A new initiate while a request is unanswered: the old one got no response.
        let initiate = matches!(
            req,
            Request::InitiateDownload { .. }
                | Request::InitiateUpload { .. }
                | Request::BlockDownloadInitiate { .. }
                | Request::BlockUploadInitiate { .. }
        );
        if initiate && let Some(mut old) = self.open.take() {
            old.t.outcome = old.cut_short();
            done.push(old.t);
        }
        let start = |mux: cantwin_canopen::sdo::wire::Mux, dir, mode| Open {
            t: Transfer {
                direction: Some(dir),
                mode: Some(mode),
                ..new_transfer(t, channel, node, mux.index, mux.sub)
            },
            phase: Phase::Confirmed,
            block: Vec::new(),
            answered: false,
        };
        match req {
            Request::InitiateDownload { mux, init } => {
                let open = match init {
                    Initiate::Expedited { data, len } => {
                        let mut o = start(mux, Direction::Download, Mode::Expedited);
                        o.push(&data[..usize::from(len.unwrap_or(4).min(4))]);
                        o
                    }
                    Initiate::Segmented { .. } => start(mux, Direction::Download, Mode::Segmented),
                };
                self.open = Some(open);
            }
            Request::InitiateUpload { mux } => {
                self.open = Some(start(mux, Direction::Upload, Mode::Expedited));
            }
            Request::BlockDownloadInitiate { mux, .. } => {
                self.open = Some(start(mux, Direction::Download, Mode::Block));
            }
            Request::BlockUploadInitiate { mux, .. } => {
                self.open = Some(start(mux, Direction::Upload, Mode::Block));
            }
            Request::DownloadSegment {
                len, data, last, ..
            } => {
                if let Some(open) = &mut self.open {
                    open.push(&data[..usize::from(len.min(7))]);
                    if last {
                        open.phase = Phase::SegDownLast;
                    }
                    open.t.end_ns = t;
                }
            }
            Request::UploadSegment { .. } | Request::BlockUploadStart => {
                if let Some(open) = &mut self.open {
                    open.t.end_ns = t;
                    if req == Request::BlockUploadStart {
                        open.phase = Phase::BlockUpData;
                    }
                }
            }
            Request::BlockDownloadEnd { unused, .. } => {
                if let Some(open) = &mut self.open {
                    open.trim(unused);
                    open.t.end_ns = t;
                    open.phase = Phase::Confirmed;
                }
            }
            Request::BlockUploadEnd => {
                if let Some(mut open) = self.open.take() {
                    open.t.end_ns = t;
                    done.push(open.t);
                }
            }
            Request::BlockUploadAck { .. } => {}
            Request::Abort { mux, code } => {
                let mut tr = match self.open.take() {
                    Some(open) => open.t,
                    None => new_transfer(t, channel, node, mux.index, mux.sub),
                };
                tr.end_ns = t;
                tr.outcome = Outcome::Aborted {
                    code,
                    by_server: false,
                };
                done.push(tr);
            }
        }
        done
    }

    fn response(&mut self, t: u64, channel: &str, node: u8, b: &[u8; 8]) -> Vec<Transfer> {
        let mut done = Vec::new();
        if let Some(open) = &mut self.open
            && open.phase == Phase::BlockUpData
            && b[0] != 0x80
        {
            let seg = BlockSegment::decode(b);
            open.block.push(seg.data);
            open.t.end_ns = t;
            if seg.last {
                open.phase = Phase::BlockUpEnd;
            }
            return done;
        }
        let Ok(resp) = Response::decode(b) else {
            return done;
        };
        if let Response::Abort { mux, code } = resp {
            let mut tr = match self.open.take() {
                Some(open) => open.t,
                None => new_transfer(t, channel, node, mux.index, mux.sub),
            };
            tr.end_ns = t;
            tr.outcome = Outcome::Aborted {
                code,
                by_server: true,
            };
            done.push(tr);
            return done;
        }
        let Some(open) = &mut self.open else {
            return done;
        };
        open.t.end_ns = t;
        let mut finished = false;
        match resp {
            Response::InitiateDownload { .. } => {
                finished = open.t.mode == Some(Mode::Expedited);
            }
            Response::DownloadSegment { .. } => {
                finished = open.phase == Phase::SegDownLast;
            }
            Response::InitiateUpload { init, .. } => match init {
                Initiate::Expedited { data, len } => {
                    open.push(&data[..usize::from(len.unwrap_or(4).min(4))]);
                    finished = true;
                }
                Initiate::Segmented { .. } => open.t.mode = Some(Mode::Segmented),
            },
            Response::UploadSegment {
                last, len, data, ..
            } => {
                open.push(&data[..usize::from(len.min(7))]);
                finished = last;
            }
            Response::BlockDownloadInitiate { .. } => open.phase = Phase::BlockDownData,
            Response::BlockDownloadAck { ackseq, .. } => {
                open.commit_block(ackseq);
                if open.phase != Phase::BlockDownEnd {
                    open.phase = Phase::BlockDownData;
                }
            }
            Response::BlockDownloadEnd => finished = true,
            Response::BlockUploadInitiate { .. } => {}
            Response::BlockUploadEnd { unused, .. } => {
                open.trim(unused);
                open.phase = Phase::Confirmed;
            }
            Response::Abort { .. } => {}
        }
        if finished && let Some(open) = self.open.take() {
            done.push(open.t);
        }
        done
    }

    /// The end of the capture: the open transfer, if any, as unanswered or incomplete.
    pub fn finish(&mut self) -> Option<Transfer> {
        let open = self.open.take()?;
        let outcome = open.cut_short();
        let mut t = open.t;
        t.outcome = outcome;
        Some(t)
    }
}
