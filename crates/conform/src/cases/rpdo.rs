//! Area 4, the receiving side: an RPDO received in OPERATIONAL writes the objects its
//! mapping names (CiA 301 §7.2.2, §7.3.2.2.5, §7.5.2.36).

use cantwin_can::{Duration, Frame, Id};
use cantwin_canopen::wire::NmtCs;

use super::{Case, access, eds_entry, m};
use crate::ctx::{Ctx, Finding, Outcome, fail, fail_kind, fail_sdo};
use crate::profile::FailureKind;
use crate::report::Area::Pdo as A;

pub(super) fn cases() -> Vec<Case> {
    vec![m(
        "pdo.rpdo-processed",
        A,
        "CiA 301 §7.2.2, §7.3.2.2.5, §7.5.2.36",
        "in OPERATIONAL an RPDO with a new value of a mapped writable object changes it",
        rpdo_processed,
    )]
}

/// One mapped object of an RPDO: where it sits in the PDO and what it holds now.
struct Field {
    index: u16,
    sub: u8,
    /// Byte offset in the PDO.
    at: usize,
    len: usize,
    /// Its value read over SDO (zeros for a dummy entry or one that does not read back).
    now: Vec<u8>,
    /// Readable and writable in the file, read back at its mapped length.
    changeable: bool,
}

/// A valid RPDO with a byte-aligned mapping and at least one object to change.
struct Rpdo {
    comm: u16,
    cob: u16,
    ty: u8,
    fields: Vec<Field>,
}

impl Rpdo {
    fn frame(&self, changed: Option<(usize, &[u8])>) -> Result<Frame, Finding> {
        let len = self.fields.iter().map(|f| f.at + f.len).max().unwrap_or(0);
        let mut data = vec![0u8; len];
        for (k, f) in self.fields.iter().enumerate() {
            let v = match changed {
                Some((c, v)) if c == k => v,
                _ => &f.now,
            };
            data[f.at..f.at + f.len].copy_from_slice(v);
        }
        let id = Id::standard(self.cob).map_err(|e| fail(e.to_string()))?;
        Frame::data(id, &data).map_err(|e| fail(e.to_string()))
    }
}

/// The first RPDO of the file that is valid, maps whole bytes and maps an object the case
/// can change over SDO.
fn find(ctx: &mut Ctx<'_>) -> Result<Option<(Rpdo, usize)>, Finding> {
    for k in 0..512u16 {
        let (comm, map) = (0x1400 + k, 0x1600 + k);
        if !ctx.eds.objects.contains_key(&comm) || !super::runnable(ctx, comm) {
            continue;
        }
        let cob = ctx.read_u32(comm, 1, "an RPDO COB-ID")?;
        if cob & 0xA000_0000 != 0 {
            continue;
        }
        let ty = match ctx.upload(comm, 2)? {
            Ok(d) if !d.is_empty() => d[0],
            _ => 255,
        };
        let n = ctx.read_u32(map, 0, "the number of mapped objects")?;
        let mut fields = Vec::new();
        let mut at = 0usize;
        let mut aligned = true;
        for s in 1..=u8::try_from(n.min(64)).unwrap_or(0) {
            let e = ctx.read_u32(map, s, "a mapping entry")?;
            let (index, sub, bits) = (
                u16::try_from(e >> 16).unwrap_or(0),
                u8::try_from((e >> 8) & 0xFF).unwrap_or(0),
                (e & 0xFF) as usize,
            );
            if bits == 0 || bits % 8 != 0 {
                aligned = false;
                break;
            }
            let len = bits / 8;
            // Indices below 0x20 are dummy entries (§7.4.7.1).
            let mut now = vec![0u8; len];
            let mut changeable = false;
            if index >= 0x20
                && eds_entry(ctx, index, sub).is_some_and(|e| access(e).readable())
                && let Ok(d) = ctx.upload(index, sub)?
                && d.len() == len
            {
                changeable = eds_entry(ctx, index, sub).is_some_and(|e| access(e).writable());
                now = d;
            }
            fields.push(Field {
                index,
                sub,
                at,
                len,
                now,
                changeable,
            });
            at += len;
        }
        if !aligned || at == 0 || at > 8 {
            continue;
        }
        if let Some(pick) = fields.iter().position(|f| f.changeable) {
            let cob = u16::try_from(cob & 0x7FF).unwrap_or(0);
            return Ok(Some((
                Rpdo {
                    comm,
                    cob,
                    ty,
                    fields,
                },
                pick,
            )));
        }
    }
    Ok(None)
}

/// A value other than `v` of the same length: its lowest byte one lower (one higher from
/// 0), so that a value inside a range stays inside it.
fn other_value(v: &[u8]) -> Vec<u8> {
    let mut w = v.to_vec();
    if let Some(b) = w.first_mut() {
        *b = if *b == 0 { 1 } else { *b - 1 };
    }
    w
}

/// Sends `frame` and, for a synchronous RPDO (types 0–240), a SYNC: §7.2.2.2 has a
/// synchronous RPDO's data take effect at the next SYNC.
fn deliver(ctx: &mut Ctx<'_>, r: &Rpdo, frame: Frame) -> Result<(), Finding> {
    ctx.send(frame)?;
    ctx.idle(Duration::from_millis(10))?;
    if r.ty <= 240 {
        let cob = match ctx.upload(0x1005, 0)? {
            Ok(d) => super::u32_of(&d) & 0x7FF,
            Err(_) => 0x80,
        };
        let id =
            Id::standard(u16::try_from(cob).unwrap_or(0x80)).map_err(|e| fail(e.to_string()))?;
        ctx.send(Frame::data(id, &[]).map_err(|e| fail(e.to_string()))?)?;
    }
    ctx.idle(Duration::from_millis(20))
}

fn rpdo_processed(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((r, pick)) = find(ctx)? else {
        return Err(Finding::NotApplicable(format!(
            "no valid RPDO maps a readable and writable object{}",
            super::left_out_brief(ctx)
        )));
    };
    let (index, sub) = (r.fields[pick].index, r.fields[pick].sub);
    let old = r.fields[pick].now.clone();
    let new = other_value(&old);
    ctx.nmt(NmtCs::Start)?;
    ctx.idle(Duration::from_millis(20))?;
    deliver(ctx, &r, r.frame(Some((pick, &new)))?)?;
    let read = ctx.upload(index, sub)?;
    // Put the old value back, by the RPDO and by SDO, before leaving OPERATIONAL.
    deliver(ctx, &r, r.frame(None)?)?;
    let restored = ctx.download(index, sub, &old)?;
    ctx.nmt(NmtCs::EnterPreOperational)?;
    ctx.idle(Duration::from_millis(20))?;
    let read = read.map_err(|a| fail_sdo(format!("reading 0x{index:04X} sub {sub} back"), a))?;
    restored.map_err(|a| fail_sdo(format!("restoring 0x{index:04X} sub {sub}"), a))?;
    let what = format!(
        "RPDO 0x{:03X} (0x{:04X}, type {}) carrying {new:02X?} for 0x{index:04X} sub {sub} (was {old:02X?})",
        r.cob, r.comm, r.ty
    );
    if read == new {
        Ok(format!("{what}: read back by SDO"))
    } else {
        Err(fail_kind(
            FailureKind::Event,
            format!("{what}: the object reads {read:02X?} in OPERATIONAL"),
        ))
    }
}
