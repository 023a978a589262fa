//! Area 1: the EDS and the device agree (CiA 306 §4.5–4.6, CiA 301 §7.4.3, §7.5).

use cantwin_canopen::AbortCode;

use super::{Case, a, access, data_type, default_bytes, entries, hex, m};
use crate::ctx::{Aborted, Ctx, Finding, Outcome, fail, fail_kind};
use crate::profile::FailureKind;
use crate::report::Area::Eds as A;

pub(super) fn cases() -> Vec<Case> {
    vec![
        m(
            "eds.file-valid",
            A,
            "CiA 306 §4",
            "the file has no errors by CiA 306",
            file_valid,
        ),
        m(
            "eds.mandatory-objects",
            A,
            "CiA 301 §7.4.1, CiA 306 §4.5.2",
            "the file and the device have 0x1000, 0x1001 and 0x1018 sub 1",
            mandatory_objects,
        ),
        m(
            "eds.entries-exist",
            A,
            "CiA 306 §4.6.3, CiA 301 §7.2.4.3.17",
            "every object and sub-index of the file exists on the device",
            entries_exist,
        ),
        m(
            "eds.access-types",
            A,
            "CiA 306 §4.6.3 AccessType",
            "write-only entries refuse a read with 0x06010001, read-only ones a write with 0x06010002, readable ones are read",
            access_types,
        ),
        m(
            "eds.data-lengths",
            A,
            "CiA 306 §4.6.3 DataType, CiA 301 §7.1.2",
            "every fixed-size entry reads with the length of its data type",
            data_lengths,
        ),
        a(
            "eds.default-values",
            A,
            "CiA 306 §4.6.3 DefaultValue",
            "constant and configuration entries read as the file's default",
            default_values,
        ),
    ]
}

/// One entry of the scan.
type ScanEntry = (u16, u8, Result<Vec<u8>, Aborted>);

/// Reads every entry of the file once, for the cases of this area.
fn scan<'c>(ctx: &'c mut Ctx<'_>) -> Result<&'c [ScanEntry], Finding> {
    if ctx.scan.is_none() {
        let mut out = Vec::new();
        let mut silent = 0;
        for (index, sub, _) in entries(ctx) {
            let got = ctx.upload(index, sub)?;
            // A device that stops answering would take every entry to its timeout.
            silent = match &got {
                Err(a) if !a.by_server => silent + 1,
                _ => 0,
            };
            out.push((index, sub, got));
            if silent == 5 {
                ctx.scan = Some(out);
                return Err(fail_kind(
                    FailureKind::Silence,
                    format!(
                        "the device stopped answering at 0x{index:04X} sub {sub} (5 requests in a row without an answer)"
                    ),
                ));
            }
        }
        ctx.scan = Some(out);
    }
    Ok(ctx.scan.as_deref().unwrap_or_default())
}

fn file_valid(ctx: &mut Ctx<'_>) -> Outcome {
    let report = ctx.eds.check();
    let errors: Vec<String> = report.errors().map(|i| i.to_string()).collect();
    if errors.is_empty() {
        Ok(format!(
            "{} objects, {} warnings",
            ctx.eds.objects.len(),
            report.warnings().count()
        ))
    } else {
        Err(fail(super::listing(&errors)))
    }
}

fn mandatory_objects(ctx: &mut Ctx<'_>) -> Outcome {
    let mut missing = Vec::new();
    for (index, sub) in [(0x1000u16, 0u8), (0x1001, 0), (0x1018, 0), (0x1018, 1)] {
        if ctx.eds.entry(index, sub).is_none() {
            missing.push(format!("0x{index:04X} sub {sub} is not in the file"));
        }
        match ctx.upload(index, sub)? {
            Ok(_) => {}
            Err(a) => missing.push(format!("0x{index:04X} sub {sub}: {a}")),
        }
    }
    if missing.is_empty() {
        Ok("device type, error register and vendor-ID present".into())
    } else {
        Err(fail(super::listing(&missing)))
    }
}

fn entries_exist(ctx: &mut Ctx<'_>) -> Outcome {
    let scanned = scan(ctx)?;
    let missing: Vec<String> = scanned
        .iter()
        .filter_map(|(i, s, r)| match r {
            Err(a) if [AbortCode::NO_OBJECT, AbortCode::NO_SUB_INDEX].contains(&a.code) => {
                Some(format!("0x{i:04X} sub {s}: {a}"))
            }
            Err(a) if a.code == AbortCode::TIMEOUT => Some(format!("0x{i:04X} sub {s}: no answer")),
            _ => None,
        })
        .collect();
    let n = scanned.len();
    if missing.is_empty() {
        Ok(format!("{n} entries answered"))
    } else {
        Err(fail(format!(
            "{} of {n} entries missing: {}",
            missing.len(),
            super::listing(&missing)
        )))
    }
}

