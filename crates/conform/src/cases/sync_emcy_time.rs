//! Area 5: SYNC, EMCY and TIME (CiA 301 §7.2.5–7.2.7, §7.5.2.2–7.5.2.22).

use cantwin_can::{Duration, Frame, Id};
use cantwin_canopen::AbortCode;

use super::{Case, access, eds_entry, m, u32_of, within};
use crate::ctx::{Ctx, Finding, Outcome, fail, fail_abort, fail_kind, fail_sdo, not_supported};
use crate::profile::FailureKind;
use crate::report::Area::SyncEmcyTime as A;

pub(super) fn cases() -> Vec<Case> {
    vec![
        m(
            "sync.cob-id",
            A,
            "CiA 301 §7.5.2.5",
            "0x1005 holds an 11-bit COB-ID (0x80 by default) with bit 29 clear",
            sync_cob_id,
        ),
        m(
            "sync.producer",
            A,
            "CiA 301 §7.2.5, §7.5.2.5, §7.5.2.6",
            "with bit 30 of 0x1005 set and 0x1006 = 20 ms, SYNC every 20 ms",
            sync_producer,
        ),
        m(
            "sync.counter",
            A,
            "CiA 301 §7.2.5.2, §7.5.2.22",
            "with 0x1019 = 3 the SYNC carries a counter running 1, 2, 3, 1 …",
            sync_counter,
        ),
        m(
            "emcy.cob-id",
            A,
            "CiA 301 §7.5.2.17, §7.5.2.2",
            "0x1014 is valid with an 11-bit COB-ID; 0x1001 reads one byte",
            emcy_cob_id,
        ),
        m(
            "emcy.cob-id-change-valid",
            A,
            "CiA 301 §7.5.2.17, §7.3.5",
            "a new CAN-ID in 0x1014 while the EMCY is valid (bit 31 = 0) is refused",
            emcy_cob_id_change_valid,
        ),
        m(
            "emcy.history",
            A,
            "CiA 301 §7.5.2.4",
            "0x1003 sub 0 = 0 clears the history; any other value is refused with 0x06090030",
            emcy_history,
        ),
        m(
            "emcy.history-records",
            A,
            "CiA 301 §7.5.2.4, §7.2.7.1",
            "after an EMCY, 0x1003 sub 0 counts it and sub 1 holds its code; 0 written to sub 0 clears the history",
            emcy_history_records,
        ),
        m(
            "emcy.error-register",
            A,
            "CiA 301 §7.2.7.1, §7.5.2.2",
            "while an error stands 0x1001 bit 0 is set and the EMCY's byte 2 equals 0x1001; the error reset EMCY (0x0000) follows its end and 0x1001 bit 0 clears",
            emcy_error_register,
        ),
        m(
            "emcy.inhibit",
            A,
            "CiA 301 §7.2.7.1, §7.5.2.18",
            "with 0x1015 = 300 ms, two EMCYs of the device are at least 300 ms apart",
            emcy_inhibit,
        ),
        m(
            "emcy.after-boot-up",
            A,
            "CiA 301 §7.2.7.1, §7.2.8.3.2.4",
            "no EMCY precedes the boot-up message after a reset",
            emcy_after_boot,
        ),
        m(
            "time.cob-id",
            A,
            "CiA 301 §7.2.6, §7.5.2.15",
            "0x1012 holds an 11-bit COB-ID; a TIME message leaves the device serving",
            time_cob_id,
        ),
        m(
            "time.producer",
            A,
            "CiA 301 §7.2.6, §7.5.2.15 (bit 30)",
            "where the device produces TIME, 0x1012 bit 30 is set and read back; TIME frames carry 6 bytes, none in STOPPED",
            time_producer,
        ),
        m(
            "time.consumer",
            A,
            "CiA 301 §7.2.6, §7.5.2.15 (bit 31)",
            "where the device consumes TIME, 0x1012 bit 31 is set and read back, and a TIME message leaves it serving",
            time_consumer,
        ),
    ]
}

fn sync_cob_id(ctx: &mut Ctx<'_>) -> Outcome {
    if ctx.profile.features.sync == Some(false) {
        return Err(not_supported("no SYNC (0x1005 not in the file)"));
    }
    let v = ctx.read_u32(0x1005, 0, "the COB-ID SYNC")?;
    if v & 0x2000_0000 != 0 || v & 0x1FFF_F800 != 0 {
        return Err(fail(format!(
            "0x1005 = 0x{v:08X}: not an 11-bit identifier"
        )));
    }
    Ok(format!(
        "0x1005 = 0x{v:08X}{}",
        if v & 0x4000_0000 != 0 {
            " (producer)"
        } else {
            ""
        }
    ))
}

