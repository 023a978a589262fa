//! PDO data through the device's hooks (CiA 301 §7.2.2): RPDO entries are checked as an
//! SDO download of their bytes and applied all or none, TPDOs read hooked objects through
//! the read hook.
#![allow(clippy::unwrap_used)]

use cantwin_can::{Frame, Id, Instant, Outbox};
use cantwin_canopen::AbortCode;
use cantwin_canopen::od::{
    Access, DataType, ObjectDictionary, OdBuilder, OdHooks, ReadInfo, SubObject, Value,
};
use cantwin_canopen::pdo::{PdoEngine, PdoEvent, PdoObjects};
use std::sync::Arc;

const NODE: u8 = 5;

/// A drive model: it holds the speed reference (0x2000) itself, refuses 0xDEAD as a
/// control word (0x2001, stored), and serves the actual speed (0x2003).
#[derive(Default)]
struct Model {
    reference: i16,
    actual: i16,
    calls: Vec<String>,
}

impl OdHooks for Model {
    fn read(
        &mut self,
        _: &ObjectDictionary,
        index: u16,
        _: u8,
        offset: usize,
        buf: &mut [u8],
    ) -> Option<Result<ReadInfo, AbortCode>> {
        let v = match index {
            0x2000 => self.reference,
            0x2003 => self.actual,
            _ => return None,
        };
        let b = v.to_le_bytes();
        let start = offset.min(2);
        let n = buf.len().min(2 - start);
        buf[..n].copy_from_slice(&b[start..start + n]);
        Some(Ok(ReadInfo { size: 2, copied: n }))
    }

    fn validate(
        &mut self,
        _: &ObjectDictionary,
        index: u16,
        _: u8,
        data: &[u8],
    ) -> Result<(), AbortCode> {
        self.calls.push(format!("validate {index:04X} {data:02X?}"));
        if index == 0x2001 && data == [0xAD, 0xDE] {
            return Err(AbortCode::DEVICE_STATE);
        }
        Ok(())
    }

    fn write(
        &mut self,
        _: &mut ObjectDictionary,
        index: u16,
        _: u8,
        data: &[u8],
    ) -> Option<Result<(), AbortCode>> {
        self.calls.push(format!("write {index:04X}"));
        (index == 0x2000).then(|| {
            self.reference = i16::from_le_bytes([data[0], data[1]]);
            Ok(())
        })
    }

    fn written(&mut self, _: &mut ObjectDictionary, index: u16, _: u8) {
        self.calls.push(format!("written {index:04X}"));
    }
}

fn dictionary() -> ObjectDictionary {
    let b = OdBuilder::new()
        .var(
            0x2000,
            SubObject::new("Speed reference", DataType::Integer16, Access::Rw)
                .mappable()
                .limits(Value::Integer16(-3000), Value::Integer16(3000)),
        )
        .var(
            0x2001,
            SubObject::new("Control word", DataType::Unsigned16, Access::Rw).mappable(),
        )
        .var(
            0x2003,
            SubObject::new("Actual speed", DataType::Integer16, Access::Ro).mappable(),
        )
        .var(
            0x6200,
            SubObject::new("Outputs", DataType::Unsigned8, Access::Rw).mappable(),
        )
        .hook(0x2000..=0x20FF);
    // RPDO1: reference, a dummy byte, control word, outputs (6 bytes, event-driven).
    // TPDO1 on every SYNC: actual speed, reference, outputs.
    let b = PdoObjects::new(1, 1)
        .rpdo(
            0,
            255,
            &[0x2000_0010, 0x0005_0008, 0x2001_0010, 0x6200_0008],
        )
        .tpdo(0, 1, &[0x2003_0010, 0x2000_0010, 0x6200_0008])
        .add_to(b);
    ObjectDictionary::new(Arc::new(b.build().unwrap()), NODE)
}

fn rpdo1(data: &[u8]) -> Frame {
    Frame::std(0x205, data).unwrap()
}

fn engine(od: &ObjectDictionary) -> PdoEngine {
    let mut pdo = PdoEngine::new(od).unwrap();
    pdo.set_operational(true, Instant::ZERO);
    pdo
}

#[test]
fn cia301_7_2_2_rpdo_entries_are_validated_then_written_and_notified_in_mapping_order() {
    let mut od = dictionary();
    let mut pdo = engine(&od);
    let mut model = Model::default();
    let mut out = Outbox::new();
    let t = Instant::from_nanos(1_000);
    // 1500 rpm, dummy 0xFF, control word 0x000F, outputs 0x81.
    let f = rpdo1(&[0xDC, 0x05, 0xFF, 0x0F, 0x00, 0x81]);
    assert!(pdo.on_frame(&f, t, &mut od, &mut model, &mut out));
    assert_eq!(pdo.poll_event(), Some(PdoEvent::Received { rpdo: 0 }));
    assert_eq!(
        model.calls,
        [
            "validate 2000 [DC, 05]",
            "validate 2001 [0F, 00]",
            "write 2000",
            "write 2001",
            "written 2000",
            "written 2001",
        ]
    );
    // The model holds the reference; the dictionary keeps no copy of it.
    assert_eq!(model.reference, 1500);
    assert_eq!(od.get(0x2000, 0), Ok(Value::Integer16(0)));
    assert_eq!(od.get(0x2001, 0), Ok(Value::Unsigned16(0x000F)));
    assert_eq!(od.get(0x6200, 0), Ok(Value::Unsigned8(0x81)));
    assert!(out.frames().is_empty());
}

