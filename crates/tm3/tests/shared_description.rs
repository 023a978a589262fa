//! Couplers built on one shared description: one description in memory, each coupler with
//! its own node-ID, values and I/O.
#![allow(clippy::unwrap_used)]

use cantwin_can::{Frame, Instant, Node, Outbox};
use cantwin_canopen::od::Value;
use cantwin_tm3::coupler::{CouplerConfig, CouplerError, Tm3Coupler};
use cantwin_tm3::island::Island;
use cantwin_tm3::od::IslandDescription;
use std::sync::Arc;

const MODULES: [&str; 3] = ["TM3DI16", "TM3DQ16T", "TM3AI4"];

fn on(shared: &IslandDescription, node_id: u8) -> Tm3Coupler {
    let island = Island::from_references(&MODULES).unwrap();
    Tm3Coupler::with_description(CouplerConfig::new(node_id, island), shared).unwrap()
}

#[test]
fn couplers_on_one_description_keep_their_own_node_id_and_values() {
    let shared = IslandDescription::new(&Island::from_references(&MODULES).unwrap()).unwrap();
    let mut a = on(&shared, 3);
    let mut b = on(&shared, 9);
    assert!(Arc::ptr_eq(a.description(), b.description()));
    assert!(Arc::ptr_eq(a.description(), shared.description()));

    let mut out = Outbox::new();
    a.on_power_up(Instant::ZERO, &mut out);
    b.on_power_up(Instant::ZERO, &mut out);
    assert_eq!(
        out.frames(),
        [
            Frame::std(0x703, &[0]).unwrap(),
            Frame::std(0x709, &[0]).unwrap()
        ]
    );
    // `$NODEID` defaults resolve per coupler: SDO server and TPDO1 COB-IDs.
    for (c, node) in [(&a, 3u32), (&b, 9)] {
        let od = c.device().od();
        assert_eq!(od.get(0x1200, 1).unwrap(), Value::Unsigned32(0x600 + node));
        assert_eq!(od.get(0x1800, 1).unwrap(), Value::Unsigned32(0x180 + node));
    }
    // An input of one coupler is not the other's.
    a.set_digital_input(1, 0, true).unwrap();
    assert_eq!(a.device().od().get(0x6000, 1).unwrap(), Value::Unsigned8(1));
    assert_eq!(b.device().od().get(0x6000, 1).unwrap(), Value::Unsigned8(0));
}

#[test]
fn a_description_of_other_modules_is_refused() {
    let shared = IslandDescription::new(&Island::from_references(&MODULES).unwrap()).unwrap();
    let other = Island::from_references(&["TM3DI16", "TM3AI4"]).unwrap();
    let refused = Tm3Coupler::with_description(CouplerConfig::new(3, other), &shared);
    assert!(matches!(refused, Err(CouplerError::OtherIsland)));
}