/// Starts the SYNC producer with `period_us`; the original 0x1005 and 0x1006.
fn producer_on(ctx: &mut Ctx<'_>, period_us: u32) -> Result<(u32, Vec<u8>), Finding> {
    if ctx.profile.features.sync == Some(false) {
        return Err(not_supported("no SYNC (0x1005 not in the file)"));
    }
    if !eds_entry(ctx, 0x1006, 0).is_some_and(|e| access(e).writable()) {
        return Err(not_supported(
            "no writable communication cycle period (0x1006): SYNC consumer only",
        ));
    }
    let cob = ctx.read_u32(0x1005, 0, "the COB-ID SYNC")?;
    let period = ctx
        .upload(0x1006, 0)?
        .map_err(|a| fail_sdo("reading 0x1006", a))?;
    ctx.write(
        0x1006,
        0,
        &period_us.to_le_bytes(),
        "the communication cycle period",
    )?;
    match ctx.download(0x1005, 0, &(cob | 0x4000_0000).to_le_bytes())? {
        Ok(()) => Ok((cob, period)),
        Err(a) => {
            ctx.write(0x1006, 0, &period, "the communication cycle period")?;
            Err(Finding::NotSupported {
                why: format!("0x1005 bit 30 refused ({a}): SYNC consumer only"),
                abort: Some(a.code),
            })
        }
    }
}

fn producer_off(ctx: &mut Ctx<'_>, cob: u32, period: &[u8]) -> Result<(), Finding> {
    ctx.write(
        0x1005,
        0,
        &(cob & !0x4000_0000).to_le_bytes(),
        "the COB-ID SYNC",
    )?;
    ctx.write(0x1006, 0, period, "the communication cycle period")
}

fn sync_producer(ctx: &mut Ctx<'_>) -> Outcome {
    super::no_foreign_sync(ctx)?;
    let (cob, period) = producer_on(ctx, 20_000)?;
    let id = cob & 0x7FF;
    let frames = ctx.collect(Duration::from_millis(205), |f| {
        f.id().as_raw() == id && !f.is_remote()
    })?;
    producer_off(ctx, cob, &period)?;
    if !(9..=11).contains(&frames.len()) {
        return Err(fail(format!(
            "{} SYNC frames in 205 ms at 20 ms",
            frames.len()
        )));
    }
    for w in frames.windows(2) {
        let d = w[1].0.saturating_duration_since(w[0].0);
        if !within(ctx, d, Duration::from_millis(20)) {
            return Err(fail_kind(
                FailureKind::Timing,
                format!("a SYNC interval of {} µs, period 20 ms", d.as_micros()),
            ));
        }
    }
    Ok(format!(
        "{} SYNC frames, intervals within tolerance",
        frames.len()
    ))
}

fn sync_counter(ctx: &mut Ctx<'_>) -> Outcome {
    super::no_foreign_sync(ctx)?;
    if !eds_entry(ctx, 0x1019, 0).is_some_and(|e| access(e).writable()) {
        return Err(not_supported(
            "no synchronous counter overflow value (0x1019)",
        ));
    }
    // 0x1019 changes only while the producer is off (0x1006 = 0, §7.5.2.22).
    let overflow = ctx
        .upload(0x1019, 0)?
        .map_err(|a| fail_sdo("reading 0x1019", a))?;
    let period = ctx
        .upload(0x1006, 0)?
        .map_err(|a| fail_sdo("reading 0x1006", a))?;
    ctx.write(
        0x1006,
        0,
        &0u32.to_le_bytes(),
        "the communication cycle period",
    )?;
    ctx.write(0x1019, 0, &[3], "the synchronous counter overflow value")?;
    ctx.write(0x1006, 0, &period, "the communication cycle period")?;
    let (cob, period) = producer_on(ctx, 20_000)?;
    let id = cob & 0x7FF;
    let frames = ctx.collect(Duration::from_millis(150), |f| {
        f.id().as_raw() == id && !f.is_remote()
    })?;
    producer_off(ctx, cob, &period)?;
    let p = ctx.upload(0x1006, 0)?.unwrap_or_default();
    ctx.write(
        0x1006,
        0,
        &0u32.to_le_bytes(),
        "the communication cycle period",
    )?;
    ctx.write(
        0x1019,
        0,
        &overflow,
        "the synchronous counter overflow value",
    )?;
    ctx.write(0x1006, 0, &p, "the communication cycle period")?;
    let counters: Vec<u8> = frames
        .iter()
        .map(|(_, f)| f.data_bytes().first().copied().unwrap_or(0))
        .collect();
    if frames.iter().any(|(_, f)| f.len() != 1) || counters.len() < 4 {
        return Err(fail(format!(
            "SYNC frames {:?}: expected one counter byte each",
            frames
                .iter()
                .map(|(_, f)| f.to_string())
                .collect::<Vec<_>>()
        )));
    }
    let ok = counters
        .windows(2)
        .all(|w| w[1] == if w[0] >= 3 { 1 } else { w[0] + 1 })
        && counters.iter().all(|c| (1..=3).contains(c));
    if !ok {
        return Err(fail(format!("counters {counters:?} with overflow value 3")));
    }
    Ok(format!("counters {counters:?}"))
}

