//! Reports of CAN captures: [`analyse`] turns the records of a capture (pcap, pcapng or
//! candump, read with `cantwin-capture`) into a [`Report`] — bus load over time, statistics
//! per identifier, a decoded timeline and anomalies — and [`render_html`] writes it as one
//! self-contained HTML page (inline CSS and SVG, a few lines of inline script to filter the
//! timeline; nothing fetched from anywhere, so it opens offline).
//!
//! The timeline decodes CANopen (NMT, SDO transfers reassembled into one row each with
//! their value or abort code, heartbeat state changes, EMCY with meanings, PDOs named from an
//! EDS), DeviceNet identifiers and CAL CMS frames, by the protocol each channel is said to
//! carry. Anomalies: heartbeat gaps and stops, SDO aborts, SDO requests without response,
//! error frames and unexpected boot-ups.
//!
//! ```
//! use cantwin_can::{Frame, Id};
//! use cantwin_capture::Record;
//! use cantwin_report::{Options, analyse, render_html};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let t0 = 1_700_000_000_000_000_000;
//! let records = [
//!     Record::new(t0, "can0", Frame::data(Id::standard(0x705)?, &[0x00])?),
//!     Record::new(t0 + 1_000_000, "can0", Frame::data(Id::standard(0x605)?, &[0x40, 0x08, 0x10, 0, 0, 0, 0, 0])?),
//!     Record::new(t0 + 2_000_000, "can0", Frame::data(Id::standard(0x585)?, &[0x43, 0x08, 0x10, 0, b'T', b'w', b'i', b'n'])?),
//! ];
//! let report = analyse(&records, &Options::default());
//! assert_eq!(report.sdo[0].data, b"Twin");
//! let html = render_html(&report);
//! assert!(html.contains("&quot;Twin&quot;"));
//! # Ok(())
//! # }
//! ```
#![forbid(unsafe_code)]

pub mod cal;
pub mod canopen;
pub mod decode;
pub mod devicenet;
mod hex;
mod html;
pub mod lss;
pub mod sdo;

use std::collections::{BTreeMap, HashMap};

use cantwin_can::{BitRate, Frame, Id};
use cantwin_canopen::master::pdo::PdoDecoder;
use cantwin_canopen::wire::{self, ErrorControl, Message, NmtCs};
use cantwin_capture::{Event, Record};

pub use decode::Decoder;
pub use html::{escape, render_html};

/// The protocol a channel carries, which decides how its frames are decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Protocol {
    /// CANopen (CiA 301 pre-defined connection set).
    #[default]
    CanOpen,
    /// DeviceNet (identifier groups 1–4).
    DeviceNet,
    /// CAL CMS (DS 202): control byte and data.
    Cal,
}

impl Protocol {
    /// The protocol's usual name.
    pub fn name(self) -> &'static str {
        match self {
            Protocol::CanOpen => "CANopen",
            Protocol::DeviceNet => "DeviceNet",
            Protocol::Cal => "CAL",
        }
    }
}

impl std::str::FromStr for Protocol {
    type Err = String;

    /// `canopen`, `devicenet` or `cal` (any case).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "canopen" => Ok(Protocol::CanOpen),
            "devicenet" => Ok(Protocol::DeviceNet),
            "cal" => Ok(Protocol::Cal),
            _ => Err(format!(
                "unknown protocol {s:?}: use canopen, devicenet or cal"
            )),
        }
    }
}

/// The bit rate assumed for a channel whose rate is not given: pcap, pcapng and candump
/// logs do not record it. 500 kbit/s, the rate of the shipped scenarios and the demo, and
/// the default of `cantwin monitor` too.
pub const DEFAULT_BIT_RATE: BitRate = BitRate::R500K;

