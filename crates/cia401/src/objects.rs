//! The CiA 401 objects a device with a given [`IoLayout`] has, with the profile's defaults.
//!
//! | index | object | type, access | default |
//! |---|---|---|---|
//! | 0x6000 | read input 8-bit, one sub-index per byte | UNSIGNED8 `ro`, mappable | 0 |
//! | 0x6002 | polarity input 8-bit | UNSIGNED8 `rw` | 0 |
//! | 0x6005 | global interrupt enable digital | BOOLEAN `rw` | TRUE |
//! | 0x6006 | interrupt mask any change 8-bit | UNSIGNED8 `rw` | 0xFF |
//! | 0x6007 | interrupt mask low-to-high 8-bit | UNSIGNED8 `rw` | 0 |
//! | 0x6008 | interrupt mask high-to-low 8-bit | UNSIGNED8 `rw` | 0 |
//! | 0x6200 | write output 8-bit | UNSIGNED8 `rw`, mappable | 0 |
//! | 0x6202 | change polarity output 8-bit | UNSIGNED8 `rw` | 0 |
//! | 0x6206 | error mode output 8-bit | UNSIGNED8 `rw` | 0xFF |
//! | 0x6207 | error value output 8-bit | UNSIGNED8 `rw` | 0 |
//! | 0x6401 | read analog input 16-bit, one sub-index per channel | INTEGER16 `ro`, mappable | 0 |
//! | 0x6411 | write analog output 16-bit | INTEGER16 `rw`, mappable | 0 |
//! | 0x6421 | analog input interrupt trigger selection | UNSIGNED8 `rw` | 0x07 |
//! | 0x6423 | analog input global interrupt enable | BOOLEAN `rw` | FALSE |
//! | 0x6424 | analog input interrupt upper limit integer | INTEGER32 `rw` | 0 |
//! | 0x6425 | analog input interrupt lower limit integer | INTEGER32 `rw` | 0 |
//! | 0x6426 | analog input interrupt delta unsigned | UNSIGNED32 `rw` | 0 |
//! | 0x6443 | analog output error mode | UNSIGNED8 `rw` | 1 |
//! | 0x6444 | analog output error value integer | INTEGER32 `rw` | 0 |
//!
//! An object whose channel count is 0 is left out (CiA 401 makes each group optional).

use cantwin_canopen::od::{Access, DataType, OdBuilder, SubObject, Value};

/// 0x6000 read input 8-bit.
pub const READ_INPUT_8: u16 = 0x6000;
/// 0x6002 polarity input 8-bit.
pub const POLARITY_INPUT_8: u16 = 0x6002;
/// 0x6005 global interrupt enable digital 8-bit.
pub const GLOBAL_INTERRUPT_ENABLE_DIGITAL: u16 = 0x6005;
/// 0x6006 interrupt mask any change 8-bit.
pub const INTERRUPT_MASK_ANY_CHANGE_8: u16 = 0x6006;
/// 0x6007 interrupt mask low-to-high 8-bit.
pub const INTERRUPT_MASK_LOW_TO_HIGH_8: u16 = 0x6007;
/// 0x6008 interrupt mask high-to-low 8-bit.
pub const INTERRUPT_MASK_HIGH_TO_LOW_8: u16 = 0x6008;
/// 0x6200 write output 8-bit.
pub const WRITE_OUTPUT_8: u16 = 0x6200;
/// 0x6202 change polarity output 8-bit.
pub const POLARITY_OUTPUT_8: u16 = 0x6202;
/// 0x6206 error mode output 8-bit.
pub const ERROR_MODE_OUTPUT_8: u16 = 0x6206;
/// 0x6207 error value output 8-bit.
pub const ERROR_VALUE_OUTPUT_8: u16 = 0x6207;
/// 0x6401 read analog input 16-bit.
pub const READ_ANALOG_INPUT_16: u16 = 0x6401;
/// 0x6411 write analog output 16-bit.
pub const WRITE_ANALOG_OUTPUT_16: u16 = 0x6411;
/// 0x6421 analog input interrupt trigger selection.
pub const ANALOG_INTERRUPT_TRIGGER: u16 = 0x6421;
/// 0x6423 analog input global interrupt enable.
pub const ANALOG_GLOBAL_INTERRUPT_ENABLE: u16 = 0x6423;
/// 0x6424 analog input interrupt upper limit integer.
pub const ANALOG_UPPER_LIMIT: u16 = 0x6424;
/// 0x6425 analog input interrupt lower limit integer.
pub const ANALOG_LOWER_LIMIT: u16 = 0x6425;
/// 0x6426 analog input interrupt delta unsigned.
pub const ANALOG_DELTA: u16 = 0x6426;
/// 0x6443 analog output error mode.
pub const ANALOG_OUTPUT_ERROR_MODE: u16 = 0x6443;
/// 0x6444 analog output error value integer.
pub const ANALOG_OUTPUT_ERROR_VALUE: u16 = 0x6444;

