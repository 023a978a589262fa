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
