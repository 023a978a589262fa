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

/// What CiA 306 §4 requires of every EDS and DCF that the file lacks: the sections of
/// the file and device information (§4.5.1, §4.5.2), the object lists (§4.5.4) and at least
/// one object. A section without a key reads as absent: each of these has mandatory keys.
pub(crate) fn missing_parts(eds: &cantwin_eds::Eds) -> Vec<String> {
    let mut missing = Vec::new();
    if eds.file_info == cantwin_eds::FileInfo::default() {
        missing.push("no [FileInfo] (CiA 306 §4.5.1)".to_string());
    }
    if eds.device_info == cantwin_eds::DeviceInfo::default() {
        missing.push("no [DeviceInfo] (CiA 306 §4.5.2)".to_string());
    }
    if eds.mandatory_objects.is_empty() {
        missing.push("no [MandatoryObjects] list (CiA 306 §4.5.4)".to_string());
    }
    if eds.objects.is_empty() {
        missing.push("no object defined (CiA 306 §4.6)".to_string());
    }
    missing
}

fn file_valid(ctx: &mut Ctx<'_>) -> Outcome {
    let report = ctx.eds.check();
    let mut errors = missing_parts(ctx.eds);
    errors.extend(report.errors().map(|i| i.to_string()));
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

#[cfg(test)]
mod tests {
    use cantwin_can::{Frame, Instant};

    use crate::transport::{Transport, TransportError};
    use crate::{Area, Options, Profile, Verdict, run};

    /// A bus with nobody on it: the file checks need none.
    struct Silent(Instant);

    impl Transport for Silent {
        fn send(&mut self, _frame: Frame) -> Result<(), TransportError> {
            Ok(())
        }
        fn recv(&mut self, deadline: Instant) -> Result<Option<(Instant, Frame)>, TransportError> {
            self.0 = self.0.max(deadline);
            Ok(None)
        }
        fn now(&self) -> Instant {
            self.0
        }
        fn describe(&self) -> String {
            "silence".into()
        }
    }

    fn file_valid(text: &str) -> (Verdict, String) {
        let eds = cantwin_eds::load(text).eds;
        let skip = crate::catalogue()
            .iter()
            .filter(|c| c.area == Area::Eds && c.id != "eds.file-valid")
            .map(|c| c.id.to_string())
            .collect();
        let options = Options {
            only: vec![Area::Eds],
            skip,
            ..Options::default()
        };
        let r = run(
            &mut Silent(Instant::ZERO),
            5,
            &eds,
            &Profile::from_eds(&eds),
            &options,
            &mut |_| {},
        );
        let c = r.case("eds.file-valid").unwrap();
        (c.verdict, c.detail.clone())
    }

    const COMPLETE: &str = "[FileInfo]\nFileName=x.eds\nEDSVersion=4.0\n\
        [DeviceInfo]\nVendorName=x\nProductName=y\n\
        [MandatoryObjects]\nSupportedObjects=2\n1=0x1000\n2=0x1001\n\
        [1000]\nParameterName=Device type\nObjectType=0x7\nDataType=0x0007\nAccessType=ro\nDefaultValue=0\nPDOMapping=0\n\
        [1001]\nParameterName=Error register\nObjectType=0x7\nDataType=0x0005\nAccessType=ro\nPDOMapping=0\n";

    #[test]
    fn cia306_4_an_empty_file_is_not_a_valid_eds() {
        let (v, why) = file_valid("");
        assert_eq!(v, Verdict::Fail, "{why}");
        for part in [
            "[FileInfo]",
            "[DeviceInfo]",
            "[MandatoryObjects]",
            "no object",
        ] {
            assert!(why.contains(part), "{part}: {why}");
        }
    }

    #[test]
    fn cia306_4_a_file_without_its_device_information_is_not_a_valid_eds() {
        let (v, why) =
            file_valid(&COMPLETE.replace("[DeviceInfo]\nVendorName=x\nProductName=y\n", ""));
        assert_eq!(v, Verdict::Fail, "{why}");
        assert!(why.contains("[DeviceInfo]"), "{why}");
        assert!(!why.contains("[FileInfo]"), "{why}");
    }

    #[test]
    fn cia306_4_a_text_file_is_not_a_valid_eds() {
        let (v, why) = file_valid("hello, this is not an EDS\n");
        assert_eq!(v, Verdict::Fail, "{why}");
    }

    #[test]
    fn cia306_4_a_complete_file_is_valid() {
        let (v, why) = file_valid(COMPLETE);
        assert_eq!(v, Verdict::Pass, "{why}");
    }
}
