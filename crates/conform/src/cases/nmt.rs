//! Area 7: NMT (CiA 301 §7.3.2): states and transitions, boot-up after each reset, which
//! services answer in which state, what each reset restores.

use cantwin_can::{Duration, Frame, Instant};
use cantwin_canopen::wire::NmtCs;

use super::{Case, access, eds_entry, m};
use crate::ctx::{Ctx, Finding, Outcome, fail, fail_kind, fail_sdo};
use crate::profile::FailureKind;
use crate::report::Area::Nmt as A;

pub(super) fn cases() -> Vec<Case> {
    vec![
        m(
            "nmt.boot-up-reset-communication",
            A,
            "CiA 301 §7.3.2.2.2, §7.2.8.3.2.4",
            "reset communication ends with a boot-up message (0x700 + node-ID, 0x00)",
            boot_reset_comm,
        ),
        m(
            "nmt.boot-up-reset-node",
            A,
            "CiA 301 §7.3.2.2.2, §7.2.8.3.2.4",
            "reset node ends with a boot-up message",
            boot_reset_node,
        ),
        m(
            "nmt.reset-from-operational-stopped",
            A,
            "CiA 301 §7.3.2.2.1 figure 48, §7.3.2.2.2",
            "reset node and reset communication from OPERATIONAL and from STOPPED end with a boot-up and PRE-OPERATIONAL",
            reset_from_operational_stopped,
        ),
        m(
            "nmt.pre-operational-after-boot-up",
            A,
            "CiA 301 §7.3.2.2.1 figure 48, §7.2.8.3.2.4",
            "the first state the device reports after its boot-up (heartbeat or guarding answer) is PRE-OPERATIONAL (127)",
            pre_operational_after_boot_up,
        ),
        m(
            "nmt.other-node",
            A,
            "CiA 301 §7.2.8.3.1",
            "an NMT stop for another node-ID leaves the device's state and SDO server alone",
            other_node,
        ),
        m(
            "nmt.broadcast",
            A,
            "CiA 301 §7.2.8.3.1",
            "an NMT command to node-ID 0 addresses the device",
            broadcast,
        ),
        m(
            "nmt.states",
            A,
            "CiA 301 §7.3.2.2, §7.2.8.3.2",
            "start, stop and enter pre-operational move the state the error control reports (5, 4, 127)",
            states,
        ),
        m(
            "nmt.sdo-stopped",
            A,
            "CiA 301 §7.3.2.2.5 (NMT states and communication objects)",
            "no SDO answer in STOPPED; SDO again in PRE-OPERATIONAL",
            sdo_stopped,
        ),
        m(
            "nmt.pdo-operational-only",
            A,
            "CiA 301 §7.3.2.2.5 (NMT states and communication objects)",
            "a TPDO with an event timer is sent in OPERATIONAL only",
            pdo_operational_only,
        ),
        m(
            "nmt.services-stopped",
            A,
            "CiA 301 §7.3.2.2.5 (NMT states and communication objects)",
            "in STOPPED an RPDO is not processed, a SYNC triggers no TPDO and no EMCY is sent",
            services_stopped,
        ),
        m(
            "nmt.services-pre-operational",
            A,
            "CiA 301 §7.3.2.2.5 (NMT states and communication objects)",
            "in PRE-OPERATIONAL an RPDO is not processed and a SYNC triggers no TPDO",
            services_pre_operational,
        ),
        m(
            "nmt.reset-communication-restores",
            A,
            "CiA 301 §7.3.2.2.2",
            "reset communication sets the communication area back to its power-on values",
            reset_comm_restores,
        ),
        m(
            "nmt.reset-node-restores",
            A,
            "CiA 301 §7.3.2.2.2",
            "reset node sets the communication area back to its power-on values",
            reset_node_restores,
        ),
    ]
}

fn boot(ctx: &mut Ctx<'_>, cs: NmtCs, what: &str) -> Outcome {
    let sent = ctx.now();
    match ctx.reset(cs)? {
        Some(t) => Ok(format!(
            "boot-up {} ms after {what}",
            t.saturating_duration_since(sent).as_millis()
        )),
        None => Err(fail_kind(
            FailureKind::Silence,
            format!(
                "no boot-up message within {} ms of {what}",
                ctx.options.boot_timeout.as_millis()
            ),
        )),
    }
}

