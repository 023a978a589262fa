//! Area 4: PDOs (CiA 301 §7.2.2, §7.5.2.35–38): communication and mapping parameters,
//! the procedure for changing a mapping, COB-ID rules, transmission types, the event
//! timer, the inhibit time and RPDO length errors.

use cantwin_can::{Duration, Frame, Id};
use cantwin_canopen::wire::NmtCs;

use super::{Case, a, access, eds_entry, m, within};
use crate::ctx::{Ctx, Finding, Outcome, fail, fail_kind, fail_sdo, not_supported};
use crate::profile::FailureKind;
use crate::report::Area::Pdo as A;

pub(super) fn cases() -> Vec<Case> {
    vec![
        m(
            "pdo.cob-ids",
            A,
            "CiA 301 §7.5.2.35, §7.5.2.37, §7.3.5",
            "every valid PDO uses an 11-bit COB-ID outside the restricted ones",
            cob_ids,
        ),
        m(
            "pdo.mapping-procedure",
            A,
            "CiA 301 §7.5.2.36, §7.5.2.38",
            "a valid PDO's mapping cannot change; invalid, sub 0 = 0, entries, sub 0 = n, valid succeeds",
            mapping_procedure,
        ),
        m(
            "pdo.cob-id-change-valid",
            A,
            "CiA 301 §7.5.2.35, §7.5.2.37",
            "bits 0–29 of a valid PDO's COB-ID cannot change",
            cob_id_change_valid,
        ),
        m(
            "pdo.transmission-sync",
            A,
            "CiA 301 §7.2.2.2, §7.5.2.37 table 71",
            "transmission types 1 and 2 send the TPDO at every and every second SYNC",
            transmission_sync,
        ),
        m(
            "pdo.transmission-cyclic",
            A,
            "CiA 301 §7.2.2.2, §7.5.2.37 table 71 (types 1–240)",
            "transmission type 3 sends the TPDO at every third SYNC",
            transmission_cyclic,
        ),
        m(
            "pdo.transmission-rtr-sync",
            A,
            "CiA 301 §7.2.2.2, §7.5.2.37 table 71 (type 252)",
            "with transmission type 252 a TPDO is sent on a remote frame only, never on a SYNC",
            transmission_rtr_sync,
        ),
        m(
            "pdo.transmission-reserved",
            A,
            "CiA 301 §7.5.2.37 table 71 (241–251 reserved), §7.2.4.3.17",
            "the reserved transmission types 241–251 are refused with an abort",
            transmission_reserved,
        ),
        m(
            "pdo.transmission-acyclic",
            A,
            "CiA 301 §7.2.2.2, §7.5.2.37 table 71 (type 0)",
            "with transmission type 0 a TPDO goes out only after a SYNC, at most one per SYNC",
            transmission_acyclic,
        ),
        m(
            "pdo.rtr",
            A,
            "CiA 301 §7.2.2.2, §7.5.2.37 (COB-ID bit 30)",
            "a TPDO whose COB-ID allows RTR answers a remote frame",
            rtr,
        ),
        m(
            "pdo.sync-start-value",
            A,
            "CiA 301 §7.5.2.37 (sub 6), §7.2.5.2",
            "with SYNC start value 3 and type 2, the TPDO starts at the SYNC counting 3",
            sync_start_value,
        ),
        m(
            "pdo.event-timer",
            A,
            "CiA 301 §7.5.2.37 (sub 5, sub 3)",
            "transmission type 254 (or 255) with a 50 ms event timer sends every 50 ms, or every inhibit time where that is longer",
            event_timer,
        ),
        m(
            "pdo.inhibit-time",
            A,
            "CiA 301 §7.5.2.37 (sub 3)",
            "an inhibit time of 100 ms spaces the TPDO at least 100 ms apart",
            inhibit_time,
        ),
        a(
            "pdo.rpdo-length",
            A,
            "CiA 301 §7.2.2.2, §7.2.7.1 table 26",
            "an RPDO shorter than its mapping raises EMCY 0x8210",
            rpdo_length,
        ),
    ]
}

/// CAN-IDs CiA 301 reserves (§7.3.5 table 36): no PDO may use them.
fn restricted(id: u32) -> bool {
    matches!(id, 0x000 | 0x001..=0x07F | 0x101..=0x180 | 0x581..=0x5FF | 0x601..=0x67F | 0x6E0..=0x6FF | 0x701..=0x77F | 0x780..=0x7FF)
}

/// Every PDO of the file: (communication index, mapping index).
fn all_pdos(ctx: &Ctx<'_>, tx: bool) -> Vec<(u16, u16)> {
    let base = if tx { 0x1800 } else { 0x1400 };
    (0..512u16)
        .map(|k| (base + k, base + 0x200 + k))
        .filter(|(c, _)| ctx.eds.objects.contains_key(c))
        .collect()
}

/// The PDOs of the file whose file mapping can run ([`super::runnable`]).
fn pdos(ctx: &Ctx<'_>, tx: bool) -> Vec<(u16, u16)> {
    all_pdos(ctx, tx)
        .into_iter()
        .filter(|(c, _)| super::runnable(ctx, *c))
        .collect()
}

