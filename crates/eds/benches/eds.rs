//! Parse and write throughput on a large EDS: 1000 RECORD objects of 8 sub-objects each
//! (about 9000 sections), the size of a big drive's EDS.
#![allow(missing_docs, clippy::unwrap_used)]

use cantwin_eds::{parse, write};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::fmt::Write as _;
use std::hint::black_box;

fn big_eds() -> String {
    let mut s = String::from("[FileInfo]\nFileName=big.eds\n\n[DeviceInfo]\nVendorName=x\n\n");
    s.push_str("[ManufacturerObjects]\nSupportedObjects=1000\n");
    for i in 0..1000u16 {
        let _ = writeln!(s, "{}=0x{:04X}", i + 1, 0x2000 + i);
    }
    for i in 0..1000u16 {
        let index = 0x2000 + i;
        let _ = write!(
            s,
            "\n[{index:04X}]\nParameterName=Parameter group {i}\nObjectType=0x9\nSubNumber=8\n"
        );
        for sub in 0..8u8 {
            let _ = write!(
                s,
                "\n[{index:04X}sub{sub:X}]\nParameterName=Parameter {i}.{sub}\nObjectType=0x7\nDataType=0x0007\nAccessType=rw\nDefaultValue=$NODEID+0x{sub:X}00\nPDOMapping=1\nLowLimit=0\nHighLimit=0xFFFF\n"
            );
        }
    }
    s
}

fn bench(c: &mut Criterion) {
    let text = big_eds();
    let eds = parse(&text).unwrap();
    let mut g = c.benchmark_group("eds");
    g.throughput(Throughput::Bytes(text.len() as u64));
    g.bench_function("parse_1000_records", |b| {
        b.iter(|| parse(black_box(&text)).unwrap())
    });
    g.bench_function("write_1000_records", |b| b.iter(|| write(black_box(&eds))));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