fn access_types(ctx: &mut Ctx<'_>) -> Outcome {
    let list: Vec<_> = entries(ctx)
        .into_iter()
        .map(|(i, s, e)| ((i, s), access(&e)))
        .collect();
    let scanned = scan(ctx)?.to_vec();
    let mut bad = Vec::new();
    for ((index, sub), acc) in list {
        let Some((_, _, got)) = scanned.iter().find(|(i, s, _)| (*i, *s) == (index, sub)) else {
            continue;
        };
        match (acc.readable(), got) {
            (true, Err(a)) if a.code == AbortCode::WRITE_ONLY => bad.push(format!(
                "0x{index:04X} sub {sub} is {} in the file, the device says write-only",
                acc.eds_name()
            )),
            (false, Ok(_)) => bad.push(format!(
                "0x{index:04X} sub {sub} is wo in the file, the device answered a read"
            )),
            (false, Err(a)) if a.code != AbortCode::WRITE_ONLY => bad.push(format!(
                "0x{index:04X} sub {sub} (wo): a read gave {}, not {}",
                hex(a.code),
                hex(AbortCode::WRITE_ONLY)
            )),
            // A read-only entry refuses a write, even of its own value (§7.2.4.3.17).
            (true, Ok(value)) if !acc.writable() && !value.is_empty() => {
                match ctx.download(index, sub, value)? {
                    Err(a) if a.by_server && a.code == AbortCode::READ_ONLY => {}
                    Err(a) => bad.push(format!(
                        "0x{index:04X} sub {sub} ({}): a write of its own value gave {a}, not {}",
                        acc.eds_name(),
                        hex(AbortCode::READ_ONLY)
                    )),
                    Ok(()) => bad.push(format!(
                        "0x{index:04X} sub {sub} is {} in the file, the device took a write",
                        acc.eds_name()
                    )),
                }
            }
            _ => {}
        }
    }
    if bad.is_empty() {
        Ok("access types agree".into())
    } else {
        Err(fail(super::listing(&bad)))
    }
}

fn data_lengths(ctx: &mut Ctx<'_>) -> Outcome {
    let sizes: Vec<_> = entries(ctx)
        .into_iter()
        .filter_map(|(i, s, e)| Some(((i, s), data_type(&e)?.fixed_size()?)))
        .collect();
    let scanned = scan(ctx)?.to_vec();
    let mut bad = Vec::new();
    let mut checked = 0;
    for ((index, sub), size) in sizes {
        if let Some((_, _, Ok(d))) = scanned.iter().find(|(i, s, _)| (*i, *s) == (index, sub)) {
            checked += 1;
            if d.len() != size {
                bad.push(format!(
                    "0x{index:04X} sub {sub}: {} bytes, its type has {size}",
                    d.len()
                ));
            }
        }
    }
    if bad.is_empty() {
        Ok(format!("{checked} entries of fixed size"))
    } else {
        Err(fail(super::listing(&bad)))
    }
}

/// Entries whose value the device may change by itself, or that a configuration changes
/// by design: their defaults are not checked.
fn live(index: u16, e: &cantwin_eds::Entry) -> bool {
    e.pdo_mapping == Some(true)
        || matches!(index, 0x1001..=0x1003 | 0x1010 | 0x1011 | 0x1F80)
        || (index >= 0x2000 && access(e) == cantwin_canopen::od::Access::Ro)
}

fn default_values(ctx: &mut Ctx<'_>) -> Outcome {
    let node = ctx.node;
    let defaults: Vec<_> = entries(ctx)
        .into_iter()
        .filter(|(i, _, e)| !live(*i, e) && access(e).readable())
        .filter_map(|(i, s, e)| Some(((i, s), default_bytes(&e, node)?)))
        .collect();
    let scanned = scan(ctx)?.to_vec();
    let mut bad = Vec::new();
    let mut checked = 0;
    for ((index, sub), want) in defaults {
        if let Some((_, _, Ok(d))) = scanned.iter().find(|(i, s, _)| (*i, *s) == (index, sub)) {
            checked += 1;
            if *d != want {
                bad.push(format!(
                    "0x{index:04X} sub {sub}: reads {d:02X?}, the file's default is {want:02X?}"
                ));
            }
        }
    }
    if bad.is_empty() {
        Ok(format!("{checked} defaults agree"))
    } else {
        Err(fail(super::listing(&bad)))
    }
}
