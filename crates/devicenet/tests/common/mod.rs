//! Shared test fixtures: a reference drive application following the EXP-CAN/DN-ADV
//! manual §3.4 (Parameter object "instance = PAR", Drive Parameter Access 0x66, error
//! codes of table 3.4.1, data types of table 3.4.2), frame helpers and a zero-latency
//! wire that connects nodes in virtual time.
#![allow(dead_code, clippy::unwrap_used)]

use cantwin_can::{BitRate, Frame, Id, Instant, Node, Outbox};
use cantwin_devicenet::objects::CipError;
use cantwin_devicenet::wire::{Request, status};
use cantwin_devicenet::{Application, Identity, MacId, Reply, Slave, SlaveConfig, SlaveEvent};
use std::collections::BTreeMap;

pub const SEC: u64 = 1_000_000_000;
pub const MS: u64 = 1_000_000;

pub fn at(ns: u64) -> Instant {
    Instant::from_nanos(ns)
}

pub fn mac(m: u8) -> MacId {
    MacId::new(m).unwrap()
}

/// A frame from candump notation `44E#0A4B0301010A`.
pub fn f(s: &str) -> Frame {
    let (id, data) = s.split_once('#').unwrap();
    let id = u16::from_str_radix(id, 16).unwrap();
    let bytes: Vec<u8> = (0..data.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&data[i..i + 2], 16).unwrap())
        .collect();
    Frame::std(id, &bytes).unwrap()
}

/// The outbox as candump strings, emptied.
pub fn sent(out: &mut Outbox) -> Vec<String> {
    out.drain().map(|f| f.to_string()).collect()
}

/// Identity values used by the tests (the manual gives none; the twin configures its own).
pub fn identity() -> Identity {
    Identity {
        vendor: 0x0123,
        device_type: 0x02,
        product_code: 0x0200,
        revision: (1, 2),
        serial: 0x0A0B_0C0D,
        product_name: "ADV200 DN".into(),
    }
}

/// Drive parameter data types, manual table 3.4.2.
pub mod db_t {
    pub const VOID: u8 = 0;
    pub const INT: u8 = 3;
    pub const LONG: u8 = 4;
    pub const WORD: u8 = 6;
    pub const DWORD: u8 = 7;
    pub const FLOAT: u8 = 8;
}

/// Drive error codes, manual table 3.4.1.
pub mod drive_err {
    pub const WRONG_PARAMETER: u16 = 1;
    pub const ABOVE_MAX: u16 = 9;
    pub const BELOW_MIN: u16 = 10;
    pub const NOT_ALLOWED: u16 = 11;
    pub const READ_ONLY: u16 = 12;
    pub const NOT_WRITABLE_ENABLED: u16 = 16;
}

#[derive(Debug, Clone)]
pub struct Par {
    pub ty: u8,
    pub value: i64,
    pub min: i64,
    pub max: i64,
    pub writable: bool,
    pub disabled_only: bool,
}

/// A reference drive: a few parameters and a PDC of configurable size.
#[derive(Debug)]
pub struct Drive {
    pub pars: BTreeMap<u16, Par>,
    pub words_in: u16,
    pub words_out: u16,
    pub input: Vec<u8>,
    pub consumed: Vec<Vec<u8>>,
    pub events: Vec<(u64, SlaveEvent)>,
    pub enabled: bool,
}

impl Drive {
    pub fn new(words_in: u16, words_out: u16) -> Self {
        let mut pars = BTreeMap::new();
        let p = |ty, value, min, max, writable, disabled_only| Par {
            ty,
            value,
            min,
            max,
            writable,
            disabled_only,
        };
        // PAR 600 Dig Ramp ref 1 (the manual's §3.4.1 example), INT.
        pars.insert(600, p(db_t::INT, 0, -10_000, 10_000, true, false));
        // A 32-bit parameter.
        pars.insert(
            700,
            p(db_t::LONG, 100_000, -1_000_000, 1_000_000, true, false),
        );
        // PAR 4014 Fieldbus state: read-only.
        pars.insert(4014, p(db_t::WORD, 2, 0, 2, false, false));
        // A parameter that cannot be written while the drive is enabled.
        pars.insert(4006, p(db_t::WORD, 12, 1, 63, true, true));
        Drive {
            pars,
            words_in,
            words_out,
            input: (0..words_out * 2).map(|i| i as u8).collect(),
            consumed: Vec::new(),
            events: Vec::new(),
            enabled: false,
        }
    }

