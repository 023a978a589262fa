//! Object dictionary behaviour (CiA 301 §7.4, CiA 306 attributes, device hooks).
#![allow(clippy::unwrap_used)]

use cantwin_canopen::od::*;
use cantwin_canopen::{AbortCode, ObjectAccess};
use std::sync::Arc;

fn u8s(name: &str) -> SubObject {
    SubObject::new(name, DataType::Unsigned8, Access::Rw)
}

#[test]
fn cia306_every_eds_attribute_is_kept() {
    let desc = OdBuilder::new()
        .var(
            0x2000,
            SubObject::new("Speed", DataType::Integer16, Access::Rww)
                .mappable()
                .limits(Value::Integer16(-3000), Value::Integer16(3000))
                .default(Value::Integer16(100)),
        )
        .flags(0x0001)
        .array_of(
            0x1600,
            "RPDO1 mapping",
            2,
            SubObject::new("Mapped object", DataType::Unsigned32, Access::Rw),
        )
        .compact()
        .build()
        .unwrap();
    let o = desc.object(0x2000).unwrap();
    assert_eq!(
        (o.name(), o.code(), o.flags(), o.sub_number()),
        ("Speed", ObjectCode::Var, 1, 1)
    );
    let (sub, s) = o.subs().next().unwrap();
    assert_eq!(sub, 0);
    assert_eq!(s.access, Access::Rww);
    assert!(s.pdo_mappable);
    assert_eq!(s.low_limit, Some(Value::Integer16(-3000)));
    assert_eq!(s.high_limit, Some(Value::Integer16(3000)));
    assert_eq!(s.default, Some(Value::Integer16(100)));
    let a = desc.object(0x1600).unwrap();
    assert_eq!(
        (a.code(), a.sub_number(), a.compact_sub_obj()),
        (ObjectCode::Array, 3, true)
    );
    let subs: Vec<_> = a
        .subs()
        .map(|(i, s)| (i, s.name.clone(), s.access))
        .collect();
    assert_eq!(
        subs,
        [
            (0, "Highest sub-index supported".to_string(), Access::Const),
            (1, "Mapped object 1".to_string(), Access::Rw),
            (2, "Mapped object 2".to_string(), Access::Rw)
        ]
    );
    assert_eq!(
        desc.objects().map(|o| o.index()).collect::<Vec<_>>(),
        [0x1600, 0x2000]
    );
    assert_eq!(Access::from_eds_name("RWW"), Some(Access::Rww));
    assert_eq!(ObjectCode::from_u8(9), Some(ObjectCode::Record));
}

#[test]
fn cia301_7_4_sparse_record_lookup() {
    let desc = OdBuilder::new()
        .record(0x1018, "Identity", [(1, u8s("a")), (4, u8s("d"))])
        .build()
        .unwrap();
    assert!(desc.locate(0x1018, 0).is_ok());
    assert!(desc.locate(0x1018, 4).is_ok());
    assert_eq!(desc.locate(0x1018, 2), Err(AbortCode::NO_SUB_INDEX));
    assert_eq!(desc.locate(0x1019, 0), Err(AbortCode::NO_OBJECT));
    let od = ObjectDictionary::new(Arc::new(desc), 1);
    assert_eq!(od.get(0x1018, 0), Ok(Value::Unsigned8(4)));
}

