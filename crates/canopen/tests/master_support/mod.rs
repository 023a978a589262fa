//! A master and small CANopen devices on a 1 Mbit/s virtual bus.
#![allow(dead_code, clippy::unwrap_used)]

use cantwin_bus::{BusConfig, BusId, PortConfig, PortId, Recorder, Simulation, TapId};
use cantwin_can::{BitRate, Duration, Frame, Instant, Node, Outbox};
use cantwin_canopen::AbortCode;
use cantwin_canopen::master::{Master, MasterEvent};
use cantwin_canopen::od::{
    Access, DataType, ObjectDictionary, OdBuilder, OdDescription, SubObject, Value,
};
use cantwin_canopen::pdo::PdoObjects;
use cantwin_canopen::sdo::SdoServer;
use cantwin_canopen::sdo::wire::{Mux, Response};
use std::sync::Arc;

pub const DEVICE_TYPE: u32 = 0x0002_0192;

/// The dictionary of every test device.
pub fn description() -> OdDescription {
    use DataType as T;
    let b = OdBuilder::new()
        .var(
            0x1000,
            SubObject::new("Device type", T::Unsigned32, Access::Ro)
                .default(Value::Unsigned32(DEVICE_TYPE)),
        )
        .var(
            0x1017,
            SubObject::new("Producer heartbeat time", T::Unsigned16, Access::Rw),
        )
        .var(
            0x2000,
            SubObject::new("Limited U8", T::Unsigned8, Access::Rw)
                .limits(Value::Unsigned8(10), Value::Unsigned8(100))
                .default(Value::Unsigned8(50)),
        )
        .var(
            0x2003,
            SubObject::new("Big domain", T::Domain, Access::Rw).max_len(200_000),
        )
        .var(
            0x2006,
            SubObject::new("Short string", T::VisibleString, Access::Rw).max_len(20),
        )
        .var(
            0x2007,
            SubObject::new("Unbounded domain", T::Domain, Access::Rw),
        )
        .var(
            0x6041,
            SubObject::new("Statusword", T::Unsigned16, Access::Ro).mappable(),
        )
        .var(
            0x6064,
            SubObject::new("Position actual value", T::Integer32, Access::Ro).mappable(),
        );
    PdoObjects::new(1, 1)
        .tpdo(1, 0xFE, &[0x6041_0010])
        .add_to(b)
        .build()
        .unwrap()
}

/// A device: an SDO server over a dictionary, optional heartbeat producer, node guarding
/// slave, and knobs to misbehave.
pub struct Device {
    pub node: u8,
    pub od: ObjectDictionary,
    pub server: SdoServer,
    /// Answer block initiates with abort 0x05040001 (a server without block transfer).
    pub refuse_block: bool,
    /// Ignore SDO requests.
    pub silent: bool,
    /// Heartbeat period.
    pub heartbeat: Option<Duration>,
    next_beat: Option<Instant>,
    /// Answer guarding remote frames.
    pub answer_guarding: bool,
    /// Alternate the guarding toggle bit (a broken device does not).
    pub toggles: bool,
    toggle: bool,
    /// NMT state code reported.
    pub state: u8,
    /// Send a boot-up message on power-up.
    pub boot: bool,
}

impl Device {
    pub fn new(node: u8) -> Self {
        Device {
            node,
            od: ObjectDictionary::new(Arc::new(description()), node),
            server: SdoServer::for_node(node),
            refuse_block: false,
            silent: false,
            heartbeat: None,
            next_beat: None,
            answer_guarding: true,
            toggles: true,
            toggle: false,
            state: 0x7F,
            boot: false,
        }
    }

    fn ec(&self, byte: u8) -> Frame {
        Frame::std(0x700 + u16::from(self.node), &[byte]).unwrap()
    }
}