fn boot_reset_comm(ctx: &mut Ctx<'_>) -> Outcome {
    boot(ctx, NmtCs::ResetCommunication, "reset communication")
}

fn boot_reset_node(ctx: &mut Ctx<'_>) -> Outcome {
    boot(ctx, NmtCs::ResetNode, "reset node")
}

/// Figure 48: from OPERATIONAL and from STOPPED, each reset leads through INITIALISATION
/// (with its boot-up, §7.2.8.3.2.4) to PRE-OPERATIONAL.
fn reset_from_operational_stopped(ctx: &mut Ctx<'_>) -> Outcome {
    let heartbeat = eds_entry(ctx, 0x1017, 0).is_some_and(|e| access(e).writable());
    if !heartbeat && !ctx.eds.objects.contains_key(&0x100C) {
        return Err(Finding::NotApplicable(
            "neither heartbeat nor node guarding to report the state".into(),
        ));
    }
    let mut seen = Vec::new();
    for (from, from_name) in [(NmtCs::Start, "OPERATIONAL"), (NmtCs::Stop, "STOPPED")] {
        for (cs, what) in [
            (NmtCs::ResetNode, "reset node"),
            (NmtCs::ResetCommunication, "reset communication"),
        ] {
            ctx.nmt(from)?;
            ctx.idle(Duration::from_millis(10))?;
            if ctx.reset(cs)?.is_none() {
                return Err(fail_kind(
                    FailureKind::Silence,
                    format!(
                        "no boot-up within {} ms of {what} in {from_name}",
                        ctx.options.boot_timeout.as_millis()
                    ),
                ));
            }
            // The reset set 0x1017 back to its power-on value: have the state reported
            // again (an SDO write, which STOPPED would not answer).
            let orig = state_reporting(ctx)?;
            let state = reported_state(ctx, orig.is_some())?;
            if let Some(o) = orig {
                ctx.write(0x1017, 0, &o, "the heartbeat producer time")?;
            }
            match state {
                Some(0x7F) => seen.push(format!("{what} in {from_name}")),
                Some(s) => {
                    return Err(fail(format!(
                        "after {what} in {from_name} the device reports state {s}, not 127 (PRE-OPERATIONAL)"
                    )));
                }
                None => {
                    return Err(fail_kind(
                        FailureKind::Silence,
                        format!("no state report after {what} in {from_name}"),
                    ));
                }
            }
        }
    }
    Ok(format!(
        "boot-up and PRE-OPERATIONAL after {}",
        seen.join(", ")
    ))
}

/// §7.3.2.2.1: INITIALISATION ends with the boot-up and PRE-OPERATIONAL, so the first
/// heartbeat after the boot-up (at the power-on producer time), or the first guarding
/// answer if the device produces no heartbeat, reports 127.
fn pre_operational_after_boot_up(ctx: &mut Ctx<'_>) -> Outcome {
    let guarding = ctx.eds.objects.contains_key(&0x100C);
    // The producer time the device runs with; read before the reset, since an SDO
    // transfer after the boot-up could hide the first heartbeat.
    let period = if ctx.eds.objects.contains_key(&0x1017) {
        ctx.read_u32(0x1017, 0, "the heartbeat producer time")?
    } else {
        0
    };
    if period == 0 && !guarding {
        return Err(Finding::NotApplicable(
            "the device produces neither heartbeat (0x1017 = 0) nor node guarding".into(),
        ));
    }
    let Some(booted) = ctx.reset(NmtCs::ResetCommunication)? else {
        return Err(fail_kind(
            FailureKind::Silence,
            "no boot-up after reset communication",
        ));
    };
    let ec = ctx.ec_id();
    if guarding {
        ctx.send(Frame::remote(ec, 1).map_err(|e| fail(e.to_string()))?)?;
    }
    let within = ctx
        .options
        .sdo_timeout
        .max(Duration::from_millis(2 * u64::from(period) + 50));
    // A state 0 after the boot-up is another boot-up message (INITIALISATION), not a
    // report of PRE-OPERATIONAL: counted for the finding.
    let mut initialising = 0usize;
    let got = ctx.wait_for(within, |f| {
        let ours = f.id() == ec && !f.is_remote() && f.len() == 1;
        if ours && f.data_bytes()[0] == 0 {
            initialising += 1;
        }
        ours && f.data_bytes()[0] != 0
    })?;
    match got {
        Some((t, f)) if f.data_bytes()[0] & 0x7F == 0x7F => Ok(format!(
            "the first state report after the boot-up ({} ms later) is 127 (PRE-OPERATIONAL)",
            t.saturating_duration_since(booted).as_millis()
        )),
        Some((_, f)) => Err(fail(format!(
            "the first state report after the boot-up is {}, not 127 (PRE-OPERATIONAL)",
            f.data_bytes()[0] & 0x7F
        ))),
        None if initialising > 0 => Err(fail(format!(
            "within {} ms of the boot-up the device reports only state 0 (INITIALISATION), {initialising} times, never 127 (PRE-OPERATIONAL)",
            within.as_millis()
        ))),
        None => Err(fail_kind(
            FailureKind::Silence,
            format!(
                "no heartbeat or guarding answer within {} ms of the boot-up",
                within.as_millis()
            ),
        )),
    }
}

