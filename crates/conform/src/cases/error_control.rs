//! Area 6: error control (CiA 301 §7.2.8.3.2): the heartbeat producer's period, the
//! heartbeat consumer's timeout and its EMCY, the duplicate-entry rule of 0x1016, node
//! guarding and life guarding.

use cantwin_can::{Duration, Frame, Id};
use cantwin_canopen::AbortCode;

use super::{Case, access, eds_entry, m, within};
use crate::ctx::{Ctx, Finding, Outcome, fail, fail_abort, fail_kind, fail_sdo, not_supported};
use crate::profile::FailureKind;
use crate::report::Area::ErrorControl as A;

pub(super) fn cases() -> Vec<Case> {
    vec![
        m(
            "error-control.heartbeat-period",
            A,
            "CiA 301 §7.2.8.3.2.2, §7.5.2.20",
            "with 0x1017 = 100 ms, heartbeats every 100 ms reporting the state",
            heartbeat_period,
        ),
        m(
            "error-control.heartbeat-off",
            A,
            "CiA 301 §7.5.2.20",
            "with 0x1017 = 0 no heartbeat is sent",
            heartbeat_off,
        ),
        m(
            "error-control.heartbeat-consumer",
            A,
            "CiA 301 §7.2.8.3.2.2, §7.2.7.1 table 26",
            "a consumed heartbeat that stops raises EMCY 0x8130 after the consumer time, not before the first heartbeat",
            heartbeat_consumer,
        ),
        m(
            "error-control.heartbeat-consumer-duplicate",
            A,
            "CiA 301 §7.5.2.19",
            "two 0x1016 entries for one node-ID are refused with 0x06040043",
            heartbeat_duplicate,
        ),
        m(
            "error-control.node-guarding",
            A,
            "CiA 301 §7.2.8.3.2.1",
            "guarding requests are answered with the state and an alternating toggle bit",
            node_guarding,
        ),
        m(
            "error-control.life-guarding",
            A,
            "CiA 301 §7.2.8.3.2.1, §7.2.7.1 table 26",
            "guarding requests that stop raise EMCY 0x8130 after the node life time",
            life_guarding,
        ),
    ]
}

fn heartbeat_writable(ctx: &Ctx<'_>) -> Result<(), Finding> {
    if ctx.profile.features.heartbeat_producer == Some(false) {
        return Err(not_supported(
            "no heartbeat producer (0x1017 not in the file)",
        ));
    }
    if !eds_entry(ctx, 0x1017, 0).is_some_and(|e| access(e).writable()) {
        return Err(fail(
            "0x1017 is not writable in the file (CiA 301 §7.5.2.20: rw)",
        ));
    }
    Ok(())
}

fn heartbeat_period(ctx: &mut Ctx<'_>) -> Outcome {
    heartbeat_writable(ctx)?;
    let orig = ctx
        .upload(0x1017, 0)?
        .map_err(|a| fail_sdo("reading 0x1017", a))?;
    ctx.write(
        0x1017,
        0,
        &100u16.to_le_bytes(),
        "the heartbeat producer time",
    )?;
    let ec = ctx.ec_id();
    // The first heartbeat may come at once (the timer restarts at the write).
    ctx.wait_for(Duration::from_millis(250), |f| f.id() == ec)?;
    let beats = ctx.collect(Duration::from_millis(1050), |f| {
        f.id() == ec && !f.is_remote()
    })?;
    ctx.write(0x1017, 0, &orig, "the heartbeat producer time")?;
    let nominal = Duration::from_millis(100);
    if !(9..=11).contains(&beats.len()) {
        return Err(fail_kind(
            FailureKind::Timing,
            format!("{} heartbeats in 1.05 s at 100 ms", beats.len()),
        ));
    }
    for w in beats.windows(2) {
        let d = w[1].0.saturating_duration_since(w[0].0);
        if !within(ctx, d, nominal) {
            return Err(fail_kind(
                FailureKind::Timing,
                format!(
                    "a heartbeat interval of {} µs, nominal 100 ms",
                    d.as_micros()
                ),
            ));
        }
    }
    for (_, f) in &beats {
        if f.data_bytes() != [0x7F] {
            return Err(fail(format!(
                "heartbeat {f} in PRE-OPERATIONAL: expected one byte 0x7F"
            )));
        }
    }
    Ok(format!(
        "{} heartbeats, intervals within tolerance",
        beats.len()
    ))
}

