//! Area 2: the SDO server (CiA 301 §7.2.4): the transfer protocols in both directions and
//! the aborts the server must give, each followed by a check that it serves again.

use cantwin_can::Duration;
use cantwin_canopen::AbortCode;
use cantwin_canopen::sdo::crc::Crc16;

use super::{
    Case, abort_of, absent_index, access, block, data_type, entries, hex, le, m, recovered,
    writable,
};
use crate::ctx::{Aborted, Ctx, Finding, Outcome, fail, fail_abort, fail_kind};
use crate::profile::FailureKind;
use crate::report::Area::Sdo as A;

pub(super) fn cases() -> Vec<Case> {
    vec![
        m(
            "sdo.expedited-upload",
            A,
            "CiA 301 §7.2.4.3.6",
            "expedited upload of 0x1000: scs 2, e = 1, s = 1, the multiplexer echoed",
            expedited_upload,
        ),
        m(
            "sdo.expedited-download",
            A,
            "CiA 301 §7.2.4.3.3",
            "expedited download of a writable entry with its own value",
            expedited_download,
        ),
        m(
            "sdo.expedited-download-no-size",
            A,
            "CiA 301 §7.2.4.3.3 (e = 1, s = 0)",
            "expedited download of a 4-byte entry without size indication",
            expedited_download_no_size,
        ),
        m(
            "sdo.segmented-upload",
            A,
            "CiA 301 §7.2.4.3.5, §7.2.4.3.7",
            "segmented upload of an entry longer than 4 bytes: size indicated, toggle alternating",
            segmented_upload,
        ),
        m(
            "sdo.segmented-download",
            A,
            "CiA 301 §7.2.4.3.3, §7.2.4.3.4",
            "segmented download with size indication",
            segmented_download,
        ),
        m(
            "sdo.segmented-download-no-size",
            A,
            "CiA 301 §7.2.4.3.3 (s = 0)",
            "segmented download without size indication",
            segmented_download_no_size,
        ),
        m(
            "sdo.block-upload",
            A,
            "CiA 301 §7.2.4.3.12–16",
            "block upload with block sizes 1, 2, 7, 64, 126 and 127, CRC on and off: each sub-block has the segments asked for",
            block_upload,
        ),
        m(
            "sdo.block-download",
            A,
            "CiA 301 §7.2.4.3.9–11",
            "block download with size indication, CRC on and off: the server's block sizes are 1 to 127 and the client keeps to them",
            block_download,
        ),
        m(
            "sdo.block-download-no-size",
            A,
            "CiA 301 §7.2.4.3.9 (s = 0), §7.2.4.3.10, §7.2.4.3.11",
            "block download without size indication, CRC on and off",
            block_download_no_size,
        ),
        m(
            "sdo.abort-no-object",
            A,
            "CiA 301 §7.2.4.3.17",
            "an absent object is refused with 0x06020000",
            abort_no_object,
        ),
        m(
            "sdo.abort-no-sub",
            A,
            "CiA 301 §7.2.4.3.17",
            "an absent sub-index is refused with 0x06090011",
            abort_no_sub,
        ),
        m(
            "sdo.abort-read-only",
            A,
            "CiA 301 §7.2.4.3.17",
            "a write to a read-only entry is refused with 0x06010002",
            abort_read_only,
        ),
        m(
            "sdo.abort-write-only",
            A,
            "CiA 301 §7.2.4.3.17",
            "a read of a write-only entry is refused with 0x06010001",
            abort_write_only,
        ),
        m(
            "sdo.abort-length-high",
            A,
            "CiA 301 §7.2.4.3.17",
            "a write longer than the entry is refused with 0x06070012 (or 0x06070010)",
            abort_length_high,
        ),
        m(
            "sdo.abort-length-low",
            A,
            "CiA 301 §7.2.4.3.17",
            "a write shorter than the entry is refused with 0x06070013 (or 0x06070010)",
            abort_length_low,
        ),
        m(
            "sdo.abort-value-high",
            A,
            "CiA 301 §7.2.4.3.17, CiA 306 §4.6.3 HighLimit",
            "a value above the file's HighLimit is refused with 0x06090031 (or 0x06090030)",
            abort_value_high,
        ),
        m(
            "sdo.abort-value-low",
            A,
            "CiA 301 §7.2.4.3.17, CiA 306 §4.6.3 LowLimit",
            "a value below the file's LowLimit is refused with 0x06090032 (or 0x06090030)",
            abort_value_low,
        ),
        m(
            "sdo.abort-toggle-upload",
            A,
            "CiA 301 §7.2.4.3.7, §7.2.4.3.17",
            "an upload segment request with the wrong toggle bit is refused with 0x05030000",
            abort_toggle_upload,
        ),
        m(
            "sdo.abort-toggle",
            A,
            "CiA 301 §7.2.4.3.4, §7.2.4.3.17",
            "a download segment with the wrong toggle bit is refused with 0x05030000",
            abort_toggle,
        ),
        m(
            "sdo.abort-invalid-ccs",
            A,
            "CiA 301 §7.2.4.3.17",
            "an unknown command specifier is refused with 0x05040001",
            abort_invalid_ccs,
        ),
        m(
            "sdo.abort-block-size",
            A,
            "CiA 301 §7.2.4.3.12",
            "a block upload asking for 0 or 128 segments is refused with 0x05040002",
            abort_block_size,
        ),
        m(
            "sdo.abort-sequence",
            A,
            "CiA 301 §7.2.4.3.10",
            "a block segment with sequence number 0 is refused (0x05040003) or discarded",
            abort_sequence,
        ),
        m(
            "sdo.abort-crc",
            A,
            "CiA 301 §7.2.4.3.11",
            "a block download with a wrong CRC is refused with 0x05040004",
            abort_crc,
        ),
        m(
            "sdo.abort-timeout",
            A,
            "CiA 301 §7.2.4.3.17",
            "a segmented download left unfinished is aborted with 0x05040000",
            abort_timeout,
        ),
    ]
}

