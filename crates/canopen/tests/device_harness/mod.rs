//! Drives one [`Device`] through the `Node` trait in virtual time and records what it sends.

#![allow(dead_code, clippy::unwrap_used)]

use cantwin_can::{ControllerEvent, Frame, Id, Instant, Node, Outbox};
use cantwin_canopen::ObjectAccess;
use cantwin_canopen::abort::AbortCode;
use cantwin_canopen::device::{Device, DeviceConfig, Event};
use cantwin_canopen::objects::{Cia301Options, cia301_defaults};
use cantwin_canopen::od::{Access, DataType, OdBuilder, SubObject, Value};
use cantwin_canopen::pdo::PdoObjects;
use std::sync::Arc;

/// Milliseconds as an instant.
pub fn ms(v: u64) -> Instant {
    Instant::from_nanos(v * 1_000_000)
}

/// Microseconds as an instant.
pub fn us(v: u64) -> Instant {
    Instant::from_nanos(v * 1_000)
}

/// A frame from candump notation: `705#00`, `705#R1`.
pub fn frame(s: &str) -> Frame {
    let (id, data) = s.split_once('#').unwrap();
    let id = Id::standard(u16::from_str_radix(id, 16).unwrap()).unwrap();
    if let Some(r) = data.strip_prefix('R') {
        return Frame::remote(id, r.parse().unwrap_or(0)).unwrap();
    }
    let bytes: Vec<u8> = (0..data.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&data[i..i + 2], 16).unwrap())
        .collect();
    Frame::data(id, &bytes).unwrap()
}

/// The default test dictionary: CiA 301 objects, two application objects, one TPDO
/// (synchronous, type 1) mapping 0x6000, one RPDO mapping 0x6200.
pub fn options() -> Cia301Options {
    Cia301Options {
        device_type: 0x0001_0191,
        vendor_id: 0x0500_005A,
        product_code: 811_044,
        revision: 0x0001_0015,
        serial: 1234,
        device_name: "TEST".into(),
        emcy_consumers: 2,
        extra_sdo_servers: 1,
        ..Cia301Options::default()
    }
}

/// A device with node-ID 5 on the test dictionary built with `opts`.
pub fn device_with(opts: &Cia301Options) -> Device {
    let b = cia301_defaults(OdBuilder::new(), opts)
        .var(
            0x2000,
            SubObject::new("Parameter", DataType::Unsigned32, Access::Rw)
                .default(Value::Unsigned32(7)),
        )
        .var(
            0x6000,
            SubObject::new("Inputs", DataType::Unsigned16, Access::Ro).mappable(),
        )
        .var(
            0x6200,
            SubObject::new("Outputs", DataType::Unsigned8, Access::Rww).mappable(),
        );
    let b = PdoObjects::new(1, 1)
        .tpdo(0, 1, &[0x6000_0010])
        .rpdo(0, 255, &[0x6200_0008])
        .add_to(b);
    Device::new(Arc::new(b.build().unwrap()), DeviceConfig::new(5)).unwrap()
}

/// The device under test with what it sent.
pub struct Harness {
    pub dev: Device,
    pub now: Instant,
    sent: Vec<(u64, String)>,
    out: Outbox,
}

impl Harness {
    /// The standard device, not powered.
    pub fn new() -> Self {
        Harness::with_device(device_with(&options()))
    }

    /// A harness around `dev`.
    pub fn with_device(dev: Device) -> Self {
        Harness {
            dev,
            now: Instant::ZERO,
            sent: Vec::new(),
            out: Outbox::new(),
        }
    }

    /// The standard device, powered at t = 0, its boot-up taken.
    pub fn booted() -> Self {
        let mut h = Harness::new();
        h.power_up(Instant::ZERO);
        assert_eq!(h.take(), [(0, "705#00".to_string())]);
        h
    }