#[test]
fn builder_refuses_inconsistent_definitions() {
    let e = |b: OdBuilder| b.build().unwrap_err();
    assert_eq!(
        e(OdBuilder::new().var(0x2000, u8s("a")).var(0x2000, u8s("b"))),
        OdBuildError::Duplicate(0x2000)
    );
    assert_eq!(
        e(OdBuilder::new().record(0x2000, "r", [(1, u8s("a")), (1, u8s("b"))])),
        OdBuildError::DuplicateSub(0x2000, 1)
    );
    assert!(matches!(
        e(OdBuilder::new().var(0x2000, u8s("a").default(Value::Unsigned16(1)))),
        OdBuildError::WrongType(
            0x2000,
            0,
            "the default",
            DataType::Unsigned16,
            DataType::Unsigned8
        )
    ));
    assert_eq!(
        e(OdBuilder::new().var(
            0x2000,
            SubObject::new("s", DataType::VisibleString, Access::Rw)
                .max_len(2)
                .default(Value::VisibleString("abc".into()))
        )),
        OdBuildError::DefaultTooLong(0x2000, 0)
    );
    assert_eq!(
        e(OdBuilder::new().var(
            0x2000,
            u8s("a").limits(Value::Unsigned8(5), Value::Unsigned8(4))
        )),
        OdBuildError::LimitsInverted(0x2000, 0)
    );
    assert_eq!(
        e(OdBuilder::new().var(
            0x2000,
            SubObject::new("s", DataType::Real32, Access::Rw)
                .default_node_id_plus(Value::Real32(1.0))
        )),
        OdBuildError::NodeIdNotInteger(0x2000, 0)
    );
}

#[test]
fn cia306_4_6_3_node_id_defaults_follow_the_node_id_on_restore() {
    let desc = OdBuilder::new()
        .var(
            0x1014,
            SubObject::new("COB-ID EMCY", DataType::Unsigned32, Access::Rw)
                .default_node_id_plus(Value::Unsigned32(0x80)),
        )
        .build()
        .unwrap();
    let mut od = ObjectDictionary::new(Arc::new(desc), 0x10);
    assert_eq!(od.get(0x1014, 0), Ok(Value::Unsigned32(0x90)));
    od.write(0x1014, 0, &0x1234u32.to_le_bytes()).unwrap();
    od.set_node_id(0x20);
    assert_eq!(od.get(0x1014, 0), Ok(Value::Unsigned32(0x1234)));
    od.restore_defaults(0x1000..=0x1FFF);
    assert_eq!(od.get(0x1014, 0), Ok(Value::Unsigned32(0xA0)));
}

#[test]
fn device_side_set_bypasses_access_but_not_type() {
    let desc = OdBuilder::new()
        .var(
            0x1001,
            SubObject::new("Error register", DataType::Unsigned8, Access::Ro),
        )
        .build()
        .unwrap();
    let mut od = ObjectDictionary::new(Arc::new(desc), 1);
    assert_eq!(od.write(0x1001, 0, &[1]), Err(AbortCode::READ_ONLY));
    od.set(0x1001, 0, &Value::Unsigned8(0x81)).unwrap();
    assert_eq!(od.get_unsigned(0x1001, 0), Some(0x81));
    assert_eq!(
        od.set(0x1001, 0, &Value::Unsigned16(1)),
        Err(AbortCode::TYPE_MISMATCH)
    );
}

/// A drive model behind 0x2000..=0x20FF.
#[derive(Default)]
struct Drive {
    running: bool,
    written: Vec<(u16, u8)>,
    speed: i16,
}

impl OdHooks for Drive {
    fn read(
        &mut self,
        _: &ObjectDictionary,
        index: u16,
        _: u8,
        offset: usize,
        buf: &mut [u8],
    ) -> Option<Result<ReadInfo, AbortCode>> {
        (index == 0x2001).then(|| {
            let v = self.speed.to_le_bytes();
            let n = buf.len().min(2usize.saturating_sub(offset));
            buf[..n].copy_from_slice(&v[offset.min(2)..offset.min(2) + n]);
            Ok(ReadInfo { size: 2, copied: n })
        })
    }

    fn validate(
        &mut self,
        _: &ObjectDictionary,
        index: u16,
        _: u8,
        data: &[u8],
    ) -> Result<(), AbortCode> {
        if index == 0x2000 && self.running {
            return Err(AbortCode::DEVICE_STATE);
        }
        if index == 0x2002 && data.first() == Some(&b'!') {
            return Err(AbortCode::INVALID_VALUE);
        }
        Ok(())
    }