fn mux_bytes(index: u16, sub: u8) -> [u8; 3] {
    let i = index.to_le_bytes();
    [i[0], i[1], sub]
}

fn req(cmd: u8, index: u16, sub: u8, data: [u8; 4]) -> [u8; 8] {
    let m = mux_bytes(index, sub);
    [cmd, m[0], m[1], m[2], data[0], data[1], data[2], data[3]]
}

/// A refusal of a segmented transfer: expedited-only unless the profile claims segmented
/// transfers (CiA 306 cannot say; without a profile this is not a failure).
fn segmented_refused(ctx: &Ctx<'_>, what: &str, code: AbortCode) -> Finding {
    if code == AbortCode::INVALID_COMMAND && ctx.profile.sdo.segmented != Some(true) {
        Finding::NotSupported {
            why: format!(
                "expedited-only: the server answers a segmented {what} with {}",
                hex(code)
            ),
            abort: Some(code),
        }
    } else {
        fail_abort(format!("segmented {what} refused"), code)
    }
}

/// A refusal of a block transfer: not supported unless the profile claims it.
fn block_refused(ctx: &Ctx<'_>, what: &str, a: Aborted) -> Finding {
    if a.by_server
        && [AbortCode::INVALID_COMMAND, AbortCode::UNSUPPORTED_ACCESS].contains(&a.code)
        && ctx.profile.sdo.block != Some(true)
    {
        Finding::NotSupported {
            why: format!(
                "no block transfer: the server answers a block {what} with {}",
                hex(a.code)
            ),
            abort: Some(a.code),
        }
    } else {
        fail_abort(format!("block {what}"), a.code)
    }
}

fn expedited_upload(ctx: &mut Ctx<'_>) -> Outcome {
    let (index, sub, size) = super::served_entry(ctx);
    let what = format!("0x{index:04X} sub {sub}");
    let Some(b) = ctx.sdo_raw(req(0x40, index, sub, [0; 4]))? else {
        return Err(fail_kind(
            FailureKind::Silence,
            format!("no answer to an upload of {what}"),
        ));
    };
    if let Some(code) = abort_of(&b) {
        return Err(fail_abort(format!("upload of {what}"), code));
    }
    if b[0] & 0xE0 != 0x40 || b[1..4] != mux_bytes(index, sub) {
        return Err(fail(format!(
            "answer {b:02X?} is not an initiate upload response for {what}"
        )));
    }
    // Data of 1 to 4 bytes goes expedited (§7.2.4.3.6); a larger entry may go segmented.
    let small = size.is_some_and(|n| (1..=4).contains(&n));
    if b[0] & 0x02 == 0 {
        if small {
            return Err(fail(format!(
                "a {}-byte entry not sent expedited: {b:02X?}",
                size.unwrap_or(0)
            )));
        }
        ctx.sdo_raw(req(
            0x80,
            index,
            sub,
            AbortCode::GENERAL_ERROR.to_u32().to_le_bytes(),
        ))?;
        return Err(Finding::NotApplicable(format!(
            "{what} is not of 1 to 4 bytes and was answered segmented"
        )));
    }
    let n = if b[0] & 0x01 != 0 {
        4 - usize::from((b[0] >> 2) & 3)
    } else {
        4
    };
    if size.is_some_and(|want| want != n) {
        return Err(fail(format!(
            "{what} ({} bytes) uploaded with {n} bytes",
            size.unwrap_or(0)
        )));
    }
    let value = u32::from_le_bytes([b[4], b[5], b[6], b[7]]) & (u32::MAX >> (8 * (4 - n.min(4))));
    if index == 0x1000 {
        Ok(format!("device type 0x{value:08X}"))
    } else {
        Ok(format!(
            "{what} = 0x{value:0w$X} (the file has no 0x1000)",
            w = 2 * n
        ))
    }
}

fn expedited_download(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((index, sub, size, value)) = writable(ctx, 1..=4)? else {
        return Err(Finding::NotApplicable(
            "no writable entry of 1 to 4 bytes".into(),
        ));
    };
    let n = u8::try_from(4 - size).unwrap_or(0);
    let mut d = [0u8; 4];
    d[..size].copy_from_slice(&value);
    let Some(b) = ctx.sdo_raw(req(0x23 | (n << 2), index, sub, d))? else {
        return Err(fail_kind(
            FailureKind::Silence,
            "no answer to an expedited download",
        ));
    };
    if let Some(code) = abort_of(&b) {
        return Err(fail_abort(
            format!("writing 0x{index:04X} sub {sub} with its own value"),
            code,
        ));
    }
    if b[0] != 0x60 || b[1..4] != mux_bytes(index, sub) {
        return Err(fail(format!(
            "answer {b:02X?} is not an initiate download response"
        )));
    }
    Ok(format!("0x{index:04X} sub {sub} written with {value:02X?}"))
}

