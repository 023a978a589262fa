//! The EDS files of both CANopen personalities: generated from the object dictionary, clean
//! under the CiA 306 checks, and identical to the files shipped in `crates/adv200/eds/`.
//! `CANTWIN_BLESS=1 cargo test -p cantwin-adv200 --test eds` rewrites the shipped files.
#![allow(clippy::unwrap_used)]

use cantwin_adv200::eds::eds_text;
use cantwin_adv200::od::Personality;

fn check(personality: Personality, file: &str) {
    let text = eds_text(personality).unwrap();
    let eds = cantwin_eds::parse(&text).unwrap();
    let report = eds.check();
    assert!(report.is_ok(), "{:?}", report.errors().collect::<Vec<_>>());
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("eds")
        .join(file);
    if std::env::var_os("CANTWIN_BLESS").is_some() {
        std::fs::write(&path, &text).unwrap();
    }
    let shipped = std::fs::read_to_string(&path).unwrap();
    assert!(
        shipped == text,
        "{file} differs from the generated EDS; rerun with CANTWIN_BLESS=1"
    );
}

#[test]
fn manual_1_1_5_canopen_eds_is_generated_from_the_od() {
    check(Personality::CanOpen, "adv200-canopen.eds");
    let eds = cantwin_eds::parse(&eds_text(Personality::CanOpen).unwrap()).unwrap();
    // Table 1.5.1 objects and no TIME object; parameters at 0x2000 + PAR sub 1.
    for index in [
        0x1000u16, 0x1001, 0x1005, 0x100C, 0x1014, 0x1018, 0x1400, 0x1A03, 0x2258,
    ] {
        assert!(eds.objects.contains_key(&index), "{index:04X}");
    }
    assert!(!eds.objects.contains_key(&0x1012));
    assert!(!eds.objects.contains_key(&0x6040));
}

#[test]
fn manual_2_ds402_eds_is_generated_from_the_od() {
    check(Personality::Ds402, "adv200-ds402.eds");
    let eds = cantwin_eds::parse(&eds_text(Personality::Ds402).unwrap()).unwrap();
    for index in [
        0x6040u16, 0x6041, 0x6042, 0x6043, 0x6044, 0x6046, 0x6048, 0x6049, 0x6060, 0x6061,
    ] {
        assert!(eds.objects.contains_key(&index), "{index:04X}");
    }
    // Only what chapter 2 lists: no 0x6502 supported drive modes.
    assert!(!eds.objects.contains_key(&0x6502));
}

#[test]
fn manual_1_2_and_2_units_travel_in_the_eds_unit_key() {
    let unit = |eds: &cantwin_eds::Eds, index: u16, sub: u8| {
        let o = &eds.objects[&index];
        let e = if o.subs.is_empty() {
            &o.entry
        } else {
            &o.subs[&sub]
        };
        e.extra
            .iter()
            .find(|(k, _)| k == "Unit")
            .map(|(_, v)| v.clone())
    };
    let eds = cantwin_eds::parse(&eds_text(Personality::CanOpen).unwrap()).unwrap();
    // PAR 600 Dig ramp ref 1 and PAR 900 Speed zero threshold in rpm; a control word has none.
    assert_eq!(unit(&eds, 0x2258, 1).as_deref(), Some("rpm"));
    assert_eq!(unit(&eds, 0x2384, 1).as_deref(), Some("rpm"));
    assert_eq!(unit(&eds, 0x2000 + 4452, 1), None);
    let eds = cantwin_eds::parse(&eds_text(Personality::Ds402).unwrap()).unwrap();
    // Chapter 2 note (1): 0x6042–0x6044 in rpm.
    for index in [0x6042u16, 0x6043, 0x6044] {
        assert_eq!(unit(&eds, index, 0).as_deref(), Some("rpm"), "{index:04X}");
    }
    assert_eq!(unit(&eds, 0x6048, 2).as_deref(), Some("s"));
}

/// The bits of an integer DataType (CiA 301 §7.4.7: INTEGER8 0x02 … UNSIGNED32 0x07).
fn type_bits(data_type: u16) -> Option<u32> {
    match data_type {
        0x0001 | 0x0002 | 0x0005 => Some(8),
        0x0003 | 0x0006 => Some(16),
        0x0004 | 0x0007 => Some(32),
        _ => None,
    }
}

