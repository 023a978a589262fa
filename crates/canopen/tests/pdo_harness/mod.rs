//! A small harness driving a `PdoEngine` with an object dictionary directly.
#![allow(dead_code)]

use cantwin_can::{Frame, Instant, Outbox};
use cantwin_canopen::AbortCode;
use cantwin_canopen::device::NoHooks;
use cantwin_canopen::od::{
    Access, DataType, Hooked, ObjectAccess, ObjectDictionary, OdBuilder, SubObject,
};
use cantwin_canopen::pdo::{PdoEngine, PdoEvent, PdoObjects};
use std::sync::Arc;

pub const NODE: u8 = 0x05;

/// Application objects: 0x6000 inputs (ro, 4 × U16 / U8 / U32), 0x6200 outputs (rw).
pub fn app(b: OdBuilder) -> OdBuilder {
    b.var(
        0x6000,
        SubObject::new("In16", DataType::Unsigned16, Access::Ro).mappable(),
    )
    .var(
        0x6001,
        SubObject::new("In8", DataType::Unsigned8, Access::Ro).mappable(),
    )
    .var(
        0x6002,
        SubObject::new("In32", DataType::Unsigned32, Access::Ro).mappable(),
    )
    .var(
        0x6003,
        SubObject::new("Flag", DataType::Boolean, Access::Ro).mappable(),
    )
    .var(
        0x6200,
        SubObject::new("Out16", DataType::Unsigned16, Access::Rw).mappable(),
    )
    .var(
        0x6201,
        SubObject::new("Out8", DataType::Unsigned8, Access::Rw).mappable(),
    )
    .var(
        0x6202,
        SubObject::new("Out32", DataType::Unsigned32, Access::Rww).mappable(),
    )
    .var(
        0x6203,
        SubObject::new("Not mappable", DataType::Unsigned8, Access::Rw),
    )
    .var(
        0x6204,
        SubObject::new("Name", DataType::VisibleString, Access::Rw).mappable(),
    )
}

pub struct Harness {
    pub od: ObjectDictionary,
    pub pdo: PdoEngine,
    pub out: Outbox,
}

pub fn ms(v: u64) -> Instant {
    Instant::from_nanos(v * 1_000_000)
}

pub fn us(v: u64) -> Instant {
    Instant::from_nanos(v * 1_000)
}

impl Harness {
    pub fn new(objects: PdoObjects) -> Self {
        let b = objects.add_to(app(OdBuilder::new()));
        let od = ObjectDictionary::new(Arc::new(b.build().unwrap()), NODE);
        let pdo = PdoEngine::new(&od).unwrap();
        Harness {
            od,
            pdo,
            out: Outbox::new(),
        }
    }

    /// Operational at `now`, with the frames queued at that instant drained.
    pub fn operational(mut self, now: Instant) -> Self {
        self.pdo.set_operational(true, now);
        self.pdo.on_tick(now, &self.od, &mut NoHooks, &mut self.out);
        self.out.clear();
        self
    }

    pub fn sync(&mut self, counter: Option<u8>, now: Instant) -> Vec<String> {
        self.pdo
            .on_sync(counter, now, &mut self.od, &mut NoHooks, &mut self.out);
        self.take()
    }

    pub fn tick(&mut self, now: Instant) -> Vec<String> {
        self.pdo.on_tick(now, &self.od, &mut NoHooks, &mut self.out);
        self.take()
    }

    pub fn frame(&mut self, f: Frame, now: Instant) -> Vec<String> {
        self.pdo
            .on_frame(&f, now, &mut self.od, &mut NoHooks, &mut self.out);
        self.take()
    }

    pub fn take(&mut self) -> Vec<String> {
        self.out.drain().map(|f| f.to_string()).collect()
    }

    pub fn events(&mut self) -> Vec<PdoEvent> {
        core::iter::from_fn(|| self.pdo.poll_event()).collect()
    }

    /// An SDO-style download through the engine's hooks, as the device routes it.
    pub fn sdo_write(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
        now: Instant,
    ) -> Result<(), AbortCode> {
        let mut hooks = self.pdo.hooks(now);
        Hooked::new(&mut self.od, &mut hooks).write(index, sub, data)
    }

    pub fn write_u32(
        &mut self,
        index: u16,
        sub: u8,
        v: u32,
        now: Instant,
    ) -> Result<(), AbortCode> {
        self.sdo_write(index, sub, &v.to_le_bytes(), now)
    }

    pub fn write_u16(
        &mut self,
        index: u16,
        sub: u8,
        v: u16,
        now: Instant,
    ) -> Result<(), AbortCode> {
        self.sdo_write(index, sub, &v.to_le_bytes(), now)
    }

    pub fn write_u8(&mut self, index: u16, sub: u8, v: u8, now: Instant) -> Result<(), AbortCode> {
        self.sdo_write(index, sub, &[v], now)
    }

    /// Runs every tick the engine asks for up to `until`, collecting "time frame" lines.
    pub fn run_until(&mut self, until: Instant) -> Vec<String> {
        let mut trace = Vec::new();
        while let Some(d) = self.pdo.next_deadline() {
            if d > until {
                break;
            }
            self.pdo.on_tick(d, &self.od, &mut NoHooks, &mut self.out);
            for f in self.out.drain() {
                trace.push(format!("{} {}", d.as_nanos(), f));
            }
        }
        trace
    }
}
