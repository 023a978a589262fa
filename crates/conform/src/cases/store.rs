//! Area 8: store and restore (CiA 301 §7.5.2.13, §7.5.2.14): the signatures, and what
//! survives each reset. Runs last: it leaves the device on its restored defaults.

use cantwin_canopen::AbortCode;
use cantwin_canopen::wire::NmtCs;

use super::{Case, access, data_type, default_bytes, eds_entry, entries, le, m, u32_of};
use crate::ctx::{Ctx, Finding, Outcome, fail, fail_abort, fail_kind, not_supported};
use crate::profile::FailureKind;
use crate::report::Area::StoreRestore as A;

/// "save" read as a little-endian UNSIGNED32 (§7.5.2.13).
const SAVE: u32 = 0x6576_6173;
/// "load" (§7.5.2.14).
const LOAD: u32 = 0x6461_6F6C;

/// The two resets, in the order the cases apply them, with their names.
const RESETS: [(NmtCs, &str); 2] = [
    (NmtCs::ResetCommunication, "reset communication"),
    (NmtCs::ResetNode, "reset node"),
];

/// The NMT `reset` (named `name`), answered by the boot-up message that ends it: a
/// device that stays silent fails, and silence is never excused.
fn reset_answered(ctx: &mut Ctx<'_>, reset: NmtCs, name: &str) -> Result<(), Finding> {
    match ctx.reset(reset)? {
        Some(_) => Ok(()),
        None => Err(fail_kind(
            FailureKind::Silence,
            format!("no boot-up after {name}"),
        )),
    }
}

pub(super) fn cases() -> Vec<Case> {
    vec![
        m(
            "store.wrong-signature",
            A,
            "CiA 301 §7.5.2.13",
            "a store command without the signature \"save\" is refused with 0x08000020",
            store_wrong,
        ),
        m(
            "restore.wrong-signature",
            A,
            "CiA 301 §7.5.2.14",
            "a restore command without the signature \"load\" is refused with 0x08000020",
            restore_wrong,
        ),
        m(
            "store.survives-resets",
            A,
            "CiA 301 §7.5.2.13, §7.3.2.2.2",
            "a stored value survives reset communication and reset node",
            store_survives,
        ),
        m(
            "restore.defaults-after-reset",
            A,
            "CiA 301 §7.5.2.14",
            "after \"load\" and reset node the defaults are back",
            restore_defaults,
        ),
        m(
            "restore.application-after-reset-node",
            A,
            "CiA 301 §7.5.2.14 (sub-index 1), §7.3.2.2.1",
            "after \"load\" to 0x1011 sub 1, a changed application parameter keeps its value through reset communication and is back at its default after reset node",
            restore_application,
        ),
        m(
            "restore.communication-after-reset-communication",
            A,
            "CiA 301 §7.5.2.14 (sub-index 2)",
            "after \"load\" to 0x1011 sub 2, reset communication brings the communication area's defaults back",
            restore_communication,
        ),
    ]
}

fn wrong(ctx: &mut Ctx<'_>, index: u16, feature: Option<bool>, what: &str) -> Outcome {
    if feature == Some(false) {
        return Err(not_supported(format!(
            "no {what} (0x{index:04X} not in the file)"
        )));
    }
    match ctx.download(index, 1, &0x1234_5678u32.to_le_bytes())? {
        Err(a) if a.code == AbortCode::DATA_TRANSFER => Ok("0x08000020".into()),
        Err(a) => Err(fail_abort(
            format!("0x{index:04X} sub 1 = 0x12345678: expected 0x08000020"),
            a.code,
        )),
        Ok(()) => Err(fail(format!(
            "0x{index:04X} sub 1 accepted a wrong signature"
        ))),
    }
}

fn store_wrong(ctx: &mut Ctx<'_>) -> Outcome {
    let f = ctx.profile.features.store;
    wrong(ctx, 0x1010, f, "store parameters")
}

fn restore_wrong(ctx: &mut Ctx<'_>) -> Outcome {
    let f = ctx.profile.features.restore;
    wrong(ctx, 0x1011, f, "restore default parameters")
}

fn probe_entry(ctx: &Ctx<'_>) -> Result<(), Finding> {
    if !eds_entry(ctx, 0x1017, 0).is_some_and(|e| access(e).writable()) {
        return Err(Finding::NotApplicable(
            "no writable heartbeat producer time to store".into(),
        ));
    }
    Ok(())
}