fn emcy_cob_id(ctx: &mut Ctx<'_>) -> Outcome {
    // A file without 0x1001 fails `eds.mandatory-objects` (CiA 301 §7.4.1); a device made
    // from it has no error register to read here.
    let reg = if ctx.eds.entry(0x1001, 0).is_some() {
        let reg = ctx
            .upload(0x1001, 0)?
            .map_err(|a| fail_sdo("reading 0x1001", a))?;
        if reg.len() != 1 {
            return Err(fail(format!("0x1001 reads {} bytes, not 1", reg.len())));
        }
        Some(reg[0])
    } else {
        None
    };
    if ctx.profile.features.emcy == Some(false) {
        return Err(not_supported("no EMCY producer (0x1014 not in the file)"));
    }
    let v = ctx.read_u32(0x1014, 0, "the COB-ID EMCY")?;
    if v & 0x2000_0000 != 0 || v & 0x1FFF_F800 != 0 {
        return Err(fail(format!(
            "0x1014 = 0x{v:08X}: not an 11-bit identifier"
        )));
    }
    Ok(match reg {
        Some(r) => format!("0x1014 = 0x{v:08X}, error register 0x{r:02X}"),
        None => format!("0x1014 = 0x{v:08X} (the file has no 0x1001)"),
    })
}

/// An 11-bit EMCY CAN-ID other than `id` that no table of CiA 301 §7.3.5 restricts (the
/// EMCY range 0x081–0x0FF): a refusal of it is a refusal of the change, not of the value.
fn other_emcy_id(id: u32) -> u32 {
    if id == 0xFE { 0xFD } else { 0xFE }
}

fn emcy_cob_id_change_valid(ctx: &mut Ctx<'_>) -> Outcome {
    if ctx.profile.features.emcy == Some(false) {
        return Err(not_supported("no EMCY producer (0x1014 not in the file)"));
    }
    // §7.5.2.17 lets 0x1014 be read-only (a fixed identifier): nothing to change then.
    if !eds_entry(ctx, 0x1014, 0).is_some_and(|e| access(e).writable()) {
        return Err(Finding::NotApplicable(
            "0x1014 is not writable in the file".into(),
        ));
    }
    let v = ctx.read_u32(0x1014, 0, "the COB-ID EMCY")?;
    if v & 0x8000_0000 != 0 {
        return Err(Finding::NotApplicable(format!(
            "0x1014 = 0x{v:08X}: the EMCY is not valid"
        )));
    }
    let other = (v & !0x1FFF_FFFF) | other_emcy_id(v & 0x7FF);
    match ctx.download(0x1014, 0, &other.to_le_bytes())? {
        Err(a) if a.by_server => {
            let now = ctx.read_u32(0x1014, 0, "the COB-ID EMCY")?;
            if now != v {
                return Err(fail(format!(
                    "0x1014 reads 0x{now:08X} after the change to 0x{other:08X} was refused ({a}), expected 0x{v:08X}"
                )));
            }
            Ok(format!("0x1014 = 0x{other:08X} refused: {a}"))
        }
        Err(a) => Err(fail_sdo(format!("writing 0x{other:08X} to 0x1014"), a)),
        Ok(()) => {
            // Put the original identifier back the way §7.3.5 allows: not valid first.
            ctx.write(
                0x1014,
                0,
                &(other | 0x8000_0000).to_le_bytes(),
                "the COB-ID EMCY",
            )?;
            ctx.write(
                0x1014,
                0,
                &(v | 0x8000_0000).to_le_bytes(),
                "the COB-ID EMCY",
            )?;
            ctx.write(0x1014, 0, &v.to_le_bytes(), "the COB-ID EMCY")?;
            Err(fail(format!(
                "0x1014 changed from 0x{v:08X} to 0x{other:08X} while the EMCY was valid"
            )))
        }
    }
}