fn cob_ids(ctx: &mut Ctx<'_>) -> Outcome {
    let mut bad = Vec::new();
    let mut valid = 0;
    // The COB-ID rules hold for every PDO, also one whose mapping cannot run.
    let all: Vec<(u16, u16)> = all_pdos(ctx, false)
        .into_iter()
        .chain(all_pdos(ctx, true))
        .collect();
    for (comm, _) in all {
        let cob = ctx.read_u32(comm, 1, "a PDO COB-ID")?;
        if cob & 0x8000_0000 != 0 {
            continue;
        }
        valid += 1;
        if cob & 0x2000_0000 == 0 && (cob & 0x1FFF_F800 != 0 || restricted(cob & 0x7FF)) {
            bad.push(format!("0x{comm:04X} sub 1 = 0x{cob:08X}"));
        }
        ctx.upload(comm, 2)?
            .map_err(|a| fail_sdo(format!("0x{comm:04X} sub 2 (transmission type)"), a))?;
    }
    if bad.is_empty() {
        Ok(format!("{valid} valid PDOs{}", super::left_out(ctx)))
    } else {
        Err(fail(format!(
            "restricted or malformed COB-IDs: {}",
            bad.join(", ")
        )))
    }
}

/// (communication index, mapping index, COB-ID, mapping entries).
type DynamicPdo = (u16, u16, u32, Vec<Vec<u8>>);

/// A valid PDO whose mapping the file says is writable: (comm, mapping, COB-ID, entries).
fn dynamic_pdo(ctx: &mut Ctx<'_>) -> Result<Option<DynamicPdo>, Finding> {
    let all: Vec<(u16, u16)> = pdos(ctx, true)
        .into_iter()
        .chain(pdos(ctx, false))
        .collect();
    for (comm, map) in all {
        if !eds_entry(ctx, map, 0).is_some_and(|e| access(e).writable())
            || !eds_entry(ctx, comm, 1).is_some_and(|e| access(e).writable())
        {
            continue;
        }
        let cob = ctx.read_u32(comm, 1, "a PDO COB-ID")?;
        let n = ctx.read_u32(map, 0, "the number of mapped objects")?;
        if cob & 0x8000_0000 != 0 || n == 0 {
            continue;
        }
        let mut list = Vec::new();
        for s in 1..=u8::try_from(n).unwrap_or(0) {
            list.push(
                ctx.upload(map, s)?
                    .map_err(|a| fail_sdo(format!("reading 0x{map:04X} sub {s}"), a))?,
            );
        }
        return Ok(Some((comm, map, cob, list)));
    }
    Ok(None)
}

fn mapping_procedure(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((comm, map, cob, list)) = dynamic_pdo(ctx)? else {
        return Err(Finding::NotApplicable(format!(
            "no valid PDO with a writable mapping{}",
            super::left_out_brief(ctx)
        )));
    };
    let n = u8::try_from(list.len()).unwrap_or(0);
    if ctx.download(map, 0, &[0])?.is_ok() {
        ctx.write(map, 0, &[n], "the number of mapped objects")?;
        return Err(fail(format!(
            "0x{map:04X} sub 0 = 0 accepted while the PDO is valid (0x{comm:04X} sub 1 = 0x{cob:08X})"
        )));
    }
    ctx.write(
        comm,
        1,
        &(cob | 0x8000_0000).to_le_bytes(),
        "the COB-ID with bit 31 set",
    )?;
    ctx.write(map, 0, &[0], "sub 0 = 0 of the invalid PDO")?;
    for (i, e) in list.iter().enumerate() {
        ctx.write(map, u8::try_from(i + 1).unwrap_or(1), e, "a mapping entry")?;
    }
    ctx.write(map, 0, &[n], "the number of mapped objects")?;
    ctx.write(comm, 1, &cob.to_le_bytes(), "the COB-ID back to valid")?;
    let back = ctx.read_u32(map, 0, "the number of mapped objects")?;
    if back != u32::from(n) {
        return Err(fail(format!(
            "0x{map:04X} sub 0 reads {back} after the procedure, written {n}"
        )));
    }
    Ok(format!(
        "0x{map:04X}: {n} entries remapped; refused while valid"
    ))
}

fn cob_id_change_valid(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((comm, _, cob, _)) = dynamic_pdo(ctx)? else {
        return Err(Finding::NotApplicable(format!(
            "no valid PDO with a writable COB-ID{}",
            super::left_out_brief(ctx)
        )));
    };
    let other = (cob & !0x7FF) | (((cob & 0x7FF) + 1) & 0x7FF);
    match ctx.download(comm, 1, &other.to_le_bytes())? {
        // The refusal must be the server's abort: silence, or the client giving up,
        // says nothing of the check (§7.5.2.35 – §7.5.2.38).
        Err(a) if a.by_server => Ok(format!("0x{comm:04X} sub 1 = 0x{other:08X} refused: {a}")),
        Err(a) => Err(fail_sdo(
            format!("writing 0x{other:08X} to 0x{comm:04X} sub 1"),
            a,
        )),
        Ok(()) => {
            ctx.write(comm, 1, &(other | 0x8000_0000).to_le_bytes(), "the COB-ID")?;
            ctx.write(comm, 1, &cob.to_le_bytes(), "the COB-ID")?;
            Err(fail(format!(
                "0x{comm:04X} sub 1 changed from 0x{cob:08X} to 0x{other:08X} while valid"
            )))
        }
    }
}

