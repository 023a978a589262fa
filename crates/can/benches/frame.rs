//! The length of a frame on the wire, `Frame::bit_length`: the CRC-15 over the header and
//! data, a table step per byte, then a count of stuff bits that visits each run of four or
//! more equal bits in SOF … CRC. The bus asks it for every distinct frame a port queues. Its
//! cost grows with the header and the data, and with the number of such runs, which the
//! worst-case stuffing below maximises.
#![allow(clippy::unwrap_used, missing_docs)]

use std::hint::black_box;
use std::time::Duration;

use cantwin_can::bits::worst_case_bits;
use cantwin_can::{Frame, Id};
use criterion::{Criterion, criterion_group, criterion_main};

/// The standard 8-byte data frame with the most stuff bits.
///
/// Repeated 0xE1 (1110 0001) is alternating runs of four zeros and four ones. Each run
/// follows a stuff bit of its own value (the complement of the run before) and makes five
/// equal bits with it, so a stuff bit follows every four data bits: the densest stuffing
/// the rule allows, since a stuff bit starts the next run of five. The
/// identifier, the first byte and the last two keep that rhythm through the header and into
/// the CRC. A search over every identifier and every payload, carrying the CRC register and
/// the current run from bit to bit, finds no standard 8-byte data frame with more than these
/// 22 stuff bits: 133 bits on the wire, 2 short of the bound in `worst_case_bits`, which
/// assumes the IDE, r0 and DLC bits and the CRC could be chosen freely.
fn worst_case_stuffing() -> Frame {
    Frame::std(0x078, &[0x01, 0xE1, 0xE1, 0xE1, 0xE1, 0xE1, 0xE0, 0x0F]).unwrap()
}

fn bit_length(c: &mut Criterion) {
    let cases = [
        ("standard_0_bytes", Frame::std(0x123, &[]).unwrap()),
        (
            "standard_8_bytes",
            Frame::std(0x123, &[0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88]).unwrap(),
        ),
        (
            "extended_8_bytes",
            Frame::data(
                Id::extended(0x18FF_50E5).unwrap(),
                &[0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88],
            )
            .unwrap(),
        ),
        ("standard_8_bytes_worst_stuffing", worst_case_stuffing()),
    ];
    let worst = worst_case_stuffing();
    assert_eq!(worst.bit_length(), 133);
    assert_eq!(worst_case_bits(&worst), 135);

    let mut group = c.benchmark_group("frame/bit_length");
    for (name, frame) in cases {
        group.bench_function(name, |b| {
            b.iter(|| black_box(black_box(&frame).bit_length()))
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(2));
    targets = bit_length
}
criterion_main!(benches);