    fn size(ty: u8) -> usize {
        match ty {
            db_t::INT | db_t::WORD => 2,
            _ => 4,
        }
    }

    fn encode(value: i64, ty: u8) -> Vec<u8> {
        match ty {
            db_t::INT | db_t::WORD => (value as u16).to_le_bytes().to_vec(),
            db_t::FLOAT => (value as f32).to_le_bytes().to_vec(),
            _ => (value as u32).to_le_bytes().to_vec(),
        }
    }

    fn decode(data: &[u8], ty: u8) -> Option<i64> {
        Some(match (ty, data) {
            (db_t::INT, [a, b]) => i64::from(i16::from_le_bytes([*a, *b])),
            (db_t::WORD, [a, b]) => i64::from(u16::from_le_bytes([*a, *b])),
            (db_t::LONG, [a, b, c, d]) => i64::from(i32::from_le_bytes([*a, *b, *c, *d])),
            (db_t::DWORD, [a, b, c, d]) => i64::from(u32::from_le_bytes([*a, *b, *c, *d])),
            (db_t::FLOAT, [a, b, c, d]) => f32::from_le_bytes([*a, *b, *c, *d]) as i64,
            _ => return None,
        })
    }

    fn write(&mut self, par: u16, value: i64) -> Result<(), u16> {
        let enabled = self.enabled;
        let p = self.pars.get_mut(&par).ok_or(drive_err::WRONG_PARAMETER)?;
        if !p.writable {
            return Err(drive_err::READ_ONLY);
        }
        if p.disabled_only && enabled {
            return Err(drive_err::NOT_WRITABLE_ENABLED);
        }
        if value > p.max {
            return Err(drive_err::ABOVE_MAX);
        }
        if value < p.min {
            return Err(drive_err::BELOW_MIN);
        }
        p.value = value;
        Ok(())
    }

    /// Manual §3.4.1: class 0x0F, instance = PAR; Get answers 4 bytes, an erroneous Set is
    /// not answered.
    fn parameter_object(&mut self, req: &Request<'_>) -> Reply {
        if req.instance == 0 {
            return match (req.service, req.data) {
                (0x0E, [1]) => Reply::Data(1u16.to_le_bytes().to_vec()),
                (0x0E, _) => CipError::new(status::ATTRIBUTE_NOT_SUPPORTED).into(),
                _ => CipError::new(status::SERVICE_NOT_SUPPORTED).into(),
            };
        }
        match req.service {
            0x0E => match (req.data, self.pars.get(&req.instance)) {
                ([1], Some(p)) => Reply::Data((p.value as u32).to_le_bytes().to_vec()),
                ([1], None) => CipError::new(status::OBJECT_DOES_NOT_EXIST).into(),
                _ => CipError::new(status::ATTRIBUTE_NOT_SUPPORTED).into(),
            },
            0x10 => {
                let Some((&1, value)) = req.data.split_first() else {
                    return Reply::Silent;
                };
                let Some(ty) = self.pars.get(&req.instance).map(|p| p.ty) else {
                    return Reply::Silent;
                };
                match Self::decode(value, ty).map(|v| self.write(req.instance, v)) {
                    Some(Ok(())) => Reply::Data(Vec::new()),
                    _ => Reply::Silent,
                }
            }
            _ => CipError::new(status::SERVICE_NOT_SUPPORTED).into(),
        }
    }