fn expedited_download_no_size(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((index, sub, _, value)) = writable(ctx, 4..=4)? else {
        return Err(Finding::NotApplicable("no writable 4-byte entry".into()));
    };
    let mut d = [0u8; 4];
    d.copy_from_slice(&value);
    let Some(b) = ctx.sdo_raw(req(0x22, index, sub, d))? else {
        return Err(fail_kind(
            FailureKind::Silence,
            "no answer to an expedited download without size",
        ));
    };
    if let Some(code) = abort_of(&b) {
        return Err(fail_abort(
            format!("writing 0x{index:04X} sub {sub} with its own value, no size indicated"),
            code,
        ));
    }
    if b[0] != 0x60 || b[1..4] != mux_bytes(index, sub) {
        return Err(fail(format!(
            "answer {b:02X?} is not an initiate download response"
        )));
    }
    Ok(format!("0x{index:04X} sub {sub} written with {value:02X?}"))
}

/// A readable entry longer than 4 bytes, from the EDS scan or by reading.
fn long_entry(ctx: &mut Ctx<'_>) -> Result<Option<(u16, u8, Vec<u8>)>, Finding> {
    if let Some(scan) = &ctx.scan
        && let Some((i, s, Ok(d))) = scan
            .iter()
            .filter(|(_, _, r)| r.as_ref().is_ok_and(|d| d.len() > 4 && d.len() <= 4096))
            .max_by_key(|(_, _, r)| r.as_ref().map(|d| d.len().min(64)).unwrap_or(0))
    {
        return Ok(Some((*i, *s, d.clone())));
    }
    let candidates: Vec<(u16, u8)> = entries(ctx)
        .into_iter()
        .filter(|(_, _, e)| {
            access(e).readable()
                && data_type(e).is_none_or(|d| d.fixed_size().is_none_or(|s| s > 4))
        })
        .map(|(i, s, _)| (i, s))
        .collect();
    for (i, s) in candidates {
        if let Ok(d) = ctx.upload(i, s)?
            && d.len() > 4
            && d.len() <= 4096
        {
            return Ok(Some((i, s, d)));
        }
    }
    Ok(None)
}

fn segmented_upload(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((index, sub, want)) = long_entry(ctx)? else {
        return Err(Finding::NotApplicable(
            "no readable entry longer than 4 bytes".into(),
        ));
    };
    let Some(b) = ctx.sdo_raw(req(0x40, index, sub, [0; 4]))? else {
        return Err(fail_kind(FailureKind::Silence, "no answer to the initiate"));
    };
    if let Some(code) = abort_of(&b) {
        return Err(segmented_refused(ctx, "upload", code));
    }
    if b[0] & 0xE3 != 0x41 {
        return Err(fail(format!(
            "a {}-byte entry: the initiate answer {b:02X?} is not segmented with size",
            want.len()
        )));
    }
    let size = u32::from_le_bytes([b[4], b[5], b[6], b[7]]) as usize;
    let mut got = Vec::new();
    let mut toggle = 0u8;
    loop {
        let Some(s) = ctx.sdo_raw([0x60 | (toggle << 4), 0, 0, 0, 0, 0, 0, 0])? else {
            return Err(fail_kind(
                FailureKind::Silence,
                "no answer to an upload segment request",
            ));
        };
        if let Some(code) = abort_of(&s) {
            return Err(fail_abort("during the segments", code));
        }
        if s[0] & 0xE0 != 0 || (s[0] >> 4) & 1 != toggle {
            return Err(fail(format!(
                "segment {s:02X?}: expected scs 0 with toggle {toggle}"
            )));
        }
        let n = usize::from((s[0] >> 1) & 7);
        got.extend_from_slice(&s[1..8 - n]);
        if s[0] & 1 != 0 {
            break;
        }
        if got.len() > size + 7 {
            return Err(fail("more data than the indicated size"));
        }
        toggle ^= 1;
    }
    if got.len() != size || got != want {
        return Err(fail(format!(
            "{} bytes uploaded, size {size}, and they differ from a normal read",
            got.len()
        )));
    }
    recovered(ctx, "a segmented upload")?;
    Ok(format!(
        "0x{index:04X} sub {sub}: {size} bytes in {} segments",
        size.div_ceil(7)
    ))
}

fn segmented_download(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((index, sub, size, value)) = writable(ctx, 1..=8)? else {
        return Err(Finding::NotApplicable(
            "no writable entry of fixed size".into(),
        ));
    };
    let s = u32::try_from(size).unwrap_or(0).to_le_bytes();
    let Some(b) = ctx.sdo_raw(req(0x21, index, sub, s))? else {
        return Err(fail_kind(
            FailureKind::Silence,
            "no answer to a segmented initiate",
        ));
    };
    if let Some(code) = abort_of(&b) {
        return Err(segmented_refused(ctx, "download", code));
    }
    if b[0] != 0x60 {
        return Err(fail(format!(
            "answer {b:02X?} to the initiate is not scs 3"
        )));
    }
    let segments = download_segments(ctx, &value)?;
    recovered(ctx, "a segmented download")?;
    let plural = if segments == 1 { "" } else { "s" };
    Ok(format!(
        "0x{index:04X} sub {sub}: {size} bytes in {segments} segment{plural}"
    ))
}

