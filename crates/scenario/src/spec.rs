//! The buses and devices of a scenario file, as read from it.

use std::collections::BTreeMap;

use cantwin_can::BitRate;

/// A bus of the scenario.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BusSpec {
    /// Its name: the socketcand channel name and the capture's interface name.
    pub name: String,
    /// Its bit rate.
    pub bit_rate: BitRate,
    /// The line of its `[[bus]]` table.
    pub line: usize,
}

/// A device of the scenario: the common keys, and the kind-specific ones left for its kind.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceSpec {
    /// Unique name.
    pub name: String,
    /// Its kind, looked up in the registry.
    pub kind: String,
    /// The bus it is on.
    pub bus: String,
    /// Index among the `[[device]]` tables, for key paths (`device[2].node_id`).
    pub index: usize,
    /// The line of its `[[device]]` table.
    pub line: usize,
    /// Kind-specific keys with their lines.
    pub settings: BTreeMap<String, (toml::Value, usize)>,
}