    /// Manual §3.4.2: class 0x66, services 0x32–0x35, reply `[Result WORD][value]`.
    fn drive_parameter_access(&mut self, req: &Request<'_>) -> Reply {
        let result = |code: u16| Reply::Data(code.to_le_bytes().to_vec());
        let ok = |value: Vec<u8>| {
            let mut d = vec![0, 0];
            d.extend(value);
            Reply::Data(d)
        };
        if req.instance == 0 {
            return match (req.service, req.data) {
                (0x0E, [1]) => Reply::Data(1u16.to_le_bytes().to_vec()),
                _ => CipError::new(status::SERVICE_NOT_SUPPORTED).into(),
            };
        }
        let par = req.instance;
        let Some(p) = self.pars.get(&par).cloned() else {
            return match req.service {
                0x32..=0x35 => result(drive_err::WRONG_PARAMETER),
                _ => CipError::new(status::SERVICE_NOT_SUPPORTED).into(),
            };
        };
        match req.service {
            0x32 if req.data.is_empty() => ok(Self::encode(p.value, p.ty)),
            0x33 => match Self::decode(req.data, p.ty) {
                None => result(drive_err::NOT_ALLOWED),
                Some(v) => result(self.write(par, v).err().unwrap_or(0)),
            },
            0x34 => match req.data {
                [db_t::VOID] => ok(Self::encode(p.value, p.ty)),
                [t @ (db_t::INT | db_t::WORD | db_t::LONG | db_t::DWORD | db_t::FLOAT)] => {
                    ok(Self::encode(p.value, *t))
                }
                _ => result(drive_err::NOT_ALLOWED),
            },
            0x35 => {
                let Some((&t, value)) = req.data.split_first() else {
                    return result(drive_err::NOT_ALLOWED);
                };
                let t = if t == db_t::VOID { p.ty } else { t };
                match Self::decode(value, t) {
                    None => result(drive_err::NOT_ALLOWED),
                    Some(v) => result(self.write(par, v).err().unwrap_or(0)),
                }
            }
            0x32 => CipError::new(status::TOO_MUCH_DATA).into(),
            _ => CipError::new(status::SERVICE_NOT_SUPPORTED).into(),
        }
    }
}

impl Application for Drive {
    fn poll_sizes(&self) -> (u16, u16) {
        (self.words_out * 2, self.words_in * 2)
    }

    fn produce(&mut self, _now: Instant) -> Vec<u8> {
        self.input.clone()
    }

    fn consume(&mut self, data: &[u8], _now: Instant) {
        self.consumed.push(data.to_vec());
    }

    fn request(&mut self, req: &Request<'_>, _now: Instant) -> Option<Reply> {
        match req.class {
            0x0F => Some(self.parameter_object(req)),
            0x66 => Some(self.drive_parameter_access(req)),
            _ => None,
        }
    }

    fn event(&mut self, event: SlaveEvent, now: Instant) {
        self.events.push((now.as_nanos(), event));
    }
}

pub fn _size_of(ty: u8) -> usize {
    Drive::size(ty)
}

/// A slave with the reference drive, 2 words each way.
pub fn slave(m: u8) -> Slave<Drive> {
    slave_with(m, Drive::new(2, 2))
}

pub fn slave_with(m: u8, drive: Drive) -> Slave<Drive> {
    Slave::new(SlaveConfig::new(mac(m), BitRate::R500K, identity()), drive).unwrap()
}

/// Power the slave at 0 and let the duplicate MAC ID check pass: on-line at 2 s.
pub fn online(s: &mut Slave<Drive>) -> Instant {
    let mut out = Outbox::new();
    s.on_power_up(at(0), &mut out);
    s.on_tick(at(SEC), &mut out);
    s.on_tick(at(2 * SEC), &mut out);
    assert!(s.link_state() == cantwin_devicenet::link::LinkState::Online);
    at(2 * SEC)
}

/// Deliver one frame to the node and return what it sent.
pub fn deliver(n: &mut dyn Node, frame: &str, now: Instant) -> Vec<String> {
    let mut out = Outbox::new();
    let fr = f(frame);
    if n.accepts(fr.id()) {
        n.on_frame(&fr, now, &mut out);
    }
    sent(&mut out)
}