/// Sends `value` as download segments after an accepted initiate and checks each answer
/// (CiA 301 §7.2.4.3.5: a segment carries up to 7 bytes, n the unused ones, c on the
/// last, the toggle alternating from 0; the server answers scs 1 with the same toggle).
/// Returns the number of segments.
fn download_segments(ctx: &mut Ctx<'_>, value: &[u8]) -> Result<usize, Finding> {
    let chunks: Vec<&[u8]> = if value.is_empty() {
        vec![&[]]
    } else {
        value.chunks(7).collect()
    };
    let count = chunks.len();
    for (i, chunk) in chunks.into_iter().enumerate() {
        let toggle = u8::try_from(i % 2).unwrap_or(0);
        let last = i + 1 == count;
        let n = u8::try_from(7 - chunk.len()).unwrap_or(0);
        let mut seg = [0u8; 8];
        seg[0] = (toggle << 4) | (n << 1) | u8::from(last);
        seg[1..1 + chunk.len()].copy_from_slice(chunk);
        let Some(b) = ctx.sdo_raw(seg)? else {
            return Err(fail_kind(
                FailureKind::Silence,
                format!("no answer to segment {i}"),
            ));
        };
        if let Some(code) = abort_of(&b) {
            return Err(fail_abort(format!("segment {i}"), code));
        }
        if b[0] != 0x20 | (toggle << 4) {
            return Err(fail(format!(
                "answer {b:02X?} to segment {i} is not scs 1 with toggle {toggle}"
            )));
        }
    }
    Ok(count)
}

fn segmented_download_no_size(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((index, sub, _, value)) = writable(ctx, 1..=8)? else {
        return Err(Finding::NotApplicable(
            "no writable entry of fixed size".into(),
        ));
    };
    let Some(b) = ctx.sdo_raw(req(0x20, index, sub, [0; 4]))? else {
        return Err(fail_kind(
            FailureKind::Silence,
            "no answer to a segmented initiate without size",
        ));
    };
    if let Some(code) = abort_of(&b) {
        return Err(segmented_refused(ctx, "download without size", code));
    }
    if b[0] != 0x60 {
        return Err(fail(format!(
            "answer {b:02X?} to the initiate is not scs 3"
        )));
    }
    download_segments(ctx, &value)?;
    recovered(ctx, "a segmented download without size")?;
    Ok(format!("0x{index:04X} sub {sub} written"))
}

/// The block sizes the upload case asks for: both ends of 1..=127 and sizes between,
/// each with the CRC on or off (CiA 301 §7.2.4.3.12: blksize 1 to 127).
const UPLOAD_BLOCK_SIZES: [(u8, bool); 8] = [
    (127, true),
    (1, false),
    (2, true),
    (7, false),
    (64, true),
    (126, false),
    (127, false),
    (1, true),
];

/// A block transfer that did not complete, as the case's finding.
fn block_finding(ctx: &Ctx<'_>, what: &str, e: block::BlockError) -> Finding {
    match e {
        block::BlockError::Refused(code) => block_refused(
            ctx,
            what,
            Aborted {
                code,
                by_server: true,
            },
        ),
        block::BlockError::Finding(f) => f,
    }
}

fn block_upload(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((index, sub, want)) = long_entry(ctx)? else {
        return Err(Finding::NotApplicable(
            "no readable entry longer than 4 bytes".into(),
        ));
    };
    for (blksize, crc) in UPLOAD_BLOCK_SIZES {
        let what = format!("upload (block size {blksize}, CRC {crc})");
        let seen = block::upload(ctx, index, sub, blksize, crc)
            .map_err(|e| block_finding(ctx, &what, e))?;
        if seen.data != want {
            return Err(fail(format!(
                "block size {blksize}, CRC {crc}: {} bytes, a normal read gave {}",
                seen.data.len(),
                want.len()
            )));
        }
    }
    recovered(ctx, "block uploads")?;
    let sizes: Vec<String> = UPLOAD_BLOCK_SIZES
        .iter()
        .filter(|(_, crc)| *crc)
        .map(|(b, _)| b.to_string())
        .collect();
    Ok(format!(
        "0x{index:04X} sub {sub}: {} bytes with block sizes 1, 2, 7, 64, 126 and 127 (CRC with {}), every sub-block of the size asked",
        want.len(),
        sizes.join(", ")
    ))
}

/// A writable entry to download as a block: a readable and writable one longer than a
/// segment and at most 4 KiB from the EDS scan (several sub-blocks where the server asks
/// for small ones), else one of fixed size up to 8 bytes. (index, sub, its value).
fn block_target(ctx: &mut Ctx<'_>) -> Result<Option<(u16, u8, Vec<u8>)>, Finding> {
    if let Some(scan) = &ctx.scan {
        let long = scan.iter().find(|(i, s, r)| {
            *i >= 0x2000
                && r.as_ref().is_ok_and(|d| d.len() > 7 && d.len() <= 4096)
                && super::eds_entry(ctx, *i, *s)
                    .is_some_and(|e| access(e).writable() && access(e).readable())
        });
        if let Some((i, s, Ok(d))) = long {
            let (i, s, d) = (*i, *s, d.clone());
            // The scan is from the start of the run: read it again, the value may have moved.
            if let Ok(now) = ctx.upload(i, s)?
                && now == d
            {
                return Ok(Some((i, s, now)));
            }
        }
    }
    if ctx.scan.is_none() {
        // No scan (the EDS area did not run): the first such entry whose upload initiate
        // indicates a size in range, the transfer then aborted unread.
        let candidates: Vec<(u16, u8)> = entries(ctx)
            .into_iter()
            .filter(|(i, _, e)| {
                *i >= 0x2000
                    && access(e).writable()
                    && access(e).readable()
                    && data_type(e).is_none_or(|d| d.fixed_size().is_none_or(|n| n > 7))
            })
            .map(|(i, s, _)| (i, s))
            .collect();
        for (i, s) in candidates {
            if indicated_size(ctx, i, s)?.is_some_and(|n| (8..=4096).contains(&n))
                && let Ok(d) = ctx.upload(i, s)?
            {
                return Ok(Some((i, s, d)));
            }
        }
    }
    Ok(writable(ctx, 1..=8)?.map(|(i, s, _, v)| (i, s, v)))
}