impl Node for Device {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.toggle = false;
        if self.boot {
            out.push(self.ec(0));
        }
        self.next_beat = self.heartbeat.map(|p| now + p);
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        let raw = frame.id().as_raw();
        if raw == 0x600 + u32::from(self.node) {
            if self.silent {
                return;
            }
            let b = frame.data_bytes();
            if self.refuse_block
                && self.server.is_idle()
                && b.len() == 8
                && matches!(b[0] >> 5, 5 | 6)
            {
                let mux = Mux::new(u16::from_le_bytes([b[1], b[2]]), b[3]);
                let r = Response::Abort {
                    mux,
                    code: AbortCode::INVALID_COMMAND,
                };
                out.push(Frame::std(0x580 + u16::from(self.node), &r.encode()).unwrap());
                return;
            }
            self.server.on_frame(frame, now, &mut self.od, out);
        } else if raw == 0x700 + u32::from(self.node) && frame.is_remote() && self.answer_guarding {
            out.push(self.ec(u8::from(self.toggle) << 7 | self.state));
            if self.toggles {
                self.toggle = !self.toggle;
            }
        }
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        self.server.on_tick(now, &mut self.od, out);
        if let (Some(p), Some(t)) = (self.heartbeat, self.next_beat)
            && now >= t
        {
            out.push(self.ec(self.state));
            self.next_beat = Some(t + p);
        }
    }

    fn next_deadline(&self) -> Option<Instant> {
        match (self.server.next_deadline(), self.next_beat) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
}

/// A master and devices on one bus, with a recorder.
pub struct Net {
    pub sim: Simulation,
    pub bus: BusId,
    pub master: PortId,
    pub devices: Vec<PortId>,
    pub tap: TapId,
}

impl Net {
    pub fn new(master: Master, devices: Vec<Device>) -> Self {
        Net::with_master_port(master, devices, PortConfig::default())
    }

    /// With the master attached through `port` (devices get a 512-frame queue: a block
    /// upload server queues a whole block at once).
    pub fn with_master_port(master: Master, devices: Vec<Device>, port: PortConfig) -> Self {
        let mut sim = Simulation::new();
        let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
        let deep = PortConfig::default().with_queue_depth(512);
        let master = sim.attach(bus, master, port).unwrap();
        let devices = devices
            .into_iter()
            .map(|d| sim.attach(bus, d, deep).unwrap())
            .collect();
        let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
        Net {
            sim,
            bus,
            master,
            devices,
            tap,
        }
    }

    /// Runs `f` on the master at the current time, its frames queued on the bus.
    pub fn with_master<R>(&mut self, f: impl FnOnce(&mut Master, Instant, &mut Outbox) -> R) -> R {
        self.sim
            .bus_mut(self.bus)
            .unwrap()
            .with_node::<Master, R>(self.master, f)
            .unwrap()
    }

    pub fn device(&mut self, i: usize) -> &mut Device {
        let p = self.devices[i];
        self.sim.node_mut::<Device>(p).unwrap()
    }

    pub fn master(&mut self) -> &mut Master {
        let p = self.master;
        self.sim.node_mut::<Master>(p).unwrap()
    }

    pub fn now(&self) -> Instant {
        self.sim.now()
    }

    pub fn run_for(&mut self, d: Duration) {
        self.sim.run_for(d);
    }

    /// Runs until the master has an event, at most `limit` of bus time; returns it.
    pub fn next_event(&mut self, limit: Duration) -> Option<(Instant, MasterEvent)> {
        let end = self.now() + limit;
        loop {
            if let Some(e) = self.master().poll_event() {
                return Some(e);
            }
            match self.sim.next_event_time() {
                Some(t) if t <= end => {
                    self.sim.step_next();
                }
                _ => return None,
            }
        }
    }

    /// All events until the bus is quiet or `limit` from now passes.
    pub fn events(&mut self, limit: Duration) -> Vec<(Instant, MasterEvent)> {
        let end = self.now() + limit;
        let mut v = Vec::new();
        while let Some(e) = self.next_event(end.saturating_duration_since(self.now())) {
            v.push(e);
        }
        v
    }

    /// The recorded frames: (start ns, end ns, "id#data").
    pub fn frames(&self) -> Vec<(u64, u64, String)> {
        let rec = self
            .sim
            .bus(self.bus)
            .unwrap()
            .tap::<Recorder>(self.tap)
            .unwrap();
        rec.frames()
            .map(|f| (f.start.as_nanos(), f.end.as_nanos(), f.frame.to_string()))
            .collect()
    }

    pub fn frame_strings(&self) -> Vec<String> {
        self.frames().into_iter().map(|f| f.2).collect()
    }
}

/// 0, 1, 2, … as bytes.
pub fn pattern(n: usize) -> Vec<u8> {
    (0..n).map(|i| (i * 7 + i / 251) as u8).collect()
}