fn heartbeat_off(ctx: &mut Ctx<'_>) -> Outcome {
    heartbeat_writable(ctx)?;
    let orig = ctx
        .upload(0x1017, 0)?
        .map_err(|a| fail_sdo("reading 0x1017", a))?;
    ctx.write(
        0x1017,
        0,
        &0u16.to_le_bytes(),
        "the heartbeat producer time",
    )?;
    let ec = ctx.ec_id();
    ctx.idle(Duration::from_millis(20))?;
    let beats = ctx.collect(Duration::from_millis(500), |f| {
        f.id() == ec && !f.is_remote()
    })?;
    ctx.write(0x1017, 0, &orig, "the heartbeat producer time")?;
    if beats.is_empty() {
        Ok("no heartbeat in 500 ms".into())
    } else {
        Err(fail(format!(
            "{} heartbeats in 500 ms with 0x1017 = 0",
            beats.len()
        )))
    }
}

/// The device's EMCY COB-ID, if it produces EMCY (0x1014 bit 31 clear).
fn emcy_cob(ctx: &mut Ctx<'_>) -> Result<Option<u32>, Finding> {
    if ctx.profile.features.emcy == Some(false) {
        return Ok(None);
    }
    let cob = match ctx.upload(0x1014, 0)? {
        Ok(d) => super::u32_of(&d),
        Err(_) => ctx.emcy_id().as_raw(),
    };
    Ok((cob & 0x8000_0000 == 0).then_some(cob & 0x7FF))
}

fn is_emcy(f: &Frame, cob: u32, code: u16) -> bool {
    f.id().as_raw() == cob
        && f.len() == 8
        && u16::from_le_bytes([f.data_bytes()[0], f.data_bytes()[1]]) == code
}

fn heartbeat_consumer(ctx: &mut Ctx<'_>) -> Outcome {
    if ctx.profile.features.heartbeat_consumer == Some(false) {
        return Err(not_supported(
            "no heartbeat consumer (0x1016 not in the file)",
        ));
    }
    let Some(cob) = emcy_cob(ctx)? else {
        return Err(Finding::NotApplicable(
            "the device produces no EMCY to report the timeout".into(),
        ));
    };
    let other = ctx.free_node();
    let entry = (u32::from(other) << 16) | 200;
    ctx.write(
        0x1016,
        1,
        &entry.to_le_bytes(),
        "a heartbeat consumer entry",
    )?;
    // Monitoring starts with the first heartbeat: nothing before it.
    let early = ctx.collect(Duration::from_millis(400), |f| is_emcy(f, cob, 0x8130))?;
    let hb = Id::standard(0x700 + u16::from(other)).map_err(|e| fail(e.to_string()))?;
    ctx.send(Frame::data_array(hb, [0x05]))?;
    let sent = ctx.now();
    let got = ctx.wait_for(Duration::from_millis(600), |f| is_emcy(f, cob, 0x8130))?;
    // The producer comes back, which ends the error (§7.2.8.3.2.2), before the entry goes.
    ctx.send(Frame::data_array(hb, [0x05]))?;
    ctx.idle(Duration::from_millis(50))?;
    ctx.write(0x1016, 1, &0u32.to_le_bytes(), "a heartbeat consumer entry")?;
    if !early.is_empty() {
        return Err(fail_kind(
            FailureKind::Timing,
            "EMCY 0x8130 before the first heartbeat of the consumed node",
        ));
    }
    let Some((t, _)) = got else {
        return Err(fail_kind(
            FailureKind::Event,
            format!(
                "no EMCY 0x8130 within 600 ms of the last heartbeat of node {other} (consumer time 200 ms)"
            ),
        ));
    };
    let after = t.saturating_duration_since(sent);
    let lo = Duration::from_millis(200).saturating_sub(ctx.options.slack);
    if after < lo
        || !within(ctx, after, Duration::from_millis(200)) && after > Duration::from_millis(200)
    {
        return Err(fail_kind(
            FailureKind::Timing,
            format!(
                "EMCY 0x8130 {} µs after the heartbeat, consumer time 200 ms",
                after.as_micros()
            ),
        ));
    }
    Ok(format!(
        "EMCY 0x8130 {} ms after the last heartbeat of node {other} (a node-ID not seen on the bus)",
        after.as_millis()
    ))
}

fn heartbeat_duplicate(ctx: &mut Ctx<'_>) -> Outcome {
    if ctx.profile.features.heartbeat_consumer == Some(false) {
        return Err(not_supported(
            "no heartbeat consumer (0x1016 not in the file)",
        ));
    }
    if ctx.eds.entry(0x1016, 2).is_none() {
        return Err(Finding::NotApplicable("0x1016 has a single entry".into()));
    }
    let other = ctx.free_node();
    ctx.write(
        0x1016,
        1,
        &((u32::from(other) << 16) | 200).to_le_bytes(),
        "0x1016 sub 1",
    )?;
    let second = ctx.download(0x1016, 2, &((u32::from(other) << 16) | 300).to_le_bytes())?;
    ctx.write(0x1016, 1, &0u32.to_le_bytes(), "0x1016 sub 1")?;
    match second {
        Err(a) if a.code == AbortCode::PARAMETER_INCOMPATIBLE => {
            Ok(format!("0x06040043 for a second entry of node {other}"))
        }
        Err(a) => Err(fail_abort("expected 0x06040043", a.code)),
        Ok(()) => {
            ctx.write(0x1016, 2, &0u32.to_le_bytes(), "0x1016 sub 2")?;
            Err(fail(format!(
                "a second entry for node {other} was accepted"
            )))
        }
    }
}

