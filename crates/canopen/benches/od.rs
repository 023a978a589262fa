//! Object dictionary access as the SDO server makes it, through `ObjectAccess`: reads and
//! writes of an UNSIGNED32 and a VISIBLE_STRING in a default CiA 301 dictionary, and the
//! lookup of an index that does not exist, which ends in an abort code.
#![allow(clippy::unwrap_used, missing_docs)]

use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

use cantwin_canopen::AbortCode;
use cantwin_canopen::objects::{Cia301Options, cia301_defaults};
use cantwin_canopen::od::{Access, DataType, ObjectAccess, ObjectDictionary, OdBuilder};
use cantwin_canopen::od::{SubObject, Value};
use criterion::{Criterion, criterion_group, criterion_main};

const NODE: u8 = 5;

/// 0x1006 communication cycle period: an UNSIGNED32 every CiA 301 device has, read-write.
const CYCLE_PERIOD: u16 = 0x1006;

/// A read-write VISIBLE_STRING in the manufacturer area: the CiA 301 strings (0x1008 to
/// 0x100A) are constants and cannot be written.
const LABEL: u16 = 0x2000;
const LABEL_TEXT: &str = "conveyor 3 drive";

/// Not an object of the dictionary, but in the page of the communication objects, so the
/// lookup goes as far as it can before it gives up.
const MISSING: u16 = 0x1004;

fn dictionary() -> ObjectDictionary {
    let label = SubObject::new("Device label", DataType::VisibleString, Access::Rw)
        .default(Value::VisibleString(LABEL_TEXT.into()))
        .max_len(32);
    let desc = cia301_defaults(OdBuilder::new(), &Cia301Options::default())
        .var(LABEL, label)
        .build()
        .unwrap();
    ObjectDictionary::new(Arc::new(desc), NODE)
}

fn access(c: &mut Criterion) {
    let mut od = dictionary();
    let mut buf = [0u8; 64];
    let period = 10_000u32.to_le_bytes();
    let text = *b"press 7 feeder 2";

    // What each benchmark repeats, checked once.
    od.write(CYCLE_PERIOD, 0, &period).unwrap();
    let info = od.read(CYCLE_PERIOD, 0, 0, &mut buf).unwrap();
    assert_eq!((info.size, &buf[..info.copied]), (4, &period[..]));
    let info = od.read(LABEL, 0, 0, &mut buf).unwrap();
    assert_eq!(&buf[..info.copied], LABEL_TEXT.as_bytes());
    od.write(LABEL, 0, &text).unwrap();
    let info = od.read(LABEL, 0, 0, &mut buf).unwrap();
    assert_eq!(&buf[..info.copied], &text[..]);
    assert_eq!(od.read(MISSING, 0, 0, &mut buf), Err(AbortCode::NO_OBJECT));

    let mut group = c.benchmark_group("od");
    group.bench_function("read_unsigned32", |b| {
        b.iter(|| black_box(od.read(black_box(CYCLE_PERIOD), 0, 0, &mut buf)))
    });
    group.bench_function("write_unsigned32", |b| {
        b.iter(|| black_box(od.write(black_box(CYCLE_PERIOD), 0, black_box(&period))))
    });
    group.bench_function("read_visible_string", |b| {
        b.iter(|| black_box(od.read(black_box(LABEL), 0, 0, &mut buf)))
    });
    group.bench_function("write_visible_string", |b| {
        b.iter(|| black_box(od.write(black_box(LABEL), 0, black_box(&text))))
    });
    group.bench_function("read_missing_index", |b| {
        b.iter(|| black_box(od.read(black_box(MISSING), 0, 0, &mut buf)))
    });
    group.finish();
    black_box(&buf);
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(2));
    targets = access
}
criterion_main!(benches);
