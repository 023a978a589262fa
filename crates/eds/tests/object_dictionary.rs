//! Between EDS/DCF files and the object dictionary: a device's EDS is generated from its
//! dictionary in the form python-canopen's importer reads, and EDS/DCF files load back.
#![allow(clippy::unwrap_used)]

use cantwin_canopen::AbortCode;
use cantwin_canopen::od::{
    Access, DataType, ObjectCode, ObjectDictionary, OdBuilder, OdDescription, SubObject, Value,
};
use cantwin_eds::{
    ConvertError, DeviceInfo, EdsValue, FileInfo, apply_parameter_values, from_od, parse,
    parse_bytes, to_dcf, to_od, write,
};
use std::path::PathBuf;
use std::sync::Arc;

fn u32_ro(name: &str, v: u32) -> SubObject {
    SubObject::new(name, DataType::Unsigned32, Access::Ro).default(Value::Unsigned32(v))
}

fn device() -> OdDescription {
    OdBuilder::new()
        .var(0x1000, u32_ro("Device type", 0x000F_0191))
        .var(
            0x1001,
            SubObject::new("Error register", DataType::Unsigned8, Access::Ro).mappable(),
        )
        .var(
            0x1008,
            SubObject::new(
                "Manufacturer device name",
                DataType::VisibleString,
                Access::Const,
            )
            .default(Value::VisibleString("TM3 coupler".into())),
        )
        .var(
            0x1014,
            SubObject::new("COB-ID EMCY", DataType::Unsigned32, Access::Ro)
                .default_node_id_plus(Value::Unsigned32(0x80)),
        )
        .record(
            0x1018,
            "Identity object",
            [
                (1, u32_ro("Vendor-ID", 0x0000_005A)),
                (2, u32_ro("Product code", 0x0000_1234)),
                (3, u32_ro("Revision number", 0x0001_0002)),
            ],
        )
        .var(
            0x1021,
            SubObject::new("Store EDS", DataType::Domain, Access::Ro)
                .default(Value::Domain(vec![0x5B, 0x5D])),
        )
        .var(
            0x2000,
            SubObject::new("Speed limit", DataType::Integer16, Access::Rw)
                .default(Value::Integer16(-100))
                .limits(Value::Integer16(-3000), Value::Integer16(3000)),
        )
        .flags(0x1)
        .var(
            0x2001,
            SubObject::new("Gain", DataType::Real32, Access::Rww)
                .default(Value::Real32(0.25))
                .mappable(),
        )
        .array_of(
            0x6000,
            "Read input 8-bit",
            2,
            SubObject::new("Input", DataType::Unsigned8, Access::Ro).mappable(),
        )
        .compact()
        .build()
        .unwrap()
}

fn info() -> DeviceInfo {
    let mut d = DeviceInfo {
        vendor_name: Some("cantwin".into()),
        product_name: Some("Test device".into()),
        granularity: Some(8),
        nr_of_rx_pdo: Some(0),
        nr_of_tx_pdo: Some(0),
        ..DeviceInfo::default()
    };
    d.set_baud_rates(&[125, 250, 500]);
    d
}

