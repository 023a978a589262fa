//! PDO engine hot paths: one SYNC cycle of a node with 4 TPDOs mapped to 8 bytes each, a
//! TM3BCCO-sized node (29 RPDOs, 56 TPDOs) and the reception of an 8-byte RPDO.
#![allow(clippy::unwrap_used, missing_docs)]

use cantwin_can::{Frame, Instant, Outbox};
use cantwin_canopen::device::NoHooks;
use cantwin_canopen::od::{Access, DataType, ObjectDictionary, OdBuilder, SubObject};
use cantwin_canopen::pdo::{PdoEngine, PdoObjects};
use criterion::{Criterion, black_box, criterion_group, criterion_main};
use std::sync::Arc;

/// A node with `rpdos` RPDOs and `tpdos` TPDOs of type 1, each mapped to 4 × UNSIGNED16.
fn node(rpdos: u16, tpdos: u16) -> (ObjectDictionary, PdoEngine) {
    let words = |name: &str, access| SubObject::new(name, DataType::Unsigned16, access).mappable();
    let mut b = OdBuilder::new()
        .array_of(0x6000, "Inputs", 224, words("Input", Access::Ro))
        .array_of(0x6200, "Outputs", 116, words("Output", Access::Rw));
    let mut objects = PdoObjects::new(rpdos, tpdos).max_entries(4);
    for n in 0..tpdos {
        let m: Vec<u32> = (0..4u32)
            .map(|k| 0x6000_0010 | ((u32::from(n) * 4 + k) % 224 + 1) << 8)
            .collect();
        objects = objects.tpdo(n, 1, &m);
    }
    for n in 0..rpdos {
        let m: Vec<u32> = (0..4u32)
            .map(|k| 0x6200_0010 | ((u32::from(n) * 4 + k) % 116 + 1) << 8)
            .collect();
        objects = objects.rpdo(n, 255, &m);
    }
    b = objects.add_to(b);
    let mut od = ObjectDictionary::new(Arc::new(b.build().unwrap()), 1);
    // PDOs beyond the fourth have no default identifier: give them 29-bit ones.
    let mut pdo = PdoEngine::new(&od).unwrap();
    for n in 4..tpdos {
        let cob = 0x2000_0000 | u32::from(n);
        od.set_raw(od.locate(0x1800 + n, 1).unwrap(), &cob.to_le_bytes())
            .unwrap();
    }
    for n in 4..rpdos {
        let cob = 0x2001_0000 | u32::from(n);
        od.set_raw(od.locate(0x1400 + n, 1).unwrap(), &cob.to_le_bytes())
            .unwrap();
    }
    pdo.configure(&od, Instant::ZERO).unwrap();
    pdo.set_operational(true, Instant::ZERO);
    (od, pdo)
}

fn sync_cycle(c: &mut Criterion) {
    for (name, rpdos, tpdos) in [
        ("4_tpdo_8_bytes", 0, 4),
        ("tm3bcco_29_rpdo_56_tpdo", 29, 56),
        ("512_rpdo_512_tpdo", 512, 512),
    ] {
        let (mut od, mut pdo) = node(rpdos, tpdos);
        let mut out = Outbox::new();
        pdo.on_sync(None, Instant::ZERO, &mut od, &mut NoHooks, &mut out);
        assert_eq!(out.len(), usize::from(tpdos));
        out.clear();
        let mut now = 0u64;
        c.bench_function(&format!("pdo/sync_cycle/{name}"), |b| {
            b.iter(|| {
                now += 1_000_000;
                pdo.on_sync(
                    None,
                    Instant::from_nanos(now),
                    &mut od,
                    &mut NoHooks,
                    &mut out,
                );
                black_box(out.frames());
                out.clear();
            })
        });
    }
}

fn rpdo_receive(c: &mut Criterion) {
    let (mut od, mut pdo) = node(29, 56);
    let mut out = Outbox::new();
    let frame = Frame::std(0x201, &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
    c.bench_function("pdo/rpdo_receive_8_bytes", |b| {
        b.iter(|| {
            black_box(pdo.on_frame(&frame, Instant::ZERO, &mut od, &mut NoHooks, &mut out));
            while pdo.poll_event().is_some() {}
        })
    });
}

criterion_group!(benches, sync_cycle, rpdo_receive);
criterion_main!(benches);
