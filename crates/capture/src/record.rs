//! What a capture holds: timestamped events on named channels.

use cantwin_can::{Frame, Instant};
use core::fmt;

/// SocketCAN error classes (the `CAN_ERR_*` bits of an error frame's identifier, Linux
/// `include/uapi/linux/can/error.h`), with the names `cantwin dump` prints.
pub mod error_class {
    /// TX timeout (by netdevice driver).
    pub const TX_TIMEOUT: u32 = 0x0000_0001;
    /// Lost arbitration; data\[0\] holds the bit number.
    pub const LOST_ARBITRATION: u32 = 0x0000_0002;
    /// Controller problems; data\[1\] holds the details.
    pub const CONTROLLER: u32 = 0x0000_0004;
    /// Protocol violations; data\[2\] holds the type, data\[3\] the location.
    pub const PROTOCOL: u32 = 0x0000_0008;
    /// Transceiver status; data\[4\].
    pub const TRANSCEIVER: u32 = 0x0000_0010;
    /// No acknowledge received on transmission.
    pub const NO_ACK: u32 = 0x0000_0020;
    /// Bus off.
    pub const BUS_OFF: u32 = 0x0000_0040;
    /// Bus error (may flood).
    pub const BUS_ERROR: u32 = 0x0000_0080;
    /// Controller restarted.
    pub const RESTARTED: u32 = 0x0000_0100;
    /// TX/RX error counters in data\[6\] and data\[7\].
    pub const COUNTERS: u32 = 0x0000_0200;

    /// Every class bit with its name, lowest bit first.
    pub const NAMES: [(u32, &str); 10] = [
        (TX_TIMEOUT, "tx-timeout"),
        (LOST_ARBITRATION, "lost-arbitration"),
        (CONTROLLER, "controller-problem"),
        (PROTOCOL, "protocol-violation"),
        (TRANSCEIVER, "transceiver-status"),
        (NO_ACK, "no-ack"),
        (BUS_OFF, "bus-off"),
        (BUS_ERROR, "bus-error"),
        (RESTARTED, "restarted"),
        (COUNTERS, "error-counters"),
    ];
}

/// The error class does not fit the 29 bits SocketCAN gives it (`CAN_ERR_MASK`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("error class {0:#x} does not fit in 29 bits")]
pub struct ErrorClassError(pub u32);

/// A SocketCAN error frame: what a CAN controller reports about the bus (not a frame that
/// was on the wire). Real captures contain them; the class bits and the 8 data bytes follow
/// Linux `include/uapi/linux/can/error.h`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ErrorFrame {
    class: u32,
    data: [u8; 8],
}

impl ErrorFrame {
    /// Largest class value: the identifier's low 29 bits (`CAN_ERR_MASK`).
    pub const CLASS_MASK: u32 = 0x1FFF_FFFF;

    /// An error frame with the given class bits (see [`error_class`]) and data bytes.
    pub const fn new(class: u32, data: [u8; 8]) -> Result<ErrorFrame, ErrorClassError> {
        if class > Self::CLASS_MASK {
            return Err(ErrorClassError(class));
        }
        Ok(ErrorFrame { class, data })
    }

    /// The error class bits.
    pub const fn class(&self) -> u32 {
        self.class
    }

    /// The 8 data bytes.
    pub const fn data(&self) -> [u8; 8] {
        self.data
    }
}

impl fmt::Display for ErrorFrame {
    /// The class bits as names, `|`-separated, e.g. `controller-problem|bus-off`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut rest = self.class;
        let mut first = true;
        for (bit, name) in error_class::NAMES {
            if rest & bit != 0 {
                if !first {
                    f.write_str("|")?;
                }
                f.write_str(name)?;
                first = false;
                rest &= !bit;
            }
        }
        if rest != 0 {
            if !first {
                f.write_str("|")?;
            }
            write!(f, "{rest:#x}")?;
        } else if first {
            f.write_str("none")?;
        }
        Ok(())
    }
}

/// What happened on a channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Event {
    /// A data or remote frame.
    Frame(Frame),
    /// A controller error report.
    Error(ErrorFrame),
}

impl From<Frame> for Event {
    fn from(frame: Frame) -> Self {
        Event::Frame(frame)
    }
}

impl From<ErrorFrame> for Event {
    fn from(error: ErrorFrame) -> Self {
        Event::Error(error)
    }
}

/// One entry of a capture.
///
/// Captures carry wall-clock time: `timestamp_ns` counts nanoseconds since the Unix epoch. A
/// simulation maps its bus time onto a start epoch (`epoch_ns + now.as_nanos()`).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Record {
    /// Nanoseconds since 1970-01-01T00:00:00Z.
    pub timestamp_ns: u64,
    /// The bus the event was seen on, e.g. `can0`.
    pub channel: String,
    /// The frame or error report.
    pub event: Event,
}

impl Record {
    /// A record of any event.
    pub fn new(timestamp_ns: u64, channel: impl Into<String>, event: impl Into<Event>) -> Record {
        Record {
            timestamp_ns,
            channel: channel.into(),
            event: event.into(),
        }
    }

    /// A record of an event seen at bus time `now` of a simulation whose bus time 0 is
    /// `epoch_ns` nanoseconds after the Unix epoch (saturating at `u64::MAX`).
    pub fn at_bus_time(
        epoch_ns: u64,
        now: Instant,
        channel: impl Into<String>,
        event: impl Into<Event>,
    ) -> Record {
        Record::new(epoch_ns.saturating_add(now.as_nanos()), channel, event)
    }

    /// The frame, if this record holds one.
    pub fn frame(&self) -> Option<&Frame> {
        match &self.event {
            Event::Frame(f) => Some(f),
            Event::Error(_) => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bus_time_maps_onto_the_start_epoch() {
        let f = Frame::std(0x80, &[]).unwrap();
        let r = Record::at_bus_time(
            1_700_000_000_000_000_000,
            Instant::from_nanos(1_234),
            "can0",
            f,
        );
        assert_eq!(r.timestamp_ns, 1_700_000_000_000_001_234);
        assert_eq!(r.frame(), Some(&f));
        let r = Record::at_bus_time(u64::MAX - 1, Instant::from_nanos(5), "can0", f);
        assert_eq!(r.timestamp_ns, u64::MAX);
    }

    #[test]
    fn error_class_display_names_bits() {
        let e = ErrorFrame::new(error_class::CONTROLLER | error_class::BUS_OFF, [0; 8]).unwrap();
        assert_eq!(e.to_string(), "controller-problem|bus-off");
        assert_eq!(
            ErrorFrame::new(0x2000_0000, [0; 8]),
            Err(ErrorClassError(0x2000_0000))
        );
    }
}