/// §7.2.8.3.1: the node-ID of an NMT command selects the node it is for; a command for
/// another node-ID (one nobody on the bus uses) is not for the device.
fn other_node(ctx: &mut Ctx<'_>) -> Outcome {
    let other = ctx.free_node();
    let orig = state_reporting(ctx)?;
    let heartbeat = orig.is_some();
    let reports = heartbeat || ctx.eds.objects.contains_key(&0x100C);
    let nmt = cantwin_can::Id::standard(0).map_err(|e| fail(e.to_string()))?;
    ctx.drain()?;
    ctx.send(Frame::data_array(nmt, [NmtCs::Stop as u8, other]))?;
    ctx.idle(Duration::from_millis(20))?;
    let state = if reports {
        reported_state(ctx, heartbeat)?
    } else {
        None
    };
    // A device that took the command is STOPPED and answers no SDO (§7.3.2.2.5).
    let (index, sub, _) = super::served_entry(ctx);
    let served = ctx.upload(index, sub)?;
    if served.is_err() {
        ctx.nmt(NmtCs::EnterPreOperational)?;
        ctx.idle(Duration::from_millis(20))?;
    }
    if let Some(o) = orig {
        ctx.write(0x1017, 0, &o, "the heartbeat producer time")?;
    }
    if let Err(a) = served {
        return Err(fail_sdo(
            format!("after an NMT stop for node {other}, reading 0x{index:04X} sub {sub}"),
            a,
        ));
    }
    match state {
        Some(0x7F) => Ok(format!(
            "after an NMT stop for node {other} (a node-ID not seen on the bus): still PRE-OPERATIONAL (127), SDO served"
        )),
        Some(s) => Err(fail(format!(
            "after an NMT stop for node {other} the device reports state {s}, not 127 (PRE-OPERATIONAL)"
        ))),
        None if reports => Err(fail_kind(
            FailureKind::Silence,
            format!("no state report after an NMT stop for node {other}"),
        )),
        None => Ok(format!(
            "after an NMT stop for node {other} (a node-ID not seen on the bus): SDO served"
        )),
    }
}

fn broadcast(ctx: &mut Ctx<'_>) -> Outcome {
    let nmt = cantwin_can::Id::standard(0).map_err(|e| fail(e.to_string()))?;
    ctx.drain()?;
    ctx.send(Frame::data_array(nmt, [NmtCs::ResetCommunication as u8, 0]))?;
    let ec = ctx.ec_id();
    let within = ctx.options.boot_timeout;
    match ctx.wait_for(within, |f| f.id() == ec && f.data_bytes() == [0])? {
        Some(_) => Ok("boot-up after a broadcast reset communication".into()),
        None => Err(fail_kind(
            FailureKind::Silence,
            "no boot-up after reset communication to node-ID 0",
        )),
    }
}

/// Has the device report its state: by heartbeat (0x1017 = 50 ms) or by node guarding.
/// Returns the original heartbeat time to restore.
pub(crate) fn state_reporting(ctx: &mut Ctx<'_>) -> Result<Option<Vec<u8>>, Finding> {
    if eds_entry(ctx, 0x1017, 0).is_some_and(|e| access(e).writable())
        && let Ok(orig) = ctx.upload(0x1017, 0)?
    {
        ctx.write(
            0x1017,
            0,
            &50u16.to_le_bytes(),
            "the heartbeat producer time",
        )?;
        return Ok(Some(orig));
    }
    Ok(None)
}

