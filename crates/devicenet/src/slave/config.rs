//! Slave configuration, its validation, and the network status shown on the LEDs.

use crate::objects::Identity;
use crate::wire::{BodyFormat, MacId};
use cantwin_can::BitRate;

/// Configuration of a slave: address, bit rate, identity and the limits of the device.
#[derive(Debug, Clone)]
pub struct SlaveConfig {
    /// MAC ID (the card accepts 1–63).
    pub mac: MacId,
    /// Bit rate (DeviceNet: 125, 250 or 500 kbit/s).
    pub bit_rate: BitRate,
    /// Identity object values.
    pub identity: Identity,
    /// Largest explicit message body in either direction (the EXP-CAN/DN-ADV card: 32
    /// bytes, manual §3.2).
    pub max_explicit: u16,
    /// Explicit connections the UCMM may open at once (the card: 3 explicit connections
    /// in all, manual §3.3.1, so 2 besides the predefined one).
    pub ucmm_connections: usize,
    /// First Connection instance ID used for UCMM connections.
    pub ucmm_first_instance: u16,
    /// The body format answered to an Allocate (8/8 unless the device needs 16-bit
    /// class or instance IDs on the predefined connection).
    pub allocate_format: BodyFormat,
    /// Timer resolution in ms: expected packet rates are rounded up to it.
    pub epr_resolution_ms: u16,
    /// Expected packet rate of a new explicit connection in ms (2500 ms by default).
    pub explicit_epr_ms: u16,
}

impl SlaveConfig {
    /// A configuration with the defaults described on each field.
    pub fn new(mac: MacId, bit_rate: BitRate, identity: Identity) -> Self {
        SlaveConfig {
            mac,
            bit_rate,
            identity,
            max_explicit: 32,
            ucmm_connections: 2,
            ucmm_first_instance: 6,
            allocate_format: BodyFormat::F8_8,
            epr_resolution_ms: 10,
            explicit_epr_ms: 2500,
        }
    }
}

/// A slave configuration DeviceNet cannot run.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    /// DeviceNet runs at 125, 250 or 500 kbit/s only.
    #[error("DeviceNet runs at 125, 250 or 500 kbit/s, not {0} bit/s")]
    BitRate(u32),
    /// Group 3 offers 5 connection message IDs (0–4) per server.
    #[error("at most 5 UCMM connections (group 3 message IDs 0-4), not {0}")]
    TooManyUcmmConnections(usize),
    /// The product name is a SHORT_STRING of at most 32 characters.
    #[error("product name longer than 32 bytes")]
    ProductName,
    /// The timer resolution must be at least 1 ms.
    #[error("expected packet rate resolution of 0 ms")]
    Resolution,
}

/// The DeviceNet object's baud rate code for a bit rate (0 = 125, 1 = 250, 2 = 500
/// kbit/s); `None` for a rate DeviceNet does not define.
pub fn baud_code(rate: BitRate) -> Option<u8> {
    match rate {
        BitRate::R125K => Some(0),
        BitRate::R250K => Some(1),
        BitRate::R500K => Some(2),
        _ => None,
    }
}

/// The network status as the module/network status LEDs show it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NetworkStatus {
    /// Not powered.
    Off,
    /// Duplicate MAC ID check in progress.
    SelfTest,
    /// On-line, waiting for the master or polled I/O not active.
    WaitingForMaster,
    /// Polled I/O established: operational.
    IoActive,
    /// Recoverable fault: duplicate MAC ID, bus-off, or a timed-out connection.
    RecoverableFault,
}

/// A LED's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Led {
    /// Off.
    Off,
    /// On.
    On,
    /// Blinking.
    Blink,
}

impl NetworkStatus {
    /// The (OP green, AL red) LEDs of the EXP-CAN/DN-ADV card (manual, "LEDs" table).
    pub fn leds(self) -> (Led, Led) {
        match self {
            NetworkStatus::Off => (Led::Off, Led::Off),
            NetworkStatus::SelfTest => (Led::Blink, Led::Blink),
            NetworkStatus::WaitingForMaster => (Led::Blink, Led::Off),
            NetworkStatus::IoActive => (Led::On, Led::Off),
            NetworkStatus::RecoverableFault => (Led::Off, Led::Blink),
        }
    }
}