fn emcy_history(ctx: &mut Ctx<'_>) -> Outcome {
    if ctx.profile.features.error_history == Some(false) {
        return Err(not_supported(
            "no pre-defined error field (0x1003 not in the file)",
        ));
    }
    let n = ctx.read_u32(0x1003, 0, "the number of errors")?;
    ctx.write(0x1003, 0, &[0], "0 to 0x1003 sub 0")?;
    let after = ctx.read_u32(0x1003, 0, "the number of errors")?;
    if after != 0 {
        return Err(fail(format!("0x1003 sub 0 reads {after} after writing 0")));
    }
    match ctx.download(0x1003, 0, &[1])? {
        Err(a) if a.code == AbortCode::INVALID_VALUE => {
            Ok(format!("{n} entries cleared; 1 refused with 0x06090030"))
        }
        Err(a) => Err(fail_abort(
            "writing 1 to 0x1003 sub 0: expected 0x06090030",
            a.code,
        )),
        Ok(()) => Err(fail("writing 1 to 0x1003 sub 0 was accepted")),
    }
}

/// The error the case raises the way CiA 301 defines one for every device with a heartbeat
/// consumer: a consumed heartbeat that stops (EMCY 0x8130, §7.2.8.3.2.2).
struct ConsumerError {
    /// 0x1016 sub 1 as it was.
    entry: Vec<u8>,
    /// The heartbeat COB-ID of the node the entry monitors.
    hb: Id,
}

/// An EMCY on COB-ID `emcy` (8 bytes, §7.2.7.3.1).
fn is_emcy_of(f: &Frame, emcy: u32) -> bool {
    f.id().as_raw() == emcy && f.len() == 8 && !f.is_remote()
}

fn payload(f: &Frame) -> [u8; 8] {
    let mut b = [0u8; 8];
    let d = f.data_bytes();
    b[..d.len().min(8)].copy_from_slice(&d[..d.len().min(8)]);
    b
}

/// Makes the device consume the heartbeat of a node-ID nobody on the bus uses with a time of 100 ms
/// (0x1016 sub 1, CiA 301 §7.5.2.19) and sends one heartbeat of that node (operational), so
/// that the consumer runs and times out 100 ms later: the heartbeat's identifier.
fn monitor_the_next_node(ctx: &mut Ctx<'_>) -> Result<Id, Finding> {
    // A live node's heartbeat would keep the consumer from timing out.
    let other = ctx.free_node();
    let hb = Id::standard(0x700 + u16::from(other)).map_err(|e| fail(e.to_string()))?;
    ctx.write(
        0x1016,
        1,
        &((u32::from(other) << 16) | 100).to_le_bytes(),
        "a heartbeat consumer entry",
    )?;
    ctx.send(Frame::data_array(hb, [0x05]))?;
    Ok(hb)
}

impl ConsumerError {
    /// As [`ConsumerError::raise`], with the whole payload of each EMCY.
    fn raise_frames(
        ctx: &mut Ctx<'_>,
        emcy: u32,
        within: Duration,
    ) -> Result<(ConsumerError, Vec<[u8; 8]>), Finding> {
        let entry = ctx
            .upload(0x1016, 1)?
            .map_err(|a| fail_sdo("reading 0x1016 sub 1", a))?;
        let hb = monitor_the_next_node(ctx)?;
        let frames = ctx
            .collect(within, |f| is_emcy_of(f, emcy))?
            .into_iter()
            .map(|(_, f)| payload(&f))
            .collect();
        Ok((ConsumerError { entry, hb }, frames))
    }

    /// As [`ConsumerError::end`], with the EMCYs the device sent meanwhile.
    fn end_frames(self, ctx: &mut Ctx<'_>, emcy: u32) -> Result<Vec<[u8; 8]>, Finding> {
        ctx.send(Frame::data_array(self.hb, [0x05]))?;
        let mut got = ctx.collect(Duration::from_millis(20), |f| is_emcy_of(f, emcy))?;
        ctx.write(0x1016, 1, &self.entry, "the heartbeat consumer entry")?;
        got.extend(ctx.collect(Duration::from_millis(20), |f| is_emcy_of(f, emcy))?);
        Ok(got.into_iter().map(|(_, f)| payload(&f)).collect())
    }

    /// Monitors the next node-ID for 100 ms and sends one heartbeat of it: the EMCYs the
    /// device sends in the next `within`.
    fn raise(
        ctx: &mut Ctx<'_>,
        emcy: u32,
        within: Duration,
    ) -> Result<(ConsumerError, Vec<u16>), Finding> {
        let entry = ctx
            .upload(0x1016, 1)?
            .map_err(|a| fail_sdo("reading 0x1016 sub 1", a))?;
        let hb = monitor_the_next_node(ctx)?;
        let is_emcy = |f: &Frame| f.id().as_raw() == emcy && f.len() == 8 && !f.is_remote();
        let codes = ctx
            .collect(within, is_emcy)?
            .into_iter()
            .map(|(_, f)| {
                let d = f.data_bytes();
                u16::from_le_bytes([d[0], d[1]])
            })
            .collect();
        Ok((ConsumerError { entry, hb }, codes))
    }