fn sync_id(ctx: &mut Ctx<'_>) -> Result<Id, Finding> {
    let cob = match ctx.upload(0x1005, 0)? {
        Ok(d) => super::u32_of(&d) & 0x7FF,
        Err(_) => 0x80,
    };
    Id::standard(u16::try_from(cob).unwrap_or(0x80)).map_err(|e| fail(e.to_string()))
}

fn is_pdo(f: &Frame, cob: u32) -> bool {
    f.id().as_raw() == cob & 0x7FF && !f.is_remote()
}

fn transmission_sync(ctx: &mut Ctx<'_>) -> Outcome {
    super::no_foreign_sync(ctx)?;
    if ctx.profile.features.sync == Some(false) {
        return Err(not_supported("no SYNC consumer (0x1005 not in the file)"));
    }
    let Some((comm, cob)) = super::nmt::first_tpdo(ctx)? else {
        return Err(Finding::NotApplicable(format!(
            "no valid TPDO with a mapping{}",
            super::left_out_brief(ctx)
        )));
    };
    let tt = ctx
        .upload(comm, 2)?
        .map_err(|a| fail_sdo(format!("reading 0x{comm:04X} sub 2"), a))?;
    let sync = sync_id(ctx)?;
    let mut notes = Vec::new();
    for (ty, syncs, want) in [(1u8, 6usize, 6usize), (2, 6, 3)] {
        // A device need not offer every synchronous type (§7.5.2.37): 0x06090030 says so.
        match ctx.download(comm, 2, &[ty])? {
            Ok(()) => {}
            Err(a) if a.code == cantwin_canopen::AbortCode::INVALID_VALUE => {
                notes.push(format!("type {ty} not offered"));
                continue;
            }
            Err(a) => {
                ctx.write(comm, 2, &tt, "the transmission type")?;
                return Err(fail_sdo(
                    format!("writing type {ty} to 0x{comm:04X} sub 2"),
                    a,
                ));
            }
        }
        ctx.nmt(NmtCs::Start)?;
        ctx.idle(Duration::from_millis(30))?;
        let mut got = 0;
        for _ in 0..syncs {
            ctx.send(Frame::data(sync, &[]).map_err(|e| fail(e.to_string()))?)?;
            got += ctx
                .collect(Duration::from_millis(20), |f| is_pdo(f, cob))?
                .len();
        }
        ctx.nmt(NmtCs::EnterPreOperational)?;
        ctx.idle(Duration::from_millis(10))?;
        if got != want {
            ctx.write(comm, 2, &tt, "the transmission type")?;
            return Err(fail(format!(
                "type {ty}: {got} TPDOs after {syncs} SYNCs, expected {want}"
            )));
        }
        notes.push(format!("type {ty}: {got} after {syncs} SYNCs"));
    }
    ctx.write(comm, 2, &tt, "the transmission type")?;
    if notes.iter().all(|n| n.ends_with("not offered")) {
        return Err(not_supported(notes.join(", ")));
    }
    Ok(notes.join(", "))
}

fn event_timer(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((comm, cob)) = super::nmt::first_tpdo(ctx)? else {
        return Err(Finding::NotApplicable(format!(
            "no valid TPDO with a mapping{}",
            super::left_out_brief(ctx)
        )));
    };
    if !eds_entry(ctx, comm, 5).is_some_and(|e| access(e).writable()) {
        return Err(not_supported(format!(
            "0x{comm:04X} has no writable event timer"
        )));
    }
    let tt = ctx
        .upload(comm, 2)?
        .map_err(|a| fail_sdo(format!("reading 0x{comm:04X} sub 2"), a))?;
    let et = ctx
        .upload(comm, 5)?
        .map_err(|a| fail_sdo(format!("reading 0x{comm:04X} sub 5"), a))?;
    // Type 254 (manufacturer-specific event) if the device offers it, else 255.
    let ty = if ctx.download(comm, 2, &[0xFE])?.is_ok() {
        0xFE
    } else {
        0xFF
    };
    ctx.write(comm, 2, &[ty], "the transmission type")?;
    ctx.write(comm, 5, &50u16.to_le_bytes(), "the event timer")?;
    // The inhibit time is the minimum interval between two TPDOs (§7.5.2.37, sub 3, in
    // 100 µs): with one longer than the event timer, the TPDO comes every inhibit time.
    let inhibit_us = if eds_entry(ctx, comm, 3).is_some() {
        match ctx.upload(comm, 3)? {
            Ok(d) => u64::from(super::u32_of(&d) & 0xFFFF) * 100,
            Err(a) => {
                ctx.write(comm, 5, &et, "the event timer")?;
                ctx.write(comm, 2, &tt, "the transmission type")?;
                return Err(fail_sdo(format!("reading 0x{comm:04X} sub 3"), a));
            }
        }
    } else {
        0
    };
    let period = Duration::from_micros(inhibit_us.max(50_000));
    let why = if inhibit_us > 50_000 {
        format!(
            "a 50 ms event timer and an inhibit time of {} ms",
            inhibit_us as f64 / 1000.0
        )
    } else {
        "a 50 ms event timer".to_string()
    };
    // Ten periods and a half: 9 to 11 TPDOs whatever the phase of the first.
    let window = Duration::from_micros(period.as_micros() * 21 / 2);
    ctx.nmt(NmtCs::Start)?;
    ctx.wait_for(period + period, |f| is_pdo(f, cob))?;
    let frames = ctx.collect(window, |f| is_pdo(f, cob))?;
    ctx.nmt(NmtCs::EnterPreOperational)?;
    ctx.idle(Duration::from_millis(10))?;
    ctx.write(comm, 5, &et, "the event timer")?;
    ctx.write(comm, 2, &tt, "the transmission type")?;
    if !(9..=11).contains(&frames.len()) {
        return Err(fail_kind(
            FailureKind::Timing,
            format!(
                "{} TPDOs in {} ms with {why}, expected 9 to 11",
                frames.len(),
                window.as_micros() / 1000
            ),
        ));
    }
    for w in frames.windows(2) {
        let d = w[1].0.saturating_duration_since(w[0].0);
        if !within(ctx, d, period) {
            return Err(fail_kind(
                FailureKind::Timing,
                format!(
                    "a TPDO interval of {} µs, expected {} µs ({why})",
                    d.as_micros(),
                    period.as_micros()
                ),
            ));
        }
    }
    Ok(format!(
        "{} TPDOs every {} ms ({why}), intervals within tolerance",
        frames.len(),
        period.as_micros() / 1000
    ))
}