/// Sets up guarding (heartbeat off, guard time 100 ms, factor 3); the heartbeat time to
/// restore.
fn guarding_on(ctx: &mut Ctx<'_>) -> Result<Vec<u8>, Finding> {
    if ctx.profile.features.node_guarding == Some(false) {
        return Err(not_supported(
            "no node guarding (0x100C/0x100D not in the file)",
        ));
    }
    let hb = match ctx.upload(0x1017, 0)? {
        Ok(d) => {
            ctx.write(
                0x1017,
                0,
                &0u16.to_le_bytes(),
                "the heartbeat producer time",
            )?;
            d
        }
        Err(_) => Vec::new(),
    };
    ctx.write(0x100C, 0, &100u16.to_le_bytes(), "the guard time")?;
    ctx.write(0x100D, 0, &[3], "the life time factor")?;
    Ok(hb)
}

fn guarding_off(ctx: &mut Ctx<'_>, hb: &[u8]) -> Result<(), Finding> {
    ctx.write(0x100C, 0, &0u16.to_le_bytes(), "the guard time")?;
    ctx.write(0x100D, 0, &[0], "the life time factor")?;
    if !hb.is_empty() {
        ctx.write(0x1017, 0, hb, "the heartbeat producer time")?;
    }
    Ok(())
}

fn node_guarding(ctx: &mut Ctx<'_>) -> Outcome {
    let hb = guarding_on(ctx)?;
    let ec = ctx.ec_id();
    let mut answers = Vec::new();
    for _ in 0..4 {
        ctx.send(Frame::remote(ec, 1).map_err(|e| fail(e.to_string()))?)?;
        let got = ctx.wait_for(Duration::from_millis(100), |f| {
            f.id() == ec && !f.is_remote()
        })?;
        answers.push(got.map(|(_, f)| f));
        ctx.idle(Duration::from_millis(50))?;
    }
    guarding_off(ctx, &hb)?;
    let mut toggles = Vec::new();
    for a in &answers {
        let Some(f) = a else {
            return Err(fail_kind(
                FailureKind::Silence,
                "a guarding request was not answered within 100 ms",
            ));
        };
        if f.len() != 1 || f.data_bytes()[0] & 0x7F != 0x7F {
            return Err(fail(format!(
                "guarding answer {f}: expected one byte with state 127"
            )));
        }
        toggles.push(f.data_bytes()[0] >> 7);
    }
    if toggles.windows(2).any(|w| w[0] == w[1]) {
        return Err(fail(format!("toggle bits {toggles:?} do not alternate")));
    }
    Ok(format!("toggle bits {toggles:?}"))
}

fn life_guarding(ctx: &mut Ctx<'_>) -> Outcome {
    let Some(cob) = emcy_cob(ctx)? else {
        return Err(Finding::NotApplicable(
            "the device produces no EMCY to report the event".into(),
        ));
    };
    let hb = guarding_on(ctx)?;
    let ec = ctx.ec_id();
    ctx.send(Frame::remote(ec, 1).map_err(|e| fail(e.to_string()))?)?;
    let first = ctx.wait_for(Duration::from_millis(100), |f| {
        f.id() == ec && !f.is_remote()
    })?;
    let sent = ctx.now();
    let got = ctx.wait_for(Duration::from_millis(900), |f| is_emcy(f, cob, 0x8130))?;
    // A poll ends the life guarding event before guarding goes off.
    ctx.send(Frame::remote(ec, 1).map_err(|e| fail(e.to_string()))?)?;
    ctx.idle(Duration::from_millis(50))?;
    guarding_off(ctx, &hb)?;
    if first.is_none() {
        return Err(fail_kind(
            FailureKind::Silence,
            "the guarding request was not answered",
        ));
    }
    let Some((t, _)) = got else {
        return Err(fail_kind(
            FailureKind::Event,
            "no EMCY 0x8130 within 900 ms of the last guarding request (life time 300 ms)",
        ));
    };
    let after = t.saturating_duration_since(sent);
    if after + ctx.options.slack < Duration::from_millis(300) {
        return Err(fail_kind(
            FailureKind::Timing,
            format!(
                "EMCY 0x8130 {} ms after the last request, before the life time of 300 ms",
                after.as_millis()
            ),
        ));
    }
    Ok(format!(
        "EMCY 0x8130 {} ms after the last request",
        after.as_millis()
    ))
}
