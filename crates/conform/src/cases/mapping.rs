//! Area 4, the mapping procedure (CiA 301 §7.5.2.36 RPDO mapping, §7.5.2.38 TPDO mapping):
//! what a device must refuse while a mapping is changed (an entry written while sub-index 0
//! is not 0, a mapping longer than 64 bits, an object that cannot be mapped or does not
//! exist) and that a changed mapping is the one the PDO then carries.
//!
//! Every case works on the first valid PDO whose mapping the file says is writable, made
//! invalid (COB-ID bit 31) for the time of the case, and puts its mapping and COB-ID back.

use cantwin_can::{Duration, Frame, Id};
use cantwin_canopen::AbortCode;
use cantwin_canopen::wire::NmtCs;

use super::{Case, absent_index, access, data_type, eds_entry, entries, hex, m, u32_of};
use crate::ctx::{Ctx, Finding, Outcome, fail, fail_abort, fail_kind, fail_sdo};
use crate::profile::FailureKind;
use crate::report::Area::Pdo as A;

pub(super) fn cases() -> Vec<Case> {
    vec![
        m(
            "pdo.mapping-entry-while-enabled",
            A,
            "CiA 301 §7.5.2.36, §7.5.2.38",
            "with the PDO invalid and sub 0 ≠ 0, a write to a mapping entry is refused",
            entry_while_enabled,
        ),
        m(
            "pdo.mapping-length",
            A,
            "CiA 301 §7.5.2.36, §7.5.2.38, §7.2.4.3.17",
            "a mapping of more than 64 bits is refused with 0x06040042, sub 0 above the entries the object has with 0x06040042 (or a value-range code)",
            length,
        ),
        m(
            "pdo.mapping-not-mappable",
            A,
            "CiA 301 §7.5.2.36, §7.5.2.38, §7.2.4.3.17",
            "mapping an object the file says cannot be mapped is refused with 0x06040041",
            not_mappable,
        ),
        m(
            "pdo.mapping-no-object",
            A,
            "CiA 301 §7.5.2.36, §7.5.2.38, §7.2.4.3.17",
            "mapping an object that does not exist is refused with 0x06020000",
            no_object,
        ),
        m(
            "pdo.mapping-carried",
            A,
            "CiA 301 §7.5.2.38, §7.2.2.2",
            "after invalid, sub 0 = 0, new entries, sub 0 = n, valid, the TPDO carries the new mapping",
            carried,
        ),
    ]
}

/// A PDO taken apart for a case: its parameters as they were.
struct Remap {
    comm: u16,
    map: u16,
    cob: u32,
    entries: Vec<u32>,
}

/// The first valid PDO (TPDOs first; only TPDOs with `tx_only`) whose COB-ID and mapping
/// the file says are writable and which maps something.
fn find(ctx: &mut Ctx<'_>, tx_only: bool) -> Result<Option<Remap>, Finding> {
    let mut all = Vec::new();
    for (tx, base) in [(true, 0x1800u16), (false, 0x1400)] {
        if tx_only && !tx {
            continue;
        }
        for k in 0..512u16 {
            if ctx.eds.objects.contains_key(&(base + k)) && super::runnable(ctx, base + k) {
                all.push((tx, base + k, base + 0x200 + k));
            }
        }
    }
    for (_, comm, map) in all {
        if !eds_entry(ctx, map, 0).is_some_and(|e| access(e).writable())
            || !eds_entry(ctx, comm, 1).is_some_and(|e| access(e).writable())
        {
            continue;
        }
        let cob = ctx.read_u32(comm, 1, "a PDO COB-ID")?;
        let n = ctx.read_u32(map, 0, "the number of mapped objects")?;
        if cob & 0x8000_0000 != 0 || n == 0 || n > 64 {
            continue;
        }
        let mut list = Vec::new();
        for s in 1..=u8::try_from(n).unwrap_or(0) {
            list.push(ctx.read_u32(map, s, "a mapping entry")?);
        }
        return Ok(Some(Remap {
            comm,
            map,
            cob,
            entries: list,
        }));
    }
    Ok(None)
}

/// Makes the PDO invalid, and with `clear` its mapping disabled (sub 0 = 0): the first two
/// steps of the procedure.
fn open(ctx: &mut Ctx<'_>, r: &Remap, clear: bool) -> Result<(), Finding> {
    ctx.write(
        r.comm,
        1,
        &(r.cob | 0x8000_0000).to_le_bytes(),
        "the COB-ID with bit 31 set",
    )?;
    if clear {
        ctx.write(r.map, 0, &[0], "sub 0 = 0 of the invalid PDO")?;
    }
    Ok(())
}