/// How to analyse a capture.
#[derive(Debug, Clone)]
pub struct Options {
    /// Bit rate of channels not named in `bit_rates` (for the bus load); `None` assumes
    /// [`DEFAULT_BIT_RATE`], which the report then says it did.
    pub default_bit_rate: Option<BitRate>,
    /// Bit rate per channel name.
    pub bit_rates: BTreeMap<String, BitRate>,
    /// Protocol per channel name.
    pub protocols: BTreeMap<String, Protocol>,
    /// Protocol of channels not named in `protocols` (CANopen unless told).
    pub default_protocol: Protocol,
    /// PDO mappings that name PDO values (see [`canopen::add_eds_pdos`]).
    pub pdos: PdoDecoder,
    /// Width of a bus load window; `None` chooses 100 ms, widened so a capture has at most
    /// [`MAX_WINDOWS`] windows.
    pub window_ns: Option<u64>,
    /// At most this many timeline rows are kept; the rest are counted.
    pub max_timeline: usize,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            default_bit_rate: None,
            bit_rates: BTreeMap::new(),
            protocols: BTreeMap::new(),
            default_protocol: Protocol::CanOpen,
            pdos: PdoDecoder::new(),
            window_ns: None,
            max_timeline: 20_000,
        }
    }
}

impl Options {
    /// The bit rate of `channel`, and whether it is assumed rather than given.
    fn bit_rate(&self, channel: &str) -> (BitRate, bool) {
        match (self.bit_rates.get(channel).copied(), self.default_bit_rate) {
            (Some(r), _) | (None, Some(r)) => (r, false),
            (None, None) => (DEFAULT_BIT_RATE, true),
        }
    }

    fn protocol(&self, channel: &str) -> Protocol {
        self.protocols
            .get(channel)
            .copied()
            .unwrap_or(self.default_protocol)
    }
}

/// The most bus load windows per channel when the width is chosen automatically.
pub const MAX_WINDOWS: u64 = 2_000;
const DEFAULT_WINDOW_NS: u64 = 100_000_000;

/// Bus load and totals of one channel.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    /// The channel name.
    pub name: String,
    /// The bit rate used for the load.
    pub bit_rate: BitRate,
    /// Whether `bit_rate` is [`DEFAULT_BIT_RATE`], assumed because none was given.
    pub bit_rate_assumed: bool,
    /// Protocol used for decoding.
    pub protocol: Protocol,
    /// Data and remote frames.
    pub frames: u64,
    /// Error frames.
    pub error_frames: u64,
    /// Bits on the bus: the sum of every frame's exact length (stuff bits, intermission).
    pub bits: u64,
    /// Width of a load window.
    pub window_ns: u64,
    /// Bus load of each window from the capture start, 0.0–1.0 (and more if the
    /// capture's timestamps crowd more bits into a window than it can hold).
    pub load: Vec<f64>,
    /// SYNC messages seen (CANopen).
    pub syncs: u64,
}

impl Channel {
    /// The mean load over the capture (bits over capacity of the covered windows).
    pub fn mean_load(&self) -> f64 {
        if self.load.is_empty() {
            return 0.0;
        }
        self.load.iter().sum::<f64>() / self.load.len() as f64
    }

    /// The highest window load.
    pub fn peak_load(&self) -> f64 {
        self.load.iter().copied().fold(0.0, f64::max)
    }
}

/// Traffic of one identifier on one channel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IdStats {
    /// The channel.
    pub channel: String,
    /// The identifier.
    pub id: Id,
    /// Frames.
    pub frames: u64,
    /// Data bytes.
    pub bytes: u64,
    /// Bits on the bus.
    pub bits: u64,
    /// First and last time seen.
    pub first_ns: u64,
    /// Last time seen.
    pub last_ns: u64,
    /// Shortest gap between two frames, if seen twice.
    pub min_period_ns: Option<u64>,
    /// Longest gap between two frames.
    pub max_period_ns: Option<u64>,
}

impl IdStats {
    /// The mean gap between two frames.
    pub fn avg_period_ns(&self) -> Option<u64> {
        (self.frames > 1).then(|| self.last_ns.saturating_sub(self.first_ns) / (self.frames - 1))
    }
}

/// What a timeline row is about (the filter of the HTML page).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Kind {
    /// NMT module control.
    Nmt,
    /// Boot-up and heartbeat/guarding state changes.
    Heartbeat,
    /// A reassembled SDO transfer.
    Sdo,
    /// An emergency message.
    Emcy,
    /// A PDO.
    Pdo,
    /// TIME stamp.
    Time,
    /// A DeviceNet frame.
    DeviceNet,
    /// A CAL frame.
    Cal,
    /// A controller error frame.
    Error,
    /// Anything else.
    Other,
}