    fn collect(&mut self) {
        let t = self.now.as_nanos();
        let frames: Vec<Frame> = self.out.drain().collect();
        for f in frames {
            self.sent.push((t, f.to_string()));
            // The bus confirms the boot-up message, which EMCYs wait for; other frames are
            // confirmed by the tests that need it (`sent_ok`).
            if f.id().as_raw() & !0x7F == 0x700 && f.data_bytes() == [0] {
                self.dev.on_sent(&f, self.now, &mut self.out);
            }
        }
        let more: Vec<Frame> = self.out.drain().collect();
        for f in more {
            self.sent.push((t, f.to_string()));
        }
    }

    /// Runs timers up to `t` (inclusive), then sets the time to `t`.
    pub fn run_until(&mut self, t: Instant) {
        let mut guard = 0;
        while let Some(d) = self.dev.next_deadline() {
            if d > t {
                break;
            }
            guard += 1;
            assert!(guard < 100_000, "the device keeps asking for a tick at {d}");
            self.now = d.max(self.now);
            self.dev.on_tick(self.now, &mut self.out);
            self.collect();
        }
        self.now = t.max(self.now);
    }

    /// Power-up at `t`.
    pub fn power_up(&mut self, t: Instant) {
        self.run_until(t);
        self.dev.on_power_up(t, &mut self.out);
        self.collect();
    }

    /// A frame received at `t` (timers before it run first).
    pub fn rx(&mut self, t: Instant, f: &str) {
        self.rx_frame(t, &frame(f));
    }

    /// A frame received at `t`.
    pub fn rx_frame(&mut self, t: Instant, f: &Frame) {
        self.run_until(t);
        self.dev.on_frame(f, t, &mut self.out);
        self.collect();
    }

    /// A controller event at `t`.
    pub fn event(&mut self, t: Instant, e: ControllerEvent) {
        self.run_until(t);
        self.dev.on_controller_event(e, t, &mut self.out);
        self.collect();
    }

    /// The device's frame `f` was sent at `t`.
    pub fn sent_ok(&mut self, t: Instant, f: &str) {
        self.run_until(t);
        self.dev.on_sent(&frame(f), t, &mut self.out);
        self.collect();
    }

    /// A local write (the SDO server's path) at `t`.
    pub fn write(&mut self, t: Instant, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode> {
        self.run_until(t);
        // Tell the device the time (a tick with nothing due changes nothing else).
        self.dev.on_tick(t, &mut self.out);
        self.collect();
        let r = self.dev.write(index, sub, data);
        // Writes can make something due now (an EMCY); let it out.
        self.run_until(t);
        r
    }

    /// A u32 read.
    pub fn read_u32(&mut self, index: u16, sub: u8) -> Result<u32, AbortCode> {
        let mut b = [0u8; 4];
        let info = self.dev.read(index, sub, 0, &mut b)?;
        let mut v = [0u8; 4];
        v[..info.copied].copy_from_slice(&b[..info.copied]);
        Ok(u32::from_le_bytes(v))
    }

    /// What was sent since the last call, with times in ns.
    pub fn take(&mut self) -> Vec<(u64, String)> {
        std::mem::take(&mut self.sent)
    }

    /// The events since the last call.
    pub fn events(&mut self) -> Vec<Event> {
        std::iter::from_fn(|| self.dev.poll_event()).collect()
    }
}

/// `(ns, frame)` pairs from `(ms, frame)`.
pub fn at_ms(v: &[(u64, &str)]) -> Vec<(u64, String)> {
    v.iter()
        .map(|(t, f)| (t * 1_000_000, f.to_string()))
        .collect()
}

/// A device with node-ID 5 on the test dictionary, with `config` (its node-ID is kept).
pub fn device_with_config(opts: &Cia301Options, config: DeviceConfig) -> Device {
    let d = device_with(opts);
    let desc = Arc::clone(d.od().description());
    Device::new(desc, config).unwrap()
}