    /// Ends the error as the device's own logic does, by the heartbeat's return (an EMCY of
    /// the error reset follows), then puts the consumer entry back before it times out again:
    /// an error left standing would hide the next case's.
    fn end(self, ctx: &mut Ctx<'_>) -> Result<(), Finding> {
        ctx.send(Frame::data_array(self.hb, [0x05]))?;
        ctx.idle(Duration::from_millis(20))?;
        ctx.write(0x1016, 1, &self.entry, "the heartbeat consumer entry")?;
        ctx.idle(Duration::from_millis(20))
    }
}

/// The identifier of the EMCYs a heartbeat consumer timeout raises (0x1014, CiA 301
/// §7.5.2.17), where the device has a writable consumer entry (0x1016 sub 1) to raise one
/// with and its EMCY producer is on; not applicable otherwise.
fn emcy_raised_by_a_consumer(ctx: &mut Ctx<'_>) -> Result<u32, Finding> {
    if ctx.profile.features.heartbeat_consumer == Some(false)
        || !eds_entry(ctx, 0x1016, 1).is_some_and(|e| access(e).writable())
    {
        return Err(Finding::NotApplicable(
            "no writable heartbeat consumer entry to raise an error with".into(),
        ));
    }
    let emcy = ctx.read_u32(0x1014, 0, "the COB-ID EMCY")?;
    if emcy & 0x8000_0000 != 0 {
        return Err(Finding::NotApplicable("the EMCY producer is off".into()));
    }
    Ok(emcy & 0x7FF)
}

fn emcy_history_records(ctx: &mut Ctx<'_>) -> Outcome {
    if ctx.profile.features.error_history == Some(false) {
        return Err(not_supported(
            "no pre-defined error field (0x1003 not in the file)",
        ));
    }
    let emcy = emcy_raised_by_a_consumer(ctx)?;
    ctx.write(0x1003, 0, &[0], "0 to 0x1003 sub 0")?;
    let (error, codes) = ConsumerError::raise(ctx, emcy, Duration::from_millis(400))?;
    let newest = codes.iter().rev().find(|c| **c != 0).copied();
    // Read while the error stands: the history is what the device reports of it.
    let read = match newest {
        Some(_) => Some((
            ctx.read_u32(0x1003, 0, "the number of errors")?,
            ctx.read_u32(0x1003, 1, "the newest error")?,
        )),
        None => None,
    };
    error.end(ctx)?;
    let (Some(newest), Some((n, e))) = (newest, read) else {
        return Err(Finding::NotApplicable(
            "the heartbeat consumer timeout raised no EMCY".into(),
        ));
    };
    if n == 0 {
        return Err(fail(format!(
            "after EMCY 0x{newest:04X}, 0x1003 sub 0 reads 0"
        )));
    }
    if e & 0xFFFF != u32::from(newest) {
        return Err(fail(format!(
            "after EMCY 0x{newest:04X}, 0x1003 sub 1 (the newest error) reads 0x{e:08X}"
        )));
    }
    ctx.write(0x1003, 0, &[0], "0 to 0x1003 sub 0")?;
    let after = ctx.read_u32(0x1003, 0, "the number of errors")?;
    if after != 0 {
        return Err(fail(format!("0x1003 sub 0 reads {after} after writing 0")));
    }
    Ok(format!(
        "EMCY 0x{newest:04X}: 0x1003 sub 0 = {n}, sub 1 = 0x{e:08X}; cleared by 0"
    ))
}