/// 0x6421 bit 0: the input rose above the upper limit (0x6424).
pub const TRIGGER_UPPER_LIMIT: u8 = 1 << 0;
/// 0x6421 bit 1: the input fell below the lower limit (0x6425).
pub const TRIGGER_LOWER_LIMIT: u8 = 1 << 1;
/// 0x6421 bit 2: the input changed by more than the delta (0x6426) either way.
pub const TRIGGER_DELTA: u8 = 1 << 2;
/// 0x6421 bit 3: the input fell by more than the delta.
pub const TRIGGER_NEGATIVE_DELTA: u8 = 1 << 3;
/// 0x6421 bit 4: the input rose by more than the delta.
pub const TRIGGER_POSITIVE_DELTA: u8 = 1 << 4;

/// How many channels of each kind a device has.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct IoLayout {
    /// Bytes of digital inputs (0x6000 sub-indices), at most 254.
    pub digital_input_bytes: u8,
    /// Bytes of digital outputs (0x6200 sub-indices), at most 254.
    pub digital_output_bytes: u8,
    /// Analog input channels (0x6401 sub-indices), at most 254.
    pub analog_inputs: u8,
    /// Analog output channels (0x6411 sub-indices), at most 254.
    pub analog_outputs: u8,
}

impl IoLayout {
    /// The CiA 401 additional information of 0x1000 (bits 16–19): bit 16 digital inputs,
    /// bit 17 digital outputs, bit 18 analog inputs, bit 19 analog outputs.
    pub const fn device_type_io_bits(&self) -> u32 {
        ((self.digital_input_bytes > 0) as u32) << 16
            | ((self.digital_output_bytes > 0) as u32) << 17
            | ((self.analog_inputs > 0) as u32) << 18
            | ((self.analog_outputs > 0) as u32) << 19
    }
}

/// The CiA 401 profile number, 0x1000 bits 0–15.
pub const PROFILE_NUMBER: u32 = 401;

fn u8_rw(name: &str, v: u8) -> SubObject {
    SubObject::new(name, DataType::Unsigned8, Access::Rw).default(Value::Unsigned8(v))
}

fn per_channel(b: OdBuilder, index: u16, name: &str, count: u8, element: SubObject) -> OdBuilder {
    if count == 0 {
        return b;
    }
    b.array_of(index, name, count.min(254), element)
}