fn inhibit_time(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((comm, cob)) = super::nmt::first_tpdo(ctx)? else {
        return Err(Finding::NotApplicable(format!(
            "no valid TPDO with a mapping{}",
            super::left_out_brief(ctx)
        )));
    };
    if !eds_entry(ctx, comm, 3).is_some_and(|e| access(e).writable())
        || !eds_entry(ctx, comm, 5).is_some_and(|e| access(e).writable())
    {
        return Err(not_supported(format!(
            "0x{comm:04X} has no writable inhibit time and event timer"
        )));
    }
    let tt = ctx
        .upload(comm, 2)?
        .map_err(|a| fail_sdo(format!("reading 0x{comm:04X} sub 2"), a))?;
    let it = ctx
        .upload(comm, 3)?
        .map_err(|a| fail_sdo(format!("reading 0x{comm:04X} sub 3"), a))?;
    let et = ctx
        .upload(comm, 5)?
        .map_err(|a| fail_sdo(format!("reading 0x{comm:04X} sub 5"), a))?;
    // The inhibit time changes only while the PDO is invalid (§7.5.2.37).
    ctx.write(
        comm,
        1,
        &(cob | 0x8000_0000).to_le_bytes(),
        "the COB-ID with bit 31 set",
    )?;
    ctx.write(comm, 3, &1000u16.to_le_bytes(), "the inhibit time (100 ms)")?;
    ctx.write(comm, 1, &cob.to_le_bytes(), "the COB-ID back to valid")?;
    ctx.write(comm, 2, &[0xFF], "the transmission type")?;
    ctx.write(comm, 5, &20u16.to_le_bytes(), "the event timer")?;
    ctx.nmt(NmtCs::Start)?;
    let frames = ctx.collect(Duration::from_millis(650), |f| is_pdo(f, cob))?;
    ctx.nmt(NmtCs::EnterPreOperational)?;
    ctx.idle(Duration::from_millis(10))?;
    ctx.write(comm, 5, &et, "the event timer")?;
    ctx.write(comm, 2, &tt, "the transmission type")?;
    ctx.write(
        comm,
        1,
        &(cob | 0x8000_0000).to_le_bytes(),
        "the COB-ID with bit 31 set",
    )?;
    ctx.write(comm, 3, &it, "the inhibit time")?;
    ctx.write(comm, 1, &cob.to_le_bytes(), "the COB-ID back to valid")?;
    if frames.len() < 3 {
        return Err(fail_kind(
            FailureKind::Timing,
            format!(
                "{} TPDOs in 650 ms (event timer 20 ms, inhibit 100 ms)",
                frames.len()
            ),
        ));
    }
    let min = Duration::from_millis(100).saturating_sub(ctx.options.slack);
    for w in frames.windows(2) {
        let d = w[1].0.saturating_duration_since(w[0].0);
        if d < min {
            return Err(fail_kind(
                FailureKind::Timing,
                format!("two TPDOs {} µs apart, inhibit time 100 ms", d.as_micros()),
            ));
        }
    }
    Ok(format!("{} TPDOs at least 100 ms apart", frames.len()))
}