impl Kind {
    /// Short lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Nmt => "nmt",
            Kind::Heartbeat => "heartbeat",
            Kind::Sdo => "sdo",
            Kind::Emcy => "emcy",
            Kind::Pdo => "pdo",
            Kind::Time => "time",
            Kind::DeviceNet => "devicenet",
            Kind::Cal => "cal",
            Kind::Error => "error",
            Kind::Other => "other",
        }
    }
}

/// One line of the decoded timeline.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Row {
    /// Capture time (ns since the Unix epoch).
    pub t_ns: u64,
    /// The channel.
    pub channel: String,
    /// The service.
    pub kind: Kind,
    /// The node concerned, if any.
    pub node: Option<u8>,
    /// What happened.
    pub text: String,
    /// How many times it happened in a row: identical EMCYs of a node, one after the other,
    /// make one row (1 for every other row).
    pub repeats: u64,
    /// Capture time of the last repeat (`t_ns` when there is one).
    pub last_ns: u64,
}

/// What kind of anomaly.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum AnomalyKind {
    /// A heartbeat came more than 1.5× the node's median period after the previous one.
    HeartbeatGap,
    /// A node's heartbeats stopped before the end of the capture.
    HeartbeatStopped,
    /// An SDO transfer was aborted.
    SdoAbort,
    /// An SDO request got no response.
    SdoNoResponse,
    /// A controller error frame.
    ErrorFrame,
    /// A node booted again without an NMT reset addressed to it.
    UnexpectedBootUp,
    /// An EMCY other than "error reset".
    Emergency,
}

impl AnomalyKind {
    /// Human-readable name.
    pub fn name(self) -> &'static str {
        match self {
            AnomalyKind::HeartbeatGap => "heartbeat gap",
            AnomalyKind::HeartbeatStopped => "heartbeat stopped",
            AnomalyKind::SdoAbort => "SDO abort",
            AnomalyKind::SdoNoResponse => "SDO without response",
            AnomalyKind::ErrorFrame => "error frame",
            AnomalyKind::UnexpectedBootUp => "unexpected boot-up",
            AnomalyKind::Emergency => "emergency",
        }
    }
}

/// Something worth a look.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Anomaly {
    /// When.
    pub t_ns: u64,
    /// Where.
    pub channel: String,
    /// What.
    pub kind: AnomalyKind,
    /// The node concerned, if any.
    pub node: Option<u8>,
    /// Details.
    pub text: String,
    /// How many times it happened in a row (identical EMCYs of a node make one anomaly).
    pub repeats: u64,
    /// Capture time of the last repeat (`t_ns` when there is one).
    pub last_ns: u64,
}

/// The analysis of a capture.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Timestamp of the first record (0 for an empty capture).
    pub start_ns: u64,
    /// Timestamp of the last record.
    pub end_ns: u64,
    /// Per channel, by name.
    pub channels: Vec<Channel>,
    /// Per identifier, by channel then identifier.
    pub ids: Vec<IdStats>,
    /// SDO transfers in the order they ended.
    pub sdo: Vec<sdo::Transfer>,
    /// SDO transfers seen; only the first [`Options::max_timeline`] are kept in `sdo`.
    pub sdo_total: u64,
    /// The decoded timeline, in time order: the first [`Options::max_timeline`] rows in
    /// capture order.
    pub timeline: Vec<Row>,
    /// Rows left out of the timeline by the cap.
    pub timeline_dropped: u64,
    /// Anomalies in time order.
    pub anomalies: Vec<Anomaly>,
}

#[derive(Debug, Default)]
struct NodeHb {
    state: Option<u8>,
    last_ns: Option<u64>,
    times: Vec<u64>,
    /// An NMT reset addressed to the node since its last message.
    reset_pending: bool,
    heard: bool,
    /// A node guarding remote request is waiting for its answer (CiA 301 §7.2.8.3.2.1).
    guard_pending: bool,
}

/// The EMCYs of one node that repeat the same message, collapsed into one timeline row and
/// one anomaly.
#[derive(Debug)]
struct EmcyRun {
    /// Code, error register and manufacturer bytes.
    emcy: (u16, u8, [u8; 5]),
    /// Its row in the timeline, if the timeline had room.
    row: Option<usize>,
    /// Its anomaly (none for an error reset).
    anomaly: Option<usize>,
}

