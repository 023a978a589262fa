//! Inputs: the device writes its physical inputs here; the functions store them in 0x6000
//! and 0x6401 and say whether they raise an interrupt, i.e. whether the event-driven
//! TPDOs mapping them are due (CiA 401 §6.2 digital inputs, §6.4 analog inputs).

use crate::objects::*;
use cantwin_canopen::od::{ObjectDictionary, Value};

fn u8_at(od: &ObjectDictionary, index: u16, sub: u8, default: u8) -> u8 {
    od.get_unsigned(index, sub).map_or(default, |v| v as u8)
}

fn flag(od: &ObjectDictionary, index: u16, default: bool) -> bool {
    match od.get(index, 0) {
        Ok(Value::Boolean(b)) => b,
        _ => default,
    }
}

/// Stores the physical state of input byte `sub` (1-based) in 0x6000, inverted where
/// 0x6002 says so. Returns whether the change raises an interrupt: 0x6005 is TRUE and a
/// changed bit is selected by 0x6006 (any change), a rising one by 0x6007 or a falling one
/// by 0x6008. A byte that does not exist is ignored (returns false).
pub fn set_digital_input_byte(od: &mut ObjectDictionary, sub: u8, physical: u8) -> bool {
    let Some(old) = od.get_unsigned(READ_INPUT_8, sub).map(|v| v as u8) else {
        return false;
    };
    let new = physical ^ u8_at(od, POLARITY_INPUT_8, sub, 0);
    if od.set(READ_INPUT_8, sub, &Value::Unsigned8(new)).is_err() {
        return false;
    }
    let changed = old ^ new;
    if changed == 0 || !flag(od, GLOBAL_INTERRUPT_ENABLE_DIGITAL, true) {
        return false;
    }
    let rising = changed & new;
    let falling = changed & old;
    changed & u8_at(od, INTERRUPT_MASK_ANY_CHANGE_8, sub, 0xFF) != 0
        || rising & u8_at(od, INTERRUPT_MASK_LOW_TO_HIGH_8, sub, 0) != 0
        || falling & u8_at(od, INTERRUPT_MASK_HIGH_TO_LOW_8, sub, 0) != 0
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Channel {
    /// The value at the last interrupt (the delta triggers compare against it).
    reference: i32,
    above: bool,
    below: bool,
}

/// The analog input interrupt state (0x6421–0x6426) of every channel.
///
/// Choices where CiA 401 leaves room: the limit triggers fire on the transition into the
/// condition (value > upper limit, value < lower limit), not on every sample while it
/// lasts; the delta triggers compare against the value at the channel's previous
/// interrupt (initially 0, the power-on value of 0x6401), with a delta of 0 meaning any
/// change.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct AnalogTriggers {
    channels: Vec<Channel>,
}

impl AnalogTriggers {
    /// State for `channels` analog inputs.
    pub fn new(channels: u8) -> Self {
        AnalogTriggers {
            channels: vec![Channel::default(); usize::from(channels)],
        }
    }

    /// Forgets every reference (reset application).
    pub fn reset(&mut self) {
        self.channels.fill(Channel::default());
    }

