//! Area 8: store and restore (CiA 301 §7.5.2.13, §7.5.2.14): the signatures, and what
//! survives each reset. Runs last: it leaves the device on its restored defaults.

use cantwin_canopen::AbortCode;
use cantwin_canopen::wire::NmtCs;

use super::{Case, access, default_bytes, eds_entry, m};
use crate::ctx::{Ctx, Finding, Outcome, fail, fail_abort, fail_kind, not_supported};
use crate::profile::FailureKind;
use crate::report::Area::StoreRestore as A;

/// "save" read as a little-endian UNSIGNED32 (§7.5.2.13).
const SAVE: u32 = 0x6576_6173;
/// "load" (§7.5.2.14).
const LOAD: u32 = 0x6461_6F6C;

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
    for (cs, name) in [
        (NmtCs::ResetCommunication, "reset communication"),
        (NmtCs::ResetNode, "reset node"),
    ] {
        if ctx.reset(cs)?.is_none() {
            return Err(fail_kind(
                FailureKind::Silence,
                format!("no boot-up after {name}"),
            ));
        }
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
    if ctx.profile.features.restore == Some(false) {
        return Err(not_supported(
            "no restore default parameters (0x1011 not in the file)",
        ));
    }
    probe_entry(ctx)?;
    let flags = ctx.read_u32(0x1011, 1, "the restore parameters sub 1")?;
    if flags & 1 == 0 {
        return Err(not_supported(format!(
            "0x1011 sub 1 = 0x{flags:08X}: the device does not restore on command"
        )));
    }
    let Some(default) = eds_entry(ctx, 0x1017, 0).and_then(|e| default_bytes(e, ctx.node)) else {
        return Err(Finding::NotApplicable(
            "the file gives 0x1017 no default".into(),
        ));
    };
    let default = super::u32_of(&default);
    // A twin or a commissioned device may power on with a configured value: its own
    // default, which the EDS area read first.
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
    ctx.write(0x1011, 1, &LOAD.to_le_bytes(), "\"load\" to 0x1011 sub 1")?;
    if ctx.reset(NmtCs::ResetNode)?.is_none() {
        return Err(fail_kind(
            FailureKind::Silence,
            "no boot-up after reset node",
        ));
    }
    let after = ctx.read_u32(0x1017, 0, "the heartbeat producer time")?;
    if after != default && Some(after) != power_on {
        return Err(fail(format!(
            "after \"load\" and reset node 0x1017 reads {after}, its default is {default}"
        )));
    }
    Ok(format!("0x1017 back to its default {default}"))
}