/// Tick the node at `now` and return what it sent.
pub fn tick(n: &mut dyn Node, now: Instant) -> Vec<String> {
    let mut out = Outbox::new();
    n.on_tick(now, &mut out);
    sent(&mut out)
}

/// Decides whether a frame sent by node `usize` is lost.
pub type DropRule = Box<dyn FnMut(usize, &Frame) -> bool>;

/// A zero-latency broadcast wire in virtual time: every frame reaches every other node
/// at the instant it was queued; `drop` can lose frames on the way.
pub struct Wire {
    pub now: Instant,
    pub log: Vec<(u64, usize, String)>,
    pub drop: DropRule,
}

impl Wire {
    pub fn new() -> Self {
        Wire {
            now: Instant::ZERO,
            log: Vec::new(),
            drop: Box::new(|_, _| false),
        }
    }

    fn flush(&mut self, nodes: &mut [&mut dyn Node], mut pending: Vec<(usize, Frame)>) {
        let mut guard = 0;
        while !pending.is_empty() {
            guard += 1;
            assert!(guard < 100_000, "frame storm");
            let (from, frame) = pending.remove(0);
            self.log
                .push((self.now.as_nanos(), from, frame.to_string()));
            if (self.drop)(from, &frame) {
                continue;
            }
            for (i, n) in nodes.iter_mut().enumerate() {
                if i == from || !n.accepts(frame.id()) {
                    continue;
                }
                let mut out = Outbox::new();
                n.on_frame(&frame, self.now, &mut out);
                pending.extend(out.drain().map(|f| (i, f)));
            }
        }
    }

    pub fn power_up(&mut self, nodes: &mut [&mut dyn Node]) {
        let mut pending = Vec::new();
        for (i, n) in nodes.iter_mut().enumerate() {
            let mut out = Outbox::new();
            n.on_power_up(self.now, &mut out);
            pending.extend(out.drain().map(|f| (i, f)));
        }
        self.flush(nodes, pending);
    }

    /// Power one node.
    pub fn power_up_one(&mut self, nodes: &mut [&mut dyn Node], i: usize) {
        let mut out = Outbox::new();
        nodes[i].on_power_up(self.now, &mut out);
        let pending = out.drain().map(|f| (i, f)).collect();
        self.flush(nodes, pending);
    }

    /// Inject a frame as if node `from` sent it.
    pub fn inject(&mut self, nodes: &mut [&mut dyn Node], from: usize, frame: Frame) {
        self.flush(nodes, vec![(from, frame)]);
    }

    /// Run timers and deliveries until `until`.
    pub fn run_until(&mut self, nodes: &mut [&mut dyn Node], until: Instant) {
        let mut guard = 0;
        loop {
            guard += 1;
            assert!(guard < 1_000_000, "timer storm");
            let next = nodes.iter().filter_map(|n| n.next_deadline()).min();
            let Some(next) = next else { break };
            let t = next.max(self.now);
            if t > until {
                break;
            }
            self.now = t;
            let mut pending = Vec::new();
            for (i, n) in nodes.iter_mut().enumerate() {
                if n.next_deadline().is_some_and(|d| d <= t) {
                    let mut out = Outbox::new();
                    n.on_tick(t, &mut out);
                    pending.extend(out.drain().map(|f| (i, f)));
                }
            }
            self.flush(nodes, pending);
        }
        self.now = self.now.max(until);
    }

    /// Log lines from `since` (index) as "t_ms node frame".
    pub fn lines(&self, since: usize) -> Vec<String> {
        self.log[since..]
            .iter()
            .map(|(t, n, f)| format!("{}.{:03} {n} {f}", t / SEC, (t % SEC) / MS))
            .collect()
    }
}

impl Default for Wire {
    fn default() -> Self {
        Self::new()
    }
}

pub fn id(raw: u16) -> Id {
    Id::standard(raw).unwrap()
}