/// The most bins of [`Options::window_ns`] (or 100 ms) a channel's load is counted in
/// before windows are merged; later frames count in the last bin (a capture whose clock
/// jumps by years stays bounded in memory).
const MAX_BINS: usize = 1 << 22;

/// A capture analysis fed one record at a time, so that captures larger than memory can be
/// analysed as they are read; [`analyse`] does it for records already in memory.
#[derive(Debug)]
pub struct Analysis<'o> {
    opts: &'o Options,
    start: u64,
    end: u64,
    /// Time of the first record: bin 0 of the load.
    origin: Option<u64>,
    channels: BTreeMap<String, Channel>,
    /// Channel name → index in `bins` and the keys below (no allocation per frame).
    chan_ix: HashMap<String, usize>,
    /// Bits per load bin, per channel index.
    bins: Vec<Vec<u64>>,
    /// (channel index, id) → stats.
    ids: HashMap<(usize, Id), IdStats>,
    sdo: HashMap<(usize, u8), sdo::Tracker>,
    hb: BTreeMap<(String, u8), NodeHb>,
    /// DeviceNet slaves' message body formats, per channel.
    dn_formats: BTreeMap<String, devicenet::BodyFormats>,
    emcy: HashMap<(usize, u8), EmcyRun>,
    transfers: Vec<sdo::Transfer>,
    transfers_total: u64,
    rows: Vec<Row>,
    dropped: u64,
    anomalies: Vec<Anomaly>,
}

/// Analyses the records of a capture (in capture order; timestamps that go backwards are
/// taken as they come).
pub fn analyse<'r>(records: impl IntoIterator<Item = &'r Record>, opts: &Options) -> Report {
    let mut a = Analysis::new(opts);
    for r in records {
        a.push(r);
    }
    a.finish()
}

fn fmt_mux(index: u16, sub: u8) -> String {
    format!("0x{index:04X}sub{sub}")
}

/// A transfer's value for display: quoted text when it is printable, otherwise the
/// little-endian number (up to 8 bytes) and the bytes in hex.
pub fn value_text(data: &[u8], size: usize) -> String {
    let printable = data.len() >= 2 && data.iter().all(|&b| b.is_ascii_graphic() || b == b' ');
    let mut s = if printable {
        format!("\"{}\"", String::from_utf8_lossy(data))
    } else if !data.is_empty() && data.len() <= 8 {
        let mut v = 0u64;
        for (i, b) in data.iter().enumerate() {
            v |= u64::from(*b) << (8 * i);
        }
        format!("0x{v:0w$X} ({v})", w = data.len() * 2)
    } else {
        canopen::hex_bytes(data)
    };
    if size > data.len() {
        s.push_str(&format!(" … ({size} bytes)"));
    }
    s
}

impl<'o> Analysis<'o> {
    /// An empty analysis.
    pub fn new(opts: &'o Options) -> Self {
        Analysis {
            opts,
            start: u64::MAX,
            end: 0,
            origin: None,
            channels: BTreeMap::new(),
            chan_ix: HashMap::new(),
            bins: Vec::new(),
            ids: HashMap::new(),
            sdo: HashMap::new(),
            hb: BTreeMap::new(),
            dn_formats: BTreeMap::new(),
            emcy: HashMap::new(),
            transfers: Vec::new(),
            transfers_total: 0,
            rows: Vec::new(),
            dropped: 0,
            anomalies: Vec::new(),
        }
    }

    fn bin_ns(&self) -> u64 {
        self.opts.window_ns.unwrap_or(DEFAULT_WINDOW_NS).max(1)
    }

    fn channel_index(&mut self, name: &str) -> usize {
        if let Some(&i) = self.chan_ix.get(name) {
            return i;
        }
        let i = self.bins.len();
        self.chan_ix.insert(name.to_string(), i);
        self.bins.push(Vec::new());
        i
    }

    /// The timeline is full: further rows are only counted.
    fn full(&mut self) -> bool {
        if self.rows.len() >= self.opts.max_timeline {
            self.dropped += 1;
            true
        } else {
            false
        }
    }