/// Adds the objects of `layout` (see the [module documentation](self)) to `b`.
pub fn add_objects(mut b: OdBuilder, layout: &IoLayout) -> OdBuilder {
    let di = layout.digital_input_bytes;
    b = per_channel(
        b,
        READ_INPUT_8,
        "Read input 8-bit",
        di,
        SubObject::new("Read input", DataType::Unsigned8, Access::Ro)
            .default(Value::Unsigned8(0))
            .mappable(),
    );
    b = per_channel(
        b,
        POLARITY_INPUT_8,
        "Polarity input 8-bit",
        di,
        u8_rw("Polarity input", 0),
    );
    if di > 0 {
        b = b.var(
            GLOBAL_INTERRUPT_ENABLE_DIGITAL,
            SubObject::new(
                "Global interrupt enable digital",
                DataType::Boolean,
                Access::Rw,
            )
            .default(Value::Boolean(true)),
        );
    }
    for (index, name, default) in [
        (
            INTERRUPT_MASK_ANY_CHANGE_8,
            "Interrupt mask any change",
            0xFF,
        ),
        (
            INTERRUPT_MASK_LOW_TO_HIGH_8,
            "Interrupt mask low-to-high",
            0,
        ),
        (
            INTERRUPT_MASK_HIGH_TO_LOW_8,
            "Interrupt mask high-to-low",
            0,
        ),
    ] {
        b = per_channel(b, index, &format!("{name} 8-bit"), di, u8_rw(name, default));
    }
    let dq = layout.digital_output_bytes;
    b = per_channel(
        b,
        WRITE_OUTPUT_8,
        "Write output 8-bit",
        dq,
        u8_rw("Write output", 0).mappable(),
    );
    for (index, name, default) in [
        (POLARITY_OUTPUT_8, "Change polarity output", 0),
        (ERROR_MODE_OUTPUT_8, "Error mode output", 0xFF),
        (ERROR_VALUE_OUTPUT_8, "Error value output", 0),
    ] {
        b = per_channel(b, index, &format!("{name} 8-bit"), dq, u8_rw(name, default));
    }
    let ai = layout.analog_inputs;
    b = per_channel(
        b,
        READ_ANALOG_INPUT_16,
        "Read analog input 16-bit",
        ai,
        SubObject::new("Analog input", DataType::Integer16, Access::Ro)
            .default(Value::Integer16(0))
            .mappable(),
    );
    b = per_channel(
        b,
        ANALOG_INTERRUPT_TRIGGER,
        "Analog input interrupt trigger selection",
        ai,
        u8_rw(
            "Trigger selection",
            TRIGGER_UPPER_LIMIT | TRIGGER_LOWER_LIMIT | TRIGGER_DELTA,
        ),
    );
    if ai > 0 {
        b = b.var(
            ANALOG_GLOBAL_INTERRUPT_ENABLE,
            SubObject::new(
                "Analog input global interrupt enable",
                DataType::Boolean,
                Access::Rw,
            )
            .default(Value::Boolean(false)),
        );
    }
    let i32_rw = |name: &str| {
        SubObject::new(name, DataType::Integer32, Access::Rw).default(Value::Integer32(0))
    };
    b = per_channel(
        b,
        ANALOG_UPPER_LIMIT,
        "Analog input interrupt upper limit integer",
        ai,
        i32_rw("Upper limit"),
    );
    b = per_channel(
        b,
        ANALOG_LOWER_LIMIT,
        "Analog input interrupt lower limit integer",
        ai,
        i32_rw("Lower limit"),
    );
    b = per_channel(
        b,
        ANALOG_DELTA,
        "Analog input interrupt delta unsigned",
        ai,
        SubObject::new("Delta", DataType::Unsigned32, Access::Rw).default(Value::Unsigned32(0)),
    );
    let aq = layout.analog_outputs;
    b = per_channel(
        b,
        WRITE_ANALOG_OUTPUT_16,
        "Write analog output 16-bit",
        aq,
        SubObject::new("Analog output", DataType::Integer16, Access::Rw)
            .default(Value::Integer16(0))
            .mappable(),
    );
    b = per_channel(
        b,
        ANALOG_OUTPUT_ERROR_MODE,
        "Analog output error mode",
        aq,
        u8_rw("Error mode", 1),
    );
    per_channel(
        b,
        ANALOG_OUTPUT_ERROR_VALUE,
        "Analog output error value integer",
        aq,
        i32_rw("Error value"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_canopen::od::ObjectDictionary;
    use std::sync::Arc;

    #[test]
    fn cia401_device_type_bits_per_kind() {
        let l = |a, b, c, d| IoLayout {
            digital_input_bytes: a,
            digital_output_bytes: b,
            analog_inputs: c,
            analog_outputs: d,
        };
        assert_eq!(l(0, 0, 0, 0).device_type_io_bits(), 0);
        assert_eq!(l(1, 0, 0, 0).device_type_io_bits(), 0x1_0000);
        assert_eq!(l(0, 2, 0, 0).device_type_io_bits(), 0x2_0000);
        assert_eq!(l(0, 0, 3, 0).device_type_io_bits(), 0x4_0000);
        assert_eq!(l(0, 0, 0, 4).device_type_io_bits(), 0x8_0000);
        assert_eq!(l(1, 1, 1, 1).device_type_io_bits(), 0xF_0000);
    }

    #[test]
    fn cia401_defaults_and_sizes() {
        let layout = IoLayout {
            digital_input_bytes: 3,
            digital_output_bytes: 2,
            analog_inputs: 4,
            analog_outputs: 0,
        };
        let desc = add_objects(OdBuilder::new(), &layout).build().unwrap();
        let od = ObjectDictionary::new(Arc::new(desc), 1);
        assert_eq!(od.get_unsigned(0x6000, 0), Some(3));
        assert_eq!(od.get_unsigned(0x6200, 0), Some(2));
        assert_eq!(od.get_unsigned(0x6401, 0), Some(4));
        assert!(od.description().object(0x6411).is_none());
        assert!(od.description().object(0x6443).is_none());
        assert_eq!(od.get_unsigned(0x6006, 3), Some(0xFF));
        assert_eq!(od.get_unsigned(0x6206, 2), Some(0xFF));
        assert_eq!(od.get_unsigned(0x6421, 4), Some(0x07));
        assert_eq!(od.get(0x6005, 0), Ok(Value::Boolean(true)));
        assert_eq!(od.get(0x6423, 0), Ok(Value::Boolean(false)));
    }
}