fn store_survives(ctx: &mut Ctx<'_>) -> Outcome {
    if ctx.profile.features.store == Some(false) {
        return Err(not_supported(
            "no store parameters (0x1010 not in the file)",
        ));
    }
    probe_entry(ctx)?;
    let flags = ctx.read_u32(0x1010, 1, "the store parameters sub 1")?;
    if flags & 1 == 0 {
        return Err(not_supported(format!(
            "0x1010 sub 1 = 0x{flags:08X}: the device does not store on command"
        )));
    }
    let before = ctx.read_u32(0x1017, 0, "the heartbeat producer time")?;
    let value: u16 = if before == 1234 { 1235 } else { 1234 };
    ctx.write(
        0x1017,
        0,
        &value.to_le_bytes(),
        "the heartbeat producer time",
    )?;
    ctx.write(0x1010, 1, &SAVE.to_le_bytes(), "\"save\" to 0x1010 sub 1")?;
    let mut seen = Vec::new();
    for (cs, name) in RESETS {
        reset_answered(ctx, cs, name)?;
        let after = ctx.read_u32(0x1017, 0, "the heartbeat producer time")?;
        if after != u32::from(value) {
            return Err(fail(format!(
                "stored 0x1017 = {value}; after {name} it reads {after}"
            )));
        }
        seen.push(name);
    }
    // Store the original value again: a device without restore keeps what it had.
    let original = u16::try_from(before).unwrap_or(0);
    ctx.write(
        0x1017,
        0,
        &original.to_le_bytes(),
        "the heartbeat producer time",
    )?;
    ctx.write(0x1010, 1, &SAVE.to_le_bytes(), "\"save\" to 0x1010 sub 1")?;
    Ok(format!("0x1017 = {value} survives {}", seen.join(" and ")))
}

fn restore_defaults(ctx: &mut Ctx<'_>) -> Outcome {
    restore_heartbeat_time(ctx, 1, NmtCs::ResetNode, "reset node")
}

/// §7.5.2.14: the defaults restored through sub-index 2 (communication parameters) take
/// effect with reset communication; those of sub-index 1 (all parameters) with reset node,
/// which [`restore_defaults`] checks.
fn restore_communication(ctx: &mut Ctx<'_>) -> Outcome {
    if ctx.profile.features.restore != Some(false) && eds_entry(ctx, 0x1011, 2).is_none() {
        return Err(not_supported(
            "0x1011 has no sub-index 2 (communication parameters)",
        ));
    }
    restore_heartbeat_time(ctx, 2, NmtCs::ResetCommunication, "reset communication")
}

/// The producer heartbeat time 0x1017 changed (and stored where the device stores, so that
/// the reset cannot find the value in storage), "load" to 0x1011 `sub`, then the `reset`
/// named `name`: 0x1017 reads its default (or the value the device powered on with, a
/// twin's or a commissioned device's own default, which the EDS area read first).
fn restore_heartbeat_time(ctx: &mut Ctx<'_>, sub: u8, reset: NmtCs, name: &str) -> Outcome {
    if ctx.profile.features.restore == Some(false) {
        return Err(not_supported(
            "no restore default parameters (0x1011 not in the file)",
        ));
    }
    probe_entry(ctx)?;
    let flags = ctx.read_u32(0x1011, sub, &format!("the restore parameters sub {sub}"))?;
    if flags & 1 == 0 {
        return Err(not_supported(format!(
            "0x1011 sub {sub} = 0x{flags:08X}: the device does not restore on command"
        )));
    }
    let Some(default) = eds_entry(ctx, 0x1017, 0).and_then(|e| default_bytes(e, ctx.node)) else {
        return Err(Finding::NotApplicable(
            "the file gives 0x1017 no default".into(),
        ));
    };
    let default = super::u32_of(&default);
    let power_on = ctx.scan.as_ref().and_then(|s| {
        s.iter()
            .find(|(i, sub, _)| (*i, *sub) == (0x1017, 0))
            .and_then(|(_, _, r)| r.as_ref().ok().map(|d| super::u32_of(d)))
    });
    let changed: u16 = if default == 1500 { 1501 } else { 1500 };
    ctx.write(
        0x1017,
        0,
        &changed.to_le_bytes(),
        "the heartbeat producer time",
    )?;
    if ctx.profile.features.store != Some(false)
        && ctx.download(0x1010, 1, &SAVE.to_le_bytes())?.is_err()
    {
        return Err(fail("\"save\" to 0x1010 sub 1 refused"));
    }
    ctx.write(
        0x1011,
        sub,
        &LOAD.to_le_bytes(),
        &format!("\"load\" to 0x1011 sub {sub}"),
    )?;
    reset_answered(ctx, reset, name)?;
    let after = ctx.read_u32(0x1017, 0, "the heartbeat producer time")?;
    if after != default && Some(after) != power_on {
        return Err(fail(format!(
            "after \"load\" to 0x1011 sub {sub} and {name} 0x1017 reads {after}, its default is {default}"
        )));
    }
    Ok(format!("0x1017 back to its default {after} after {name}"))
}