    fn written(&mut self, od: &mut ObjectDictionary, index: u16, sub: u8) {
        self.written.push((index, sub));
        if index == 0x2000 {
            self.speed = od
                .get(0x2000, 0)
                .ok()
                .and_then(|v| v.as_i128())
                .unwrap_or(0) as i16;
        }
    }
}

fn drive_od() -> ObjectDictionary {
    let desc = OdBuilder::new()
        .var(
            0x1017,
            SubObject::new("Heartbeat", DataType::Unsigned16, Access::Rw),
        )
        .var(
            0x2000,
            SubObject::new("Speed reference", DataType::Integer16, Access::Rw)
                .limits(Value::Integer16(-3000), Value::Integer16(3000)),
        )
        .var(
            0x2001,
            SubObject::new("Actual speed", DataType::Integer16, Access::Ro),
        )
        .var(
            0x2002,
            SubObject::new("Name", DataType::VisibleString, Access::Rw).max_len(32),
        )
        .hook(0x2000..=0x20FF)
        .build()
        .unwrap();
    ObjectDictionary::new(Arc::new(desc), 1)
}

#[test]
fn hooks_validate_writes_after_the_dictionary_checks() {
    let mut od = drive_od();
    let mut drive = Drive {
        running: true,
        ..Drive::default()
    };
    let mut a = Hooked::new(&mut od, &mut drive);
    // The limit check comes first ...
    assert_eq!(
        a.write(0x2000, 0, &4000i16.to_le_bytes()),
        Err(AbortCode::VALUE_TOO_HIGH)
    );
    // ... then the device's own rule.
    assert_eq!(
        a.write(0x2000, 0, &1500i16.to_le_bytes()),
        Err(AbortCode::DEVICE_STATE)
    );
    drive.running = false;
    let mut a = Hooked::new(&mut od, &mut drive);
    assert_eq!(a.write(0x2000, 0, &1500i16.to_le_bytes()), Ok(()));
    assert_eq!(drive.written, [(0x2000, 0)]);
    assert_eq!(drive.speed, 1500);
}

#[test]
fn hooks_serve_reads_dynamically() {
    let mut od = drive_od();
    let mut drive = Drive {
        speed: -42,
        ..Drive::default()
    };
    let mut a = Hooked::new(&mut od, &mut drive);
    let mut buf = [0u8; 4];
    assert_eq!(
        a.read(0x2001, 0, 0, &mut buf),
        Ok(ReadInfo { size: 2, copied: 2 })
    );
    assert_eq!(i16::from_le_bytes([buf[0], buf[1]]), -42);
    // Access rules still apply to hooked objects.
    assert_eq!(a.write(0x2001, 0, &[0, 0]), Err(AbortCode::READ_ONLY));
}

#[test]
fn hooks_see_streamed_writes_whole_and_unhooked_objects_bypass_them() {
    let mut od = drive_od();
    let mut drive = Drive::default();
    let mut a = Hooked::new(&mut od, &mut drive);
    a.write_begin(0x2002, 0, Some(9)).unwrap();
    a.write_segment(0x2002, 0, b"!bad").unwrap();
    a.write_segment(0x2002, 0, b" name").unwrap();
    assert_eq!(a.write_end(0x2002, 0), Err(AbortCode::INVALID_VALUE));
    a.write_begin(0x2002, 0, None).unwrap();
    a.write_segment(0x2002, 0, b"ADV200").unwrap();
    assert_eq!(a.write_end(0x2002, 0), Ok(()));
    a.write(0x1017, 0, &[0xE8, 0x03]).unwrap();
    assert_eq!(drive.written, [(0x2002, 0)]);
    assert_eq!(od.get(0x2002, 0), Ok(Value::VisibleString("ADV200".into())));
    assert_eq!(od.get(0x1017, 0), Ok(Value::Unsigned16(1000)));
}