#[test]
fn cia301_7_2_2_a_refused_rpdo_entry_writes_nothing() {
    let mut od = dictionary();
    let mut pdo = engine(&od);
    let mut model = Model::default();
    let mut out = Outbox::new();
    let t = Instant::from_nanos(1_000);
    // The model refuses the control word: the reference and the outputs stay too.
    let f = rpdo1(&[0xDC, 0x05, 0x00, 0xAD, 0xDE, 0x81]);
    pdo.on_frame(&f, t, &mut od, &mut model, &mut out);
    assert_eq!(
        pdo.poll_event(),
        Some(PdoEvent::Refused {
            rpdo: 0,
            index: 0x2001,
            sub: 0,
            code: AbortCode::DEVICE_STATE
        })
    );
    assert_eq!(pdo.poll_event(), None);
    assert_eq!(model.reference, 0);
    assert_eq!(od.get(0x2001, 0), Ok(Value::Unsigned16(0)));
    assert_eq!(od.get(0x6200, 0), Ok(Value::Unsigned8(0)));
    // The dictionary's limits come before the hooks, as for an SDO download
    // (4000 > 3000: 0x06090031); the model is not asked.
    model.calls.clear();
    let f = rpdo1(&[0xA0, 0x0F, 0x00, 0x0F, 0x00, 0x81]);
    pdo.on_frame(&f, t, &mut od, &mut model, &mut out);
    assert_eq!(
        pdo.poll_event(),
        Some(PdoEvent::Refused {
            rpdo: 0,
            index: 0x2000,
            sub: 0,
            code: AbortCode::VALUE_TOO_HIGH
        })
    );
    assert!(model.calls.is_empty());
    assert_eq!(od.get(0x6200, 0), Ok(Value::Unsigned8(0)));
    assert!(out.frames().is_empty());
}

#[test]
fn cia301_7_2_2_tpdo_reads_hooked_objects_through_the_read_hook() {
    let mut od = dictionary();
    let mut pdo = engine(&od);
    let mut model = Model {
        reference: -1500,
        actual: 1499,
        ..Model::default()
    };
    od.set(0x6200, 0, &Value::Unsigned8(0x42)).unwrap();
    let mut out = Outbox::new();
    pdo.on_sync(
        None,
        Instant::from_nanos(1_000),
        &mut od,
        &mut model,
        &mut out,
    );
    assert_eq!(
        out.frames(),
        [Frame::data(
            Id::standard(0x185).unwrap(),
            &[0xDB, 0x05, 0x24, 0xFA, 0x42]
        )
        .unwrap()]
    );
}

#[test]
fn cia301_7_2_2_a_device_passes_a_refused_rpdo_on_without_an_emcy() {
    use cantwin_can::Node;
    use cantwin_canopen::device::{Device, DeviceConfig, Event};
    use cantwin_canopen::objects::{Cia301Options, cia301_defaults};

    let b = cia301_defaults(OdBuilder::new(), &Cia301Options::default())
        .var(
            0x2001,
            SubObject::new("Control word", DataType::Unsigned16, Access::Rw).mappable(),
        )
        .hook(0x2000..=0x20FF);
    let b = PdoObjects::new(1, 0).rpdo(0, 255, &[0x2001_0010]).add_to(b);
    let desc = Arc::new(b.build().unwrap());
    let mut dev = Device::with_hooks(desc, DeviceConfig::new(NODE), Model::default()).unwrap();
    let mut out = Outbox::new();
    dev.on_power_up(Instant::ZERO, &mut out);
    dev.on_frame(
        &Frame::std(0x000, &[0x01, NODE]).unwrap(),
        Instant::ZERO,
        &mut out,
    );
    while dev.poll_event().is_some() {}
    out.clear();
    let t = Instant::from_nanos(1_000_000);
    dev.on_frame(&rpdo1(&[0xAD, 0xDE]), t, &mut out);
    assert_eq!(
        dev.poll_event(),
        Some(Event::Pdo(PdoEvent::Refused {
            rpdo: 0,
            index: 0x2001,
            sub: 0,
            code: AbortCode::DEVICE_STATE
        }))
    );
    assert_eq!(dev.poll_event(), None);
    assert!(out.frames().is_empty());
    assert_eq!(dev.od().get(0x2001, 0), Ok(Value::Unsigned16(0)));
    // The next good RPDO is applied.
    dev.on_frame(&rpdo1(&[0x0F, 0x00]), t, &mut out);
    assert_eq!(
        dev.poll_event(),
        Some(Event::Pdo(PdoEvent::Received { rpdo: 0 }))
    );
    assert_eq!(dev.od().get(0x2001, 0), Ok(Value::Unsigned16(0x000F)));
    assert_eq!(
        dev.hooks().calls.last().map(String::as_str),
        Some("written 2001")
    );
}