    fn channel(&mut self, name: &str) -> &mut Channel {
        let opts = self.opts;
        self.channels
            .entry(name.to_string())
            .or_insert_with(|| Channel {
                name: name.to_string(),
                bit_rate: opts.bit_rate(name).0,
                bit_rate_assumed: opts.bit_rate(name).1,
                protocol: opts.protocol(name),
                frames: 0,
                error_frames: 0,
                bits: 0,
                window_ns: 0,
                load: Vec::new(),
                syncs: 0,
            })
    }

    fn row(&mut self, t_ns: u64, channel: &str, kind: Kind, node: Option<u8>, text: String) {
        if self.full() {
            return;
        }
        self.rows.push(Row {
            t_ns,
            channel: channel.to_string(),
            kind,
            node,
            text,
            repeats: 1,
            last_ns: t_ns,
        });
    }

    fn anomaly(&mut self, t_ns: u64, ch: &str, kind: AnomalyKind, node: Option<u8>, text: String) {
        self.anomalies.push(Anomaly {
            t_ns,
            channel: ch.to_string(),
            kind,
            node,
            text,
            repeats: 1,
            last_ns: t_ns,
        });
    }

    /// An EMCY of `node`: the same message as the node's previous EMCY only counts as a
    /// repeat of its row and anomaly; any other starts a new run.
    fn emergency(&mut self, t: u64, ch: &str, node: u8, emcy: wire::Emcy, text: String) {
        let key = (self.channel_index(ch), node);
        let same = (emcy.code, emcy.register, emcy.manufacturer);
        if let Some(run) = self.emcy.get(&key)
            && run.emcy == same
        {
            if let Some(r) = run.row.and_then(|i| self.rows.get_mut(i)) {
                r.repeats += 1;
                r.last_ns = t;
            }
            if let Some(a) = run.anomaly.and_then(|i| self.anomalies.get_mut(i)) {
                a.repeats += 1;
                a.last_ns = t;
            }
            return;
        }
        let anomaly = (emcy.code != 0).then(|| {
            self.anomaly(t, ch, AnomalyKind::Emergency, Some(node), text.clone());
            self.anomalies.len() - 1
        });
        let before = self.rows.len();
        self.row(t, ch, Kind::Emcy, Some(node), text);
        let row = (self.rows.len() > before).then_some(before);
        self.emcy.insert(
            key,
            EmcyRun {
                emcy: same,
                row,
                anomaly,
            },
        );
    }

    /// Adds one record.
    pub fn push(&mut self, r: &Record) {
        let t = r.timestamp_ns;
        let origin = *self.origin.get_or_insert(t);
        self.start = self.start.min(t);
        self.end = self.end.max(t);
        let ch = r.channel.as_str();
        match &r.event {
            Event::Error(e) => {
                self.channel(ch).error_frames += 1;
                let text = format!("error frame: class {}", e);
                self.row(t, ch, Kind::Error, None, text.clone());
                self.anomaly(t, ch, AnomalyKind::ErrorFrame, None, text);
            }
            Event::Frame(f) => {
                let bits = f.bit_length();
                let c = self.channel(ch);
                c.frames += 1;
                c.bits += u64::from(bits);
                let protocol = c.protocol;
                let ix = self.channel_index(ch);
                let bin = usize::try_from(t.saturating_sub(origin) / self.bin_ns())
                    .unwrap_or(usize::MAX)
                    .min(MAX_BINS - 1);
                let v = &mut self.bins[ix];
                if v.len() <= bin {
                    v.resize(bin + 1, 0);
                }
                v[bin] += u64::from(bits);
                let s = self.ids.entry((ix, f.id())).or_insert_with(|| IdStats {
                    channel: ch.to_string(),
                    id: f.id(),
                    frames: 0,
                    bytes: 0,
                    bits: 0,
                    first_ns: t,
                    last_ns: t,
                    min_period_ns: None,
                    max_period_ns: None,
                });
                if s.frames > 0 {
                    let gap = t.saturating_sub(s.last_ns);
                    s.min_period_ns = Some(s.min_period_ns.map_or(gap, |m| m.min(gap)));
                    s.max_period_ns = Some(s.max_period_ns.map_or(gap, |m| m.max(gap)));
                }
                s.frames += 1;
                s.bytes += f.data_bytes().len() as u64;
                s.bits += u64::from(bits);
                s.last_ns = t;
                match protocol {
                    Protocol::CanOpen => self.canopen(t, ch, f),
                    Protocol::DeviceNet => self.devicenet(t, ch, f),
                    Protocol::Cal => self.cal(t, ch, f),
                }
            }
        }
    }

