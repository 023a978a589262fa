//! SDO hot path: an expedited upload request answered by the SDO server, on its own over a
//! bare object dictionary and through the whole CiA 301 device stack (`Device` as a
//! `Node`). No bus: the request frame goes in, the response frame comes out.
#![allow(clippy::unwrap_used, missing_docs)]

use cantwin_can::{Frame, Id, Instant, Node, Outbox};
use cantwin_canopen::device::{Device, DeviceConfig};
use cantwin_canopen::objects::{Cia301Options, cia301_defaults};
use cantwin_canopen::od::{Access, DataType, ObjectDictionary, OdBuilder, SubObject};
use cantwin_canopen::pdo::PdoObjects;
use cantwin_canopen::sdo::SdoServer;
use criterion::{Criterion, black_box, criterion_group, criterion_main};
use std::sync::Arc;

const NODE: u8 = 5;

fn request() -> Frame {
    // Initiate upload of 0x1018 sub 1 (vendor-ID).
    Frame::data_array(
        Id::standard(0x600 + u16::from(NODE)).unwrap(),
        [0x40, 0x18, 0x10, 0x01, 0, 0, 0, 0],
    )
}

fn bench(c: &mut Criterion) {
    let desc = Arc::new(
        cia301_defaults(OdBuilder::new(), &Cia301Options::default())
            .build()
            .unwrap(),
    );
    let req = request();

    let mut od = ObjectDictionary::new(Arc::clone(&desc), NODE);
    let mut server = SdoServer::for_node(NODE);
    let mut out = Outbox::new();
    server.on_frame(&req, Instant::ZERO, &mut od, &mut out);
    assert_eq!(out.frames()[0].data_bytes()[0], 0x43);
    c.bench_function("sdo_server/expedited_upload", |b| {
        b.iter(|| {
            out.clear();
            server.on_frame(black_box(&req), Instant::ZERO, &mut od, &mut out);
            black_box(out.frames());
        })
    });

    let mut device = Device::new(Arc::clone(&desc), DeviceConfig::new(NODE)).unwrap();
    let mut out = Outbox::new();
    device.on_power_up(Instant::ZERO, &mut out);
    out.clear();
    device.on_frame(&req, Instant::ZERO, &mut out);
    assert_eq!(out.frames()[0].data_bytes()[0], 0x43);
    eprintln!(
        "default CiA 301 device: {} bytes of heap",
        device.heap_bytes()
    );
    c.bench_function("device/expedited_upload", |b| {
        b.iter(|| {
            out.clear();
            device.on_frame(black_box(&req), Instant::ZERO, &mut out);
            black_box(out.frames());
        })
    });
}

/// RAM of a device the size of a TM3BCCO coupler: the CiA 301 objects, 29 RPDOs and 56
/// TPDOs (85 PDOs) with 8 mapping entries each, and 224 input and 116 output words.
fn tm3bcco_sized_ram() {
    let words = |name: &str, access| SubObject::new(name, DataType::Unsigned16, access).mappable();
    let b = cia301_defaults(OdBuilder::new(), &Cia301Options::default())
        .array_of(0x6000, "Inputs", 224, words("Input", Access::Ro))
        .array_of(0x6200, "Outputs", 116, words("Output", Access::Rw));
    let desc = Arc::new(
        PdoObjects::new(29, 56)
            .max_entries(8)
            .add_to(b)
            .build()
            .unwrap(),
    );
    let od = ObjectDictionary::new(Arc::clone(&desc), NODE);
    let device = Device::new(desc, DeviceConfig::new(NODE)).unwrap();
    eprintln!(
        "TM3BCCO-sized device (85 PDOs): dictionary values {} bytes of heap, whole device {} bytes",
        od.heap_bytes(),
        device.heap_bytes()
    );
}

fn ram(_: &mut Criterion) {
    tm3bcco_sized_ram();
}

criterion_group!(benches, bench, ram);
criterion_main!(benches);
