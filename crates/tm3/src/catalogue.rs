//! The TM3 and TM2 expansion modules a coupler can carry, with their channel counts.
//!
//! The manual gives 0x1027 one UNSIGNED16 "product code" per module but does not list the
//! codes; cantwin numbers the catalogue itself (TM3 modules from 0x0100, TM2 modules from
//! 0x0200), so a master sees a distinct, stable code per reference.

/// The expansion bus family of a module.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Family {
    /// A TM3 module.
    Tm3,
    /// A TM2 module (supported by the coupler, manual: presentation).
    Tm2,
}

/// The output stage of a module with digital outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum OutputKind {
    /// No digital outputs.
    None,
    /// Transistor outputs.
    Transistor,
    /// Relay outputs.
    Relay,
}

/// One expansion module reference.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ModuleSpec {
    /// The commercial reference, e.g. `TM3DI16`.
    pub reference: &'static str,
    /// The code the coupler reports in 0x1027.
    pub code: u16,
    /// TM3 or TM2.
    pub family: Family,
    /// Digital inputs.
    pub digital_inputs: u8,
    /// Digital outputs.
    pub digital_outputs: u8,
    /// The digital output stage.
    pub output_kind: OutputKind,
    /// Analog inputs (temperature inputs included).
    pub analog_inputs: u8,
    /// Analog outputs.
    pub analog_outputs: u8,
}

impl ModuleSpec {
    /// Bytes of 0x6000 the module's digital inputs take (each module starts a new byte).
    pub const fn input_bytes(&self) -> u8 {
        self.digital_inputs.div_ceil(8)
    }

    /// Bytes of 0x6200 the module's digital outputs take.
    pub const fn output_bytes(&self) -> u8 {
        self.digital_outputs.div_ceil(8)
    }
}

const fn m(
    reference: &'static str,
    code: u16,
    family: Family,
    io: (u8, u8, OutputKind, u8, u8),
) -> ModuleSpec {
    ModuleSpec {
        reference,
        code,
        family,
        digital_inputs: io.0,
        digital_outputs: io.1,
        output_kind: io.2,
        analog_inputs: io.3,
        analog_outputs: io.4,
    }
}

use Family::{Tm2, Tm3};
use OutputKind::{None as NoOut, Relay, Transistor};

/// Every module the twin knows.
pub const CATALOGUE: &[ModuleSpec] = &[
    // Digital inputs.
    m("TM3DI8", 0x0101, Tm3, (8, 0, NoOut, 0, 0)),
    m("TM3DI16", 0x0102, Tm3, (16, 0, NoOut, 0, 0)),
    m("TM3DI32K", 0x0103, Tm3, (32, 0, NoOut, 0, 0)),
    // Digital outputs, transistor and relay.
    m("TM3DQ8T", 0x0111, Tm3, (0, 8, Transistor, 0, 0)),
    m("TM3DQ16T", 0x0112, Tm3, (0, 16, Transistor, 0, 0)),
    m("TM3DQ32TK", 0x0113, Tm3, (0, 32, Transistor, 0, 0)),
    m("TM3DQ8R", 0x0114, Tm3, (0, 8, Relay, 0, 0)),
    m("TM3DQ16R", 0x0115, Tm3, (0, 16, Relay, 0, 0)),
    // Mixed digital.
    m("TM3DM8R", 0x0121, Tm3, (4, 4, Relay, 0, 0)),
    m("TM3DM24R", 0x0122, Tm3, (16, 8, Relay, 0, 0)),
    // Analog inputs.
    m("TM3AI2H", 0x0131, Tm3, (0, 0, NoOut, 2, 0)),
    m("TM3AI4", 0x0132, Tm3, (0, 0, NoOut, 4, 0)),
    m("TM3AI8", 0x0133, Tm3, (0, 0, NoOut, 8, 0)),
    m("TM3TI4", 0x0134, Tm3, (0, 0, NoOut, 4, 0)),
    // Analog outputs.
    m("TM3AQ2", 0x0141, Tm3, (0, 0, NoOut, 0, 2)),
    m("TM3AQ4", 0x0142, Tm3, (0, 0, NoOut, 0, 4)),
    // Mixed analog.
    m("TM3AM6", 0x0151, Tm3, (0, 0, NoOut, 4, 2)),
    m("TM3TM3", 0x0152, Tm3, (0, 0, NoOut, 2, 1)),
    // TM2 modules.
    m("TM2DDI8DT", 0x0201, Tm2, (8, 0, NoOut, 0, 0)),
    m("TM2DDO8TT", 0x0211, Tm2, (0, 8, Transistor, 0, 0)),
    m("TM2DMM8DRT", 0x0221, Tm2, (4, 4, Relay, 0, 0)),
    m("TM2AMI2HT", 0x0231, Tm2, (0, 0, NoOut, 2, 0)),
    m("TM2AMO1HT", 0x0241, Tm2, (0, 0, NoOut, 0, 1)),
];

/// The module with commercial reference `reference` (case-insensitive).
pub fn find(reference: &str) -> Option<&'static ModuleSpec> {
    CATALOGUE
        .iter()
        .find(|m| m.reference.eq_ignore_ascii_case(reference))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn catalogue_codes_and_references_are_unique() {
        for (i, a) in CATALOGUE.iter().enumerate() {
            for b in &CATALOGUE[i + 1..] {
                assert_ne!(a.code, b.code);
                assert_ne!(a.reference, b.reference);
            }
            let io = a.digital_inputs + a.digital_outputs + a.analog_inputs + a.analog_outputs;
            assert!(io > 0, "{} has channels", a.reference);
            assert_eq!(a.digital_outputs > 0, a.output_kind != OutputKind::None);
        }
        assert_eq!(
            find("tm3dm24r").map(|m| (m.digital_inputs, m.digital_outputs)),
            Some((16, 8))
        );
        assert_eq!(find("TM3XYZ"), None);
        assert!(CATALOGUE.iter().any(|m| m.family == Family::Tm2));
    }
}