fn rpdo_length(ctx: &mut Ctx<'_>) -> Outcome {
    let mut found = None;
    for (comm, map) in pdos(ctx, false) {
        let cob = ctx.read_u32(comm, 1, "an RPDO COB-ID")?;
        let n = ctx.read_u32(map, 0, "the number of mapped objects")?;
        if cob & 0x8000_0000 != 0 || cob & 0x2000_0000 != 0 || n == 0 {
            continue;
        }
        let mut bits = 0u32;
        for s in 1..=u8::try_from(n).unwrap_or(0) {
            bits += ctx.read_u32(map, s, "a mapping entry")? & 0xFF;
        }
        if bits >= 8 {
            found = Some((cob & 0x7FF, bits.div_ceil(8)));
            break;
        }
    }
    let Some((cob, len)) = found else {
        return Err(Finding::NotApplicable(format!(
            "no valid RPDO with a mapping{}",
            super::left_out_brief(ctx)
        )));
    };
    let emcy = match ctx.upload(0x1014, 0)? {
        Ok(d) if super::u32_of(&d) & 0x8000_0000 == 0 => super::u32_of(&d) & 0x7FF,
        _ => return Err(Finding::NotApplicable("the device produces no EMCY".into())),
    };
    let id = Id::standard(u16::try_from(cob).unwrap_or(0)).map_err(|e| fail(e.to_string()))?;
    ctx.nmt(NmtCs::Start)?;
    ctx.idle(Duration::from_millis(20))?;
    let short = vec![0u8; usize::try_from(len - 1).unwrap_or(0)];
    ctx.send(Frame::data(id, &short).map_err(|e| fail(e.to_string()))?)?;
    let got = ctx.wait_for(Duration::from_millis(200), |f| {
        f.id().as_raw() == emcy && f.len() == 8 && f.data_bytes()[..2] == [0x10, 0x82]
    })?;
    ctx.nmt(NmtCs::EnterPreOperational)?;
    ctx.idle(Duration::from_millis(20))?;
    match got {
        Some(_) => Ok(format!(
            "RPDO 0x{cob:03X} with {} of {len} bytes: EMCY 0x8210",
            len - 1
        )),
        None => Err(fail_kind(
            FailureKind::Event,
            format!(
                "RPDO 0x{cob:03X} with {} of {len} bytes: no EMCY 0x8210 within 200 ms",
                len - 1
            ),
        )),
    }
}

/// Sets transmission type `ty` on `comm`; `Ok(false)` when the device refuses it as an
/// invalid value (it need not offer every type, §7.5.2.37).
fn set_type(ctx: &mut Ctx<'_>, comm: u16, ty: u8) -> Result<bool, Finding> {
    match ctx.download(comm, 2, &[ty])? {
        Ok(()) => Ok(true),
        Err(a) if a.code == cantwin_canopen::AbortCode::INVALID_VALUE => Ok(false),
        Err(a) => Err(fail_sdo(
            format!("writing type {ty} to 0x{comm:04X} sub 2"),
            a,
        )),
    }
}

/// A mapped object of the TPDO whose mapping is `map` that the case can change over SDO:
/// writable and readable in the file, byte-aligned, and read back at its mapped length.
/// `(index, sub, value now)`.
fn sdo_writable_mapped(ctx: &mut Ctx<'_>, map: u16) -> Result<Option<(u16, u8, Vec<u8>)>, Finding> {
    let n = ctx.read_u32(map, 0, "the number of mapped objects")?;
    for s in 1..=u8::try_from(n.min(64)).unwrap_or(0) {
        let e = ctx.read_u32(map, s, "a mapping entry")?;
        let (index, sub, bits) = (
            u16::try_from(e >> 16).unwrap_or(0),
            u8::try_from((e >> 8) & 0xFF).unwrap_or(0),
            e & 0xFF,
        );
        // Indices below 0x20 are dummy entries (§7.4.7.1): nothing to change.
        if index < 0x20 || bits == 0 || bits % 8 != 0 {
            continue;
        }
        if !eds_entry(ctx, index, sub).is_some_and(|e| access(e).writable() && access(e).readable())
        {
            continue;
        }
        if let Ok(d) = ctx.upload(index, sub)?
            && d.len() == usize::try_from(bits / 8).unwrap_or(0)
        {
            return Ok(Some((index, sub, d)));
        }
    }
    Ok(None)
}

