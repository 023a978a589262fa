//! The [`Twin`] trait.

use cantwin_canopen::od::ObjectDictionary;

use crate::fault::{Fault, FaultError, FaultKind};
use crate::live::LiveValue;
use crate::object::{Context, ObjectError};
use crate::param::{ParameterError, ParameterKey};
use crate::sheet::{DataSheetError, FileDate};
use crate::signal::{Direction, SignalDescription, SignalError, SignalId, SignalValue};

/// One entry of a device model's summary ([`Twin::summary`]).
#[derive(Debug, Clone, PartialEq)]
pub struct SummaryEntry {
    /// Its name (`"speed_rpm"`, `"nmt_state"`).
    pub name: &'static str,
    /// Its value; `None` when the model has none now (no NMT state outside CANopen).
    pub value: Option<SignalValue>,
}

impl SummaryEntry {
    /// The entry `name` with `value`.
    pub fn new(name: &'static str, value: Option<SignalValue>) -> Self {
        SummaryEntry { name, value }
    }
}

/// A simulated device as front ends see it: its object dictionary where it has one, its
/// signals, live values, internal faults and parameters. Every method has a default that
/// says the device has none of that, so a device implements what it has.
///
/// Changes made from above take a [`Context`]: the device may react on the bus at once.
pub trait Twin {
    /// The object dictionary, for front ends that walk it (an EDS export, a monitor's
    /// PDO decoder). `None` (the default) when the device has none.
    fn dictionary(&self) -> Option<&ObjectDictionary> {
        None
    }

    /// The little-endian bytes of object `index`/`sub`, as an SDO upload would give them.
    /// The default reads [`Twin::dictionary`].
    fn read_object(&self, index: u16, sub: u8) -> Result<Vec<u8>, ObjectError> {
        let od = self.dictionary().ok_or(ObjectError::NoDictionary)?;
        Ok(od.get(index, sub)?.to_le_bytes())
    }

    /// Writes the whole value `data` to object `index`/`sub` through the device's own
    /// checks, as an expedited SDO download on its default server would: access, value
    /// range and the device's hooks apply, and a communication object takes effect at once.
    /// `data` must have the size of a fixed-size type (0x06070010 otherwise). The default
    /// refuses: the device has no dictionary.
    fn write_object(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
        cx: &mut Context<'_>,
    ) -> Result<(), ObjectError> {
        let _ = (index, sub, data, cx);
        Err(ObjectError::NoDictionary)
    }

    /// Bytes of heap the device's CANopen stack uses (the values of its dictionary, its SDO
    /// servers, services and queues; a description shared between alike twins is not
    /// counted), for memory benchmarks. `None` (the default) when it has no such stack.
    fn dictionary_heap_bytes(&self) -> Option<usize> {
        None
    }

    /// The CANopen node-ID (CiA 301 §7.3.2.1), when the device is a CANopen slave now.
    fn canopen_node_id(&self) -> Option<u8> {
        None
    }

    /// Whether the device is a CiA 305 LSS slave (answers the layer setting services on
    /// 0x7E5/0x7E4), which its EDS states as `LSS_Supported` (CiA 306 §4.6.1).
    fn lss_slave(&self) -> bool {
        false
    }

    /// The bit rate the device's CAN controller is set to, for a device that sets it from
    /// its own parameters. A rate other than its bus's is a misconfiguration the bus
    /// models ([`cantwin_can`] frames it cannot decode become error frames), not an error
    /// of the scenario.
    fn controller_bit_rate(&self) -> Option<cantwin_can::BitRate> {
        None
    }

    /// The signals the device knows, with what they take and give.
    fn signals(&self) -> Vec<SignalDescription> {
        Vec::new()
    }

    /// Sets the physical quantity `id` (an input, a load, a module pulled out) to `value`,
    /// now. The error says why not, naming the signals the device knows.
    fn set_signal(
        &mut self,
        id: &SignalId,
        value: &SignalValue,
        cx: &mut Context<'_>,
    ) -> Result<(), SignalError> {
        let _ = (value, cx);
        Err(SignalError::unknown(id, Direction::Set, ""))
    }

    /// Reads the physical quantity `id` (an output, an alarm).
    fn read_signal(&self, id: &SignalId) -> Result<SignalValue, SignalError> {
        Err(SignalError::unknown(id, Direction::Read, ""))
    }

    /// The live values of the device's model (measurements, inputs, outputs), for
    /// dashboards. Empty (the default) when it shows none.
    fn live_values(&self) -> Vec<LiveValue> {
        Vec::new()
    }

    /// Gives the device the internal fault `fault`. The default refuses: the device has
    /// none.
    fn inject(&mut self, fault: &Fault, cx: &mut Context<'_>) -> Result<(), FaultError> {
        let _ = cx;
        Err(FaultError::None { kind: fault.kind })
    }

    /// Removes every injected fault of `kind`. The default refuses: the device has none.
    fn repair(&mut self, kind: FaultKind, cx: &mut Context<'_>) -> Result<(), FaultError> {
        let _ = cx;
        Err(FaultError::None { kind })
    }

    /// The value of the model's parameter `key`, in its internal units.
    fn parameter(&self, key: &ParameterKey) -> Result<i64, ParameterError> {
        let _ = key;
        Err(ParameterError::None)
    }

    /// Sets the model's parameter `key` to `value`, as its keypad would.
    fn set_parameter(
        &mut self,
        key: &ParameterKey,
        value: i64,
        cx: &mut Context<'_>,
    ) -> Result<(), ParameterError> {
        let _ = (key, value, cx);
        Err(ParameterError::None)
    }

    /// The device's own data sheet as text, dated `written`: the EDS of a personality
    /// whose description is not an object dictionary (a drive's DeviceNet EDS). The default
    /// has none; a CANopen twin's EDS is generated from [`Twin::dictionary`].
    fn data_sheet(&self, written: &FileDate) -> Result<String, DataSheetError> {
        let _ = written;
        Err(DataSheetError::None)
    }

    /// A summary of the device's model (a drive's speed, current, alarms and states).
    /// Empty (the default) when the device has no model to summarise.
    fn summary(&self) -> Vec<SummaryEntry> {
        Vec::new()
    }
}