/// Puts the PDO back as [`find`] read it.
fn restore(ctx: &mut Ctx<'_>, r: &Remap) -> Result<(), Finding> {
    ctx.write(
        r.comm,
        1,
        &(r.cob | 0x8000_0000).to_le_bytes(),
        "the COB-ID with bit 31 set",
    )?;
    ctx.write(r.map, 0, &[0], "sub 0 = 0")?;
    for (i, e) in r.entries.iter().enumerate() {
        let sub = u8::try_from(i + 1).unwrap_or(1);
        ctx.write(r.map, sub, &e.to_le_bytes(), "a mapping entry")?;
    }
    let n = u8::try_from(r.entries.len()).unwrap_or(0);
    ctx.write(r.map, 0, &[n], "the number of mapped objects")?;
    ctx.write(r.comm, 1, &r.cob.to_le_bytes(), "the COB-ID back to valid")
}

fn none(ctx: &Ctx<'_>) -> Finding {
    Finding::NotApplicable(format!(
        "no valid PDO with a writable mapping{}",
        super::left_out_brief(ctx)
    ))
}

fn entry_while_enabled(ctx: &mut Ctx<'_>) -> Outcome {
    let Some(r) = find(ctx, false)? else {
        return Err(none(ctx));
    };
    // Another value than sub 1's own (a device may take a write of the value an entry
    // holds, which changes nothing): the second entry where it differs, else the first one
    // a byte shorter, else a cleared entry.
    let first = r.entries[0];
    let other = match r.entries.get(1) {
        Some(e) if *e != first => *e,
        _ if first & 0xFF > 8 => first - 8,
        _ => 0,
    };
    open(ctx, &r, false)?;
    let got = ctx.download(r.map, 1, &other.to_le_bytes())?;
    restore(ctx, &r)?;
    match got {
        Err(a) if a.by_server => Ok(format!(
            "0x{:04X} sub 1 = 0x{other:08X} with sub 0 = {} refused: {a}",
            r.map,
            r.entries.len()
        )),
        Err(a) => Err(fail_sdo(
            format!(
                "writing 0x{other:08X} to 0x{:04X} sub 1 with sub 0 ≠ 0",
                r.map
            ),
            a,
        )),
        Ok(()) => Err(fail(format!(
            "0x{:04X} sub 1 = 0x{other:08X} accepted while sub 0 = {} (the PDO invalid)",
            r.map,
            r.entries.len()
        ))),
    }
}

/// The highest sub-index of the mapping object, as the file lists it.
fn highest_sub(ctx: &Ctx<'_>, map: u16) -> u8 {
    ctx.eds
        .objects
        .get(&map)
        .and_then(|o| o.subs.keys().max().copied())
        .unwrap_or(0)
}

/// Writes `list` as the entries 1… of the open mapping and then sub 0 = its length: the
/// refusal with its step, if any. An entry write may be refused already: a device may
/// check each entry as it is written or all of them when sub 0 enables them.
fn map_entries(
    ctx: &mut Ctx<'_>,
    map: u16,
    list: &[u32],
) -> Result<Option<(String, crate::ctx::Aborted)>, Finding> {
    for (i, e) in list.iter().enumerate() {
        let sub = u8::try_from(i + 1).unwrap_or(1);
        if let Err(a) = ctx.download(map, sub, &e.to_le_bytes())? {
            return Ok(Some((format!("sub {sub} = 0x{e:08X}"), a)));
        }
    }
    let n = u8::try_from(list.len()).unwrap_or(0);
    Ok(ctx
        .download(map, 0, &[n])?
        .err()
        .map(|a| (format!("sub 0 = {n}"), a)))
}

/// Judges a refusal that must carry `code`.
fn refused_with(
    what: &str,
    got: Option<(String, crate::ctx::Aborted)>,
    code: AbortCode,
) -> Result<String, Finding> {
    refused_with_any(what, got, &[code])
}

/// Judges a refusal that must carry one of `codes`.
fn refused_with_any(
    what: &str,
    got: Option<(String, crate::ctx::Aborted)>,
    codes: &[AbortCode],
) -> Result<String, Finding> {
    match got {
        Some((step, a)) if a.by_server && codes.contains(&a.code) => {
            Ok(format!("{what}: {step} refused with {}", hex(a.code)))
        }
        Some((step, a)) if a.by_server => Err(fail_abort(
            format!(
                "{what}: {step} refused, expected {}",
                codes
                    .iter()
                    .map(|c| hex(*c))
                    .collect::<Vec<_>>()
                    .join(" or ")
            ),
            a.code,
        )),
        Some((step, a)) => Err(fail_sdo(format!("{what}: {step}"), a)),
        None => Err(fail(format!("{what}: accepted"))),
    }
}