fn transmission_acyclic(ctx: &mut Ctx<'_>) -> Outcome {
    if ctx.profile.features.sync == Some(false) {
        return Err(not_supported("no SYNC consumer (0x1005 not in the file)"));
    }
    let Some((comm, cob)) = super::nmt::first_tpdo(ctx)? else {
        return Err(Finding::NotApplicable(format!(
            "no valid TPDO with a mapping{}",
            super::left_out_brief(ctx)
        )));
    };
    // Type 0 is acyclic synchronous (CiA 301 §7.2.2.2.2): the TPDO goes out with the
    // SYNC after an event of the device. The case makes the event itself by changing a
    // mapped value; without one it can change, there is nothing to see.
    let Some((index, sub, before)) = sdo_writable_mapped(ctx, comm + 0x200)? else {
        return Err(Finding::NotApplicable(format!(
            "no mapped object of the TPDO at 0x{comm:04X} is writable over SDO, so no event can be caused"
        )));
    };
    let tt = ctx
        .upload(comm, 2)?
        .map_err(|a| fail_sdo(format!("reading 0x{comm:04X} sub 2"), a))?;
    if !set_type(ctx, comm, 0)? {
        return Err(not_supported("transmission type 0 refused with 0x06090030"));
    }
    let sync = sync_id(ctx)?;
    let sync_frame = Frame::data(sync, &[]).map_err(|e| fail(e.to_string()))?;
    let mut changed = before.clone();
    changed[0] ^= 0x01;
    ctx.nmt(NmtCs::Start)?;
    // Without SYNC nothing goes out; the first SYNCs may carry a TPDO for the start, at
    // most one each.
    let idle = ctx
        .collect(Duration::from_millis(200), |f| is_pdo(f, cob))?
        .len();
    let mut settling = Vec::new();
    for _ in 0..2 {
        ctx.send(sync_frame)?;
        settling.push(
            ctx.collect(Duration::from_millis(20), |f| is_pdo(f, cob))?
                .len(),
        );
    }
    // The event: the mapped value changes. Nothing before the next SYNC, one with it.
    // The SYNC after may carry one again: the device's own process may have changed a
    // mapped value meanwhile, which is an event too.
    let written = ctx.download(index, sub, &changed)?;
    let early = ctx
        .collect(Duration::from_millis(50), |f| is_pdo(f, cob))?
        .len();
    let mut after = Vec::new();
    for _ in 0..2 {
        ctx.send(sync_frame)?;
        after.push(
            ctx.collect(Duration::from_millis(20), |f| is_pdo(f, cob))?
                .len(),
        );
    }
    ctx.nmt(NmtCs::EnterPreOperational)?;
    ctx.idle(Duration::from_millis(10))?;
    ctx.write(comm, 2, &tt, "the transmission type")?;
    if written.is_ok() {
        ctx.write(index, sub, &before, "the mapped object")?;
    }
    if let Err(a) = written {
        return Err(Finding::NotApplicable(format!(
            "the mapped object 0x{index:04X} sub {sub} could not be written in OPERATIONAL ({a}), so no event was caused"
        )));
    }
    if idle != 0 {
        return Err(fail(format!(
            "{idle} TPDOs in 200 ms without SYNC at type 0"
        )));
    }
    if settling.iter().any(|n| *n > 1) {
        return Err(fail(format!("TPDOs per SYNC at type 0: {settling:?}")));
    }
    if early != 0 {
        return Err(fail(format!(
            "{early} TPDOs after 0x{index:04X} sub {sub} changed, before the SYNC, at type 0"
        )));
    }
    if after[0] != 1 || after[1] > 1 {
        return Err(fail(format!(
            "after 0x{index:04X} sub {sub} changed, TPDOs per SYNC at type 0: {after:?}, expected one with the first SYNC and at most one with the next"
        )));
    }
    Ok(format!(
        "none without SYNC; 0x{index:04X} sub {sub} changed: none before the SYNC, one with it; per SYNC {after:?}"
    ))
}

/// The SYNCs (counted from 1) of `syncs` sent 20 ms apart in OPERATIONAL after which the
/// TPDO with `cob` came.
fn tpdos_on_syncs(ctx: &mut Ctx<'_>, cob: u32, syncs: usize) -> Result<Vec<usize>, Finding> {
    let sync = sync_id(ctx)?;
    let mut at = Vec::new();
    for k in 1..=syncs {
        ctx.send(Frame::data(sync, &[]).map_err(|e| fail(e.to_string()))?)?;
        let n = ctx
            .collect(Duration::from_millis(20), |f| is_pdo(f, cob))?
            .len();
        at.extend(std::iter::repeat_n(k, n));
    }
    Ok(at)
}

fn transmission_cyclic(ctx: &mut Ctx<'_>) -> Outcome {
    super::no_foreign_sync(ctx)?;
    if ctx.profile.features.sync == Some(false) {
        return Err(not_supported("no SYNC consumer (0x1005 not in the file)"));
    }
    let Some((comm, cob)) = super::nmt::first_tpdo(ctx)? else {
        return Err(Finding::NotApplicable(format!(
            "no valid TPDO with a mapping{}",
            super::left_out_brief(ctx)
        )));
    };
    let tt = ctx
        .upload(comm, 2)?
        .map_err(|a| fail_sdo(format!("reading 0x{comm:04X} sub 2"), a))?;
    if !set_type(ctx, comm, 3)? {
        return Err(not_supported(format!(
            "0x{comm:04X} refuses type 3 with 0x06090030"
        )));
    }
    ctx.nmt(NmtCs::Start)?;
    ctx.idle(Duration::from_millis(30))?;
    let at = tpdos_on_syncs(ctx, cob, 9)?;
    ctx.nmt(NmtCs::EnterPreOperational)?;
    ctx.idle(Duration::from_millis(10))?;
    ctx.write(comm, 2, &tt, "the transmission type")?;
    // Nine SYNCs hold three periods whatever SYNC the device counts from.
    let spaced = at.windows(2).all(|w| w[1] - w[0] == 3);
    if at.len() != 3 || !spaced {
        return Err(fail(format!(
            "type 3: TPDO 0x{:03X} after SYNCs {at:?} of 9, expected one every third SYNC",
            cob & 0x7FF
        )));
    }
    Ok(format!(
        "type 3: TPDO 0x{:03X} after SYNCs {at:?} of 9",
        cob & 0x7FF
    ))
}