/// Every entry the default mappings of `eds` map: each one's DataType is as wide as its
/// mapping length, and it states its limits.
fn mapped_entries_agree(eds: &cantwin_eds::Eds) -> usize {
    let mut mapped = 0;
    for map in (0x1600u16..=0x1603).chain(0x1A00..=0x1A03) {
        let value = |sub: u8| {
            eds.entry(map, sub)
                .and_then(|e| e.default_value.as_ref())
                .and_then(|v| v.evaluate(1))
                .unwrap() as u32
        };
        for k in 1..=value(0) as u8 {
            let entry = value(k);
            let (index, sub, bits) = ((entry >> 16) as u16, (entry >> 8) as u8, entry & 0xFF);
            let e = eds.entry(index, sub).unwrap();
            let ty = e.data_type.unwrap();
            assert_eq!(
                type_bits(ty),
                Some(bits),
                "{map:04X} sub {k}: {index:04X}sub{sub} is DataType {ty:#06X}, mapped with {bits} bits"
            );
            assert!(
                e.low_limit.is_some() && e.high_limit.is_some(),
                "{index:04X}sub{sub} states no limits"
            );
            mapped += 1;
        }
    }
    mapped
}

#[test]
fn manual_1_6_exported_eds_types_every_mapped_entry_as_its_mapping() {
    // The worked example's PDC: RPDO1 control word + speed reference, TPDO1 status word,
    // speed and analog input 2 (the mapping python-canopen reads with `map[i].raw`).
    use cantwin_can::Node;
    let mut drive = cantwin_adv200::example::drive().unwrap();
    drive.on_power_up(cantwin_can::Instant::ZERO, &mut cantwin_can::Outbox::new());
    let pdc = drive.pdc().unwrap().clone();
    let eds = cantwin_adv200::eds::eds_for(Personality::CanOpen, &pdc).unwrap();
    assert_eq!(mapped_entries_agree(&eds), 5);
    // PAR 4186 Fieldbus S->M1 mon carries the WordComp status word: UNSIGNED16; 4196 the
    // motor speed: INTEGER16 (1500 rpm reads 1500, not 0x100005DC).
    assert_eq!(eds.entry(0x2000 + 4186, 1).unwrap().data_type, Some(0x0006));
    assert_eq!(eds.entry(0x2000 + 4196, 1).unwrap().data_type, Some(0x0003));
    assert_eq!(eds.entry(0x2000 + 4024, 1).unwrap().data_type, Some(0x0003));
    let report = eds.check();
    assert!(report.is_ok(), "{:?}", report.errors().collect::<Vec<_>>());
    // The twin's own dictionary is the one the EDS describes: the same type at the same
    // index, so a PDO it sends carries what the EDS says.
    let od = drive.device().unwrap().od();
    for (index, sub) in [
        (0x2000u16 + 4186, 1u8),
        (0x2000 + 4196, 1),
        (0x2000 + 4024, 1),
    ] {
        let id = od.locate(index, sub).unwrap();
        let ty = od.sub_object(id).data_type as u16;
        assert_eq!(Some(ty), eds.entry(index, sub).unwrap().data_type);
    }
}

#[test]
fn manual_2_exported_eds_types_every_mapped_entry_as_its_mapping() {
    // RPDO1 0x6040 + 0x6042, TPDO1 0x6041 + 0x6044, 16 bits each.
    let eds = cantwin_eds::parse(&eds_text(Personality::Ds402).unwrap()).unwrap();
    assert_eq!(mapped_entries_agree(&eds), 4);
}

#[test]
fn manual_1_4_out_of_range_writes_abort_with_the_eds_limits() {
    use cantwin_can::{Frame, Instant, Node, Outbox};
    let eds = cantwin_eds::parse(&eds_text(Personality::CanOpen).unwrap()).unwrap();
    // PAR 600 Dig ramp ref 1: ±8000 rpm.
    let e = eds.entry(0x2258, 1).unwrap();
    let hi = e.high_limit.as_ref().and_then(|v| v.evaluate(12)).unwrap();
    let lo = e.low_limit.as_ref().and_then(|v| v.evaluate(12)).unwrap();
    assert_eq!((lo, hi), (-8000, 8000));
    let mut drive = cantwin_adv200::example::drive().unwrap();
    let mut out = Outbox::new();
    drive.on_power_up(Instant::ZERO, &mut out);
    let mut write = |v: i128| {
        out.clear();
        let b = (v as i16).to_le_bytes();
        let req = Frame::std(0x60C, &[0x2B, 0x58, 0x22, 0x01, b[0], b[1], 0, 0]).unwrap();
        drive.on_frame(&req, Instant::from_nanos(1_000_000), &mut out);
        out.frames()[0].data_bytes().to_vec()
    };
    assert_eq!(write(hi), [0x60, 0x58, 0x22, 0x01, 0, 0, 0, 0]);
    assert_eq!(write(lo), [0x60, 0x58, 0x22, 0x01, 0, 0, 0, 0]);
    // 0x06090031 above the high limit, 0x06090032 below the low one.
    assert_eq!(
        write(hi + 1),
        [0x80, 0x58, 0x22, 0x01, 0x31, 0x00, 0x09, 0x06]
    );
    assert_eq!(
        write(lo - 1),
        [0x80, 0x58, 0x22, 0x01, 0x32, 0x00, 0x09, 0x06]
    );
}