fn length(ctx: &mut Ctx<'_>) -> Outcome {
    let Some(r) = find(ctx, false)? else {
        return Err(none(ctx));
    };
    let highest = highest_sub(ctx, r.map);
    // The longest entry the PDO maps, repeated past 64 bits, if the object has room.
    let longest = r
        .entries
        .iter()
        .copied()
        .max_by_key(|e| e & 0xFF)
        .unwrap_or(0);
    let bits = (longest & 0xFF).max(1);
    let k = usize::try_from(64 / bits + 1).unwrap_or(usize::MAX);
    open(ctx, &r, true)?;
    let mut notes = Vec::new();
    let mut outcome = Ok(());
    if (1..64).contains(&highest) {
        // Sub 0 counting entries the object does not have: beyond the value range the file
        // may give sub 0 too, so a value-range code refuses it as well.
        let got = ctx.download(r.map, 0, &[highest + 1])?;
        let judged = refused_with_any(
            &format!("sub 0 = {} (the object has {highest})", highest + 1),
            got.err().map(|a| (format!("sub 0 = {}", highest + 1), a)),
            &[
                AbortCode::PDO_LENGTH_EXCEEDED,
                AbortCode::VALUE_TOO_HIGH,
                AbortCode::INVALID_VALUE,
            ],
        );
        match judged {
            Ok(n) => notes.push(n),
            Err(f) => outcome = Err(f),
        }
        ctx.write(r.map, 0, &[0], "sub 0 = 0")?;
    }
    if outcome.is_ok() && k <= usize::from(highest) {
        let list = vec![longest; k];
        let got = map_entries(ctx, r.map, &list)?;
        match refused_with(
            &format!("{k} entries of {bits} bits ({} bits)", k as u32 * bits),
            got,
            AbortCode::PDO_LENGTH_EXCEEDED,
        ) {
            Ok(n) => notes.push(n),
            Err(f) => outcome = Err(f),
        }
    }
    restore(ctx, &r)?;
    outcome?;
    if notes.is_empty() {
        return Err(Finding::NotApplicable(format!(
            "0x{:04X} has {highest} entries: no room past its entries nor past 64 bits",
            r.map
        )));
    }
    Ok(format!("0x{:04X}: {}", r.map, notes.join("; ")))
}

/// Maps `entry` alone into the open mapping, then closes the procedure as [`restore`] does;
/// the refusal must carry `code`.
fn map_one(ctx: &mut Ctx<'_>, entry: u32, what: &str, code: AbortCode) -> Outcome {
    let Some(r) = find(ctx, false)? else {
        return Err(none(ctx));
    };
    open(ctx, &r, true)?;
    let got = map_entries(ctx, r.map, &[entry])?;
    restore(ctx, &r)?;
    refused_with(&format!("0x{:04X}: {what}", r.map), got, code)
}

fn not_mappable(ctx: &mut Ctx<'_>) -> Outcome {
    // An entry of fixed size, readable and writable (so that neither direction excuses it by
    // access), that the file says cannot be mapped.
    let Some((index, sub, bits)) = entries(ctx).into_iter().find_map(|(i, s, e)| {
        let size = data_type(&e).and_then(|d| d.fixed_size())?;
        (e.pdo_mapping != Some(true)
            && access(&e).readable()
            && access(&e).writable()
            && size <= 8
            && !(0x1400..=0x1BFF).contains(&i))
        .then(|| (i, s, 8 * size as u32))
    }) else {
        return Err(Finding::NotApplicable(
            "the file has no readable and writable entry that cannot be mapped".into(),
        ));
    };
    let entry = (u32::from(index) << 16) | (u32::from(sub) << 8) | bits;
    map_one(
        ctx,
        entry,
        &format!("0x{index:04X} sub {sub} (not mappable)"),
        AbortCode::NOT_MAPPABLE,
    )
}

fn no_object(ctx: &mut Ctx<'_>) -> Outcome {
    let index = absent_index(ctx);
    let entry = (u32::from(index) << 16) | 0x08;
    map_one(
        ctx,
        entry,
        &format!("absent 0x{index:04X}"),
        AbortCode::NO_OBJECT,
    )
}

/// What makes the remapped TPDO go out.
enum Trigger {
    /// A SYNC, at transmission type 1.
    Sync,
    /// A remote frame.
    Remote,
    /// Its event timer at type 255 (the value to put back).
    Timer(Vec<u8>),
}

