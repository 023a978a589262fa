//! `kind = "generator"`: a traffic generator, like can-utils' `cangen`, for load and fault
//! scenarios.
//!
//! Keys: `id` (integer; required), `extended` (bool, default false), `period_ms` (float,
//! required, > 0), `start_ms` (float, default 0), `count` (integer, default unlimited),
//! `data`: `"counter"` (default: a little-endian frame counter over `len` bytes), `"random"`
//! (seeded by `seed`, default the device index) or hex bytes such as `"DEADBEEF"`; `len`
//! (0–8, default 8 for counter/random).

use cantwin_bus::{BoxedNode, PortConfig, SplitMix64};
use cantwin_can::{Duration, Frame, Id, Instant, Node, Outbox};

use crate::error::ScenarioError;
use crate::registry::{BuildEnv, DeviceKind, Settings};
use crate::spec::BusSpec;

/// The generator kind.
pub struct Generator;

#[derive(Debug, Clone)]
enum Payload {
    Counter(u8),
    Random(u8, SplitMix64),
    Fixed(Vec<u8>),
}

/// A node that sends frames periodically.
#[derive(Debug, Clone)]
pub struct GeneratorNode {
    id: Id,
    period: Duration,
    start: Duration,
    remaining: Option<u64>,
    payload: Payload,
    sent: u64,
    next: Option<Instant>,
}

impl GeneratorNode {
    /// Frames queued so far.
    pub fn sent(&self) -> u64 {
        self.sent
    }

    fn frame(&mut self) -> Option<Frame> {
        let bytes: Vec<u8> = match &mut self.payload {
            Payload::Counter(len) => self.sent.to_le_bytes()[..usize::from(*len)].to_vec(),
            Payload::Random(len, rng) => rng.next_u64().to_le_bytes()[..usize::from(*len)].to_vec(),
            Payload::Fixed(b) => b.clone(),
        };
        Frame::data(self.id, &bytes).ok()
    }
}

impl Node for GeneratorNode {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.next = Some(now + self.start);
        self.on_tick(now, out);
    }
    fn on_frame(&mut self, _frame: &Frame, _now: Instant, _out: &mut Outbox) {}
    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        while let Some(next) = self.next.filter(|n| *n <= now) {
            if self.remaining == Some(0) {
                self.next = None;
                break;
            }
            if let Some(f) = self.frame() {
                out.push(f);
            }
            self.sent += 1;
            self.remaining = self.remaining.map(|r| r - 1);
            self.next = Some(next + self.period);
        }
    }
    fn next_deadline(&self) -> Option<Instant> {
        self.next
    }
    fn accepts(&self, _id: Id) -> bool {
        false
    }
}

fn positive_ms(settings: &Settings<'_>, key: &str, v: f64) -> Result<Duration, ScenarioError> {
    if (0.0..1e12).contains(&v) {
        Ok(Duration::from_secs_f64(v / 1e3))
    } else {
        Err(settings.error(
            key,
            format!("`{key}` must be a non-negative number of milliseconds"),
        ))
    }
}

impl DeviceKind for Generator {
    fn name(&self) -> &'static str {
        "generator"
    }

    fn summary(&self) -> &'static str {
        "periodic traffic generator (like cangen): id, period_ms, data = counter|random|HEX"
    }

    fn build(
        &self,
        s: &Settings<'_>,
        _bus: &BusSpec,
        _env: &BuildEnv,
    ) -> Result<(BoxedNode, PortConfig), ScenarioError> {
        let raw: u32 = s.require("id")?;
        let extended = s.get_or("extended", false)?;
        let id = if extended {
            Id::extended(raw)
        } else {
            Id::standard(raw.min(0xFFFF) as u16)
        }
        .ok()
        .filter(|_| extended || raw <= 0x7FF)
        .ok_or_else(|| {
            s.error(
                "id",
                format!(
                    "identifier {raw:#x} is out of range for a {} frame",
                    if extended { "29-bit" } else { "11-bit" }
                ),
            )
        })?;
        let period = positive_ms(s, "period_ms", s.require::<f64>("period_ms")?)?;
        if period.is_zero() {
            return Err(s.error("period_ms", "`period_ms` must be greater than 0"));
        }
        let start = positive_ms(s, "start_ms", s.get_or::<f64>("start_ms", 0.0)?)?;
        let remaining: Option<u64> = s.get("count")?;
        let len: u8 = s.get_or("len", 8u8)?;
        if len > 8 {
            return Err(s.error("len", "`len` is at most 8"));
        }
        let seed: u64 = s.get_or("seed", s.device().index as u64)?;
        let data: String = s.get_or("data", "counter".to_string())?;
        let payload = match data.as_str() {
            "counter" => Payload::Counter(len),
            "random" => Payload::Random(len, SplitMix64::new(seed)),
            hex => {
                let clean: String = hex.chars().filter(|c| !c.is_whitespace()).collect();
                if clean.len() % 2 != 0 || clean.len() > 16 {
                    return Err(s.error("data", "`data` is counter, random, or 0–8 bytes of hex"));
                }
                let bytes = (0..clean.len())
                    .step_by(2)
                    .map(|i| u8::from_str_radix(&clean[i..i + 2], 16))
                    .collect::<Result<Vec<u8>, _>>()
                    .map_err(|_| {
                        s.error("data", "`data` is counter, random, or 0–8 bytes of hex")
                    })?;
                Payload::Fixed(bytes)
            }
        };
        let node = GeneratorNode {
            id,
            period,
            start,
            remaining,
            payload,
            sent: 0,
            next: None,
        };
        Ok((BoxedNode::plain(node), PortConfig::default()))
    }
}