    fn sdo_done(&mut self, done: Vec<sdo::Transfer>) {
        for tr in done {
            let dir = match tr.direction {
                Some(sdo::Direction::Upload) => "read",
                Some(sdo::Direction::Download) => "write",
                None => "transfer",
            };
            let mode = match tr.mode {
                Some(sdo::Mode::Expedited) => " (expedited)",
                Some(sdo::Mode::Segmented) => " (segmented)",
                Some(sdo::Mode::Block) => " (block)",
                None => "",
            };
            let what = format!(
                "SDO {dir} node {} {}{mode}",
                tr.node,
                fmt_mux(tr.index, tr.sub)
            );
            let text = match tr.outcome {
                sdo::Outcome::Done => {
                    format!(
                        "{what}: {} bytes = {}",
                        tr.size,
                        value_text(&tr.data, tr.size)
                    )
                }
                sdo::Outcome::Aborted { code, by_server } => {
                    let by = if by_server { "server" } else { "client" };
                    let text = format!("{what}: aborted by {by}, {code}");
                    self.anomaly(
                        tr.end_ns,
                        &tr.channel,
                        AnomalyKind::SdoAbort,
                        Some(tr.node),
                        text.clone(),
                    );
                    text
                }
                sdo::Outcome::Incomplete => {
                    format!("{what}: incomplete, {} bytes seen", tr.size)
                }
                sdo::Outcome::NoResponse => {
                    let text = format!("{what}: no response");
                    self.anomaly(
                        tr.end_ns,
                        &tr.channel,
                        AnomalyKind::SdoNoResponse,
                        Some(tr.node),
                        text.clone(),
                    );
                    text
                }
            };
            self.row(
                tr.start_ns,
                &tr.channel.clone(),
                Kind::Sdo,
                Some(tr.node),
                text,
            );
            self.transfers_total += 1;
            if self.transfers.len() < self.opts.max_timeline {
                self.transfers.push(tr);
            }
        }
    }

    fn canopen(&mut self, t: u64, ch: &str, f: &Frame) {
        let msg = wire::decode(f);
        if matches!(msg, Message::Pdo { .. } | Message::Other(_))
            && self.rows.len() >= self.opts.max_timeline
        {
            // PDOs are most of the traffic: once the timeline is full, count them only.
            if matches!(msg, Message::Pdo { .. }) || self.opts.pdos.decode(f).is_some() {
                self.dropped += 1;
            }
            return;
        }
        if let Some(text) = canopen::describe_pdo(f, &self.opts.pdos) {
            self.row(t, ch, Kind::Pdo, None, text);
            return;
        }
        match msg {
            Message::Nmt(cmd) => {
                if matches!(cmd.cs, NmtCs::ResetNode | NmtCs::ResetCommunication) {
                    for ((c, n), hb) in self.hb.iter_mut() {
                        if c == ch && (cmd.node == 0 || cmd.node == *n) {
                            hb.reset_pending = true;
                        }
                    }
                }
                let node = (cmd.node != 0).then_some(cmd.node);
                let text = canopen::describe(f, &self.opts.pdos);
                self.row(t, ch, Kind::Nmt, node, text);
            }
            Message::Sync(_) => self.channel(ch).syncs += 1,
            Message::Emcy { node, emcy } => {
                let text = canopen::describe(f, &self.opts.pdos);
                self.emergency(t, ch, node, emcy, text);
            }
            Message::Time(_) => {
                let text = canopen::describe(f, &self.opts.pdos);
                self.row(t, ch, Kind::Time, None, text);
            }
            Message::Pdo { kind, node, frame } => {
                let text = format!(
                    "PDO {kind:?} node {node}: {}",
                    canopen::hex_bytes(frame.data_bytes())
                );
                self.row(t, ch, Kind::Pdo, Some(node), text);
            }
            Message::SdoRequest { node, data, len } => {
                if len == 8 {
                    let ix = self.channel_index(ch);
                    let done = self
                        .sdo
                        .entry((ix, node))
                        .or_default()
                        .on_request(t, ch, node, &data);
                    self.sdo_done(done);
                }
            }
            Message::SdoResponse { node, data, len } => {
                if len == 8 {
                    let ix = self.channel_index(ch);
                    let done = self
                        .sdo
                        .entry((ix, node))
                        .or_default()
                        .on_response(t, ch, node, &data);
                    self.sdo_done(done);
                }
            }
            Message::ErrorControl(ErrorControl::State {
                node,
                state,
                toggle,
            }) => {
                self.error_control(t, ch, node, state, toggle);
            }
            Message::ErrorControl(ErrorControl::GuardRequest { node }) => {
                self.hb
                    .entry((ch.to_string(), node))
                    .or_default()
                    .guard_pending = true;
            }
            Message::Malformed { error, .. } => {
                let text = lss::describe(f).unwrap_or_else(|| format!("{f}: malformed: {error}"));
                self.row(t, ch, Kind::Other, None, text);
            }
            // LSS (CiA 305) is outside the pre-defined connection set but on every
            // CANopen network that configures node-IDs.
            Message::Other(_) => {
                if let Some(text) = lss::describe(f) {
                    self.row(t, ch, Kind::Other, None, text);
                }
            }
        }
    }

