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
    let boot_up = out.frames()[0];
    out.clear();
    c.on_sent(&boot_up, Instant::ZERO, &mut out);
    assert!(out.is_empty());
    c
}

/// The frames of `out` as `ID#DATA` strings, emptied, as the bus sends them: each is
/// reported sent at `t` ([`Node::on_sent`]), and what the coupler queues on that (the
/// EMCYs held behind the boot-up message or an SDO answer) follows.
pub fn acked(c: &mut Tm3Coupler, t: Instant, out: &mut Outbox) -> Vec<String> {
    let mut sent = Vec::new();
    while !out.is_empty() {
        let frames: Vec<Frame> = out.drain().collect();
        for f in frames {
            sent.push(f.to_string());
            c.on_sent(&f, t, out);
        }
    }
    sent
}

/// The frames of `out` as `ID#DATA` strings, emptied.
pub fn take(out: &mut Outbox) -> Vec<String> {
    out.drain().map(|f| f.to_string()).collect()
}

/// Feeds `frame` at `t` and returns what the coupler sent.
pub fn send(c: &mut Tm3Coupler, t: Instant, id: u16, data: &[u8]) -> Vec<String> {
    let mut out = Outbox::new();
    c.on_frame(&Frame::std(id, data).unwrap(), t, &mut out);
    acked(c, t, &mut out)
}

/// Ticks at `t` and returns what the coupler sent.
pub fn tick(c: &mut Tm3Coupler, t: Instant) -> Vec<String> {
    let mut out = Outbox::new();
    c.on_tick(t, &mut out);
    acked(c, t, &mut out)
}

/// NMT start at `t`; returns what the coupler sent.
pub fn start(c: &mut Tm3Coupler, t: Instant) -> Vec<String> {
    send(c, t, 0, &[0x01, NODE])
}

/// Expedited upload: the value's bytes, or the abort code.
pub fn read(c: &mut Tm3Coupler, t: Instant, index: u16, sub: u8) -> Result<Vec<u8>, u32> {
    let [lo, hi] = index.to_le_bytes();
    let d = sdo(c, t, [0x40, lo, hi, sub, 0, 0, 0, 0]);
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
                let d = sdo(c, t, [0x60 | toggle, 0, 0, 0, 0, 0, 0, 0]);
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
    let d = sdo(c, t, f);
    if let Some(code) = abort_of(d) {
        return Err(code);
    }
    assert_eq!(d[0], 0x60);
    Ok(())
}

/// Feeds one SDO request at `t` and returns the server's answer (0x583).
fn sdo(c: &mut Tm3Coupler, t: Instant, req: [u8; 8]) -> [u8; 8] {
    let mut out = Outbox::new();
    c.on_frame(&Frame::std(0x603, &req).unwrap(), t, &mut out);
    let a = answer(&out);
    acked(c, t, &mut out);
    a
}

/// The server's SDO answer (0x583, always 8 bytes: CiA 301 §7.2.4.3) among `out`'s frames.
fn answer(out: &Outbox) -> [u8; 8] {
    let f = out
        .frames()
        .iter()
        .find(|f| f.to_string().starts_with("583#"))
        .cloned()
        .unwrap();
    f.data_bytes().try_into().unwrap()
}

/// Initiates a download with size indicated (CiA 301 §7.2.4.3.3, §7.2.4.3.9): the server's
/// answer, or its abort code.
fn initiate_download(
    c: &mut Tm3Coupler,
    t: Instant,
    first: u8,
    index: u16,
    sub: u8,
    size: usize,
) -> Result<[u8; 8], u32> {
    let [lo, hi] = index.to_le_bytes();
    let [s0, s1, s2, s3] = (size as u32).to_le_bytes();
    let d = sdo(c, t, [first, lo, hi, sub, s0, s1, s2, s3]);
    abort_of(d).map_or(Ok(d), Err)
}

fn abort_of(d: [u8; 8]) -> Option<u32> {
    (d[0] == 0x80).then(|| u32::from_le_bytes([d[4], d[5], d[6], d[7]]))
}

/// Segmented download of `data` (size indicated, CiA 301 §7.2.4.3.4-7): Ok or the abort
/// code.
pub fn write_segmented(
    c: &mut Tm3Coupler,
    t: Instant,
    index: u16,
    sub: u8,
    data: &[u8],
) -> Result<(), u32> {
    let d = initiate_download(c, t, 0x21, index, sub, data.len())?;
    assert_eq!(d[0], 0x60);
    let mut toggle = 0u8;
    let chunks: Vec<&[u8]> = data.chunks(7).collect();
    for (k, chunk) in chunks.iter().enumerate() {
        let last = k + 1 == chunks.len();
        let mut req = [0u8; 8];
        req[0] = toggle | ((7 - chunk.len() as u8) << 1) | u8::from(last);
        req[1..1 + chunk.len()].copy_from_slice(chunk);
        let d = sdo(c, t, req);
        if let Some(code) = abort_of(d) {
            return Err(code);
        }
        assert_eq!(d[0], 0x20 | toggle);
        toggle ^= 0x10;
    }
    Ok(())
}

/// Block download of `data` (size indicated, no CRC, one block, CiA 301 §7.2.4.3.9-11):
/// Ok or the abort code.
pub fn write_block(
    c: &mut Tm3Coupler,
    t: Instant,
    index: u16,
    sub: u8,
    data: &[u8],
) -> Result<(), u32> {
    let d = initiate_download(c, t, 0xC2, index, sub, data.len())?;
    assert_eq!(d[0] & 0xFB, 0xA0);
    let chunks: Vec<&[u8]> = data.chunks(7).collect();
    let mut out = Outbox::new();
    for (k, chunk) in chunks.iter().enumerate() {
        let last = k + 1 == chunks.len();
        let mut req = [0u8; 8];
        req[0] = (k as u8 + 1) | if last { 0x80 } else { 0 };
        req[1..1 + chunk.len()].copy_from_slice(chunk);
        c.on_frame(&Frame::std(0x603, &req).unwrap(), t, &mut out);
    }
    let ack = answer(&out);
    if let Some(code) = abort_of(ack) {
        return Err(code);
    }
    assert_eq!((ack[0], usize::from(ack[1])), (0xA2, chunks.len()));
    let unused = (7 * chunks.len() - data.len()) as u8;
    let d = sdo(c, t, [0xC1 | (unused << 2), 0, 0, 0, 0, 0, 0, 0]);
    if let Some(code) = abort_of(d) {
        return Err(code);
    }
    assert_eq!(d[0], 0xA1);
    Ok(())
}