/// Raises an error by a consumed heartbeat that stops (EMCY 0x8130) and ends it by the
/// heartbeat's return: the error register and the EMCYs of both.
fn emcy_error_register(ctx: &mut Ctx<'_>) -> Outcome {
    if ctx.profile.features.emcy == Some(false) {
        return Err(not_supported("no EMCY producer (0x1014 not in the file)"));
    }
    let emcy = emcy_raised_by_a_consumer(ctx)?;
    // An error that stands already (a drive's fault) keeps bit 0 set after this one ends:
    // then only the EMCYs and the register while it stands are checked.
    let before = ctx.read_u32(0x1001, 0, "the error register")?;
    let clean = before & 0x01 == 0;
    let (error, frames) = ConsumerError::raise_frames(ctx, emcy, Duration::from_millis(400))?;
    let raised = frames
        .iter()
        .rev()
        .find(|d| u16::from_le_bytes([d[0], d[1]]) != 0)
        .cloned();
    // Read while the error stands (§7.5.2.2: bit 0 is set at any error).
    let standing = match raised {
        Some(_) => Some(ctx.read_u32(0x1001, 0, "the error register")?),
        None => None,
    };
    let ended = error.end_frames(ctx, emcy)?;
    ctx.idle(Duration::from_millis(50))?;
    let after = ctx.read_u32(0x1001, 0, "the error register")?;
    let (Some(raised), Some(standing)) = (raised, standing) else {
        return Err(Finding::NotApplicable(
            "the heartbeat consumer timeout raised no EMCY".into(),
        ));
    };
    let code = u16::from_le_bytes([raised[0], raised[1]]);
    let mut wrong = Vec::new();
    if standing & 0x01 == 0 {
        wrong.push(format!(
            "while the error of EMCY 0x{code:04X} stands, 0x1001 = 0x{standing:02X} (bit 0, generic error, clear)"
        ));
    }
    if u32::from(raised[2]) != standing {
        wrong.push(format!(
            "EMCY 0x{code:04X} carries error register 0x{:02X} in byte 2, 0x1001 reads 0x{standing:02X}",
            raised[2]
        ));
    }
    let reset = ended
        .iter()
        .find(|d| u16::from_le_bytes([d[0], d[1]]) == 0)
        .cloned();
    match &reset {
        None => {
            wrong.push("no error reset EMCY (error code 0x0000) after the error ended".to_string())
        }
        Some(d) if clean && u32::from(d[2]) & 0x01 != 0 => wrong.push(format!(
            "the error reset EMCY carries error register 0x{:02X} (bit 0 set)",
            d[2]
        )),
        Some(_) => {}
    }
    if clean && after & 0x01 != 0 {
        wrong.push(format!(
            "after the error reset, 0x1001 = 0x{after:02X} (bit 0 still set)"
        ));
    }
    if wrong.is_empty() {
        let other = if clean {
            String::new()
        } else {
            format!(" (another error stood before: 0x1001 was 0x{before:02X})")
        };
        Ok(format!(
            "EMCY 0x{code:04X} with 0x1001 = 0x{standing:02X}, then the error reset EMCY and 0x1001 = 0x{after:02X}{other}"
        ))
    } else {
        Err(fail_kind(FailureKind::Value, super::listing(&wrong)))
    }
}

fn emcy_after_boot(ctx: &mut Ctx<'_>) -> Outcome {
    let emcy = ctx
        .upload(0x1014, 0)?
        .map(|d| u32_of(&d) & 0x7FF)
        .unwrap_or(ctx.emcy_id().as_raw());
    // Only what comes after the command answers it: a boot-up or EMCY the transport still
    // holds from before is read off first.
    ctx.drain()?;
    ctx.nmt(cantwin_canopen::wire::NmtCs::ResetCommunication)?;
    let ec = ctx.ec_id();
    let within = ctx.options.boot_timeout;
    // The boot-up message is the one with data 0x00 (CiA 301 §7.2.8.3.2.1); a heartbeat
    // on the same COB-ID carries the state (0x04 stopped, 0x05 operational, 0x7F
    // pre-operational) and is not it.
    let boot_up = |f: &Frame| f.id() == ec && !f.is_remote() && f.data_bytes() == [0];
    let first = ctx.wait_for(within, |f| {
        boot_up(f) || (f.id().as_raw() == emcy && !f.is_remote())
    })?;
    match first {
        Some((_, f)) if boot_up(&f) => Ok("the boot-up message comes first".into()),
        Some((_, f)) => Err(fail(format!("EMCY {f} before the boot-up message"))),
        None => Err(fail_kind(
            FailureKind::Silence,
            "no boot-up message after reset communication",
        )),
    }
}

fn time_cob_id(ctx: &mut Ctx<'_>) -> Outcome {
    if ctx.profile.features.time == Some(false) {
        return Err(not_supported("no TIME (0x1012 not in the file)"));
    }
    let v = ctx.read_u32(0x1012, 0, "the COB-ID TIME")?;
    if v & 0x2000_0000 != 0 || v & 0x1FFF_F800 != 0 {
        return Err(fail(format!(
            "0x1012 = 0x{v:08X}: not an 11-bit identifier"
        )));
    }
    if v & 0x8000_0000 != 0 {
        let id = Id::standard(u16::try_from(v & 0x7FF).unwrap_or(0x100))
            .map_err(|e| fail(e.to_string()))?;
        // TIME_OF_DAY: milliseconds after midnight (28 bits) and days since 1984.
        ctx.send(
            Frame::data(id, &[0x00, 0x5C, 0x26, 0x05, 0x10, 0x3A])
                .map_err(|e| fail(e.to_string()))?,
        )?;
        super::recovered(ctx, "a TIME message")?;
    }
    Ok(format!("0x1012 = 0x{v:08X}"))
}

