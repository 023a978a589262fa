//! The configured island: up to [`MAX_MODULES`] expansion modules in bus order, and where
//! each module's channels sit in the CiA 401 objects.

use crate::catalogue::{self, ModuleSpec};
use cantwin_cia401::IoLayout;

/// The most expansion modules a coupler carries (manual: 0x1002, 0x1027).
pub const MAX_MODULES: usize = 14;

/// Why an island cannot be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum IslandError {
    /// More than [`MAX_MODULES`] modules.
    #[error("{0} modules configured, the coupler carries at most 14")]
    TooMany(usize),
    /// A reference the catalogue does not know.
    #[error("unknown module reference {0:?}")]
    UnknownModule(String),
}

/// One configured module.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ModuleSlot {
    /// The module ordered for this position.
    pub spec: &'static ModuleSpec,
    /// An optional module may be absent without a configuration error (0x1002 status 3).
    pub optional: bool,
}

/// Where a module's channels start (0-based byte or channel numbers; sub-index = n + 1).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Offsets {
    /// First 0x6000 byte.
    pub input_byte: u8,
    /// First 0x6200 byte.
    pub output_byte: u8,
    /// First 0x6401 channel.
    pub analog_input: u8,
    /// First 0x6411 channel.
    pub analog_output: u8,
}

/// The modules of a coupler in bus order (module 1 is next to the coupler).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Island {
    modules: Vec<ModuleSlot>,
    offsets: Vec<Offsets>,
    layout: IoLayout,
}

impl Island {
    /// An island of `modules`.
    pub fn new(modules: Vec<ModuleSlot>) -> Result<Self, IslandError> {
        if modules.len() > MAX_MODULES {
            return Err(IslandError::TooMany(modules.len()));
        }
        let mut at = Offsets::default();
        let mut offsets = Vec::with_capacity(modules.len());
        for m in &modules {
            offsets.push(at);
            // At most 14 modules of at most 32 channels: every sum fits in a u8.
            at.input_byte += m.spec.input_bytes();
            at.output_byte += m.spec.output_bytes();
            at.analog_input += m.spec.analog_inputs;
            at.analog_output += m.spec.analog_outputs;
        }
        let layout = IoLayout {
            digital_input_bytes: at.input_byte,
            digital_output_bytes: at.output_byte,
            analog_inputs: at.analog_input,
            analog_outputs: at.analog_output,
        };
        Ok(Island {
            modules,
            offsets,
            layout,
        })
    }

    /// An island of the catalogue references `refs`, none optional.
    pub fn from_references<S: AsRef<str>>(refs: &[S]) -> Result<Self, IslandError> {
        let modules = refs
            .iter()
            .map(|r| {
                catalogue::find(r.as_ref())
                    .map(|spec| ModuleSlot {
                        spec,
                        optional: false,
                    })
                    .ok_or_else(|| IslandError::UnknownModule(r.as_ref().to_string()))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Island::new(modules)
    }

    /// The modules.
    pub fn modules(&self) -> &[ModuleSlot] {
        &self.modules
    }

    /// Where module `n` (0-based) starts.
    pub fn offsets(&self, n: usize) -> Option<Offsets> {
        self.offsets.get(n).copied()
    }

    /// The channel counts of the whole island.
    pub fn layout(&self) -> IoLayout {
        self.layout
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_start_each_module_on_a_new_byte() {
        let i = Island::from_references(&["TM3DM8R", "TM3DI16", "TM3AM6", "TM3DQ8R", "TM3AI4"])
            .unwrap();
        assert_eq!(i.offsets(1).map(|o| o.input_byte), Some(1));
        assert_eq!(i.offsets(3).map(|o| o.output_byte), Some(1));
        assert_eq!(i.offsets(4).map(|o| o.analog_input), Some(4));
        assert_eq!(
            i.layout(),
            IoLayout {
                digital_input_bytes: 3,
                digital_output_bytes: 2,
                analog_inputs: 8,
                analog_outputs: 2
            }
        );
        assert_eq!(
            Island::from_references(&["TM3DI8"; 15]),
            Err(IslandError::TooMany(15))
        );
        assert_eq!(
            Island::from_references(&["TM9"]),
            Err(IslandError::UnknownModule("TM9".into()))
        );
    }
}