/// The size an upload initiate of `index`/`sub` indicates (§7.2.4.3.6), the transfer
/// aborted after the answer; `None` when refused or not indicated.
fn indicated_size(ctx: &mut Ctx<'_>, index: u16, sub: u8) -> Result<Option<usize>, Finding> {
    let Some(b) = ctx.sdo_raw(req(0x40, index, sub, [0; 4]))? else {
        return Ok(None);
    };
    if abort_of(&b).is_some() || b[0] & 0xE0 != 0x40 {
        return Ok(None);
    }
    if b[0] & 0x02 != 0 {
        // Expedited: the size is in the answer, and the transfer over.
        let n = if b[0] & 0x01 != 0 {
            4 - usize::from((b[0] >> 2) & 3)
        } else {
            4
        };
        return Ok(Some(n));
    }
    // Segmented: end it unread (§7.2.4.3.17, an abort is not answered).
    let abort = req(
        0x80,
        index,
        sub,
        AbortCode::GENERAL_ERROR.to_u32().to_le_bytes(),
    );
    ctx.send(cantwin_can::Frame::data_array(ctx.sdo_rx(), abort))?;
    Ok((b[0] & 0x01 != 0).then(|| u32::from_le_bytes([b[4], b[5], b[6], b[7]]) as usize))
}

fn block_download_with(ctx: &mut Ctx<'_>, size_indicated: bool) -> Outcome {
    let Some((index, sub, value)) = block_target(ctx)? else {
        return Err(Finding::NotApplicable(
            "no writable entry of fixed size".into(),
        ));
    };
    let mut blksizes = std::collections::BTreeSet::new();
    let mut sub_blocks = 0;
    for crc in [true, false] {
        let what = format!(
            "download ({}size indicated, CRC {crc})",
            if size_indicated { "" } else { "no " }
        );
        let seen = block::download(ctx, index, sub, &value, size_indicated, crc)
            .map_err(|e| block_finding(ctx, &what, e))?;
        blksizes.extend(seen.server_blksizes);
        sub_blocks += seen.sub_blocks.len();
    }
    match ctx.upload(index, sub)? {
        Ok(d) if d == value => {}
        Ok(d) => {
            return Err(fail(format!(
                "0x{index:04X} sub {sub} reads {} bytes after the block downloads of its own {} bytes",
                d.len(),
                value.len()
            )));
        }
        Err(a) => {
            return Err(crate::ctx::fail_sdo(
                "reading back after the block downloads",
                a,
            ));
        }
    }
    let sizes: Vec<String> = blksizes.iter().map(u8::to_string).collect();
    Ok(format!(
        "0x{index:04X} sub {sub}: {} bytes written with its own value, CRC on and off, {sub_blocks} sub-blocks; the server asked for blocks of {}",
        value.len(),
        sizes.join(", ")
    ))
}

fn block_download(ctx: &mut Ctx<'_>) -> Outcome {
    block_download_with(ctx, true)
}

fn block_download_no_size(ctx: &mut Ctx<'_>) -> Outcome {
    block_download_with(ctx, false)
}

/// Sends `request` and expects an abort with one of `codes`, then a server that serves.
fn expect_abort(ctx: &mut Ctx<'_>, request: [u8; 8], codes: &[AbortCode], what: &str) -> Outcome {
    expect_abort_mux(ctx, request, codes, what, true)
}

/// As [`expect_abort`]; `same_mux`: the abort must name the request's object (not for a
/// request whose command the server cannot parse).
fn expect_abort_mux(
    ctx: &mut Ctx<'_>,
    request: [u8; 8],
    codes: &[AbortCode],
    what: &str,
    same_mux: bool,
) -> Outcome {
    let Some(b) = ctx.sdo_raw(request)? else {
        return Err(fail(format!("{what}: no answer")));
    };
    let Some(code) = abort_of(&b) else {
        return Err(fail(format!("{what}: answered {b:02X?}, not an abort")));
    };
    if !codes.contains(&code) {
        let want: Vec<String> = codes.iter().map(|c| hex(*c)).collect();
        return Err(fail_abort(
            format!("{what}: expected {}", want.join(" or ")),
            code,
        ));
    }
    if same_mux && b[1..4] != request[1..4] {
        return Err(fail(format!(
            "{what}: the abort names another object: {b:02X?}"
        )));
    }
    recovered(ctx, what)?;
    Ok(format!("{what}: {}", hex(code)))
}

fn abort_no_object(ctx: &mut Ctx<'_>) -> Outcome {
    let index = absent_index(ctx);
    expect_abort(
        ctx,
        req(0x40, index, 0, [0; 4]),
        &[AbortCode::NO_OBJECT],
        &format!("upload of absent 0x{index:04X}"),
    )
}

fn abort_no_sub(ctx: &mut Ctx<'_>) -> Outcome {
    let highest = ctx
        .eds
        .objects
        .get(&0x1018)
        .and_then(|o| o.subs.keys().max().copied())
        .unwrap_or(4);
    let sub = highest.saturating_add(1).max(5);
    expect_abort(
        ctx,
        req(0x40, 0x1018, sub, [0; 4]),
        &[AbortCode::NO_SUB_INDEX],
        &format!("upload of 0x1018 sub {sub}"),
    )
}