/// Sets `bit` of 0x1012 (30: producer, 31: consumer, §7.5.2.15): the original value, or
/// the finding when the device does not offer it.
fn time_bit(ctx: &mut Ctx<'_>, bit: u32, what: &str) -> Result<u32, Finding> {
    if ctx.profile.features.time == Some(false) {
        return Err(not_supported("no TIME (0x1012 not in the file)"));
    }
    if !eds_entry(ctx, 0x1012, 0).is_some_and(|e| access(e).writable()) {
        return Err(not_supported(format!(
            "0x1012 is not writable in the file: no TIME {what} to switch on"
        )));
    }
    let v = ctx.read_u32(0x1012, 0, "the COB-ID TIME")?;
    if v & bit == 0 {
        match ctx.download(0x1012, 0, &(v | bit).to_le_bytes())? {
            Ok(()) => {}
            // §7.5.2.15: a device that cannot be TIME producer refuses bit 30.
            Err(a) if a.by_server => {
                return Err(Finding::NotSupported {
                    why: format!("0x1012 = 0x{:08X} refused ({a}): no TIME {what}", v | bit),
                    abort: Some(a.code),
                });
            }
            Err(a) => return Err(fail_sdo(format!("writing 0x{:08X} to 0x1012", v | bit), a)),
        }
    }
    let now = ctx.read_u32(0x1012, 0, "the COB-ID TIME")?;
    if now & bit == 0 {
        let _ = ctx.download(0x1012, 0, &v.to_le_bytes())?;
        return Err(fail(format!(
            "0x1012 = 0x{:08X} accepted, it reads 0x{now:08X}",
            v | bit
        )));
    }
    Ok(v)
}

fn time_producer(ctx: &mut Ctx<'_>) -> Outcome {
    let v = time_bit(ctx, 0x4000_0000, "producer")?;
    let id = v & 0x7FF;
    let is_time = |f: &Frame| f.id().as_raw() == id && !f.is_remote();
    // CiA 301 leaves the moment of a TIME message to the producer's application: what comes
    // is checked, none is required.
    let operating = ctx.collect(Duration::from_millis(500), is_time)?;
    ctx.nmt(cantwin_canopen::wire::NmtCs::Stop)?;
    let stopped = ctx.collect(Duration::from_millis(300), is_time)?;
    ctx.nmt(cantwin_canopen::wire::NmtCs::EnterPreOperational)?;
    ctx.idle(Duration::from_millis(10))?;
    ctx.write(0x1012, 0, &v.to_le_bytes(), "the COB-ID TIME")?;
    if let Some((_, f)) = operating.iter().find(|(_, f)| f.len() != 6) {
        return Err(fail(format!(
            "TIME {f}: {} bytes, a TIME_OF_DAY has 6",
            f.len()
        )));
    }
    if let Some((_, f)) = stopped.first() {
        return Err(fail(format!("TIME {f} in STOPPED")));
    }
    Ok(format!(
        "0x1012 bit 30 set and read back; {} TIME messages in 500 ms, none in STOPPED",
        operating.len()
    ))
}

fn time_consumer(ctx: &mut Ctx<'_>) -> Outcome {
    let v = time_bit(ctx, 0x8000_0000, "consumer")?;
    let id =
        Id::standard(u16::try_from(v & 0x7FF).unwrap_or(0x100)).map_err(|e| fail(e.to_string()))?;
    ctx.send(
        Frame::data(id, &[0x00, 0x5C, 0x26, 0x05, 0x10, 0x3A]).map_err(|e| fail(e.to_string()))?,
    )?;
    super::recovered(ctx, "a TIME message")?;
    ctx.write(0x1012, 0, &v.to_le_bytes(), "the COB-ID TIME")?;
    Ok("0x1012 bit 31 set and read back; a TIME message consumed".into())
}