#[test]
fn values_live_in_one_arena_plus_growable_buffers() {
    let od = drive_od();
    // 3 × 2 bytes of fixed values; one (empty) string buffer.
    assert_eq!(od.description().fixed_storage_len(), 6);
    assert!(od.heap_bytes() < 64);
}

/// A model that holds 0x2000 (speed reference) and 0x2002 (name) itself: the dictionary
/// keeps no copy of them.
#[derive(Default)]
struct Model {
    speed: i16,
    name: Vec<u8>,
    calls: Vec<&'static str>,
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
        let v: Vec<u8> = match index {
            0x2000 => self.speed.to_le_bytes().to_vec(),
            0x2002 => self.name.clone(),
            _ => return None,
        };
        let start = offset.min(v.len());
        let n = buf.len().min(v.len() - start);
        buf[..n].copy_from_slice(&v[start..start + n]);
        Some(Ok(ReadInfo {
            size: v.len(),
            copied: n,
        }))
    }

    fn validate(&mut self, _: &ObjectDictionary, _: u16, _: u8, _: &[u8]) -> Result<(), AbortCode> {
        self.calls.push("validate");
        Ok(())
    }

    fn write(
        &mut self,
        _: &mut ObjectDictionary,
        index: u16,
        _: u8,
        data: &[u8],
    ) -> Option<Result<(), AbortCode>> {
        self.calls.push("write");
        match index {
            0x2000 => {
                let v = i16::from_le_bytes([data[0], data[1]]);
                // The model's own rule, answered from the write itself.
                if v == 1234 {
                    return Some(Err(AbortCode::DEVICE_STATE));
                }
                self.speed = v;
                Some(Ok(()))
            }
            0x2002 => {
                self.name = data.to_vec();
                Some(Ok(()))
            }
            _ => None,
        }
    }

    fn written(&mut self, _: &mut ObjectDictionary, _: u16, _: u8) {
        self.calls.push("written");
    }
}

#[test]
fn cia301_7_2_4_3_3_write_hook_takes_an_expedited_download_after_the_checks() {
    let mut od = drive_od();
    let mut model = Model::default();
    let mut a = Hooked::new(&mut od, &mut model);
    // The dictionary's limits come first: the model is not asked.
    assert_eq!(
        a.write(0x2000, 0, &4000i16.to_le_bytes()),
        Err(AbortCode::VALUE_TOO_HIGH)
    );
    assert_eq!(a.write(0x2000, 0, &1500i16.to_le_bytes()), Ok(()));
    // The model refuses: no notification follows.
    assert_eq!(
        a.write(0x2000, 0, &1234i16.to_le_bytes()),
        Err(AbortCode::DEVICE_STATE)
    );
    let mut buf = [0u8; 4];
    assert_eq!(
        a.read(0x2000, 0, 0, &mut buf),
        Ok(ReadInfo { size: 2, copied: 2 })
    );
    assert_eq!(buf, [0xDC, 0x05, 0, 0]);
    // The model holds the value; the stored copy stays at its default.
    assert_eq!(od.get(0x2000, 0), Ok(Value::Integer16(0)));
    assert_eq!(model.speed, 1500);
    assert_eq!(
        model.calls,
        ["validate", "write", "written", "validate", "write"]
    );
}

#[test]
fn cia301_7_2_4_3_4_write_hook_takes_a_segmented_download_whole() {
    let mut od = drive_od();
    let mut model = Model::default();
    let mut a = Hooked::new(&mut od, &mut model);
    a.write_begin(0x2002, 0, None).unwrap();
    a.write_segment(0x2002, 0, b"ADV").unwrap();
    a.write_segment(0x2002, 0, b"200").unwrap();
    assert_eq!(a.write_end(0x2002, 0), Ok(()));
    assert_eq!(model.name, b"ADV200");
    assert_eq!(od.get(0x2002, 0), Ok(Value::VisibleString(String::new())));
    assert!(od.staged().is_empty());
    assert_eq!(model.calls, ["validate", "write", "written"]);
}
