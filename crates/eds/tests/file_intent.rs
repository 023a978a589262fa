//! A device from an EDS keeps what the file says beyond its values: an object without a
//! `DefaultValue` starts inside its own limits, and `[DummyUsage]` (CiA 306 §4.5.5) decides
//! which dummy entries (CiA 301 §7.4.7.1) the dictionary holds, exports and lets an RPDO map.
#![allow(clippy::unwrap_used)]

use cantwin_canopen::device::{Device, DeviceConfig};
use cantwin_canopen::od::{OdDescription, Value};
use cantwin_canopen::{AbortCode, ObjectAccess};
use cantwin_eds::{
    DeviceCommissioning, DeviceInfo, FileInfo, Loaded, Severity, commission, configured, from_od,
    load_bytes, to_od, write,
};
use std::sync::Arc;

const HEAD: &str = "[FileInfo]\nFileName=t.eds\nFileVersion=1\nFileRevision=0\nEDSVersion=4.0\n\n\
[DeviceInfo]\nVendorName=cantwin tests\nVendorNumber=0x0000ABCD\nProductName=T\nProductNumber=1\n\
RevisionNumber=1\nBaudRate_500=1\nSimpleBootUpSlave=1\nGranularity=8\nNrOfRXPDO=1\nNrOfTXPDO=0\n\n";

const MANDATORY: &str = "[MandatoryObjects]\nSupportedObjects=3\n1=0x1000\n2=0x1001\n3=0x1018\n\n\
[1000]\nParameterName=Device type\nObjectType=0x7\nDataType=0x0007\nAccessType=ro\nDefaultValue=0\n\n\
[1001]\nParameterName=Error register\nObjectType=0x7\nDataType=0x0005\nAccessType=ro\nDefaultValue=0\n\n\
[1018]\nParameterName=Identity object\nObjectType=0x9\nSubNumber=2\n\n\
[1018sub0]\nParameterName=Highest sub-index supported\nDataType=0x0005\nAccessType=ro\nDefaultValue=1\n\n\
[1018sub1]\nParameterName=Vendor-ID\nDataType=0x0007\nAccessType=ro\nDefaultValue=0x0000ABCD\n\n";

/// Three manufacturer objects without a `DefaultValue`: 0 is below the LowLimit of the
/// first, above the HighLimit of the second, inside the limits of the third.
const LIMITS: &str = "[ManufacturerObjects]\nSupportedObjects=3\n1=0x2000\n2=0x2001\n3=0x2002\n\n\
[2000]\nParameterName=Low above zero\nObjectType=0x7\nDataType=0x0005\nAccessType=rw\nLowLimit=2\nHighLimit=9\n\n\
[2001]\nParameterName=High below zero\nObjectType=0x7\nDataType=0x0003\nAccessType=rw\nLowLimit=-20\nHighLimit=-5\n\n\
[2002]\nParameterName=Zero inside\nObjectType=0x7\nDataType=0x0005\nAccessType=rw\nLowLimit=0\nHighLimit=9\n\n";

/// RPDO 1 disabled, its mapping empty: entries can be written (CiA 301 §7.5.2.36).
const RPDO: &str = "[OptionalObjects]\nSupportedObjects=2\n1=0x1400\n2=0x1600\n\n\
[1400]\nParameterName=RPDO communication parameter\nObjectType=0x9\nSubNumber=3\n\n\
[1400sub0]\nParameterName=Highest sub-index supported\nDataType=0x0005\nAccessType=const\nDefaultValue=2\n\n\
[1400sub1]\nParameterName=COB-ID\nDataType=0x0007\nAccessType=rw\nDefaultValue=$NODEID+0x80000200\n\n\
[1400sub2]\nParameterName=Transmission type\nDataType=0x0005\nAccessType=rw\nDefaultValue=255\n\n\
[1600]\nParameterName=RPDO mapping parameter\nObjectType=0x9\nSubNumber=3\n\n\
[1600sub0]\nParameterName=Number of mapped objects\nDataType=0x0005\nAccessType=rw\nDefaultValue=0\n\n\
[1600sub1]\nParameterName=Mapping entry 1\nDataType=0x0007\nAccessType=rw\nDefaultValue=0\n\n\
[1600sub2]\nParameterName=Mapping entry 2\nDataType=0x0007\nAccessType=rw\nDefaultValue=0\n\n";

/// BOOLEAN, INTEGER8 and INTEGER16 unsupported, the unsigned dummies supported, declared in
/// `[DummyUsage]` alone (no `[0002]`..`[0007]` sections).
const DUMMY_USAGE: &str = "[DummyUsage]\nDummy0001=0\nDummy0002=0\nDummy0003=0\nDummy0004=0\n\
Dummy0005=1\nDummy0006=1\nDummy0007=1\n\n";

fn load(text: &str) -> Loaded {
    let l = load_bytes(text.as_bytes());
    assert!(l.report.is_ok(), "{}", l.report);
    l
}

fn device(desc: OdDescription) -> Device {
    Device::new(Arc::new(desc), DeviceConfig::new(5)).unwrap()
}

