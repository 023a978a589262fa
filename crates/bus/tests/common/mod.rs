//! A scripted probe node shared by the behaviour tests.
#![allow(dead_code)]

use cantwin_can::{ControllerEvent, Frame, Id, Instant, Node, Outbox};

/// Sends scripted frames at scripted instants and records everything it sees.
#[derive(Debug, Default, Clone)]
pub struct Probe {
    script: Vec<(Instant, Frame)>,
    next: usize,
    /// Frames sent on every power-up.
    pub on_power: Vec<Frame>,
    /// Only these identifiers pass the filter (all if `None`).
    pub accept: Option<Vec<Id>>,
    pub rx: Vec<(u64, Frame)>,
    pub sent: Vec<(u64, Frame)>,
    pub events: Vec<(u64, ControllerEvent)>,
    pub power_ups: Vec<u64>,
}

impl Probe {
    pub fn new() -> Self {
        Probe::default()
    }

    /// A probe that sends `frames` when powered.
    pub fn sending(frames: &[Frame]) -> Self {
        Probe {
            on_power: frames.to_vec(),
            ..Probe::default()
        }
    }

    /// Also send `frame` at `t` ns.
    pub fn at(mut self, t: u64, frame: Frame) -> Self {
        self.script.push((Instant::from_nanos(t), frame));
        self.script.sort_by_key(|(t, _)| *t);
        self
    }

    pub fn accepting(mut self, ids: &[Id]) -> Self {
        self.accept = Some(ids.to_vec());
        self
    }

    pub fn rx_ids(&self) -> Vec<(u64, u32)> {
        self.rx.iter().map(|(t, f)| (*t, f.id().as_raw())).collect()
    }
}

impl Node for Probe {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.power_ups.push(now.as_nanos());
        for f in &self.on_power {
            out.push(*f);
        }
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, _out: &mut Outbox) {
        self.rx.push((now.as_nanos(), *frame));
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        while let Some((t, f)) = self.script.get(self.next) {
            if *t > now {
                break;
            }
            out.push(*f);
            self.next += 1;
        }
    }

    fn next_deadline(&self) -> Option<Instant> {
        self.script.get(self.next).map(|(t, _)| *t)
    }

    fn on_sent(&mut self, frame: &Frame, now: Instant, _out: &mut Outbox) {
        self.sent.push((now.as_nanos(), *frame));
    }

    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, _out: &mut Outbox) {
        self.events.push((now.as_nanos(), event));
    }

    fn accepts(&self, id: Id) -> bool {
        self.accept.as_ref().is_none_or(|a| a.contains(&id))
    }
}

/// Nanoseconds of `bits` bits at 1 Mbit/s.
pub const fn us(bits: u64) -> u64 {
    bits * 1_000
}

pub fn std_frame(id: u16, data: &[u8]) -> Frame {
    Frame::std(id, data).unwrap()
}

pub fn bits(f: &Frame) -> u64 {
    u64::from(f.bit_length())
}

/// The benchmark scenario with naive nodes that offer every period and let the bus refuse
/// what does not fit: (frames delivered, offers refused, frames received).
pub fn naive_bench(config: cantwin_bus::bench::BenchConfig) -> (u64, u64, u64) {
    use cantwin_bus::{Bus, BusConfig, PortConfig};
    use cantwin_can::Duration;

    struct Naive {
        frame: Frame,
        accept: Vec<Id>,
        period: Duration,
        next: Instant,
        received: u64,
    }
    impl Node for Naive {
        fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {
            self.received += 1;
        }
        fn on_tick(&mut self, _: Instant, out: &mut Outbox) {
            out.push(self.frame);
            self.next += self.period;
        }
        fn next_deadline(&self) -> Option<Instant> {
            Some(self.next)
        }
        fn accepts(&self, id: Id) -> bool {
            self.accept.contains(&id)
        }
    }

    let n = config.nodes;
    let id = |i: u16| Id::standard(0x100 + i % n).unwrap();
    let mut bus = Bus::new(BusConfig::new("naive", config.bit_rate));
    let ports: Vec<_> = (0..n)
        .map(|i| {
            let data = [i as u8, (i >> 8) as u8, 0x55, 0xAA, 0, 1, 2, 3];
            let node = Naive {
                frame: Frame::data_array(id(i), data),
                accept: (1..=4).map(|k| id(i + k)).collect(),
                period: config.period,
                next: Instant::ZERO,
                received: 0,
            };
            bus.attach(node, PortConfig::mailbox())
        })
        .collect();
    bus.run_until(Instant::ZERO + config.duration);
    let refused = ports
        .iter()
        .map(|p| bus.port_status(*p).unwrap().stats.tx_dropped)
        .sum();
    let received = ports
        .iter()
        .map(|p| bus.node::<Naive>(*p).unwrap().received)
        .sum();
    (bus.stats().frames(), refused, received)
}