#[test]
fn generated_eds_has_the_form_python_canopen_imports() {
    let eds = from_od(&device(), info(), FileInfo::new("device.eds"));
    let text = write(&eds);
    for fragment in [
        "[FileInfo]\nFileName=device.eds\nFileVersion=1\nFileRevision=0\nEDSVersion=4.0\n\n",
        "[DeviceInfo]\nVendorName=cantwin\nVendorNumber=0x0000005A\nProductName=Test device\nProductNumber=0x00001234\nRevisionNumber=0x00010002\nBaudRate_10=0\nBaudRate_20=0\nBaudRate_50=0\nBaudRate_125=1\nBaudRate_250=1\nBaudRate_500=1\nBaudRate_800=0\nBaudRate_1000=0\nGranularity=8\n",
        "[MandatoryObjects]\nSupportedObjects=3\n1=0x1000\n2=0x1001\n3=0x1018\n",
        "[OptionalObjects]\nSupportedObjects=4\n1=0x1008\n2=0x1014\n3=0x1021\n4=0x6000\n",
        "[ManufacturerObjects]\nSupportedObjects=2\n1=0x2000\n2=0x2001\n",
        "[1000]\nParameterName=Device type\nObjectType=0x7\nDataType=0x0007\nAccessType=ro\nDefaultValue=0xF0191\nPDOMapping=0\n",
        "[1001]\nParameterName=Error register\nObjectType=0x7\nDataType=0x0005\nAccessType=ro\nDefaultValue=0x0\nPDOMapping=1\n",
        "[1008]\nParameterName=Manufacturer device name\nObjectType=0x7\nDataType=0x0009\nAccessType=const\nDefaultValue=TM3 coupler\n",
        "DefaultValue=$NODEID+0x80\n",
        "[1018]\nParameterName=Identity object\nObjectType=0x9\nSubNumber=0x4\n",
        "[1018sub0]\nParameterName=Highest sub-index supported\nObjectType=0x7\nDataType=0x0005\nAccessType=const\nDefaultValue=0x3\nPDOMapping=0\n",
        "[1018sub1]\nParameterName=Vendor-ID\nObjectType=0x7\nDataType=0x0007\nAccessType=ro\nDefaultValue=0x5A\nPDOMapping=0\n",
        "[1021]\nParameterName=Store EDS\nObjectType=0x7\nDataType=0x000F\nAccessType=ro\nDefaultValue=5B5D\n",
        "[2000]\nParameterName=Speed limit\nObjectType=0x7\nDataType=0x0003\nAccessType=rw\nDefaultValue=-100\nPDOMapping=0\nLowLimit=-3000\nHighLimit=3000\nObjFlags=0x1\n",
        "DataType=0x0008\nAccessType=rww\nDefaultValue=0.25\nPDOMapping=1\n",
        "[6000]\nParameterName=Read input 8-bit\nObjectType=0x8\nCompactSubObj=0x2\nDataType=0x0005\nAccessType=ro\nDefaultValue=0x0\nPDOMapping=1\n",
        "[6000Name]\nNrOfEntries=2\n1=Input 1\n2=Input 2\n",
    ] {
        assert!(text.contains(fragment), "missing:\n{fragment}\nin:\n{text}");
    }
    // python-canopen reads integers with int(x, 0), which refuses leading-zero decimals.
    for line in text.lines() {
        if let Some((_, v)) = line.split_once('=') {
            let v = v.trim_start_matches('-');
            let octal_looking =
                v.len() > 1 && v.starts_with('0') && v.bytes().all(|b| b.is_ascii_digit());
            assert!(!octal_looking, "{line}");
        }
    }
    assert!(eds.check().is_ok(), "{}", eds.check());
    assert_eq!(parse(&text).unwrap(), eds);
}

#[test]
fn generated_eds_loads_back_into_the_same_dictionary() {
    let desc = device();
    let eds = parse(&write(&from_od(&desc, info(), FileInfo::default()))).unwrap();
    let back = to_od(&eds).unwrap();
    assert_eq!(back.len(), desc.len());
    for (a, b) in desc.objects().zip(back.objects()) {
        assert_eq!(a.index(), b.index());
        assert_eq!(a.name(), b.name());
        assert_eq!(a.code(), b.code());
        assert_eq!(a.flags(), b.flags());
        assert_eq!(a.compact_sub_obj(), b.compact_sub_obj());
        // A compact array's sub-index 0 is CiA 306's "NrOfObjects"; the rest is identical.
        let skip = usize::from(a.compact_sub_obj());
        // An absent default is the type's zero, which the EDS states explicitly.
        let norm = |(s, d): (u8, &SubObject)| {
            let mut d = d.clone();
            d.default = Some(d.default.unwrap_or_else(|| Value::zero(d.data_type)));
            (s, d)
        };
        let sa: Vec<_> = a.subs().skip(skip).map(norm).collect();
        let sb: Vec<_> = b.subs().skip(skip).map(norm).collect();
        assert_eq!(sa, sb, "{:#06X}", a.index());
    }
}

fn corpus(name: &str) -> cantwin_eds::Eds {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/corpus")
        .join(name);
    parse_bytes(&std::fs::read(p).unwrap()).unwrap()
}