    /// Boot-up, heartbeat and node guarding (CiA 301 §7.2.8.3.2): a row on every change of
    /// state, not on every message. An answer to a guard request, or one with the toggle bit
    /// set, is node guarding; heartbeats have no toggle bit.
    fn error_control(&mut self, t: u64, ch: &str, node: u8, state: u8, toggle: bool) {
        let hb = self.hb.entry((ch.to_string(), node)).or_default();
        let guarded = std::mem::take(&mut hb.guard_pending) || toggle;
        let changed = hb.state != Some(state);
        let unexpected = state == 0 && hb.heard && !hb.reset_pending;
        hb.state = Some(state);
        hb.last_ns = Some(t);
        hb.times.push(t);
        hb.heard = true;
        hb.reset_pending = false;
        if state == 0 {
            self.row(
                t,
                ch,
                Kind::Heartbeat,
                Some(node),
                format!("BOOT-UP node {node}"),
            );
            if unexpected {
                self.anomaly(
                    t,
                    ch,
                    AnomalyKind::UnexpectedBootUp,
                    Some(node),
                    format!("node {node} booted again without an NMT reset"),
                );
            }
        } else if changed {
            let service = if guarded {
                "node guarding"
            } else {
                "heartbeat"
            };
            let text = format!("node {node} {service}: {}", canopen::state_name(state));
            self.row(t, ch, Kind::Heartbeat, Some(node), text);
        }
    }

    fn devicenet(&mut self, t: u64, ch: &str, f: &Frame) {
        if self.full() {
            return;
        }
        let text = self
            .dn_formats
            .entry(ch.to_string())
            .or_default()
            .describe(f);
        self.row(t, ch, Kind::DeviceNet, devicenet::node_of(f), text);
    }

    fn cal(&mut self, t: u64, ch: &str, f: &Frame) {
        if self.full() {
            return;
        }
        let text = cal::describe(f);
        self.row(t, ch, Kind::Cal, None, text);
    }