fn read(dev: &mut Device, index: u16, sub: u8) -> Vec<u8> {
    let mut buf = vec![0; 64];
    let info = dev.read(index, sub, 0, &mut buf).unwrap();
    buf.truncate(info.copied);
    buf
}

/// CiA 301 §7.2.4.3.17: the value a device starts with lies inside its own limits, so
/// writing back what was read never aborts 0x06090031/32; `eds dcf` still invents no value.
#[test]
fn an_object_without_default_starts_at_the_limit_nearest_zero() {
    let l = load(&format!("{HEAD}{MANDATORY}{LIMITS}"));
    for (section, key) in [("2000", "LowLimit"), ("2001", "HighLimit")] {
        assert!(
            l.report.issues.iter().any(|i| i.severity == Severity::Note
                && i.section.eq_ignore_ascii_case(section)
                && i.key.as_deref() == Some("DefaultValue")
                && i.message.contains(&format!("starts at {key}"))),
            "no note for [{section}] in\n{}",
            l.report
        );
    }
    assert!(
        !l.report.issues.iter().any(|i| i.section == "2002"),
        "{}",
        l.report
    );
    let desc = to_od(&configured(&l.eds)).unwrap();
    assert_eq!(
        desc.get(0x2000, 0).unwrap().default,
        Some(Value::Unsigned8(2))
    );
    assert_eq!(
        desc.get(0x2001, 0).unwrap().default,
        Some(Value::Integer16(-5))
    );
    let mut dev = device(desc);
    assert_eq!(read(&mut dev, 0x2000, 0), [2]);
    assert_eq!(read(&mut dev, 0x2001, 0), (-5i16).to_le_bytes());
    assert_eq!(read(&mut dev, 0x2002, 0), [0]);
    for (index, sub) in [(0x2000, 0), (0x2001, 0), (0x2002, 0)] {
        let v = read(&mut dev, index, sub);
        assert_eq!(dev.write(index, sub, &v), Ok(()), "{index:#06X}");
    }
    assert_eq!(
        dev.write(0x2000, 0, &[1]),
        Err(AbortCode::VALUE_TOO_LOW),
        "the limits still hold"
    );
    let (dcf, notes) = commission(&l.eds, 5, DeviceCommissioning::default());
    assert_eq!(dcf.entry(0x2000, 0).unwrap().parameter_value, None);
    assert_eq!(dcf.entry(0x2001, 0).unwrap().parameter_value, None);
    assert!(notes.iter().any(|n| n.section == "2000"));
}

/// CiA 306 §4.5.5: the dummy types `[DummyUsage]` supports are DEFTYPE objects of the
/// twin's dictionary, and the EDS exported from it lists them and has their sections.
#[test]
fn dummy_usage_alone_is_kept_and_exported() {
    let l = load(&format!("{HEAD}{DUMMY_USAGE}{MANDATORY}"));
    let desc = to_od(&configured(&l.eds)).unwrap();
    for index in 0x0001..=0x0007u16 {
        assert_eq!(
            desc.object(index).is_some(),
            index >= 0x0005,
            "{index:#06X}"
        );
    }
    assert_eq!(
        desc.get(0x0006, 0).unwrap().default,
        Some(Value::Unsigned32(16))
    );
    let text = write(&from_od(&desc, DeviceInfo::default(), FileInfo::default()));
    let again = load_bytes(text.as_bytes());
    let usage = again.eds.dummy_usage.clone().expect(&text);
    let supported: Vec<u16> = usage
        .iter()
        .filter(|(_, on)| **on)
        .map(|(t, _)| *t)
        .collect();
    assert_eq!(supported, [0x0005, 0x0006, 0x0007], "{text}");
    assert_eq!(usage.len(), 7, "{text}");
    for index in 0x0005..=0x0007u16 {
        assert!(
            again.eds.objects.contains_key(&index),
            "{index:#06X}\n{text}"
        );
        assert!(text.contains(&format!("[{index:04X}]")), "{text}");
    }
    assert!(!text.contains("[0002]"), "{text}");
}

/// CiA 301 §7.4.7.1 and §7.5.2.36: an RPDO maps only the dummy types the file supports;
/// the others abort 0x06040041.
#[test]
fn rpdo_maps_only_the_dummies_the_file_supports() {
    let l = load(&format!("{HEAD}{DUMMY_USAGE}{MANDATORY}{RPDO}"));
    let mut dev = device(to_od(&configured(&l.eds)).unwrap());
    for entry in [0x0001_0001u32, 0x0002_0008, 0x0003_0010] {
        assert_eq!(
            dev.write(0x1600, 1, &entry.to_le_bytes()),
            Err(AbortCode::NOT_MAPPABLE),
            "{entry:#010X}"
        );
    }
    assert_eq!(dev.write(0x1600, 1, &0x0005_0008u32.to_le_bytes()), Ok(()));
    assert_eq!(dev.write(0x1600, 2, &0x0007_0020u32.to_le_bytes()), Ok(()));
}
