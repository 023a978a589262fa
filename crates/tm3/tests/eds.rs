//! The island's EDS (CiA 306), generated from its dictionary: it parses back into the same
//! dictionary, and carries the identity and PDO counts of the coupler.
#![allow(clippy::unwrap_used)]

use cantwin_tm3::island::Island;
use cantwin_tm3::{eds, od};

#[test]
fn cia306_island_eds_round_trips_to_the_same_dictionary() {
    let island = Island::from_references(&[
        "TM3DI16",
        "TM3DQ16T",
        "TM3DM24R",
        "TM3AI4",
        "TM3AQ2",
        "TM2DDI8DT",
    ])
    .unwrap();
    let text = eds::eds_text(&island).unwrap();
    let parsed = cantwin_eds::parse(&text).unwrap();
    assert_eq!(parsed.device_info.vendor_number, Some(0x0500_005A));
    assert_eq!(parsed.device_info.product_number, Some(811_044));
    assert_eq!(parsed.device_info.nr_of_rx_pdo, Some(29));
    assert_eq!(parsed.device_info.nr_of_tx_pdo, Some(56));
    let back = cantwin_eds::to_od(&parsed).unwrap();
    let desc = od::description(&island).unwrap();
    let indices = |d: &cantwin_canopen::od::OdDescription| {
        d.objects()
            .map(|o| (o.index(), o.sub_number()))
            .collect::<Vec<_>>()
    };
    assert_eq!(indices(&back), indices(&desc));
    for o in desc.objects() {
        for (sub, s) in o.subs() {
            let b = back.get(o.index(), sub).unwrap();
            assert_eq!(b.data_type, s.data_type, "{:#06x}:{sub}", o.index());
            assert_eq!(b.access, s.access, "{:#06x}:{sub}", o.index());
            assert_eq!(
                b.default_for(3),
                s.default_for(3),
                "{:#06x}:{sub}",
                o.index()
            );
        }
    }
    assert!(text.contains("ParameterName=Read input 8-bit"));
}

#[test]
fn cia306_eds_of_an_empty_island() {
    let text = eds::eds_text(&Island::from_references::<&str>(&[]).unwrap()).unwrap();
    let back = cantwin_eds::to_od(&cantwin_eds::parse(&text).unwrap()).unwrap();
    assert_eq!(back.object(0x1027).map(|o| o.sub_number()), Some(15));
    assert!(back.object(0x6000).is_none());
}
