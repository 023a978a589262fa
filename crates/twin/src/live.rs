//! Live values of device models and the inputs a host may set, for dashboards: a front end
//! reads them straight from the twins' models rather than decoding frames.

/// What a live value is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Role {
    /// A measurement of the model (speed, current, temperature): plotted.
    Measured,
    /// A digital input (a wired terminal): 0 or 1, settable as a signal
    /// ([`crate::Twin::set_signal`], true or false).
    DigitalInput,
    /// An analog input, settable as a signal within `min..=max`.
    AnalogInput {
        /// The smallest value accepted.
        min: f64,
        /// The largest value accepted.
        max: f64,
    },
    /// A digital output the device drives: 0 or 1.
    DigitalOutput,
    /// An analog output the device drives.
    AnalogOutput,
}

impl Role {
    /// Whether the value is a number worth plotting (not an on/off signal).
    pub fn is_analog(self) -> bool {
        matches!(
            self,
            Role::Measured | Role::AnalogInput { .. } | Role::AnalogOutput
        )
    }

    /// Whether a host may set the value.
    pub fn is_input(self) -> bool {
        matches!(self, Role::DigitalInput | Role::AnalogInput { .. })
    }
}

/// One live value of a device.
#[derive(Debug, Clone, PartialEq)]
pub struct LiveValue {
    /// Its name, unique within the device; inputs and outputs are named as the device's
    /// signals (`"speed"`, `"digital_input.4"`, `"analog_input.3.0"`).
    pub name: String,
    /// The value; digital signals are 0 or 1.
    pub value: f64,
    /// The unit (`"rpm"`, `"A"`, `"V"`; empty for digital signals and raw counts).
    pub unit: &'static str,
    /// What it is.
    pub role: Role,
}

impl LiveValue {
    /// A measurement.
    pub fn measured(name: impl Into<String>, value: f64, unit: &'static str) -> Self {
        LiveValue {
            name: name.into(),
            value,
            unit,
            role: Role::Measured,
        }
    }

    /// A digital signal in `role`.
    pub fn digital(name: impl Into<String>, on: bool, role: Role) -> Self {
        LiveValue {
            name: name.into(),
            value: if on { 1.0 } else { 0.0 },
            unit: "",
            role,
        }
    }
}
