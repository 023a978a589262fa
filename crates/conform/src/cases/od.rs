//! Area 3: the object dictionary (CiA 301 §7.4): every entry of the file read, the
//! writable ones written back with their own value, the limits probed at their edges.

use cantwin_canopen::AbortCode;

use super::{Case, access, data_type, entries, hex, le, m};
use crate::ctx::{Ctx, Finding, Outcome, fail};
use crate::report::Area::Od as A;

pub(super) fn cases() -> Vec<Case> {
    vec![
        m(
            "od.read-all",
            A,
            "CiA 301 §7.4.3, §7.2.4.3.17",
            "every readable entry is read; sub-index 0 of a structure covers its highest sub-index",
            read_all,
        ),
        m(
            "od.write-back",
            A,
            "CiA 301 §7.4.3, §7.2.4.3.3",
            "every writable entry accepts its own value",
            write_back,
        ),
        m(
            "od.limits",
            A,
            "CiA 306 §4.6.3 LowLimit/HighLimit, CiA 301 §7.2.4.3.17",
            "entries with limits accept both edges and refuse one beyond each",
            limits,
        ),
    ]
}

/// Objects whose rewrite has effects beyond the value (a PDO or SDO parameter with a
/// valid bit, a store or restore command, the error history, program control).
fn side_effects(index: u16) -> bool {
    matches!(
        index,
        0x1003 | 0x1005 | 0x1010 | 0x1011 | 0x1012 | 0x1014 | 0x1200..=0x12FF | 0x1400..=0x1BFF | 0x1F50..=0x1F57 | 0x1F80
    )
}

fn read_all(ctx: &mut Ctx<'_>) -> Outcome {
    let mut bad = Vec::new();
    let mut read = 0;
    let objects: Vec<(u16, u8, Option<u8>)> = ctx
        .eds
        .objects
        .iter()
        // Sub-index 0 of the error history and of the PDO mappings counts entries in
        // use (§7.5.2.4, §7.5.2.36, §7.5.2.38), not the highest sub-index.
        .filter(|(i, o)| {
            !o.subs.is_empty() && !matches!(**i, 0x1003 | 0x1600..=0x17FF | 0x1A00..=0x1BFF)
        })
        .map(|(i, o)| {
            let highest = o.subs.keys().max().copied().unwrap_or(0);
            let readable = o.subs.get(&0).is_some_and(|e| access(e).readable());
            (*i, highest, readable.then_some(0))
        })
        .collect();
    for (index, sub, e) in entries(ctx) {
        if !access(&e).readable() {
            continue;
        }
        match ctx.upload(index, sub)? {
            Ok(_) => read += 1,
            Err(a) if a.code == AbortCode::TIMEOUT => {
                bad.push(format!("0x{index:04X} sub {sub}: no answer"));
            }
            // An empty error history entry or an empty domain has no data (0x08000024).
            Err(a) if a.code == AbortCode::NO_DATA => read += 1,
            Err(a) => bad.push(format!("0x{index:04X} sub {sub}: {a}")),
        }
    }
    for (index, highest, sub0) in objects {
        if sub0.is_none() {
            continue;
        }
        if let Ok(d) = ctx.upload(index, 0)?
            && d.len() == 1
            && d[0] < highest
        {
            bad.push(format!(
                "0x{index:04X} sub 0 reads {}, the file lists sub-index {highest}",
                d[0]
            ));
        }
    }
    if bad.is_empty() {
        Ok(format!("{read} entries read"))
    } else {
        Err(fail(super::listing(&bad)))
    }
}