/// The state the device reports next: its next heartbeat, or its answer to a guarding
/// request.
pub(crate) fn reported_state(ctx: &mut Ctx<'_>, heartbeat: bool) -> Result<Option<u8>, Finding> {
    let ec = ctx.ec_id();
    if !heartbeat {
        ctx.send(Frame::remote(ec, 1).map_err(|e| fail(e.to_string()))?)?;
    }
    let within = if heartbeat {
        Duration::from_millis(200)
    } else {
        ctx.options.sdo_timeout
    };
    // A heartbeat already queued before the command may still report the old state:
    // take the second one.
    if heartbeat {
        ctx.wait_for(within, |f| f.id() == ec && !f.is_remote())?;
    }
    Ok(ctx
        .wait_for(within, |f| f.id() == ec && !f.is_remote() && f.len() == 1)?
        .map(|(_, f)| f.data_bytes()[0] & 0x7F))
}

fn states(ctx: &mut Ctx<'_>) -> Outcome {
    ctx.fresh()?;
    let orig = state_reporting(ctx)?;
    let heartbeat = orig.is_some();
    if !heartbeat && !ctx.eds.objects.contains_key(&0x100C) {
        return Err(Finding::NotApplicable(
            "neither heartbeat nor node guarding to report the state".into(),
        ));
    }
    let mut seen = Vec::new();
    for (cs, want, name) in [
        (NmtCs::Start, 0x05u8, "OPERATIONAL"),
        (NmtCs::Stop, 0x04, "STOPPED"),
        (NmtCs::Start, 0x05, "OPERATIONAL"),
        (NmtCs::EnterPreOperational, 0x7F, "PRE-OPERATIONAL"),
        (NmtCs::Stop, 0x04, "STOPPED"),
        (NmtCs::EnterPreOperational, 0x7F, "PRE-OPERATIONAL"),
    ] {
        ctx.nmt(cs)?;
        match reported_state(ctx, heartbeat)? {
            Some(s) if s == want => seen.push(name),
            Some(s) => {
                return Err(fail(format!(
                    "after {cs:?} the device reports state {s}, expected {want} ({name})"
                )));
            }
            None => {
                return Err(fail_kind(
                    FailureKind::Silence,
                    format!("no state report after {cs:?}"),
                ));
            }
        }
    }
    if let Some(o) = orig {
        ctx.write(0x1017, 0, &o, "the heartbeat producer time")?;
    }
    Ok(seen.join(" → "))
}

fn sdo_stopped(ctx: &mut Ctx<'_>) -> Outcome {
    ctx.nmt(NmtCs::Stop)?;
    ctx.idle(Duration::from_millis(20))?;
    let answered = ctx.sdo_raw([0x40, 0x00, 0x10, 0, 0, 0, 0, 0])?;
    ctx.nmt(NmtCs::EnterPreOperational)?;
    ctx.idle(Duration::from_millis(20))?;
    if let Some(b) = answered {
        return Err(fail(format!(
            "the device answered an SDO request in STOPPED: {b:02X?}"
        )));
    }
    super::recovered(ctx, "STOPPED")?;
    Ok("silent in STOPPED, served in PRE-OPERATIONAL".into())
}

/// The first TPDO of the file with a mapping: (communication index, COB-ID).
pub(crate) fn first_tpdo(ctx: &mut Ctx<'_>) -> Result<Option<(u16, u32)>, Finding> {
    for k in 0..512u16 {
        let comm = 0x1800 + k;
        if !ctx.eds.objects.contains_key(&comm)
            || !ctx.eds.objects.contains_key(&(0x1A00 + k))
            || !super::runnable(ctx, comm)
        {
            continue;
        }
        let cob = ctx.read_u32(comm, 1, "the TPDO COB-ID")?;
        let n = ctx.read_u32(0x1A00 + k, 0, "the number of mapped objects")?;
        if cob & 0x8000_0000 == 0 && n > 0 {
            return Ok(Some((comm, cob)));
        }
    }
    Ok(None)
}

fn count_pdo(ctx: &mut Ctx<'_>, cob: u32, during: Duration) -> Result<usize, Finding> {
    let id = cob & 0x7FF;
    Ok(ctx
        .collect(during, |f| {
            f.id().as_raw() == id && !f.is_remote() && !f.is_extended()
        })?
        .len())
}

/// How the case makes the TPDO due: its event timer, or SYNCs at transmission type 1.
enum Stimulus {
    EventTimer(Vec<u8>),
    Sync(cantwin_can::Id),
}