fn carried(ctx: &mut Ctx<'_>) -> Outcome {
    let Some(r) = find(ctx, true)? else {
        return Err(Finding::NotApplicable(format!(
            "no valid TPDO with a writable mapping{}",
            super::left_out_brief(ctx)
        )));
    };
    // The new mapping: the first entry alone, or twice where it is the only one.
    let first = r.entries[0];
    let new: Vec<u32> = if r.entries.len() >= 2 {
        vec![first]
    } else {
        vec![first, first]
    };
    let bits: u32 = new.iter().map(|e| e & 0xFF).sum();
    let old_bits: u32 = r.entries.iter().map(|e| e & 0xFF).sum();
    if bits > 64 || bits.div_ceil(8) == old_bits.div_ceil(8) {
        return Err(Finding::NotApplicable(format!(
            "0x{:04X}: no other mapping of another length from its own entries",
            r.map
        )));
    }
    let want = usize::try_from(bits.div_ceil(8)).unwrap_or(8);
    let tt = ctx
        .upload(r.comm, 2)?
        .map_err(|a| fail_sdo(format!("reading 0x{:04X} sub 2", r.comm), a))?;
    open(ctx, &r, true)?;
    if let Some((step, a)) = map_entries(ctx, r.map, &new)? {
        restore(ctx, &r)?;
        return Err(fail_sdo(format!("0x{:04X} {step}", r.map), a));
    }
    ctx.write(r.comm, 1, &r.cob.to_le_bytes(), "the COB-ID back to valid")?;
    let cob = r.cob & 0x7FF;
    let id = Id::standard(u16::try_from(cob).unwrap_or(0)).map_err(|e| fail(e.to_string()))?;
    let is_tpdo = |f: &Frame| f.id() == id && !f.is_remote();
    // Sent on every SYNC (type 1) where the device offers it, else on a remote frame.
    // Sent on every SYNC (type 1) where the device offers it, else on a remote frame where
    // the COB-ID allows one (bit 30 clear), else by a 50 ms event timer at type 255.
    let trigger = if ctx.download(r.comm, 2, &[1])?.is_ok() {
        Trigger::Sync
    } else if r.cob & 0x4000_0000 == 0 {
        Trigger::Remote
    } else if eds_entry(ctx, r.comm, 5).is_some_and(|e| access(e).writable())
        && ctx.download(r.comm, 2, &[0xFF])?.is_ok()
    {
        Trigger::Timer(
            ctx.upload(r.comm, 5)?
                .map_err(|a| fail_sdo(format!("reading 0x{:04X} sub 5", r.comm), a))?,
        )
    } else {
        ctx.write(r.comm, 2, &tt, "the transmission type")?;
        restore(ctx, &r)?;
        return Err(Finding::NotApplicable(format!(
            "0x{:04X}: neither type 1, a remote frame nor an event timer makes the TPDO go out",
            r.comm
        )));
    };
    if let Trigger::Timer(_) = trigger {
        ctx.write(r.comm, 5, &50u16.to_le_bytes(), "the event timer")?;
    }
    ctx.nmt(NmtCs::Start)?;
    ctx.idle(Duration::from_millis(20))?;
    match trigger {
        Trigger::Sync => {
            let sync = match ctx.upload(0x1005, 0)? {
                Ok(d) => u32_of(&d) & 0x7FF,
                Err(_) => 0x80,
            };
            let sync = Id::standard(u16::try_from(sync).unwrap_or(0x80))
                .map_err(|e| fail(e.to_string()))?;
            ctx.send(Frame::data(sync, &[]).map_err(|e| fail(e.to_string()))?)?;
        }
        Trigger::Remote => {
            let len = u8::try_from(want).unwrap_or(8);
            ctx.send(Frame::remote(id, len).map_err(|e| fail(e.to_string()))?)?;
        }
        Trigger::Timer(_) => {}
    }
    let got = ctx.wait_for(Duration::from_millis(150), is_tpdo)?;
    ctx.nmt(NmtCs::EnterPreOperational)?;
    ctx.idle(Duration::from_millis(10))?;
    if let Trigger::Timer(et) = &trigger {
        ctx.write(r.comm, 5, et, "the event timer")?;
    }
    ctx.write(r.comm, 2, &tt, "the transmission type")?;
    restore(ctx, &r)?;
    let trigger = match trigger {
        Trigger::Sync => "a SYNC",
        Trigger::Remote => "a remote frame",
        Trigger::Timer(_) => "its 50 ms event timer",
    };
    match got {
        Some((_, f)) if f.len() == want => Ok(format!(
            "0x{:04X} remapped to {new:08X?}: {trigger} brought {f} ({want} bytes, {bits} bits mapped)",
            r.map
        )),
        Some((_, f)) => Err(fail(format!(
            "0x{:04X} remapped to {new:08X?} ({bits} bits), but the TPDO after {trigger} is {f}: {} bytes, not {want}",
            r.map,
            f.len()
        ))),
        None => Err(fail_kind(
            FailureKind::Event,
            format!(
                "0x{:04X} remapped to {new:08X?}: no TPDO 0x{cob:03X} after {trigger}",
                r.map
            ),
        )),
    }
}
