//! A bus at the drive's default bit rate (C48 = 1: 500 kbit/s) with the drive and a CAL
//! master on it, and a recorder.
#![allow(dead_code)]

use cantwin_bus::{BusConfig, BusId, PortConfig, PortId, Recorder, Simulation, TapId};
use cantwin_cal::{ClientEvent, ClientObject, CmsClient, ObjectKind, Request};
use cantwin_can::{BitRate, Duration, Frame, Instant};
use cantwin_opendrive::node::cms_objects;
use cantwin_opendrive::{Drive, DriveData, MotorData, OpenDrive};

pub struct Rig {
    pub sim: Simulation,
    pub bus: BusId,
    pub drive: PortId,
    pub master: PortId,
    pub tap: TapId,
    seen: usize,
}

/// One recorded frame: text, start and end (ns).
pub type Rec = (String, u64, u64);

pub fn rig() -> Rig {
    rig_with(OpenDrive::new(MotorData::default(), DriveData::default()))
}

pub fn rig_with(drive: OpenDrive) -> Rig {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", drive.bit_rate()));
    let objects = cms_objects(|id| drive.drive().saved_param(id)).unwrap();
    let mut client: Vec<ClientObject> = objects
        .iter()
        .map(|o| ClientObject::new(o.kind, o.cobs))
        .collect();
    client[0].remote_dlc = 4;
    let drive = sim.attach(bus, drive, PortConfig::default()).unwrap();
    let master = sim
        .attach(bus, CmsClient::new(client), PortConfig::default())
        .unwrap();
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    Rig {
        sim,
        bus,
        drive,
        master,
        tap,
        seen: 0,
    }
}

impl Rig {
    pub fn now(&self) -> Instant {
        self.sim.now()
    }

    pub fn drive(&self) -> &Drive {
        self.sim.node::<OpenDrive>(self.drive).unwrap().drive()
    }

    pub fn drive_mut(&mut self) -> &mut Drive {
        self.sim
            .node_mut::<OpenDrive>(self.drive)
            .unwrap()
            .drive_mut()
    }

    pub fn node(&self) -> &OpenDrive {
        self.sim.node::<OpenDrive>(self.drive).unwrap()
    }

    /// Send a raw frame from the master now.
    pub fn send(&mut self, frame: Frame) {
        self.sim.transmit(self.master, frame).unwrap();
    }

    /// A typed request from the master now.
    pub fn request(&mut self, object: cantwin_cal::ObjectIndex, r: Request) {
        self.sim
            .bus_mut(self.bus)
            .unwrap()
            .with_node::<CmsClient, _>(self.master, |c, now, out| c.request(object, r, now, out))
            .unwrap()
            .unwrap();
    }

    pub fn run_ms(&mut self, ms: u64) {
        self.sim.run_for(Duration::from_millis(ms));
    }

    pub fn run_until(&mut self, t: Instant) {
        self.sim.run_until(t);
    }

    /// Frames recorded since the last call.
    pub fn frames(&mut self) -> Vec<Rec> {
        let rec = self
            .sim
            .bus(self.bus)
            .unwrap()
            .tap::<Recorder>(self.tap)
            .unwrap();
        let all: Vec<Rec> = rec
            .frames()
            .map(|f| (f.frame.to_string(), f.start.as_nanos(), f.end.as_nanos()))
            .collect();
        let new = all[self.seen..].to_vec();
        self.seen = all.len();
        new
    }

    /// The text of the frames recorded since the last call.
    pub fn texts(&mut self) -> Vec<String> {
        self.frames().into_iter().map(|f| f.0).collect()
    }

    /// Send `frame` now, run 1 ms and return the frames on the bus.
    pub fn exchange(&mut self, frame: Frame) -> Vec<String> {
        self.frames();
        self.send(frame);
        self.run_ms(1);
        self.texts()
    }

    pub fn events(&mut self) -> Vec<ClientEvent> {
        let c = self.sim.node_mut::<CmsClient>(self.master).unwrap();
        std::iter::from_fn(|| c.poll_event()).collect()
    }

    pub fn power_cycle(&mut self, off_ms: u64) {
        let bus = self.sim.bus_mut(self.bus).unwrap();
        bus.set_powered(self.drive, false).unwrap();
        self.run_ms(off_ms);
        let bus = self.sim.bus_mut(self.bus).unwrap();
        bus.set_powered(self.drive, true).unwrap();
    }
}

/// Bit time at 500 kbit/s.
pub const BIT_NS: u64 = 2_000;

/// The length of a frame on the bus, intermission included, in ns at 500 kbit/s.
pub fn ns(frame: &Frame) -> u64 {
    u64::from(frame.bit_length()) * BIT_NS
}

pub fn f(id: u16, data: &[u8]) -> Frame {
    Frame::std(id, data).unwrap()
}

pub fn kind_is(o: &cantwin_cal::ServerObject, k: ObjectKind) -> bool {
    o.kind == k
}

pub const BITRATE: BitRate = BitRate::R500K;
