//! The Twin contract: typed signal values as scripts write them, terminal names, and the
//! generic CiA 301 device's dictionary reached and written through its own checks.

#![allow(clippy::unwrap_used)]

use std::sync::Arc;

use cantwin_can::{Instant, Outbox};
use cantwin_canopen::AbortCode;
use cantwin_canopen::device::{Device, DeviceConfig};
use cantwin_canopen::objects::{Cia301Options, cia301_defaults};
use cantwin_canopen::od::{Access, DataType, OdBuilder, SubObject, Value};
use cantwin_twin::{
    Context, Direction, Fault, FaultError, FaultKind, ObjectError, SignalError, SignalId,
    SignalValue, Twin,
};

fn device() -> Device {
    let desc = cia301_defaults(OdBuilder::new(), &Cia301Options::default())
        .var(
            0x2002,
            SubObject::new("Set point", DataType::Unsigned8, Access::Rw)
                .limits(Value::Unsigned8(0), Value::Unsigned8(100)),
        )
        .build()
        .unwrap();
    Device::new(Arc::new(desc), DeviceConfig::new(5)).unwrap()
}

#[test]
fn signal_values_print_as_scenario_files_write_them() {
    assert_eq!(SignalValue::Real(500.0).to_string(), "500.0");
    assert_eq!(SignalValue::Real(2.5).to_string(), "2.5");
    assert_eq!(SignalValue::Integer(-3).to_string(), "-3");
    assert_eq!(SignalValue::Text("pulled".into()).to_string(), "\"pulled\"");
    let alarms = SignalValue::List(vec!["A2".into(), "A3".into()]);
    assert_eq!(alarms.to_string(), "[\"A2\", \"A3\"]");
}

#[test]
fn numbers_match_within_the_tolerance_and_other_values_exactly() {
    assert!(SignalValue::Real(49.96).matches(&SignalValue::Integer(50), 0.05));
    assert!(!SignalValue::Real(49.9).matches(&SignalValue::Integer(50), 0.05));
    assert!(!SignalValue::Bool(true).matches(&SignalValue::Integer(1), 1.0));
    assert!(SignalValue::Text("on".into()).matches(&SignalValue::Text("on".into()), 0.0));
}

#[test]
fn values_convert_with_errors_naming_the_signal() {
    let id = SignalId::new("rotary_switch");
    assert_eq!(SignalValue::Integer(12).to_int::<u8>(&id), Ok(12));
    let e = SignalValue::Integer(300).to_int::<u8>(&id).unwrap_err();
    assert_eq!(
        e.to_string(),
        "signal \"rotary_switch\" takes an integer in range, not 300"
    );
    let e = SignalValue::Real(f64::NAN).to_f64(&id).unwrap_err();
    assert!(e.to_string().contains("takes a number"), "{e}");
    let e = SignalError::unknown(&id, Direction::Set, "module.M");
    assert_eq!(
        e.to_string(),
        "no signal \"rotary_switch\" to set (signals: module.M)"
    );
}

#[test]
fn terminal_names_carry_their_numbers() {
    let id = SignalId::indexed("digital_output", &[2, 0]);
    assert_eq!(id.as_str(), "digital_output.2.0");
    assert_eq!(id.indices("digital_output"), Some(vec![2, 0]));
    assert_eq!(id.indices("digital_input"), None);
    assert_eq!(
        SignalId::new("digital_output.x").indices("digital_output"),
        None
    );
}

/// CiA 301 §7.2.4.3.3 and table 22: a write goes through the device's download checks
/// (limits: 0x06090031; a wrong size: 0x06070010), reads give the little-endian bytes.
#[test]
fn cia301_device_writes_through_its_own_checks() {
    let mut d = device();
    let mut out = Outbox::new();
    let mut cx = Context::new(Instant::ZERO, &mut out);
    let twin: &mut dyn Twin = &mut d;
    assert_eq!(twin.canopen_node_id(), Some(5));
    twin.write_object(0x2002, 0, &[42], &mut cx).unwrap();
    assert_eq!(twin.read_object(0x2002, 0), Ok(vec![42]));
    assert_eq!(
        twin.write_object(0x2002, 0, &[101], &mut cx),
        Err(ObjectError::Abort(AbortCode::VALUE_TOO_HIGH))
    );
    assert_eq!(
        twin.write_object(0x2002, 0, &[1, 2], &mut cx),
        Err(ObjectError::Abort(AbortCode::TYPE_MISMATCH))
    );
    assert_eq!(
        twin.read_object(0x5FFF, 0),
        Err(ObjectError::Abort(AbortCode::NO_OBJECT))
    );
    assert!(twin.dictionary_heap_bytes().is_some_and(|n| n > 0));
    // No internal faults or signals by default.
    assert_eq!(
        twin.inject(&Fault::internal("FF04"), &mut cx),
        Err(FaultError::None {
            kind: FaultKind::Internal
        })
    );
    assert!(twin.read_signal(&"speed".into()).is_err());
    assert!(twin.summary().is_empty());
}
