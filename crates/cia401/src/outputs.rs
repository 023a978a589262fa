//! Outputs: what the physical outputs show, given the values the master wrote (0x6200,
//! 0x6411) and whether the device is in its failure state.
//!
//! CiA 401 §6.3 and §6.5: on a device failure or a detected communication failure (life
//! guarding, heartbeat, bus-off) an output whose error mode is enabled (0x6206 bit set,
//! 0x6443 = 1) takes its error value (0x6207 bit, 0x6444); the others keep their last
//! value. The change-polarity object 0x6202 inverts the value the master wrote, not the
//! error value, which is the physical state wanted.

use crate::objects::*;
use cantwin_canopen::od::{ObjectDictionary, Value};

fn u8_at(od: &ObjectDictionary, index: u16, sub: u8, default: u8) -> u8 {
    od.get_unsigned(index, sub).map_or(default, |v| v as u8)
}

/// The physical state of output byte `sub` (1-based); 0 for a byte that does not exist.
/// `failure` is true while the device is in its failure state.
pub fn digital_output_byte(od: &ObjectDictionary, sub: u8, failure: bool) -> u8 {
    let written = u8_at(od, WRITE_OUTPUT_8, sub, 0) ^ u8_at(od, POLARITY_OUTPUT_8, sub, 0);
    if !failure {
        return written;
    }
    let mode = u8_at(od, ERROR_MODE_OUTPUT_8, sub, 0xFF);
    let value = u8_at(od, ERROR_VALUE_OUTPUT_8, sub, 0);
    written & !mode | value & mode
}

/// The physical value of analog output `sub` (1-based); 0 for a channel that does not
/// exist. An error value outside INTEGER16 is clamped.
pub fn analog_output(od: &ObjectDictionary, sub: u8, failure: bool) -> i16 {
    let written = match od.get(WRITE_ANALOG_OUTPUT_16, sub) {
        Ok(Value::Integer16(v)) => v,
        _ => 0,
    };
    if !failure || u8_at(od, ANALOG_OUTPUT_ERROR_MODE, sub, 1) != 1 {
        return written;
    }
    match od.get(ANALOG_OUTPUT_ERROR_VALUE, sub) {
        Ok(Value::Integer32(v)) => v.clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16,
        _ => written,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_canopen::od::OdBuilder;
    use std::sync::Arc;

    fn od() -> ObjectDictionary {
        let layout = IoLayout {
            digital_output_bytes: 1,
            analog_outputs: 2,
            ..IoLayout::default()
        };
        let desc = add_objects(OdBuilder::new(), &layout).build().unwrap();
        ObjectDictionary::new(Arc::new(desc), 1)
    }

    #[test]
    fn cia401_6206_6207_error_mode_per_bit() {
        let mut od = od();
        od.set(WRITE_OUTPUT_8, 1, &Value::Unsigned8(0xF0)).unwrap();
        od.set(ERROR_MODE_OUTPUT_8, 1, &Value::Unsigned8(0x3C))
            .unwrap();
        od.set(ERROR_VALUE_OUTPUT_8, 1, &Value::Unsigned8(0x0F))
            .unwrap();
        assert_eq!(digital_output_byte(&od, 1, false), 0xF0);
        // Bits 2..5 take the error value (0b0011 of 0x0F in bits 2..3, 0 in 4..5); the
        // others keep 0xF0's bits.
        assert_eq!(digital_output_byte(&od, 1, true), 0b1100_1100);
        assert_eq!(digital_output_byte(&od, 2, true), 0);
    }

    #[test]
    fn cia401_6202_polarity_applies_to_written_values() {
        let mut od = od();
        od.set(POLARITY_OUTPUT_8, 1, &Value::Unsigned8(0x01))
            .unwrap();
        assert_eq!(digital_output_byte(&od, 1, false), 0x01);
        assert_eq!(digital_output_byte(&od, 1, true), 0x00);
    }

    #[test]
    fn cia401_6443_6444_analog_error_value() {
        let mut od = od();
        od.set(WRITE_ANALOG_OUTPUT_16, 1, &Value::Integer16(1234))
            .unwrap();
        od.set(WRITE_ANALOG_OUTPUT_16, 2, &Value::Integer16(-5))
            .unwrap();
        od.set(ANALOG_OUTPUT_ERROR_VALUE, 1, &Value::Integer32(100_000))
            .unwrap();
        od.set(ANALOG_OUTPUT_ERROR_MODE, 2, &Value::Unsigned8(0))
            .unwrap();
        assert_eq!(analog_output(&od, 1, false), 1234);
        assert_eq!(analog_output(&od, 1, true), i16::MAX);
        assert_eq!(
            analog_output(&od, 2, true),
            -5,
            "error mode off keeps the value"
        );
        assert_eq!(analog_output(&od, 3, true), 0);
    }
}