/// A configuration parameter of the application area (0x2000–0x9FFF): readable and writable,
/// not PDO-mappable (process data changes on its own), an integer of up to 4 bytes with a
/// default and both limits in the file. (index, sub, size, default, a value ≠ default
/// within the limits).
fn application_parameter(ctx: &Ctx<'_>) -> Option<(u16, u8, usize, i128, i128)> {
    entries(ctx).into_iter().find_map(|(index, sub, e)| {
        if !(0x2000..=0x9FFF).contains(&index)
            || !access(&e).readable()
            || !access(&e).writable()
            || e.pdo_mapping == Some(true)
        {
            return None;
        }
        let dt = data_type(&e)?;
        let size = dt.fixed_size().filter(|s| *s <= 4)?;
        if matches!(
            dt,
            cantwin_canopen::od::DataType::Real32 | cantwin_canopen::od::DataType::Boolean
        ) {
            return None;
        }
        let default = e.default_value.as_ref()?.evaluate(ctx.node)?;
        let lo = e.low_limit.as_ref()?.evaluate(ctx.node)?;
        let hi = e.high_limit.as_ref()?.evaluate(ctx.node)?;
        let other = if default < hi {
            default + 1
        } else {
            default - 1
        };
        (lo <= other && other <= hi && lo <= default && default <= hi)
            .then_some((index, sub, size, default, other))
    })
}

/// §7.5.2.14: defaults restored through sub-index 1 (all parameters) take effect with reset
/// node; reset communication sets only the communication area to its power-on values
/// (§7.3.2.2.1), so an application parameter keeps its value through it.
fn restore_application(ctx: &mut Ctx<'_>) -> Outcome {
    if ctx.profile.features.restore == Some(false) {
        return Err(not_supported(
            "no restore default parameters (0x1011 not in the file)",
        ));
    }
    let flags = ctx.read_u32(0x1011, 1, "the restore parameters sub 1")?;
    if flags & 1 == 0 {
        return Err(not_supported(format!(
            "0x1011 sub 1 = 0x{flags:08X}: the device does not restore on command"
        )));
    }
    let Some((index, sub, size, default, changed)) = application_parameter(ctx) else {
        return Err(Finding::NotApplicable(
            "the file has no application parameter (0x2000–0x9FFF, rw, not mappable) with a default and limits".into(),
        ));
    };
    let signed = data_type(eds_entry(ctx, index, sub).ok_or_else(|| fail("entry gone"))?)
        .is_some_and(|d| d.is_signed());
    let value = |d: &[u8]| -> i128 {
        let u = i128::from(u32_of(d));
        let bits = 8 * d.len().min(4) as u32;
        if signed && bits > 0 && u >= 1i128 << (bits - 1) {
            u - (1i128 << bits)
        } else {
            u
        }
    };
    let original = ctx
        .upload(index, sub)?
        .map_err(|a| crate::ctx::fail_sdo(format!("reading 0x{index:04X} sub {sub}"), a))?;
    let what = format!("0x{index:04X} sub {sub}");
    ctx.write(index, sub, &le(changed, size), &what)?;
    if ctx.profile.features.store != Some(false)
        && ctx.download(0x1010, 1, &SAVE.to_le_bytes())?.is_err()
    {
        return Err(fail("\"save\" to 0x1010 sub 1 refused"));
    }
    ctx.write(0x1011, 1, &LOAD.to_le_bytes(), "\"load\" to 0x1011 sub 1")?;
    let mut after = Vec::new();
    for (cs, name) in RESETS {
        reset_answered(ctx, cs, name)?;
        let d = ctx
            .upload(index, sub)?
            .map_err(|a| crate::ctx::fail_sdo(format!("reading {what} after {name}"), a))?;
        after.push(value(&d));
    }
    // Back to the value the device had: a device without restore keeps what it has.
    ctx.write(index, sub, &original, &what)?;
    if after[0] != changed {
        return Err(fail(format!(
            "{what} = {changed}, \"load\" to 0x1011 sub 1: after reset communication it reads {}, where only reset node restores the application area",
            after[0]
        )));
    }
    if after[1] != default {
        return Err(fail(format!(
            "{what} = {changed}, \"load\" to 0x1011 sub 1: after reset node it reads {}, its default is {default}",
            after[1]
        )));
    }
    Ok(format!(
        "{what}: {changed} through reset communication, its default {default} after reset node"
    ))
}