fn transmission_rtr_sync(ctx: &mut Ctx<'_>) -> Outcome {
    if ctx.profile.features.sync == Some(false) {
        return Err(not_supported("no SYNC consumer (0x1005 not in the file)"));
    }
    let Some((comm, cob)) = super::nmt::first_tpdo(ctx)? else {
        return Err(Finding::NotApplicable(format!(
            "no valid TPDO with a mapping{}",
            super::left_out_brief(ctx)
        )));
    };
    if cob & 0x4000_0000 != 0 {
        return Err(not_supported(format!(
            "0x{comm:04X} sub 1 = 0x{cob:08X}: no RTR (bit 30 set)"
        )));
    }
    let tt = ctx
        .upload(comm, 2)?
        .map_err(|a| fail_sdo(format!("reading 0x{comm:04X} sub 2"), a))?;
    if !set_type(ctx, comm, 252)? {
        return Err(not_supported(format!(
            "0x{comm:04X} refuses type 252 with 0x06090030"
        )));
    }
    let map = comm + 0x200;
    let n = ctx.read_u32(map, 0, "the number of mapped objects")?;
    let mut bits = 0u32;
    for s in 1..=u8::try_from(n).unwrap_or(0) {
        bits += ctx.read_u32(map, s, "a mapping entry")? & 0xFF;
    }
    let len = u8::try_from(bits.div_ceil(8).min(8)).unwrap_or(8);
    let id =
        Id::standard(u16::try_from(cob & 0x7FF).unwrap_or(0)).map_err(|e| fail(e.to_string()))?;
    ctx.nmt(NmtCs::Start)?;
    ctx.idle(Duration::from_millis(30))?;
    // SYNCs alone: the data is sampled, nothing sent.
    let on_sync = tpdos_on_syncs(ctx, cob, 3)?;
    ctx.send(Frame::remote(id, len).map_err(|e| fail(e.to_string()))?)?;
    let answered = ctx.wait_for(Duration::from_millis(100), |f| is_pdo(f, cob))?;
    ctx.nmt(NmtCs::EnterPreOperational)?;
    ctx.idle(Duration::from_millis(10))?;
    ctx.write(comm, 2, &tt, "the transmission type")?;
    if !on_sync.is_empty() {
        return Err(fail(format!(
            "type 252: TPDO 0x{:03X} sent after SYNCs {on_sync:?} without a remote frame",
            cob & 0x7FF
        )));
    }
    match answered {
        Some((_, f)) => Ok(format!(
            "type 252: nothing on 3 SYNCs, the remote frame answered with {f}"
        )),
        None => Err(fail_kind(
            FailureKind::Event,
            format!(
                "type 252: a remote frame after 3 SYNCs got no TPDO 0x{:03X} within 100 ms",
                cob & 0x7FF
            ),
        )),
    }
}

fn transmission_reserved(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((comm, _)) = super::nmt::first_tpdo(ctx)? else {
        return Err(Finding::NotApplicable(format!(
            "no valid TPDO with a mapping{}",
            super::left_out_brief(ctx)
        )));
    };
    let tt = ctx
        .upload(comm, 2)?
        .map_err(|a| fail_sdo(format!("reading 0x{comm:04X} sub 2"), a))?;
    let mut taken = Vec::new();
    let mut codes = std::collections::BTreeSet::new();
    for ty in 241u8..=251 {
        match ctx.download(comm, 2, &[ty])? {
            Ok(()) => taken.push(ty),
            Err(a) => {
                codes.insert(format!("0x{:08X}", a.code.to_u32()));
            }
        }
    }
    ctx.write(comm, 2, &tt, "the transmission type")?;
    if !taken.is_empty() {
        return Err(fail(format!(
            "0x{comm:04X} sub 2 took the reserved types {taken:?}"
        )));
    }
    Ok(format!(
        "0x{comm:04X} sub 2: 241–251 refused ({})",
        codes.into_iter().collect::<Vec<_>>().join(", ")
    ))
}

fn rtr(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((comm, cob)) = super::nmt::first_tpdo(ctx)? else {
        return Err(Finding::NotApplicable(format!(
            "no valid TPDO with a mapping{}",
            super::left_out_brief(ctx)
        )));
    };
    if cob & 0x4000_0000 != 0 {
        if ctx.profile.features.pdo_rtr == Some(true) {
            return Err(fail(format!(
                "the profile claims RTR, 0x{comm:04X} sub 1 = 0x{cob:08X} forbids it (bit 30)"
            )));
        }
        return Err(not_supported(format!(
            "0x{comm:04X} sub 1 = 0x{cob:08X}: no RTR (bit 30 set)"
        )));
    }
    let tt = ctx
        .upload(comm, 2)?
        .map_err(|a| fail_sdo(format!("reading 0x{comm:04X} sub 2"), a))?;
    let et = match eds_entry(ctx, comm, 5) {
        Some(_) => ctx.upload(comm, 5)?.ok(),
        None => None,
    };
    // Type 253 (RTR only) where offered, else 255 without an event timer: the answer is
    // then the only TPDO.
    let ty = if set_type(ctx, comm, 253)? { 253 } else { 255 };
    ctx.write(comm, 2, &[ty], "the transmission type")?;
    if et.is_some() {
        ctx.write(comm, 5, &0u16.to_le_bytes(), "the event timer")?;
    }
    ctx.nmt(NmtCs::Start)?;
    ctx.idle(Duration::from_millis(50))?;
    let id =
        Id::standard(u16::try_from(cob & 0x7FF).unwrap_or(0)).map_err(|e| fail(e.to_string()))?;
    // The remote frame's DLC is the TPDO's length (the sum of its mapped bits).
    let map = comm + 0x200;
    let n = ctx.read_u32(map, 0, "the number of mapped objects")?;
    let mut bits = 0u32;
    for s in 1..=u8::try_from(n).unwrap_or(0) {
        bits += ctx.read_u32(map, s, "a mapping entry")? & 0xFF;
    }
    let len = u8::try_from(bits.div_ceil(8).min(8)).unwrap_or(8);
    ctx.send(Frame::remote(id, len).map_err(|e| fail(e.to_string()))?)?;
    let got = ctx.wait_for(Duration::from_millis(100), |f| is_pdo(f, cob))?;
    ctx.nmt(NmtCs::EnterPreOperational)?;
    ctx.idle(Duration::from_millis(10))?;
    if let Some(et) = et {
        ctx.write(comm, 5, &et, "the event timer")?;
    }
    ctx.write(comm, 2, &tt, "the transmission type")?;
    match got {
        Some((_, f)) => Ok(format!("type {ty}: a remote frame answered with {f}")),
        None => Err(fail_kind(
            FailureKind::Event,
            format!(
                "0x{comm:04X} sub 1 = 0x{cob:08X} allows RTR (bit 30 clear), but a remote frame got no TPDO within 100 ms (type {ty})"
            ),
        )),
    }
}