fn emcy_inhibit(ctx: &mut Ctx<'_>) -> Outcome {
    if ctx.profile.features.emcy_inhibit == Some(false) {
        return Err(not_supported(
            "no inhibit time EMCY (0x1015 not in the file)",
        ));
    }
    if ctx.profile.features.heartbeat_consumer == Some(false) {
        return Err(Finding::NotApplicable(
            "no heartbeat consumer to raise and end an error with".into(),
        ));
    }
    let emcy = ctx.read_u32(0x1014, 0, "the COB-ID EMCY")?;
    if emcy & 0x8000_0000 != 0 {
        return Err(Finding::NotApplicable("the EMCY producer is off".into()));
    }
    let emcy = emcy & 0x7FF;
    let inhibit = ctx
        .upload(0x1015, 0)?
        .map_err(|a| fail_sdo("reading 0x1015", a))?;
    // 300 ms in units of 100 µs; the error is raised by a consumed heartbeat that stops
    // (EMCY 0x8130) and ended by its return (an EMCY of the error reset), at once.
    ctx.write(0x1015, 0, &3000u16.to_le_bytes(), "the inhibit time EMCY")?;
    let hb = monitor_the_next_node(ctx)?;
    let is_emcy = |f: &Frame| f.id().as_raw() == emcy && f.len() == 8 && !f.is_remote();
    let first = ctx.wait_for(Duration::from_millis(400), is_emcy)?;
    ctx.send(Frame::data_array(hb, [0x05]))?;
    let second = ctx.wait_for(Duration::from_millis(800), is_emcy)?;
    ctx.write(0x1016, 1, &0u32.to_le_bytes(), "a heartbeat consumer entry")?;
    ctx.write(0x1015, 0, &inhibit, "the inhibit time EMCY")?;
    let Some((t1, f1)) = first else {
        return Err(Finding::NotApplicable(
            "the heartbeat consumer timeout raised no EMCY to space".into(),
        ));
    };
    // The heartbeat's return ends the error, and §7.2.7.1 has the device signal the end
    // with an EMCY (error code 0x0000): a missing one is the device's fault.
    let Some((t2, f2)) = second else {
        return Err(fail_kind(
            FailureKind::Event,
            format!(
                "after {f1} the device sent no second EMCY (the error reset, §7.2.7.1) within 800 ms of the heartbeat's return"
            ),
        ));
    };
    let gap = t2.saturating_duration_since(t1);
    if gap + ctx.options.slack < Duration::from_millis(300) {
        return Err(fail(format!(
            "{f1} then {f2} {} µs later, inhibit time 300 ms",
            gap.as_micros()
        )));
    }
    Ok(format!("{f1} then {f2} {} ms later", gap.as_millis()))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::collections::VecDeque;

    use cantwin_can::Instant;
    use cantwin_eds::Eds;

    use super::*;
    use crate::Options;
    use crate::profile::Profile;
    use crate::transport::{Transport, TransportError};

    /// A node-5 device that answers an SDO request with an abort, behind which the
    /// transport holds a boot-up from before the reset, and that answers NMT reset
    /// communication with heartbeats reporting PRE-OPERATIONAL only.
    struct HeartbeatsOnly {
        now: Instant,
        held: VecDeque<(Instant, Frame)>,
        reset_seen: bool,
        next_heartbeat: Instant,
    }

    impl Transport for HeartbeatsOnly {
        fn send(&mut self, frame: Frame) -> Result<(), TransportError> {
            if frame.id().as_raw() == 0x605 {
                let d = frame.data_bytes();
                // Abort 0x06020000: the object does not exist.
                let abort = [0x80, d[1], d[2], d[3], 0x00, 0x00, 0x02, 0x06];
                self.held
                    .push_back((self.now, Frame::std(0x585, &abort).unwrap()));
                self.held
                    .push_back((self.now, Frame::std(0x705, &[0]).unwrap()));
            }
            if frame.id().as_raw() == 0 && frame.data_bytes() == [0x82, 5] {
                self.reset_seen = true;
                self.next_heartbeat = self.now + Duration::from_millis(10);
            }
            Ok(())
        }
        fn recv(&mut self, deadline: Instant) -> Result<Option<(Instant, Frame)>, TransportError> {
            if let Some(f) = self.held.pop_front() {
                return Ok(Some(f));
            }
            if self.reset_seen && self.next_heartbeat <= deadline {
                let t = self.next_heartbeat;
                self.now = self.now.max(t);
                self.next_heartbeat = t + Duration::from_millis(10);
                return Ok(Some((t, Frame::std(0x705, &[0x7F]).unwrap())));
            }
            self.now = self.now.max(deadline);
            Ok(None)
        }
        fn now(&self) -> Instant {
            self.now
        }
        fn describe(&self) -> String {
            "heartbeats only".into()
        }
    }

    #[test]
    fn neither_a_held_boot_up_nor_a_heartbeat_is_the_boot_up_after_the_reset() {
        let mut t = HeartbeatsOnly {
            now: Instant::from_nanos(10_000_000),
            held: VecDeque::new(),
            reset_seen: false,
            next_heartbeat: Instant::from_nanos(0),
        };
        let eds = Eds::default();
        let profile = Profile::from_eds(&eds);
        let options = Options::default();
        let mut ctx = Ctx::new(&mut t, 5, &eds, &profile, &options);
        let got = emcy_after_boot(&mut ctx);
        assert!(
            matches!(&got, Err(Finding::Fail { why, .. }) if why.contains("no boot-up")),
            "{got:?}"
        );
    }
}