#[test]
fn corpus_drive_becomes_a_working_dictionary() {
    let desc = Arc::new(to_od(&corpus("drive.eds")).unwrap());
    let mut od = ObjectDictionary::new(desc, 5);
    assert_eq!(od.get(0x1200, 1), Ok(Value::Unsigned32(0x605)));
    assert_eq!(od.get(0x1200, 2), Ok(Value::Unsigned32(0x585)));
    assert_eq!(od.get(0x2001, 0), Ok(Value::Integer32(-150)));
    assert_eq!(od.get(0x2000, 1), Ok(Value::Real32(12.5)));
    assert_eq!(od.get(0x2002, 0), Ok(Value::Boolean(true)));
    assert_eq!(
        od.get(0x1008, 0),
        Ok(Value::VisibleString("Drive V1 (400 V)".into()))
    );
    // Pole pairs: 1..=32.
    assert_eq!(
        od.download(0x2000, 2, &[40]),
        Err(AbortCode::VALUE_TOO_HIGH)
    );
    assert_eq!(od.download(0x2000, 2, &[0]), Err(AbortCode::VALUE_TOO_LOW));
    assert_eq!(od.download(0x2000, 2, &[4]), Ok(()));
    assert_eq!(od.download(0x1018, 1, &[0; 4]), Err(AbortCode::READ_ONLY));
}

#[test]
fn cia306_5_dcf_parameter_values_configure_the_device() {
    let dcf = corpus("configured.dcf");
    let desc = Arc::new(to_od(&dcf).unwrap());
    let node = dcf.commissioning.as_ref().unwrap().node_id.unwrap();
    let mut od = ObjectDictionary::new(desc, node);
    assert_eq!(od.get(0x1017, 0), Ok(Value::Unsigned16(0)));
    assert_eq!(apply_parameter_values(&dcf, &mut od), Ok(6));
    assert_eq!(od.get(0x1017, 0), Ok(Value::Unsigned16(500)));
    assert_eq!(od.get(0x1800, 1), Ok(Value::Unsigned32(0x185)));
    assert_eq!(od.get(0x1800, 2), Ok(Value::Unsigned8(1)));
    assert_eq!(od.get(0x6000, 2), Ok(Value::Unsigned8(0x0F)));
    assert_eq!(od.get(0x6000, 1), Ok(Value::Unsigned8(0)));
}

#[test]
fn corpus_compact_arrays_stay_compact_in_the_dictionary() {
    let desc = to_od(&corpus("io_module.eds")).unwrap();
    let o = desc.object(0x6000).unwrap();
    assert!(o.compact_sub_obj());
    assert_eq!(o.sub_number(), 3);
    assert_eq!(desc.get(0x6000, 2).unwrap().name, "Inputs 9-16");
    assert!(desc.get(0x6000, 2).unwrap().pdo_mappable);
    assert_eq!(desc.object(0x2000).unwrap().flags(), 1);
    // The DEFTYPE object of the quirks file is held with its code and the type's length in
    // bits (CiA 301 §7.4.7.1).
    let q = to_od(&corpus("quirks.eds")).unwrap();
    assert_eq!(q.object(0x0002).unwrap().code(), ObjectCode::DefType);
    assert_eq!(
        q.get(0x0002, 0).unwrap().default,
        Some(Value::Unsigned32(8))
    );
    assert!(q.object(0x1000).is_some());
}

#[test]
fn conversion_takes_the_evident_intent_and_fails_only_without_a_data_type() {
    let mut eds = corpus("drive.eds");
    let e = eds
        .objects
        .get_mut(&0x6048)
        .unwrap()
        .subs
        .get_mut(&2)
        .unwrap();
    e.access_type = None;
    let desc = to_od(&eds).unwrap();
    assert_eq!(desc.get(0x6048, 2).unwrap().access, Access::Ro);
    let mut eds = corpus("drive.eds");
    eds.objects.get_mut(&0x2002).unwrap().entry.default_value = Some(EdsValue::Integer(2));
    let desc = to_od(&eds).unwrap();
    assert_eq!(desc.get(0x2002, 0).unwrap().default, None);
    eds.objects.get_mut(&0x2002).unwrap().entry.data_type = None;
    let e = to_od(&eds).unwrap_err();
    assert_eq!(
        e,
        ConvertError::DataType {
            index: 0x2002,
            sub: 0,
            data_type: None
        }
    );
    assert_eq!(e.to_string(), "0x2002:0: data type None is not supported");
}

