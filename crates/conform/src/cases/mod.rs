//! The test cases, one module per area, each case a function over the [`Ctx`] naming the
//! clause it checks.

use cantwin_can::Duration;
use cantwin_canopen::AbortCode;
use cantwin_canopen::od::{Access, DataType};
use cantwin_eds::Entry;

use crate::CaseInfo;
use crate::ctx::{Ctx, Finding, Outcome, fail, fail_sdo};
use crate::report::{Area, Severity};

mod block;
mod eds;
mod error_control;
mod mapping;
mod nmt;
mod od;
mod pdo;
mod rpdo;
mod sdo;
mod store;
mod sync_emcy_time;

/// A case: what the catalogue says of it and the function that runs it.
pub(crate) struct Case {
    pub info: CaseInfo,
    pub run: fn(&mut Ctx<'_>) -> Outcome,
}

/// A mandatory case.
pub(crate) const fn m(
    id: &'static str,
    area: Area,
    clause: &'static str,
    title: &'static str,
    run: fn(&mut Ctx<'_>) -> Outcome,
) -> Case {
    Case {
        info: CaseInfo {
            id,
            area,
            clause,
            title,
            severity: Severity::Mandatory,
        },
        run,
    }
}

/// An advisory case.
pub(crate) const fn a(
    id: &'static str,
    area: Area,
    clause: &'static str,
    title: &'static str,
    run: fn(&mut Ctx<'_>) -> Outcome,
) -> Case {
    Case {
        info: CaseInfo {
            id,
            area,
            clause,
            title,
            severity: Severity::Advisory,
        },
        run,
    }
}

/// Every case in run order: the areas in the order of [`Area::ALL`]; store/restore last,
/// since it resets the device's stored values to their defaults.
pub(crate) fn all() -> &'static [Case] {
    static ALL: std::sync::OnceLock<Vec<Case>> = std::sync::OnceLock::new();
    ALL.get_or_init(|| {
        let mut v = Vec::new();
        v.extend(eds::cases());
        v.extend(sdo::cases());
        v.extend(od::cases());
        v.extend(pdo::cases());
        v.extend(rpdo::cases());
        v.extend(mapping::cases());
        v.extend(sync_emcy_time::cases());
        v.extend(error_control::cases());
        v.extend(nmt::cases());
        v.extend(store::cases());
        v
    })
}

/// After a failed case: abort whatever transfer it left open (an abort is never answered,
/// CiA 301 §7.2.4.3.17), return to PRE-OPERATIONAL and let the bus settle.
pub(crate) fn recover(ctx: &mut Ctx<'_>) {
    let mut b = [0x80, 0, 0, 0, 0, 0, 0, 0];
    b[4..].copy_from_slice(&AbortCode::GENERAL_ERROR.to_u32().to_le_bytes());
    let id = ctx.sdo_rx();
    let _ = ctx.send(cantwin_can::Frame::data_array(id, b));
    let _ = ctx.nmt(cantwin_canopen::wire::NmtCs::EnterPreOperational);
    let _ = ctx.idle(Duration::from_millis(50));
}

/// Fails a case whose verdict depends on the timing of the SYNCs it sends or the device
/// produces when another node produces SYNCs (CiA 301 §7.2.5: one producer per network):
/// the frames it counts would be that producer's as much as its own.
pub(crate) fn no_foreign_sync(ctx: &Ctx<'_>) -> Result<(), Finding> {
    if ctx.foreign_sync {
        Err(Finding::NotApplicable(
            "skipped: another SYNC producer on the bus".into(),
        ))
    } else {
        Ok(())
    }
}

/// Whether the PDO with communication index `comm` can run with the file's mapping: the
/// cases choose only such PDOs (the others the device must keep from running, CiA 301
/// §7.5.2.36, §7.5.2.38, whatever the case writes).
pub(crate) fn runnable(ctx: &Ctx<'_>, comm: u16) -> bool {
    !ctx.unrunnable.contains_key(&comm)
}

/// The PDOs left out of the PDO cases and why, for a case's note; empty if none.
pub(crate) fn left_out(ctx: &Ctx<'_>) -> String {
    if ctx.unrunnable.is_empty() {
        return String::new();
    }
    let items: Vec<String> = ctx
        .unrunnable
        .iter()
        .map(|(comm, why)| format!("0x{comm:04X}: {why}"))
        .collect();
    format!(
        "; left out, their file mapping cannot run: {}",
        listing(&items)
    )
}

/// The PDOs left out of the PDO cases, by communication index, for the note of a case
/// that found no PDO to run with; empty if none.
pub(crate) fn left_out_brief(ctx: &Ctx<'_>) -> String {
    if ctx.unrunnable.is_empty() {
        return String::new();
    }
    let items: Vec<String> = ctx
        .unrunnable
        .keys()
        .map(|comm| format!("0x{comm:04X}"))
        .collect();
    format!(
        " (left out, their file mapping cannot run: {})",
        items.join(", ")
    )
}

/// The data type of an EDS entry.
pub(crate) fn data_type(e: &Entry) -> Option<DataType> {
    e.data_type.and_then(DataType::from_index)
}

/// The access of an EDS entry (`ro` when the file gives none, as CiA 306 readers do).
pub(crate) fn access(e: &Entry) -> Access {
    e.access_type.unwrap_or(Access::Ro)
}

/// The value entries of the file: (index, sub, entry), objects in index order.
pub(crate) fn entries(ctx: &Ctx<'_>) -> Vec<(u16, u8, Entry)> {
    let mut out = Vec::new();
    for (index, obj) in &ctx.eds.objects {
        // An ARRAY or RECORD that lists no sub-object describes no entry to check.
        if matches!(obj.object_code(), cantwin_eds::ARRAY | cantwin_eds::RECORD)
            && obj.subs.is_empty()
        {
            continue;
        }
        if obj.object_code() == cantwin_eds::DOMAIN && obj.subs.is_empty() {
            out.push((*index, 0, obj.entry.clone()));
            continue;
        }
        for (sub, e) in obj.values() {
            out.push((*index, sub, e.clone()));
        }
    }
    out
}

/// The value the file gives `e` as little-endian bytes of its type, with `$NODEID`
/// resolved; `None` for entries without a default or of a variable-length type.
pub(crate) fn default_bytes(e: &Entry, node: u8) -> Option<Vec<u8>> {
    let dt = data_type(e)?;
    let size = dt.fixed_size()?;
    match e.default_value.as_ref()? {
        cantwin_eds::EdsValue::Real32(f) if dt == DataType::Real32 => {
            Some(f.to_le_bytes().to_vec())
        }
        cantwin_eds::EdsValue::Real64(f) if dt == DataType::Real64 => {
            Some(f.to_le_bytes().to_vec())
        }
        v => {
            let n = v.evaluate(node)?;
            Some(n.to_le_bytes()[..size].to_vec())
        }
    }
}

/// `v` as little-endian bytes of `size`.
pub(crate) fn le(v: i128, size: usize) -> Vec<u8> {
    v.to_le_bytes()[..size.min(16)].to_vec()
}

/// An unsigned little-endian value.
pub(crate) fn u32_of(d: &[u8]) -> u32 {
    let mut b = [0u8; 4];
    let n = d.len().min(4);
    b[..n].copy_from_slice(&d[..n]);
    u32::from_le_bytes(b)
}

/// A readable entry of the file, by index and sub.
pub(crate) fn eds_entry<'e>(ctx: &'e Ctx<'_>, index: u16, sub: u8) -> Option<&'e Entry> {
    ctx.eds.entry(index, sub)
}

/// The entry the SDO cases read to see that the server serves: 0x1000 (device type,
/// mandatory, CiA 301 §7.5.2.1) where the file has it, else the first readable entry of 1 to
/// 4 bytes the file lists (a file without 0x1000 fails `eds.mandatory-objects`, and
/// every other SDO case would fail with it, naming nothing of its own clause).
/// (index, sub, size in bytes where the type fixes one).
pub(crate) fn served_entry(ctx: &Ctx<'_>) -> (u16, u8, Option<usize>) {
    if let Some(e) = eds_entry(ctx, 0x1000, 0) {
        return (
            0x1000,
            0,
            data_type(e).and_then(|d| d.fixed_size()).or(Some(4)),
        );
    }
    entries(ctx)
        .into_iter()
        .filter(|(_, _, e)| access(e).readable())
        .find_map(|(i, s, e)| {
            data_type(&e)
                .and_then(|d| d.fixed_size())
                .filter(|n| (1..=4).contains(n))
                .map(|n| (i, s, Some(n)))
        })
        .unwrap_or((0x1000, 0, Some(4)))
}

/// Checks that the device still answers an upload of [`served_entry`] after a refused
/// request (CiA 301 §7.2.4.3.17: an abort ends the transfer; the server is free again).
pub(crate) fn recovered(ctx: &mut Ctx<'_>, after: &str) -> Result<(), Finding> {
    let (index, sub, size) = served_entry(ctx);
    match ctx.upload(index, sub)? {
        Ok(d) if size.is_none_or(|n| d.len() == n) => Ok(()),
        Ok(d) => Err(fail(format!(
            "after {after}, reading 0x{index:04X} sub {sub} returned {} bytes",
            d.len()
        ))),
        Err(a) => Err(fail_sdo(
            format!("after {after}, the server no longer serves 0x{index:04X} sub {sub}"),
            a,
        )),
    }
}

/// The abort code of a raw SDO answer, if it is an abort (cs = 4).
pub(crate) fn abort_of(b: &[u8; 8]) -> Option<AbortCode> {
    (b[0] & 0xE0 == 0x80).then(|| AbortCode::from_u32(u32::from_le_bytes([b[4], b[5], b[6], b[7]])))
}

/// Formats an abort code.
pub(crate) fn hex(code: AbortCode) -> String {
    format!("0x{:08X}", code.to_u32())
}

/// A nominal period is met: `got` within the options' tolerance of `nominal`.
pub(crate) fn within(ctx: &Ctx<'_>, got: Duration, nominal: Duration) -> bool {
    let tol =
        (nominal.as_nanos() as f64 * ctx.options.tolerance) as u64 + ctx.options.slack.as_nanos();
    got.as_nanos().abs_diff(nominal.as_nanos()) <= tol
}

/// An index the file does not list, from the manufacturer area down (for "no object").
pub(crate) fn absent_index(ctx: &Ctx<'_>) -> u16 {
    [0x5FFE, 0x4FFE, 0x3FFE, 0x2FFE, 0x1FFE, 0x2A5A]
        .into_iter()
        .find(|i| !ctx.eds.objects.contains_key(i))
        .unwrap_or(0x5FFD)
}

/// (index, sub-index, size, current value).
pub(crate) type Writable = (u16, u8, usize, Vec<u8>);

/// A writable entry of the file with a fixed size in `sizes`, outside the objects whose
/// write has side effects (PDO and SDO parameters, store/restore, COB-IDs with a valid
/// bit), that reads back now: (index, sub, size, current value).
pub(crate) fn writable(
    ctx: &mut Ctx<'_>,
    sizes: std::ops::RangeInclusive<usize>,
) -> Result<Option<Writable>, Finding> {
    // The communication objects whose rewrite is harmless come first, in this order.
    let mut candidates: Vec<(u16, u8, usize)> = Vec::new();
    for (i, s) in [
        (0x1017u16, 0u8),
        (0x100C, 0),
        (0x100D, 0),
        (0x1015, 0),
        (0x1006, 0),
    ] {
        if let Some(e) = eds_entry(ctx, i, s)
            && access(e).writable()
            && let Some(size) = data_type(e).and_then(|d| d.fixed_size())
            && sizes.contains(&size)
        {
            candidates.push((i, s, size));
        }
    }
    for (index, sub, e) in entries(ctx) {
        if index < 0x2000 || !access(&e).writable() || !access(&e).readable() {
            continue;
        }
        if let Some(size) = data_type(&e).and_then(|d| d.fixed_size())
            && sizes.contains(&size)
        {
            candidates.push((index, sub, size));
        }
    }
    for (index, sub, size) in candidates {
        if let Ok(d) = ctx.upload(index, sub)?
            && d.len() == size
        {
            return Ok(Some((index, sub, size, d)));
        }
    }
    Ok(None)
}

/// Joins findings for a report, the first ten in full and a count of the rest (a device
/// can get hundreds of entries wrong the same way).
pub(crate) fn listing(items: &[String]) -> String {
    const SHOWN: usize = 10;
    let mut s = items
        .iter()
        .take(SHOWN)
        .cloned()
        .collect::<Vec<_>>()
        .join("; ");
    if items.len() > SHOWN {
        s.push_str(&format!("; and {} more", items.len() - SHOWN));
    }
    s
}