fn abort_read_only(ctx: &mut Ctx<'_>) -> Outcome {
    // 0x1000 is read-only on every device (CiA 301 §7.5.2.1); a file without it names
    // another read-only entry.
    let (index, sub) = if ctx.eds.entry(0x1000, 0).is_some() {
        (0x1000, 0)
    } else {
        let Some((i, s)) = entries(ctx)
            .into_iter()
            .find(|(_, _, e)| !access(e).writable() && access(e).readable())
            .map(|(i, s, _)| (i, s))
        else {
            return Err(Finding::NotApplicable(
                "the file has no read-only entry".into(),
            ));
        };
        (i, s)
    };
    expect_abort(
        ctx,
        req(0x23, index, sub, [0; 4]),
        &[AbortCode::READ_ONLY],
        &format!("download to 0x{index:04X} sub {sub}"),
    )
}

fn abort_write_only(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((index, sub)) = entries(ctx)
        .into_iter()
        .find(|(_, _, e)| !access(e).readable())
        .map(|(i, s, _)| (i, s))
    else {
        return Err(Finding::NotApplicable(
            "the file has no write-only entry".into(),
        ));
    };
    expect_abort(
        ctx,
        req(0x40, index, sub, [0; 4]),
        &[AbortCode::WRITE_ONLY],
        &format!("upload of write-only 0x{index:04X} sub {sub}"),
    )
}

fn abort_length_high(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((index, sub, size, _)) = writable(ctx, 1..=3)? else {
        return Err(Finding::NotApplicable(
            "no writable entry shorter than 4 bytes".into(),
        ));
    };
    expect_abort(
        ctx,
        req(0x23, index, sub, [0; 4]),
        &[AbortCode::LENGTH_TOO_HIGH, AbortCode::TYPE_MISMATCH],
        &format!("4 bytes to the {size}-byte 0x{index:04X} sub {sub}"),
    )
}

fn abort_length_low(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((index, sub, size, _)) = writable(ctx, 2..=4)? else {
        return Err(Finding::NotApplicable(
            "no writable entry of 2 to 4 bytes".into(),
        ));
    };
    expect_abort(
        ctx,
        req(0x2F, index, sub, [0; 4]),
        &[AbortCode::LENGTH_TOO_LOW, AbortCode::TYPE_MISMATCH],
        &format!("1 byte to the {size}-byte 0x{index:04X} sub {sub}"),
    )
}