/// TPDO frames during `during`, sending a SYNC every 50 ms when `stimulus` says so.
fn pdos_during(
    ctx: &mut Ctx<'_>,
    cob: u32,
    stimulus: &Stimulus,
    during: Duration,
) -> Result<usize, Finding> {
    match stimulus {
        Stimulus::EventTimer(_) => count_pdo(ctx, cob, during),
        Stimulus::Sync(id) => {
            let mut n = 0;
            for _ in 0..during.as_millis() / 50 {
                ctx.send(Frame::data(*id, &[]).map_err(|e| fail(e.to_string()))?)?;
                n += count_pdo(ctx, cob, Duration::from_millis(50))?;
            }
            Ok(n)
        }
    }
}

fn pdo_operational_only(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((comm, cob)) = first_tpdo(ctx)? else {
        return Err(Finding::NotApplicable(format!(
            "no valid TPDO with a mapping{}",
            super::left_out_brief(ctx)
        )));
    };
    let tt = ctx
        .upload(comm, 2)?
        .map_err(|a| fail_sdo(format!("reading 0x{comm:04X} sub 2"), a))?;
    let stimulus = if eds_entry(ctx, comm, 5).is_some_and(|e| access(e).writable()) {
        let et = ctx
            .upload(comm, 5)?
            .map_err(|a| fail_sdo(format!("reading 0x{comm:04X} sub 5"), a))?;
        ctx.write(comm, 2, &[0xFF], "the transmission type")?;
        ctx.write(comm, 5, &50u16.to_le_bytes(), "the event timer")?;
        Stimulus::EventTimer(et)
    } else if ctx.eds.objects.contains_key(&0x1005) {
        let cob_sync = ctx.read_u32(0x1005, 0, "the COB-ID SYNC")? & 0x7FF;
        ctx.write(comm, 2, &[1], "the transmission type")?;
        Stimulus::Sync(
            cantwin_can::Id::standard(u16::try_from(cob_sync).unwrap_or(0x80))
                .map_err(|e| fail(e.to_string()))?,
        )
    } else {
        return Err(Finding::NotApplicable(format!(
            "0x{comm:04X} has no event timer and the device no SYNC to make it due"
        )));
    };
    let pre = pdos_during(ctx, cob, &stimulus, Duration::from_millis(300))?;
    ctx.nmt(NmtCs::Start)?;
    let op = pdos_during(ctx, cob, &stimulus, Duration::from_millis(300))?;
    ctx.nmt(NmtCs::Stop)?;
    ctx.idle(Duration::from_millis(10))?;
    let stopped = pdos_during(ctx, cob, &stimulus, Duration::from_millis(300))?;
    ctx.nmt(NmtCs::EnterPreOperational)?;
    ctx.idle(Duration::from_millis(10))?;
    if let Stimulus::EventTimer(et) = &stimulus {
        ctx.write(comm, 5, et, "the event timer")?;
    }
    ctx.write(comm, 2, &tt, "the transmission type")?;
    let how = match stimulus {
        Stimulus::EventTimer(_) => "event timer 50 ms",
        Stimulus::Sync(_) => "type 1, SYNC every 50 ms",
    };
    if pre != 0 || stopped != 0 || op == 0 {
        return Err(fail(format!(
            "TPDO 0x{:03X} ({how}) in 300 ms: {pre} in PRE-OPERATIONAL, {op} in OPERATIONAL, {stopped} in STOPPED",
            cob & 0x7FF
        )));
    }
    Ok(format!(
        "TPDO 0x{:03X} ({how}): {op} frames in 300 ms of OPERATIONAL, none otherwise",
        cob & 0x7FF
    ))
}

/// The first valid RPDO whose mapped objects all read back over SDO at their mapped
/// length, byte-aligned: its COB-ID, the frame with its current values and the first
/// mapped object `(index, sub, value now)`.
type RpdoProbe = (u32, Vec<u8>, (u16, u8, Vec<u8>));