fn write_back(ctx: &mut Ctx<'_>) -> Outcome {
    let list: Vec<(u16, u8)> = entries(ctx)
        .into_iter()
        .filter(|(i, _, e)| access(e).writable() && access(e).readable() && !side_effects(*i))
        .map(|(i, s, _)| (i, s))
        .collect();
    let mut bad = Vec::new();
    let mut written = 0;
    for (index, sub) in list {
        let Ok(value) = ctx.upload(index, sub)? else {
            continue;
        };
        if value.is_empty() {
            continue;
        }
        match ctx.download(index, sub, &value)? {
            Ok(()) => written += 1,
            Err(a) => bad.push(format!("0x{index:04X} sub {sub} with {value:02X?}: {a}")),
        }
    }
    if bad.is_empty() {
        Ok(format!("{written} entries written back"))
    } else {
        Err(fail(super::listing(&bad)))
    }
}

fn limits(ctx: &mut Ctx<'_>) -> Outcome {
    let node = ctx.node;
    let mut probes = Vec::new();
    for (index, sub, e) in entries(ctx) {
        if !access(&e).writable() || !access(&e).readable() || side_effects(index) {
            continue;
        }
        let Some(dt) = data_type(&e) else { continue };
        let Some(size) = dt.fixed_size().filter(|s| *s <= 4) else {
            continue;
        };
        if matches!(
            dt,
            cantwin_canopen::od::DataType::Real32 | cantwin_canopen::od::DataType::Boolean
        ) {
            continue;
        }
        let lo = e.low_limit.as_ref().and_then(|v| v.evaluate(node));
        let hi = e.high_limit.as_ref().and_then(|v| v.evaluate(node));
        // Limits the wrong way round are a fault of the file (eds.file-valid reports it),
        // not a range to probe.
        if (lo.is_none() && hi.is_none()) || lo.zip(hi).is_some_and(|(l, h)| l > h) {
            continue;
        }
        let bits = 8 * size as u32;
        let (min, max) = if dt.is_signed() {
            (-(1i128 << (bits - 1)), (1i128 << (bits - 1)) - 1)
        } else {
            (0, (1i128 << bits) - 1)
        };
        probes.push((index, sub, size, lo, hi, min, max));
    }
    if probes.is_empty() {
        return Err(Finding::NotApplicable(
            "no writable integer entry with limits".into(),
        ));
    }
    let mut bad = Vec::new();
    for (index, sub, size, lo, hi, min, max) in &probes {
        let Ok(original) = ctx.upload(*index, *sub)? else {
            continue;
        };
        let mut tries: Vec<(i128, bool)> = Vec::new();
        if let Some(l) = lo {
            tries.push((*l, true));
            if l > min {
                tries.push((l - 1, false));
            }
        }
        if let Some(h) = hi {
            tries.push((*h, true));
            if h < max {
                tries.push((h + 1, false));
            }
        }
        for (v, ok) in tries {
            let got = ctx.download(*index, *sub, &le(v, *size))?;
            match (ok, got) {
                // Inside the limits the device may still refuse a value it does not
                // take for another reason (0x06090030), but not call it out of range.
                (true, Err(a))
                    if [AbortCode::VALUE_TOO_HIGH, AbortCode::VALUE_TOO_LOW].contains(&a.code)
                        || a.code == AbortCode::TIMEOUT =>
                {
                    bad.push(format!(
                        "0x{index:04X} sub {sub}: the limit {v} refused: {a}"
                    ));
                }
                (false, Ok(())) => bad.push(format!(
                    "0x{index:04X} sub {sub}: {v}, beyond the limits, accepted"
                )),
                (false, Err(a))
                    if ![
                        AbortCode::VALUE_TOO_HIGH,
                        AbortCode::VALUE_TOO_LOW,
                        AbortCode::INVALID_VALUE,
                    ]
                    .contains(&a.code) =>
                {
                    bad.push(format!(
                        "0x{index:04X} sub {sub}: {v} refused with {}, not a value-range code",
                        hex(a.code)
                    ));
                }
                _ => {}
            }
        }
        if let Err(a) = ctx.download(*index, *sub, &original)? {
            bad.push(format!(
                "0x{index:04X} sub {sub}: restoring {original:02X?}: {a}"
            ));
        }
    }
    if bad.is_empty() {
        Ok(format!("{} entries probed at their limits", probes.len()))
    } else {
        Err(fail(super::listing(&bad)))
    }
}
