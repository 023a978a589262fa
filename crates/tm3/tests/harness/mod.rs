//! Drives one coupler directly through `Node`, with expedited SDO helpers.
#![allow(dead_code)]

use cantwin_can::{Frame, Instant, Node, Outbox};
use cantwin_tm3::coupler::{CouplerConfig, Tm3Coupler};
use cantwin_tm3::island::Island;

/// The node-ID of every test coupler.
pub const NODE: u8 = 3;

/// Milliseconds as an instant.
pub fn ms(v: u64) -> Instant {
    Instant::from_nanos(v * 1_000_000)
}

/// Microseconds as an instant.
pub fn us(v: u64) -> Instant {
    Instant::from_nanos(v * 1_000)
}

/// A coupler at node 3 carrying `refs`, powered up at 0 (boot-up taken out).
pub fn coupler(refs: &[&str]) -> Tm3Coupler {
    let mut c = Tm3Coupler::new(CouplerConfig::new(
        NODE,
        Island::from_references(refs).unwrap(),
    ))
    .unwrap();
    let mut out = Outbox::new();
    c.on_power_up(Instant::ZERO, &mut out);
    assert_eq!(out.frames(), [Frame::std(0x703, &[0]).unwrap()]);
    c
}

/// The frames of `out` as `ID#DATA` strings, emptied.
pub fn take(out: &mut Outbox) -> Vec<String> {
    out.drain().map(|f| f.to_string()).collect()
}

/// Feeds `frame` at `t` and returns what the coupler sent.
pub fn send(c: &mut Tm3Coupler, t: Instant, id: u16, data: &[u8]) -> Vec<String> {
    let mut out = Outbox::new();
    c.on_frame(&Frame::std(id, data).unwrap(), t, &mut out);
    take(&mut out)
}

/// Ticks at `t` and returns what the coupler sent.
pub fn tick(c: &mut Tm3Coupler, t: Instant) -> Vec<String> {
    let mut out = Outbox::new();
    c.on_tick(t, &mut out);
    take(&mut out)
}

/// NMT start at `t`; returns what the coupler sent.
pub fn start(c: &mut Tm3Coupler, t: Instant) -> Vec<String> {
    send(c, t, 0, &[0x01, NODE])
}

/// Expedited upload: the value's bytes, or the abort code.
pub fn read(c: &mut Tm3Coupler, t: Instant, index: u16, sub: u8) -> Result<Vec<u8>, u32> {
    let [lo, hi] = index.to_le_bytes();
    let mut out = Outbox::new();
    c.on_frame(
        &Frame::std(0x603, &[0x40, lo, hi, sub, 0, 0, 0, 0]).unwrap(),
        t,
        &mut out,
    );
    let f = out
        .frames()
        .iter()
        .find(|f| f.to_string().starts_with("583#"))
        .cloned()
        .unwrap();
    let d = f.data_bytes();
    match d[0] {
        0x80 => Err(u32::from_le_bytes([d[4], d[5], d[6], d[7]])),
        b if b & 0x02 != 0 => {
            let n = if b & 1 != 0 {
                4 - usize::from(b >> 2 & 3)
            } else {
                4
            };
            Ok(d[4..4 + n].to_vec())
        }
        // Segmented upload: collect the segments.
        _ => {
            let mut data = Vec::new();
            let mut toggle = 0u8;
            loop {
                let mut out = Outbox::new();
                c.on_frame(
                    &Frame::std(0x603, &[0x60 | toggle, 0, 0, 0, 0, 0, 0, 0]).unwrap(),
                    t,
                    &mut out,
                );
                let f = out
                    .frames()
                    .iter()
                    .find(|f| f.to_string().starts_with("583#"))
                    .cloned()
                    .unwrap();
                let d = f.data_bytes();
                let n = 7 - usize::from(d[0] >> 1 & 7);
                data.extend_from_slice(&d[1..1 + n]);
                if d[0] & 1 != 0 {
                    return Ok(data);
                }
                toggle ^= 0x10;
            }
        }
    }
}

/// Expedited upload of an unsigned value.
pub fn read_u32(c: &mut Tm3Coupler, t: Instant, index: u16, sub: u8) -> Result<u32, u32> {
    read(c, t, index, sub).map(|b| {
        let mut v = [0u8; 4];
        v[..b.len().min(4)].copy_from_slice(&b[..b.len().min(4)]);
        u32::from_le_bytes(v)
    })
}

/// Expedited download of `data` (1..=4 bytes): Ok or the abort code.
pub fn write(c: &mut Tm3Coupler, t: Instant, index: u16, sub: u8, data: &[u8]) -> Result<(), u32> {
    let [lo, hi] = index.to_le_bytes();
    let mut f = [0u8; 8];
    f[0] = 0x23 | ((4 - data.len() as u8) << 2);
    f[1] = lo;
    f[2] = hi;
    f[3] = sub;
    f[4..4 + data.len()].copy_from_slice(data);
    let mut out = Outbox::new();
    c.on_frame(&Frame::std(0x603, &f).unwrap(), t, &mut out);
    let f = out
        .frames()
        .iter()
        .find(|f| f.to_string().starts_with("583#"))
        .cloned()
        .unwrap();
    let d = f.data_bytes();
    if d[0] == 0x80 {
        Err(u32::from_le_bytes([d[4], d[5], d[6], d[7]]))
    } else {
        assert_eq!(d[0], 0x60);
        Ok(())
    }
}