fn rpdo_probe(ctx: &mut Ctx<'_>) -> Result<Option<RpdoProbe>, Finding> {
    'pdo: for k in 0..512u16 {
        let (comm, map) = (0x1400 + k, 0x1600 + k);
        if !ctx.eds.objects.contains_key(&comm)
            || !ctx.eds.objects.contains_key(&map)
            || !super::runnable(ctx, comm)
        {
            continue;
        }
        let cob = ctx.read_u32(comm, 1, "an RPDO COB-ID")?;
        let n = ctx.read_u32(map, 0, "the number of mapped objects")?;
        if cob & 0x8000_0000 != 0 || cob & 0x2000_0000 != 0 || n == 0 || n > 64 {
            continue;
        }
        let mut data = Vec::new();
        let mut first = None;
        for s in 1..=u8::try_from(n).unwrap_or(0) {
            let e = ctx.read_u32(map, s, "a mapping entry")?;
            let (index, sub, bits) = (
                u16::try_from(e >> 16).unwrap_or(0),
                u8::try_from((e >> 8) & 0xFF).unwrap_or(0),
                e & 0xFF,
            );
            let len = usize::try_from(bits / 8).unwrap_or(0);
            if bits == 0 || bits % 8 != 0 {
                continue 'pdo;
            }
            // Dummy entries (§7.4.7.1) take any bytes.
            if index < 0x20 {
                data.extend(std::iter::repeat_n(0, len));
                continue;
            }
            if !eds_entry(ctx, index, sub).is_some_and(|e| access(e).readable()) {
                continue 'pdo;
            }
            match ctx.upload(index, sub)? {
                Ok(d) if d.len() == len => {
                    data.extend_from_slice(&d);
                    first.get_or_insert((index, sub, d));
                }
                _ => continue 'pdo,
            }
        }
        if let Some(first) = first
            && (1..=8).contains(&data.len())
        {
            return Ok(Some((cob & 0x7FF, data, first)));
        }
    }
    Ok(None)
}

/// What `state` (entered with `cs`) must not do by §7.3.2.2.5: process an RPDO (its
/// first mapped object is sent changed and must read back unchanged), send a TPDO on
/// SYNC (the first TPDO at type 1, five SYNCs) and, in STOPPED, send an EMCY (an RPDO
/// one byte short, which OPERATIONAL answers with EMCY 0x8210, §7.2.2.2).
fn services_in(ctx: &mut Ctx<'_>, cs: NmtCs, name: &str) -> Outcome {
    let stopped = cs == NmtCs::Stop;
    let rpdo = rpdo_probe(ctx)?;
    let tpdo = if ctx.profile.features.sync == Some(false) {
        None
    } else {
        first_tpdo(ctx)?
    };
    if rpdo.is_none() && tpdo.is_none() {
        return Err(Finding::NotApplicable(format!(
            "no valid RPDO whose mapped objects read back, and no SYNC-driven TPDO{}",
            super::left_out_brief(ctx)
        )));
    }
    let emcy = match ctx.upload(0x1014, 0)? {
        Ok(d) if super::u32_of(&d) & 0x8000_0000 == 0 => Some(super::u32_of(&d) & 0x7FF),
        _ => None,
    };
    let mut tt = None;
    if let Some((comm, _)) = tpdo {
        let old = ctx
            .upload(comm, 2)?
            .map_err(|a| fail_sdo(format!("reading 0x{comm:04X} sub 2"), a))?;
        match ctx.download(comm, 2, &[1])? {
            Ok(()) => tt = Some(old),
            Err(a) if a.code == cantwin_canopen::AbortCode::INVALID_VALUE => {}
            Err(a) => return Err(fail_sdo(format!("writing type 1 to 0x{comm:04X} sub 2"), a)),
        }
    }
    let sync = if ctx.eds.objects.contains_key(&0x1005) {
        ctx.read_u32(0x1005, 0, "the COB-ID SYNC")? & 0x7FF
    } else {
        0x80
    };
    let sync = cantwin_can::Id::standard(u16::try_from(sync).unwrap_or(0x80))
        .map_err(|e| fail(e.to_string()))?;
    if stopped {
        ctx.nmt(NmtCs::Stop)?;
    } else {
        ctx.nmt(NmtCs::EnterPreOperational)?;
    }
    ctx.idle(Duration::from_millis(20))?;
    let mut problems = Vec::new();
    let mut checked = Vec::new();
    if let Some((cob, data, _)) = &rpdo {
        let mut changed = data.clone();
        changed.iter_mut().for_each(|b| *b = !*b);
        let id = cantwin_can::Id::standard(u16::try_from(*cob).unwrap_or(0))
            .map_err(|e| fail(e.to_string()))?;
        ctx.send(Frame::data(id, &changed).map_err(|e| fail(e.to_string()))?)?;
        ctx.idle(Duration::from_millis(20))?;
        if stopped && let Some(e) = emcy {
            ctx.send(Frame::data(id, &data[..data.len() - 1]).map_err(|e| fail(e.to_string()))?)?;
            let got = ctx.collect(Duration::from_millis(100), |f| {
                f.id().as_raw() == e && !f.is_remote()
            })?;
            if let Some((_, f)) = got.first() {
                problems.push(format!("EMCY {} after a short RPDO", f));
            }
            checked.push("no EMCY");
        }
    }
    if let (Some((_, cob)), Some(_)) = (tpdo, &tt) {
        let mut n = 0;
        for _ in 0..5 {
            ctx.send(Frame::data(sync, &[]).map_err(|e| fail(e.to_string()))?)?;
            n += count_pdo(ctx, cob, Duration::from_millis(20))?;
        }
        if n != 0 {
            problems.push(format!(
                "{n} TPDO 0x{:03X} (type 1) after 5 SYNCs",
                cob & 0x7FF
            ));
        }
        checked.push("no TPDO on SYNC");
    }
    if stopped {
        ctx.nmt(NmtCs::EnterPreOperational)?;
        ctx.idle(Duration::from_millis(20))?;
    }
    if let Some((cob, _, (index, sub, value))) = &rpdo {
        let now = ctx
            .upload(*index, *sub)?
            .map_err(|a| fail_sdo(format!("reading 0x{index:04X} sub {sub}"), a))?;
        if &now != value {
            let _ = ctx.download(*index, *sub, value)?;
            problems.push(format!(
                "RPDO 0x{cob:03X} processed: 0x{index:04X} sub {sub} went from {value:02X?} to {now:02X?}"
            ));
        }
        checked.push("RPDO not processed");
    }
    if let (Some((comm, _)), Some(old)) = (tpdo, &tt) {
        ctx.write(comm, 2, old, "the transmission type")?;
    }
    if !problems.is_empty() {
        return Err(fail(format!("in {name}: {}", problems.join("; "))));
    }
    if checked.is_empty() {
        return Err(Finding::NotApplicable(
            "the TPDO takes no type 1 and no RPDO reads back".into(),
        ));
    }
    Ok(format!("in {name}: {}", checked.join(", ")))
}