fn sync_start_value(ctx: &mut Ctx<'_>) -> Outcome {
    if ctx.profile.features.sync == Some(false) {
        return Err(not_supported("no SYNC consumer (0x1005 not in the file)"));
    }
    let Some((comm, cob)) = super::nmt::first_tpdo(ctx)? else {
        return Err(Finding::NotApplicable(format!(
            "no valid TPDO with a mapping{}",
            super::left_out_brief(ctx)
        )));
    };
    if !eds_entry(ctx, comm, 6).is_some_and(|e| access(e).writable()) {
        return Err(not_supported(format!(
            "0x{comm:04X} has no writable SYNC start value (sub 6)"
        )));
    }
    // A SYNC carries a counter only where 0x1019 says so (§7.5.2.22): a device whose
    // overflow value is 0 takes a SYNC with data for a length error.
    if !eds_entry(ctx, 0x1019, 0).is_some_and(|e| access(e).writable()) {
        return Err(not_supported(
            "no synchronous counter overflow value (0x1019)",
        ));
    }
    let overflow = ctx
        .upload(0x1019, 0)?
        .map_err(|a| fail_sdo("reading 0x1019", a))?;
    let period = match ctx.upload(0x1006, 0)? {
        Ok(p) => {
            // 0x1019 changes only while the communication cycle period is 0.
            ctx.write(
                0x1006,
                0,
                &0u32.to_le_bytes(),
                "the communication cycle period",
            )?;
            Some(p)
        }
        Err(_) => None,
    };
    ctx.write(0x1019, 0, &[8], "the synchronous counter overflow value")?;
    let tt = ctx
        .upload(comm, 2)?
        .map_err(|a| fail_sdo(format!("reading 0x{comm:04X} sub 2"), a))?;
    let sv = ctx
        .upload(comm, 6)?
        .map_err(|a| fail_sdo(format!("reading 0x{comm:04X} sub 6"), a))?;
    // The start value changes only while the PDO is invalid (§7.5.2.37).
    ctx.write(
        comm,
        1,
        &(cob | 0x8000_0000).to_le_bytes(),
        "the COB-ID with bit 31 set",
    )?;
    ctx.write(comm, 6, &[3], "the SYNC start value")?;
    ctx.write(comm, 1, &cob.to_le_bytes(), "the COB-ID back to valid")?;
    ctx.write(comm, 2, &[2], "the transmission type")?;
    let sync = sync_id(ctx)?;
    ctx.nmt(NmtCs::Start)?;
    ctx.idle(Duration::from_millis(20))?;
    let mut after = Vec::new();
    for counter in 1..=8u8 {
        ctx.send(Frame::data(sync, &[counter]).map_err(|e| fail(e.to_string()))?)?;
        if !ctx
            .collect(Duration::from_millis(20), |f| is_pdo(f, cob))?
            .is_empty()
        {
            after.push(counter);
        }
    }
    ctx.nmt(NmtCs::EnterPreOperational)?;
    ctx.idle(Duration::from_millis(10))?;
    ctx.write(comm, 2, &tt, "the transmission type")?;
    ctx.write(
        comm,
        1,
        &(cob | 0x8000_0000).to_le_bytes(),
        "the COB-ID with bit 31 set",
    )?;
    ctx.write(comm, 6, &sv, "the SYNC start value")?;
    ctx.write(comm, 1, &cob.to_le_bytes(), "the COB-ID back to valid")?;
    ctx.write(
        0x1019,
        0,
        &overflow,
        "the synchronous counter overflow value",
    )?;
    if let Some(p) = period {
        ctx.write(0x1006, 0, &p, "the communication cycle period")?;
    }
    if after != [3, 5, 7] {
        return Err(fail(format!(
            "TPDOs after the SYNCs counting {after:?}; start value 3, every second SYNC: expected [3, 5, 7]"
        )));
    }
    Ok("TPDOs after the SYNCs counting 3, 5, 7".into())
}
