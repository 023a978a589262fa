//! A harness that drives one ADV200 directly (no bus): frames in, frames out with their times.
#![allow(dead_code, clippy::unwrap_used)]

use cantwin_adv200::params::par;
use cantwin_adv200::{Adv200, Adv200Config};
use cantwin_can::{Frame, Instant, Node, Outbox};

pub const MS: u64 = 1_000_000;

pub fn f(s: &str) -> Frame {
    let (id, data) = s.split_once('#').unwrap();
    if data == "R" {
        return Frame::remote(
            cantwin_can::Id::standard(u16::from_str_radix(id, 16).unwrap()).unwrap(),
            0,
        )
        .unwrap();
    }
    let bytes: Vec<u8> = (0..data.len() / 2)
        .map(|i| u8::from_str_radix(&data[2 * i..2 * i + 2], 16).unwrap())
        .collect();
    Frame::std(u16::from_str_radix(id, 16).unwrap(), &bytes).unwrap()
}

pub struct H {
    pub d: Adv200,
    pub now: u64,
    pub log: Vec<(u64, String)>,
}

impl H {
    /// A drive configured by `setup` from the factory parameters, then powered up at 0.
    pub fn new(config: Adv200Config, setup: impl FnOnce(&mut Adv200)) -> H {
        let mut d = Adv200::new(config);
        setup(&mut d);
        let mut h = H {
            d,
            now: 0,
            log: Vec::new(),
        };
        let mut out = Outbox::new();
        h.d.on_power_up(Instant::ZERO, &mut out);
        h.take(&mut out);
        h.run_to(0);
        h
    }

    /// CANopen, 500k, node 12, plus `setup`.
    pub fn canopen(setup: impl FnOnce(&mut Adv200)) -> H {
        H::new(Adv200Config::default(), |d| {
            d.set_param_str(par::FIELDBUS_TYPE, "CANopen").unwrap();
            d.set_param_str(par::FIELDBUS_BAUDRATE, "500k").unwrap();
            d.set_param(par::FIELDBUS_ADDRESS, 12).unwrap();
            setup(d);
        })
    }

    /// DS402, 500k, node 2.
    pub fn ds402() -> H {
        H::new(Adv200Config::default(), |d| {
            d.set_param_str(par::FIELDBUS_TYPE, "DS402").unwrap();
            d.set_param_str(par::FIELDBUS_BAUDRATE, "500k").unwrap();
            d.set_param(par::FIELDBUS_ADDRESS, 2).unwrap();
        })
    }

    /// Logs the frames `out` holds and confirms each as sent, as the bus does
    /// ([`Node::on_sent`]); the frames the confirmations bring are logged too.
    fn take(&mut self, out: &mut Outbox) {
        loop {
            let frames: Vec<Frame> = out.drain().collect();
            if frames.is_empty() {
                return;
            }
            for fr in frames {
                self.log.push((self.now, fr.to_string()));
                self.d.on_sent(&fr, Instant::from_nanos(self.now), out);
            }
        }
    }

    /// Runs every deadline up to `t` (ns).
    pub fn run_to(&mut self, t: u64) {
        let mut out = Outbox::new();
        while let Some(dl) = self.d.next_deadline() {
            if dl.as_nanos() > t {
                break;
            }
            self.now = dl.as_nanos().max(self.now);
            self.d.on_tick(Instant::from_nanos(self.now), &mut out);
            self.take(&mut out);
        }
        self.now = t;
    }

    /// Delivers `frame` at the current time, then runs the deadlines due now; returns the
    /// frames sent meanwhile.
    pub fn send(&mut self, frame: &str) -> Vec<String> {
        let start = self.log.len();
        let mut out = Outbox::new();
        self.d
            .on_frame(&f(frame), Instant::from_nanos(self.now), &mut out);
        self.take(&mut out);
        self.run_to(self.now);
        self.log[start..].iter().map(|(_, s)| s.clone()).collect()
    }

    /// Frames sent after log position `from`, with times.
    pub fn since(&self, from: usize) -> Vec<(u64, String)> {
        self.log[from..].to_vec()
    }

    pub fn frames(&self) -> Vec<String> {
        self.log.iter().map(|(_, s)| s.clone()).collect()
    }
}