    /// Stores `value` for channel `sub` (1-based) in 0x6401 and returns the 0x6421 trigger
    /// bits that fired (0 if none, or if 0x6423 is FALSE: the conditions are still tracked
    /// so that enabling interrupts later does not fire on stale edges).
    pub fn set_input(&mut self, od: &mut ObjectDictionary, sub: u8, value: i16) -> u8 {
        let Some(ch) = usize::from(sub)
            .checked_sub(1)
            .and_then(|i| self.channels.get_mut(i))
        else {
            return 0;
        };
        if od
            .set(READ_ANALOG_INPUT_16, sub, &Value::Integer16(value))
            .is_err()
        {
            return 0;
        }
        let v = i32::from(value);
        let selection = u8_at(od, ANALOG_INTERRUPT_TRIGGER, sub, 0);
        let int = |index| match od.get(index, sub) {
            Ok(Value::Integer32(x)) => i64::from(x),
            _ => 0,
        };
        let upper = int(ANALOG_UPPER_LIMIT);
        let lower = int(ANALOG_LOWER_LIMIT);
        let delta = od.get_unsigned(ANALOG_DELTA, sub).unwrap_or(0) as i64;
        let above = i64::from(v) > upper;
        let below = i64::from(v) < lower;
        let diff = i64::from(v) - i64::from(ch.reference);
        let mut fired = 0;
        if above && !ch.above {
            fired |= TRIGGER_UPPER_LIMIT;
        }
        if below && !ch.below {
            fired |= TRIGGER_LOWER_LIMIT;
        }
        if diff != 0 && diff.abs() > delta {
            fired |= TRIGGER_DELTA;
            fired |= if diff < 0 {
                TRIGGER_NEGATIVE_DELTA
            } else {
                TRIGGER_POSITIVE_DELTA
            };
        }
        ch.above = above;
        ch.below = below;
        let fired = fired & selection;
        if !flag(od, ANALOG_GLOBAL_INTERRUPT_ENABLE, false) {
            return 0;
        }
        if fired != 0 {
            ch.reference = v;
        }
        fired
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_canopen::od::OdBuilder;
    use proptest::prelude::*;
    use std::sync::Arc;

    fn od(layout: IoLayout) -> ObjectDictionary {
        let desc = add_objects(OdBuilder::new(), &layout).build().unwrap();
        ObjectDictionary::new(Arc::new(desc), 1)
    }

    fn di() -> ObjectDictionary {
        od(IoLayout {
            digital_input_bytes: 2,
            ..IoLayout::default()
        })
    }

    fn ai() -> ObjectDictionary {
        let mut od = od(IoLayout {
            analog_inputs: 2,
            ..IoLayout::default()
        });
        od.set(ANALOG_GLOBAL_INTERRUPT_ENABLE, 0, &Value::Boolean(true))
            .unwrap();
        od
    }

    #[test]
    fn cia401_6005_6006_any_change_by_default() {
        let mut od = di();
        assert!(set_digital_input_byte(&mut od, 2, 0x01));
        assert!(!set_digital_input_byte(&mut od, 2, 0x01), "no change");
        assert!(set_digital_input_byte(&mut od, 2, 0x00));
        od.set(GLOBAL_INTERRUPT_ENABLE_DIGITAL, 0, &Value::Boolean(false))
            .unwrap();
        assert!(!set_digital_input_byte(&mut od, 2, 0xFF));
        assert_eq!(od.get_unsigned(READ_INPUT_8, 2), Some(0xFF));
        assert!(!set_digital_input_byte(&mut od, 3, 0xFF), "no such byte");
    }

    #[test]
    fn cia401_6007_6008_edge_masks() {
        let mut od = di();
        od.set(INTERRUPT_MASK_ANY_CHANGE_8, 1, &Value::Unsigned8(0))
            .unwrap();
        od.set(INTERRUPT_MASK_LOW_TO_HIGH_8, 1, &Value::Unsigned8(0x01))
            .unwrap();
        od.set(INTERRUPT_MASK_HIGH_TO_LOW_8, 1, &Value::Unsigned8(0x02))
            .unwrap();
        assert!(set_digital_input_byte(&mut od, 1, 0x01), "bit 0 rises");
        assert!(!set_digital_input_byte(&mut od, 1, 0x00), "bit 0 falls");
        assert!(!set_digital_input_byte(&mut od, 1, 0x02), "bit 1 rises");
        assert!(set_digital_input_byte(&mut od, 1, 0x00), "bit 1 falls");
        assert!(!set_digital_input_byte(&mut od, 1, 0x04), "bit 2 unmasked");
    }

    #[test]
    fn cia401_6002_polarity_inverts_the_stored_value() {
        let mut od = di();
        od.set(POLARITY_INPUT_8, 1, &Value::Unsigned8(0x0F))
            .unwrap();
        set_digital_input_byte(&mut od, 1, 0x01);
        assert_eq!(od.get_unsigned(READ_INPUT_8, 1), Some(0x0E));
    }

    #[test]
    fn cia401_6421_upper_and_lower_limit_fire_on_entry() {
        let mut od = ai();
        let mut t = AnalogTriggers::new(2);
        od.set(ANALOG_INTERRUPT_TRIGGER, 1, &Value::Unsigned8(0x03))
            .unwrap();
        od.set(ANALOG_UPPER_LIMIT, 1, &Value::Integer32(1000))
            .unwrap();
        od.set(ANALOG_LOWER_LIMIT, 1, &Value::Integer32(-1000))
            .unwrap();
        assert_eq!(t.set_input(&mut od, 1, 1000), 0);
        assert_eq!(t.set_input(&mut od, 1, 1001), TRIGGER_UPPER_LIMIT);
        assert_eq!(t.set_input(&mut od, 1, 2000), 0, "still above");
        assert_eq!(t.set_input(&mut od, 1, 0), 0);
        assert_eq!(t.set_input(&mut od, 1, -1001), TRIGGER_LOWER_LIMIT);
        assert_eq!(od.get(READ_ANALOG_INPUT_16, 1), Ok(Value::Integer16(-1001)));
    }

    #[test]
    fn cia401_6426_delta_against_the_last_interrupt() {
        let mut od = ai();
        let mut t = AnalogTriggers::new(2);
        od.set(
            ANALOG_INTERRUPT_TRIGGER,
            2,
            &Value::Unsigned8(TRIGGER_DELTA),
        )
        .unwrap();
        od.set(ANALOG_DELTA, 2, &Value::Unsigned32(100)).unwrap();
        assert_eq!(t.set_input(&mut od, 2, 100), 0);
        assert_eq!(t.set_input(&mut od, 2, 101), TRIGGER_DELTA);
        assert_eq!(t.set_input(&mut od, 2, 150), 0);
        assert_eq!(t.set_input(&mut od, 2, 0), TRIGGER_DELTA);
        od.set(ANALOG_INTERRUPT_TRIGGER, 2, &Value::Unsigned8(0x18))
            .unwrap();
        assert_eq!(t.set_input(&mut od, 2, -200), TRIGGER_NEGATIVE_DELTA);
        assert_eq!(t.set_input(&mut od, 2, 0), TRIGGER_POSITIVE_DELTA);
    }

    #[test]
    fn cia401_6423_global_enable_false_silences() {
        let mut od = ai();
        od.set(ANALOG_GLOBAL_INTERRUPT_ENABLE, 0, &Value::Boolean(false))
            .unwrap();
        let mut t = AnalogTriggers::new(2);
        assert_eq!(t.set_input(&mut od, 1, 5000), 0);
        assert_eq!(od.get(READ_ANALOG_INPUT_16, 1), Ok(Value::Integer16(5000)));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]
        #[test]
        fn analog_triggers_fire_only_selected_bits(
            values in proptest::collection::vec(any::<i16>(), 1..40),
            selection in any::<u8>(),
            delta in 0u32..5000,
        ) {
            let mut od = ai();
            od.set(ANALOG_INTERRUPT_TRIGGER, 1, &Value::Unsigned8(selection)).unwrap();
            od.set(ANALOG_DELTA, 1, &Value::Unsigned32(delta)).unwrap();
            let mut t = AnalogTriggers::new(2);
            for v in values {
                let fired = t.set_input(&mut od, 1, v);
                prop_assert_eq!(fired & !selection, 0);
                prop_assert_eq!(od.get(READ_ANALOG_INPUT_16, 1), Ok(Value::Integer16(v)));
            }
        }
    }
}