/// The stack's own CiA 301 communication objects and PDO objects: the EDS of every CANopen
/// device starts from these.
fn cia301_device() -> OdDescription {
    use cantwin_canopen::objects::{Cia301Options, cia301_defaults};
    use cantwin_canopen::pdo::PdoObjects;
    let options = Cia301Options {
        vendor_id: 0x0000_005A,
        product_code: 0x1234,
        revision: 0x0001_0000,
        device_name: "cantwin device".into(),
        ..Cia301Options::default()
    };
    let b = cia301_defaults(OdBuilder::new(), &options);
    // TPDO1 maps the VAR 0x6000 (sub-index 0), 8 bits.
    let b = PdoObjects::new(2, 2).tpdo(0, 255, &[0x6000_0008]).add_to(b);
    b.var(
        0x6000,
        SubObject::new("Inputs", DataType::Unsigned8, Access::Ro).mappable(),
    )
    .build()
    .unwrap()
}

#[test]
fn cia301_default_dictionary_generates_a_clean_lossless_eds() {
    let desc = cia301_device();
    let eds = from_od(&desc, info(), FileInfo::new("cia301.eds"));
    let report = eds.check();
    assert!(report.issues.is_empty(), "{report}");
    let text = write(&eds);
    let back = parse(&text).unwrap();
    assert_eq!(back, eds);
    assert!(text.contains("[1200sub1]\nParameterName="));
    assert!(text.contains("DefaultValue=$NODEID+0x600\n"));
    // TPDO1 is mapped, hence valid; RPDO1 is not, hence bit 31 set (CiA 301 PDO COB-ID).
    assert!(text.contains("DefaultValue=$NODEID+0x180\n"));
    assert!(text.contains("DefaultValue=$NODEID+0x80000200\n"));
    assert_eq!(back.device_info.vendor_number, Some(0x5A));
    let od = to_od(&back).unwrap();
    assert_eq!(od.len(), desc.len());
    for (a, b) in desc.objects().zip(od.objects()) {
        assert_eq!(
            (a.index(), a.name(), a.code()),
            (b.index(), b.name(), b.code())
        );
        let skip = usize::from(a.compact_sub_obj());
        let norm = |(s, d): (u8, &SubObject)| {
            let mut d = d.clone();
            d.default = Some(d.default.unwrap_or_else(|| Value::zero(d.data_type)));
            d.max_len = None;
            (s, d)
        };
        let sa: Vec<_> = a.subs().skip(skip).map(norm).collect();
        let sb: Vec<_> = b.subs().skip(skip).map(norm).collect();
        assert_eq!(sa, sb, "{:#06X}", a.index());
    }
    // The same device at node 0x22 gets the same COB-IDs from either dictionary.
    let from_eds = ObjectDictionary::new(Arc::new(od), 0x22);
    let original = ObjectDictionary::new(Arc::new(desc), 0x22);
    for (index, sub) in [
        (0x1014, 0),
        (0x1200, 1),
        (0x1200, 2),
        (0x1800, 1),
        (0x1400, 1),
    ] {
        assert_eq!(
            from_eds.get(index, sub),
            original.get(index, sub),
            "{index:#06X}:{sub}"
        );
    }
    assert_eq!(from_eds.get(0x1800, 1), Ok(Value::Unsigned32(0x1A2)));
    assert_eq!(from_eds.get(0x1400, 1), Ok(Value::Unsigned32(0x8000_0222)));
}

#[test]
fn cia306_5_device_values_round_trip_through_a_dcf() {
    let desc = Arc::new(cia301_device());
    let mut od = ObjectDictionary::new(Arc::clone(&desc), 0x22);
    od.set(0x1017, 0, &Value::Unsigned16(250)).unwrap();
    od.set(0x1800, 2, &Value::Unsigned8(1)).unwrap();
    od.set(0x1008, 0, &Value::VisibleString("renamed".into()))
        .unwrap();
    let eds = from_od(&desc, info(), FileInfo::new("cia301.eds"));
    let commissioning = cantwin_eds::DeviceCommissioning {
        node_id: Some(0x22),
        baudrate: Some(500),
        ..Default::default()
    };
    let text = write(&to_dcf(&eds, &od, commissioning));
    assert!(text.contains("[DeviceComissioning]\nNodeID=34\nBaudrate=500\n"));
    assert!(text.contains("ParameterValue=0xFA\n"));
    // ParameterValue is the device's actual value: the node-ID is already added.
    assert!(text.contains("DefaultValue=$NODEID+0x600\nPDOMapping=0\nParameterValue=0x622\n"));
    let dcf = parse(&text).unwrap();
    assert!(dcf.is_dcf());
    let mut fresh = ObjectDictionary::new(Arc::clone(&desc), 0x22);
    let applied = apply_parameter_values(&dcf, &mut fresh).unwrap();
    let total: usize = desc.objects().map(|o| o.sub_number()).sum();
    assert_eq!(applied, total);
    for o in desc.objects() {
        for (sub, _) in o.subs() {
            assert_eq!(
                fresh.get(o.index(), sub),
                od.get(o.index(), sub),
                "{:#06X}:{sub}",
                o.index()
            );
        }
    }
}

