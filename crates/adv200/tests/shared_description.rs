//! Drives given one set of descriptions share the card's dictionary description when
//! their cards are alike, and keep their own node-ID and values.
#![allow(clippy::unwrap_used)]

use cantwin_adv200::od::Descriptions;
use cantwin_adv200::params::par;
use cantwin_adv200::{Adv200, Adv200Config};
use cantwin_can::{Instant, Node, Outbox};
use cantwin_canopen::od::{OdDescription, Value};
use std::sync::Arc;

/// A powered drive on `descriptions` with the card set to `personality` at `node`.
fn drive(descriptions: &Arc<Descriptions>, personality: &str, node: i64, serial: u32) -> Adv200 {
    let config = Adv200Config {
        serial,
        ..Adv200Config::default()
    };
    let mut d = Adv200::with_descriptions(config, Arc::clone(descriptions));
    d.set_param_str(par::FIELDBUS_TYPE, personality).unwrap();
    d.set_param_str(par::FIELDBUS_BAUDRATE, "500k").unwrap();
    d.set_param(par::FIELDBUS_ADDRESS, node).unwrap();
    d.on_power_up(Instant::ZERO, &mut Outbox::new());
    d
}

fn description(d: &Adv200) -> Arc<OdDescription> {
    Arc::clone(d.device().unwrap().od().description())
}

#[test]
fn alike_drives_share_one_description_with_their_own_node_id() {
    let shared = Arc::new(Descriptions::new());
    let a = drive(&shared, "CANopen", 12, 1);
    let b = drive(&shared, "CANopen", 13, 1);
    assert!(Arc::ptr_eq(&description(&a), &description(&b)));
    assert_eq!(shared.in_use(), 1);
    // `$NODEID` defaults resolve per drive: COB-ID EMCY and TPDO1 (no RTR; invalid, as
    // nothing is mapped).
    for (d, node) in [(&a, 12u32), (&b, 13)] {
        let od = d.device().unwrap().od();
        assert_eq!(od.get(0x1014, 0).unwrap(), Value::Unsigned32(0x80 + node));
        assert_eq!(
            od.get(0x1800, 1).unwrap(),
            Value::Unsigned32(0xC000_0180 + node)
        );
    }
}

#[test]
fn drives_of_another_personality_or_serial_get_their_own() {
    let shared = Arc::new(Descriptions::new());
    let canopen = drive(&shared, "CANopen", 12, 1);
    let ds402 = drive(&shared, "DS402", 13, 1);
    let serial = drive(&shared, "CANopen", 14, 2);
    let ds402_again = drive(&shared, "DS402", 15, 1);
    assert!(!Arc::ptr_eq(&description(&canopen), &description(&ds402)));
    assert!(!Arc::ptr_eq(&description(&canopen), &description(&serial)));
    assert!(Arc::ptr_eq(
        &description(&ds402),
        &description(&ds402_again)
    ));
    let od = serial.device().unwrap().od();
    assert_eq!(od.get(0x1018, 4).unwrap(), Value::Unsigned32(2));
    assert_eq!(shared.in_use(), 3);
}

/// A PDC placed differently changes the default PDO mappings: the drive gets a description
/// of its own at the next drive reset, and the one no drive uses any more is let go.
#[test]
fn a_drive_reset_with_another_pdc_leaves_the_shared_description() {
    let shared = Arc::new(Descriptions::new());
    let mut a = drive(&shared, "CANopen", 12, 1);
    let b = drive(&shared, "CANopen", 13, 1);
    let before = description(&a);
    let mut out = Outbox::new();
    a.reset_drive(Instant::ZERO, &mut out);
    assert!(Arc::ptr_eq(&description(&a), &before), "rebuilt alike");

    // §1.6: M2S channel 1 carries a 16-bit word to the word decomposition, so RPDO1 maps
    // one object.
    a.set_param_str(par::m2s_sys(1), "Count 16").unwrap();
    a.set_param(par::m2s_ipa(1), i64::from(par::WORD_DECOMP_SRC))
        .unwrap();
    a.reset_drive(Instant::ZERO, &mut out);
    assert!(a.opt_bus_faults().is_empty());
    assert!(!Arc::ptr_eq(&description(&a), &description(&b)));
    assert_eq!(shared.in_use(), 2);
    drop(before);
    drop(b);
    assert_eq!(shared.in_use(), 1);
    assert_eq!(
        a.device().unwrap().od().get(0x1600, 0).unwrap(),
        Value::Unsigned8(1)
    );
}