fn services_stopped(ctx: &mut Ctx<'_>) -> Outcome {
    services_in(ctx, NmtCs::Stop, "STOPPED")
}

fn services_pre_operational(ctx: &mut Ctx<'_>) -> Outcome {
    services_in(ctx, NmtCs::EnterPreOperational, "PRE-OPERATIONAL")
}

fn restores(ctx: &mut Ctx<'_>, cs: NmtCs, what: &str) -> Outcome {
    if !eds_entry(ctx, 0x1017, 0).is_some_and(|e| access(e).writable()) {
        return Err(Finding::NotApplicable(
            "no writable heartbeat producer time to change".into(),
        ));
    }
    let before = ctx.read_u32(0x1017, 0, "the heartbeat producer time")?;
    let changed = if before == 777 { 778u16 } else { 777 };
    ctx.write(
        0x1017,
        0,
        &changed.to_le_bytes(),
        "the heartbeat producer time",
    )?;
    let t0: Instant = ctx.now();
    if ctx.reset(cs)?.is_none() {
        return Err(fail_kind(
            FailureKind::Silence,
            format!("no boot-up after {what}"),
        ));
    }
    let after = ctx.read_u32(0x1017, 0, "the heartbeat producer time")?;
    if after != before {
        ctx.write(
            0x1017,
            0,
            &(before as u16).to_le_bytes(),
            "the heartbeat producer time",
        )?;
        return Err(fail(format!(
            "0x1017 was {before}, set to {changed}; after {what} it reads {after}, not its power-on value"
        )));
    }
    Ok(format!(
        "0x1017 back to {before} ms {} ms after {what}",
        ctx.now().saturating_duration_since(t0).as_millis()
    ))
}

fn reset_comm_restores(ctx: &mut Ctx<'_>) -> Outcome {
    restores(ctx, NmtCs::ResetCommunication, "reset communication")
}

fn reset_node_restores(ctx: &mut Ctx<'_>) -> Outcome {
    restores(ctx, NmtCs::ResetNode, "reset node")
}