/// A writable integer entry with a limit the type's range leaves room beyond: (index,
/// sub, size, the value one past the limit).
fn beyond_limit(ctx: &Ctx<'_>, high: bool) -> Option<(u16, u8, usize, i128)> {
    for (index, sub, e) in entries(ctx) {
        if !access(&e).writable() || (0x1010..=0x1011).contains(&index) {
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
        let lo = e.low_limit.as_ref().and_then(|v| v.evaluate(ctx.node));
        let hi = e.high_limit.as_ref().and_then(|v| v.evaluate(ctx.node));
        if lo.zip(hi).is_some_and(|(l, h)| l > h) {
            continue;
        }
        let limit = if high { &e.high_limit } else { &e.low_limit };
        let Some(l) = limit.as_ref().and_then(|v| v.evaluate(ctx.node)) else {
            continue;
        };
        let bits = 8 * size as u32;
        let (min, max) = if dt.is_signed() {
            (-(1i128 << (bits - 1)), (1i128 << (bits - 1)) - 1)
        } else {
            (0, (1i128 << bits) - 1)
        };
        let v = if high { l + 1 } else { l - 1 };
        if (min..=max).contains(&v) {
            return Some((index, sub, size, v));
        }
    }
    None
}

fn abort_value(ctx: &mut Ctx<'_>, high: bool) -> Outcome {
    let Some((index, sub, size, v)) = beyond_limit(ctx, high) else {
        return Err(Finding::NotApplicable(format!(
            "no writable integer entry with a {} limit inside its type's range",
            if high { "high" } else { "low" }
        )));
    };
    let mut d = [0u8; 4];
    d[..size].copy_from_slice(&le(v, size));
    let n = u8::try_from(4 - size).unwrap_or(0);
    let code = if high {
        AbortCode::VALUE_TOO_HIGH
    } else {
        AbortCode::VALUE_TOO_LOW
    };
    expect_abort(
        ctx,
        req(0x23 | (n << 2), index, sub, d),
        &[code, AbortCode::INVALID_VALUE],
        &format!("{v} to 0x{index:04X} sub {sub}"),
    )
}

fn abort_value_high(ctx: &mut Ctx<'_>) -> Outcome {
    abort_value(ctx, true)
}

fn abort_value_low(ctx: &mut Ctx<'_>) -> Outcome {
    abort_value(ctx, false)
}

fn abort_toggle(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((index, sub, size, value)) = writable(ctx, 1..=7)? else {
        return Err(Finding::NotApplicable(
            "no writable entry of fixed size".into(),
        ));
    };
    let s = u32::try_from(size).unwrap_or(0).to_le_bytes();
    let Some(b) = ctx.sdo_raw(req(0x21, index, sub, s))? else {
        return Err(fail_kind(
            FailureKind::Silence,
            "no answer to a segmented initiate",
        ));
    };
    if let Some(code) = abort_of(&b) {
        return Err(segmented_refused(ctx, "download", code));
    }
    let n = u8::try_from(7 - size).unwrap_or(0);
    let mut seg = [0u8; 8];
    // The first segment carries toggle 0; this one carries 1.
    seg[0] = 0x10 | (n << 1) | 1;
    seg[1..1 + size].copy_from_slice(&value);
    let Some(b) = ctx.sdo_raw(seg)? else {
        return Err(fail_kind(
            FailureKind::Silence,
            "no answer to the segment with the wrong toggle bit",
        ));
    };
    match abort_of(&b) {
        Some(AbortCode::TOGGLE_BIT_NOT_ALTERNATED) => {}
        Some(code) => return Err(fail_abort("expected 0x05030000", code)),
        None => {
            return Err(fail(format!(
                "the segment with toggle 1 first was accepted: {b:02X?}"
            )));
        }
    }
    recovered(ctx, "a toggle error")?;
    Ok(format!("0x{index:04X} sub {sub}: 0x05030000"))
}

/// §7.2.4.3.7: the first upload segment request carries toggle 0; one with toggle 1 is
/// a toggle error the server aborts with 0x05030000 (§7.2.4.3.17).
fn abort_toggle_upload(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((index, sub, _)) = long_entry(ctx)? else {
        return Err(Finding::NotApplicable(
            "no readable entry longer than 4 bytes".into(),
        ));
    };
    let Some(b) = ctx.sdo_raw(req(0x40, index, sub, [0; 4]))? else {
        return Err(fail_kind(FailureKind::Silence, "no answer to the initiate"));
    };
    if let Some(code) = abort_of(&b) {
        return Err(segmented_refused(ctx, "upload", code));
    }
    if b[0] & 0xE2 != 0x40 {
        return Err(fail(format!(
            "0x{index:04X} sub {sub}: the initiate answer {b:02X?} is not a segmented upload"
        )));
    }
    let Some(b) = ctx.sdo_raw([0x70, 0, 0, 0, 0, 0, 0, 0])? else {
        return Err(fail_kind(
            FailureKind::Silence,
            "no answer to the upload segment request with the wrong toggle bit",
        ));
    };
    match abort_of(&b) {
        Some(AbortCode::TOGGLE_BIT_NOT_ALTERNATED) => {}
        Some(code) => return Err(fail_abort("expected 0x05030000", code)),
        None => {
            return Err(fail(format!(
                "the upload segment request with toggle 1 first was answered: {b:02X?}"
            )));
        }
    }
    recovered(ctx, "an upload toggle error")?;
    Ok(format!("0x{index:04X} sub {sub}: 0x05030000"))
}

fn abort_invalid_ccs(ctx: &mut Ctx<'_>) -> Outcome {
    expect_abort_mux(
        ctx,
        req(0xE0, 0x1000, 0, [0; 4]),
        &[AbortCode::INVALID_COMMAND],
        "command specifier 7",
        false,
    )
}

fn abort_block_size(ctx: &mut Ctx<'_>) -> Outcome {
    let (index, sub, _) = super::served_entry(ctx);
    let mut notes = Vec::new();
    for blksize in [0u8, 128] {
        let Some(b) = ctx.sdo_raw(req(0xA0, index, sub, [blksize, 0, 0, 0]))? else {
            return Err(fail_kind(
                FailureKind::Silence,
                format!("no answer to a block upload initiate with block size {blksize}"),
            ));
        };
        match abort_of(&b) {
            Some(AbortCode::INVALID_BLOCK_SIZE) => notes.push(format!("{blksize}: 0x05040002")),
            Some(code) => {
                return Err(block_refused(
                    ctx,
                    &format!("upload with block size {blksize}"),
                    Aborted {
                        code,
                        by_server: true,
                    },
                ));
            }
            None => {
                ctx.sdo_raw(req(
                    0x80,
                    index,
                    sub,
                    AbortCode::INVALID_BLOCK_SIZE.to_u32().to_le_bytes(),
                ))?;
                return Err(fail(format!("block size {blksize} accepted: {b:02X?}")));
            }
        }
    }
    recovered(ctx, "invalid block sizes")?;
    Ok(notes.join(", "))
}

/// Starts a block download of `value` to `index`/`sub`; the server's answer.
fn block_initiate(
    ctx: &mut Ctx<'_>,
    index: u16,
    sub: u8,
    len: usize,
    crc: bool,
) -> Result<[u8; 8], Finding> {
    let s = u32::try_from(len).unwrap_or(0).to_le_bytes();
    let cmd = 0xC2 | if crc { 0x04 } else { 0 };
    match ctx.sdo_raw(req(cmd, index, sub, s))? {
        Some(b) => {
            if let Some(code) = abort_of(&b) {
                return Err(block_refused(
                    ctx,
                    "download",
                    Aborted {
                        code,
                        by_server: true,
                    },
                ));
            }
            if b[0] & 0xE3 != 0xA0 {
                return Err(fail(format!(
                    "answer {b:02X?} to a block download initiate"
                )));
            }
            Ok(b)
        }
        None => Err(fail_kind(
            FailureKind::Silence,
            "no answer to a block download initiate",
        )),
    }
}

fn abort_sequence(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((index, sub, size, value)) = writable(ctx, 1..=7)? else {
        return Err(Finding::NotApplicable(
            "no writable entry of fixed size".into(),
        ));
    };
    block_initiate(ctx, index, sub, size, false)?;
    let mut seg = [0u8; 8];
    // Sequence number 0, not the last: with c = 1 the byte would read 0x80, an abort.
    seg[0] = 0x00;
    seg[1..1 + size].copy_from_slice(&value);
    let timeout = ctx.options.sdo_timeout;
    ctx.send(cantwin_can::Frame::data_array(ctx.sdo_rx(), seg))?;
    let note = match ctx.sdo_answer(timeout)? {
        Some(b) if abort_of(&b) == Some(AbortCode::INVALID_SEQUENCE_NUMBER) => {
            "0x05040003".to_string()
        }
        Some(b) if b[0] == 0xA2 && b[1] == 0 => {
            // Not acknowledged: the server asks for the block again. End it.
            ctx.sdo_raw(req(
                0x80,
                index,
                sub,
                AbortCode::INVALID_SEQUENCE_NUMBER.to_u32().to_le_bytes(),
            ))?;
            "acknowledged with ackseq 0 (the segment discarded)".to_string()
        }
        Some(b) => {
            if abort_of(&b).is_none() {
                ctx.sdo_raw(req(
                    0x80,
                    index,
                    sub,
                    AbortCode::GENERAL_ERROR.to_u32().to_le_bytes(),
                ))?;
            }
            return Err(fail(format!(
                "a segment with sequence number 0 was answered {b:02X?}"
            )));
        }
        None => {
            // Discarded in silence: the segment numbered 1 must then be the one taken.
            seg[0] = 0x81;
            let got = ctx.sdo_raw(seg)?;
            ctx.sdo_raw(req(
                0x80,
                index,
                sub,
                AbortCode::GENERAL_ERROR.to_u32().to_le_bytes(),
            ))?;
            match got {
                Some(b) if b[0] == 0xA2 && b[1] == 1 => {
                    "discarded; the segment numbered 1 then acknowledged".to_string()
                }
                other => {
                    return Err(fail(format!(
                        "after a segment numbered 0, segment 1 was answered {other:02X?}, not an acknowledgement of 1"
                    )));
                }
            }
        }
    };
    recovered(ctx, "an invalid sequence number")?;
    Ok(note)
}

fn abort_crc(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((index, sub, size, value)) = writable(ctx, 1..=7)? else {
        return Err(Finding::NotApplicable(
            "no writable entry of fixed size".into(),
        ));
    };
    let b = block_initiate(ctx, index, sub, size, true)?;
    if b[0] & 0x04 == 0 {
        ctx.sdo_raw(req(
            0x80,
            index,
            sub,
            AbortCode::GENERAL_ERROR.to_u32().to_le_bytes(),
        ))?;
        return Err(Finding::NotApplicable(
            "the server does not offer the block CRC (sc = 0)".into(),
        ));
    }
    let mut seg = [0u8; 8];
    seg[0] = 0x81;
    seg[1..1 + size].copy_from_slice(&value);
    let Some(ack) = ctx.sdo_raw(seg)? else {
        return Err(fail_kind(
            FailureKind::Silence,
            "no acknowledgement of the block",
        ));
    };
    if ack[0] != 0xA2 || ack[1] != 1 {
        return Err(fail(format!(
            "block acknowledgement {ack:02X?}, expected ackseq 1"
        )));
    }
    let wrong = Crc16::of(&value) ^ 0xFFFF;
    let n = u8::try_from(7 - size).unwrap_or(0);
    let w = wrong.to_le_bytes();
    let end = [0xC1 | (n << 2), w[0], w[1], 0, 0, 0, 0, 0];
    let Some(b) = ctx.sdo_raw(end)? else {
        return Err(fail_kind(
            FailureKind::Silence,
            "no answer to the end with a wrong CRC",
        ));
    };
    match abort_of(&b) {
        Some(AbortCode::CRC_ERROR) => {}
        Some(code) => return Err(fail_abort("expected 0x05040004", code)),
        None => return Err(fail(format!("a wrong CRC was accepted: {b:02X?}"))),
    }
    recovered(ctx, "a CRC error")?;
    Ok(format!("0x{index:04X} sub {sub}: 0x05040004"))
}

fn abort_timeout(ctx: &mut Ctx<'_>) -> Outcome {
    let Some((index, sub, size, _)) = writable(ctx, 1..=7)? else {
        return Err(Finding::NotApplicable(
            "no writable entry of fixed size".into(),
        ));
    };
    let s = u32::try_from(size).unwrap_or(0).to_le_bytes();
    let Some(b) = ctx.sdo_raw(req(0x21, index, sub, s))? else {
        return Err(fail_kind(
            FailureKind::Silence,
            "no answer to a segmented initiate",
        ));
    };
    if let Some(code) = abort_of(&b) {
        return Err(segmented_refused(ctx, "download", code));
    }
    // CiA 301 leaves the server's timeout to the device: wait up to 10 s for it.
    let started = ctx.now();
    let Some(b) = ctx.sdo_answer(Duration::from_secs(10))? else {
        ctx.sdo_raw(req(
            0x80,
            index,
            sub,
            AbortCode::TIMEOUT.to_u32().to_le_bytes(),
        ))?;
        return Err(fail_kind(
            FailureKind::Event,
            "the server did not time out an unfinished segmented download within 10 s",
        ));
    };
    let after = ctx.now().saturating_duration_since(started);
    match abort_of(&b) {
        Some(AbortCode::TIMEOUT) => {}
        Some(code) => return Err(fail_abort("expected 0x05040000", code)),
        None => return Err(fail(format!("unexpected answer {b:02X?}"))),
    }
    recovered(ctx, "a timeout")?;
    Ok(format!("0x05040000 after {} ms", after.as_millis()))
}