/// TIME_OF_DAY and TIME_DIFFERENCE defaults are written as `days ms` (the form tools write,
/// CiA 306 gives these types none of its own) and load back as the same value.
#[test]
fn time_of_day_is_exported_as_days_and_ms_and_loads_back() {
    use cantwin_canopen::od::TimeOfDay;
    let t = TimeOfDay {
        days: 365,
        ms: 43_200_000,
    };
    let desc = OdBuilder::new()
        .var(0x1000, u32_ro("Device type", 0))
        .var(
            0x2000,
            SubObject::new("Time", DataType::TimeOfDay, Access::Rw).default(Value::TimeOfDay(t)),
        )
        .var(
            0x2001,
            SubObject::new("Span", DataType::TimeDifference, Access::Rw)
                .default(Value::TimeDifference(TimeOfDay { days: 2, ms: 5 })),
        )
        .build()
        .unwrap();
    let text = write(&from_od(&desc, info(), FileInfo::new("t.eds")));
    assert!(text.contains("DefaultValue=365 43200000\n"), "{text}");
    assert!(text.contains("DefaultValue=2 5\n"), "{text}");
    let back = cantwin_eds::load(&text);
    assert!(back.report.is_ok(), "{}", back.report);
    let d = to_od(&back.eds).unwrap();
    assert_eq!(d.get(0x2000, 0).unwrap().default, Some(Value::TimeOfDay(t)));
    assert_eq!(
        d.get(0x2001, 0).unwrap().default,
        Some(Value::TimeDifference(TimeOfDay { days: 2, ms: 5 }))
    );
}

/// A file whose node-relative `ParameterValue`s were written for a node it does not name
/// (no `[DeviceComissioning] NodeID`): made for another node, the values that are that
/// node's `$NODEID` defaults move to the new node, the others stay, with a warning.
#[test]
fn commission_moves_values_written_for_an_unnamed_node() {
    let text = "[1014]\nParameterName=COB-ID EMCY\nDataType=0x0007\nAccessType=rw\n\
                DefaultValue=$NODEID+0x80\nParameterValue=0xA0\n\n\
                [1200]\nParameterName=SDO server\nObjectType=0x9\nSubNumber=3\n\n\
                [1200sub0]\nParameterName=n\nDataType=0x0005\nAccessType=ro\nDefaultValue=2\n\n\
                [1200sub1]\nParameterName=rx\nDataType=0x0007\nAccessType=ro\n\
                DefaultValue=$NODEID+0x600\nParameterValue=0x620\n\n\
                [1200sub2]\nParameterName=tx\nDataType=0x0007\nAccessType=ro\n\
                DefaultValue=$NODEID+0x580\nParameterValue=0x5A5\n";
    let eds = cantwin_eds::load(text).eds;
    let (dcf, found) = cantwin_eds::commission(&eds, 3, Default::default());
    let pv = |i, s| dcf.entry(i, s).unwrap().parameter_value.clone();
    assert_eq!(pv(0x1014, 0), Some(EdsValue::Integer(0x83)));
    assert_eq!(pv(0x1200, 1), Some(EdsValue::Integer(0x603)));
    assert_eq!(pv(0x1200, 2), Some(EdsValue::Integer(0x5A5)));
    let said: Vec<String> = found.iter().map(ToString::to_string).collect();
    assert!(
        said.iter().any(|s| s.contains("evidently for node 32")),
        "{said:?}"
    );
    assert!(
        said.iter()
            .any(|s| s.starts_with("warning: [1200sub2]") && s.contains("node-specific")),
        "{said:?}"
    );
}