    /// The end of the capture: closes open SDO transfers and heartbeat supervision.
    pub fn finish(mut self) -> Report {
        let mut trackers: Vec<_> = std::mem::take(&mut self.sdo).into_iter().collect();
        trackers.sort_by_key(|t| t.0);
        for (_, mut tr) in trackers {
            if let Some(t) = tr.finish() {
                self.sdo_done(vec![t]);
            }
        }
        let (start, end) = if self.start > self.end {
            (0, 0)
        } else {
            (self.start, self.end)
        };
        self.heartbeat_anomalies(end);
        // Bus load per window: bins merged k at a time so that at most MAX_WINDOWS remain
        // (unless the window width was given).
        let bin = self.bin_ns();
        let n_bins = self.bins.iter().map(Vec::len).max().unwrap_or(0).max(1);
        let k = match self.opts.window_ns {
            Some(_) => 1,
            None => n_bins.div_ceil(MAX_WINDOWS as usize).max(1),
        };
        let window = bin.saturating_mul(k as u64);
        let mut channels = Vec::new();
        for (name, mut c) in std::mem::take(&mut self.channels) {
            c.window_ns = window;
            let capacity = c.bit_rate.bits_per_second() as f64 * window as f64 / 1e9;
            let mut v = self
                .chan_ix
                .get(&name)
                .and_then(|&i| self.bins.get(i))
                .cloned()
                .unwrap_or_default();
            v.resize(n_bins, 0);
            c.load = v
                .chunks(k)
                .map(|w| w.iter().sum::<u64>() as f64 / capacity)
                .collect();
            channels.push(c);
        }
        let mut ids: Vec<IdStats> = std::mem::take(&mut self.ids).into_values().collect();
        ids.sort_by(|a, b| (&a.channel, id_key(a.id)).cmp(&(&b.channel, id_key(b.id))));
        self.rows.sort_by_key(|r| r.t_ns);
        let dropped = self.dropped;
        self.anomalies.sort_by_key(|a| a.t_ns);
        Report {
            start_ns: start,
            end_ns: end,
            channels,
            ids,
            sdo: self.transfers,
            sdo_total: self.transfers_total,
            timeline: self.rows,
            timeline_dropped: dropped,
            anomalies: self.anomalies,
        }
    }

    /// Heartbeat supervision from the outside: a gap longer than 1.5× the node's median
    /// interval, or no heartbeat for that long before the end of the capture.
    fn heartbeat_anomalies(&mut self, end: u64) {
        let mut found = Vec::new();
        for ((ch, node), hb) in &self.hb {
            let mut gaps: Vec<u64> = hb
                .times
                .windows(2)
                .map(|w| w[1].saturating_sub(w[0]))
                .collect();
            if gaps.len() < 2 {
                continue;
            }
            let pairs: Vec<(u64, u64)> = hb
                .times
                .windows(2)
                .map(|w| (w[1], w[1].saturating_sub(w[0])))
                .collect();
            gaps.sort_unstable();
            let median = gaps[gaps.len() / 2];
            if median == 0 {
                continue;
            }
            let limit = median + median / 2;
            for (t, gap) in pairs {
                if gap > limit {
                    found.push(Anomaly {
                        t_ns: t,
                        channel: ch.clone(),
                        kind: AnomalyKind::HeartbeatGap,
                        node: Some(*node),
                        text: format!(
                            "node {node}: {} ms without heartbeat (median period {} ms)",
                            gap / 1_000_000,
                            median / 1_000_000
                        ),
                        repeats: 1,
                        last_ns: t,
                    });
                }
            }
            if let Some(last) = hb.last_ns
                && end.saturating_sub(last) > limit
            {
                found.push(Anomaly {
                    t_ns: last,
                    channel: ch.clone(),
                    kind: AnomalyKind::HeartbeatStopped,
                    node: Some(*node),
                    text: format!(
                        "node {node}: last heartbeat {} ms before the end of the capture (median period {} ms)",
                        (end - last) / 1_000_000,
                        median / 1_000_000
                    ),
                    repeats: 1,
                    last_ns: last,
                });
            }
        }
        self.anomalies.extend(found);
    }
}

fn id_raw(id: Id) -> u32 {
    match id {
        Id::Standard(s) => u32::from(s.as_raw()),
        Id::Extended(e) => e.as_raw(),
    }
}

fn id_key(id: Id) -> (bool, u32) {
    (matches!(id, Id::Extended(_)), id_raw(id))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_as_text_number_or_bytes() {
        assert_eq!(value_text(b"Twin 1", 6), "\"Twin 1\"");
        assert_eq!(
            value_text(&[0x91, 0x01, 0x0F, 0x00], 4),
            "0x000F0191 (983441)"
        );
        assert_eq!(value_text(&[7], 1), "0x07 (7)");
        assert_eq!(value_text(&[], 0), "");
        let data: Vec<u8> = (0..10).collect();
        assert_eq!(
            value_text(&data, 65_536),
            "00 01 02 03 04 05 06 07 08 09 … (65536 bytes)"
        );
    }
}
