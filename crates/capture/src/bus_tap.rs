//! Bus events as capture records: what a bus tap writes into a capture.
//!
//! Frames are stamped at the end of their EOF, when receivers take them, in wall time when
//! the simulation is paced (its time map) and in bus time since the Unix epoch in virtual
//! time, so two runs of the same scenario give byte-identical captures. Error frames and
//! controller events become SocketCAN error frames (`linux/can/error.h` classes), as
//! `candump -e` shows them.

use cantwin_bus::{BusEvent, BusInfo, ErrorKind};
use cantwin_can::{ControllerEvent, Instant};

use crate::record::{ErrorFrame, Event, Record, error_class};

// SocketCAN error frame details (linux/can/error.h): data[1] controller status, data[2]
// protocol error type, data[3] protocol error location.
const CRTL_RX_OVERFLOW: u8 = 0x01;
const CRTL_TX_OVERFLOW: u8 = 0x02;
const CRTL_RX_PASSIVE: u8 = 0x10;
const CRTL_TX_PASSIVE: u8 = 0x20;
const CRTL_ACTIVE: u8 = 0x40;
const PROT_BIT: u8 = 0x01;
const PROT_FORM: u8 = 0x02;
const PROT_STUFF: u8 = 0x04;
const LOC_ID28_21: u8 = 0x02;
const LOC_CRC_SEQ: u8 = 0x08;
const LOC_ACK: u8 = 0x19;

fn error_frame(class: u32, data: [u8; 8]) -> Option<ErrorFrame> {
    ErrorFrame::new(class, data).ok()
}

/// The capture timestamp of bus instant `at` (nanoseconds since the Unix epoch).
pub fn stamp(bus: &BusInfo<'_>, at: Instant) -> u64 {
    match bus.time_map {
        Some(map) => u64::try_from(map.unix_nanos(at)).unwrap_or(u64::MAX),
        None => at.as_nanos(),
    }
}

/// The record a capture holds for `event` on `bus`, if any (frames dropped by fault
/// injection never reached the wire and are not recorded).
pub fn record_of(bus: &BusInfo<'_>, event: &BusEvent) -> Option<Record> {
    let (at, ev) = match *event {
        BusEvent::Frame(f) if f.dropped => return None,
        BusEvent::Frame(f) => (f.end, Some(Event::from(f.frame))),
        BusEvent::Error(r) => {
            let (class, data) = match r.kind {
                ErrorKind::Ack => (
                    error_class::NO_ACK | error_class::PROTOCOL,
                    [0, 0, 0, LOC_ACK, 0, 0, 0, 0],
                ),
                ErrorKind::Corrupted => (
                    error_class::PROTOCOL | error_class::BUS_ERROR,
                    [0, 0, PROT_BIT, LOC_CRC_SEQ, 0, 0, 0, 0],
                ),
                ErrorKind::BitRateMismatch => (
                    error_class::PROTOCOL | error_class::BUS_ERROR,
                    [0, 0, PROT_STUFF, LOC_ID28_21, 0, 0, 0, 0],
                ),
                ErrorKind::Aborted => (
                    error_class::PROTOCOL | error_class::BUS_ERROR,
                    [0, 0, PROT_FORM, 0, 0, 0, 0, 0],
                ),
            };
            (r.detected, error_frame(class, data).map(Into::into))
        }
        BusEvent::Controller { event, at, .. } => {
            let (class, ctrl) = match event {
                ControllerEvent::BusOff => (error_class::BUS_OFF, 0),
                ControllerEvent::BusOffRecovered => (error_class::RESTARTED, 0),
                ControllerEvent::ErrorPassive => {
                    (error_class::CONTROLLER, CRTL_RX_PASSIVE | CRTL_TX_PASSIVE)
                }
                ControllerEvent::ErrorActive => (error_class::CONTROLLER, CRTL_ACTIVE),
                ControllerEvent::RxOverrun => (error_class::CONTROLLER, CRTL_RX_OVERFLOW),
                ControllerEvent::TxDropped => (error_class::CONTROLLER, CRTL_TX_OVERFLOW),
            };
            (
                at,
                error_frame(class, [0, ctrl, 0, 0, 0, 0, 0, 0]).map(Into::into),
            )
        }
    };
    ev.map(|ev| Record::new(stamp(bus, at), bus.name, ev))
}

#[cfg(test)]
mod tests {
    use std::sync::{Arc, Mutex};

    use cantwin_bus::{BusConfig, FnTap, PortConfig, Simulation};
    use cantwin_can::{BitRate, Duration, Frame, Node, Outbox};

    use super::*;

    /// Sends one frame at power-up.
    struct Once(Frame);

    impl Node for Once {
        fn on_power_up(&mut self, _now: Instant, out: &mut Outbox) {
            out.push(self.0);
        }
        fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
        fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
        fn next_deadline(&self) -> Option<Instant> {
            None
        }
    }

    #[test]
    fn frames_at_their_end_and_bus_off_as_a_socketcan_error_frame() {
        let mut sim = Simulation::new();
        let bus = sim.add_bus(BusConfig::new("can0", BitRate::R500K));
        let frame = Frame::std(0x123, &[1, 2]).unwrap_or_else(|e| panic!("{e}"));
        let a = sim
            .attach(bus, Once(frame), PortConfig::default())
            .unwrap_or_else(|e| panic!("{e}"));
        sim.attach(
            bus,
            Once(Frame::std(0x7FF, &[]).unwrap_or_else(|e| panic!("{e}"))),
            PortConfig::default(),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let records = Arc::new(Mutex::new(Vec::new()));
        let sink = Arc::clone(&records);
        let b = sim.bus_mut(bus).unwrap_or_else(|| panic!("no bus"));
        b.add_tap(FnTap(move |info: &BusInfo<'_>, ev: &BusEvent| {
            if let Some(r) = record_of(info, ev) {
                sink.lock().unwrap_or_else(|e| panic!("{e}")).push(r);
            }
        }));
        sim.run_for(Duration::from_millis(1));
        sim.bus_mut(bus)
            .and_then(|b| b.force_bus_off(a).ok())
            .unwrap_or_else(|| panic!("bus-off"));
        sim.run_for(Duration::from_millis(1));
        let records = records.lock().unwrap_or_else(|e| panic!("{e}"));
        let first = &records[0];
        assert_eq!(first.channel, "can0");
        assert_eq!(first.event, Event::from(frame));
        // Virtual time: bus time since the epoch, at the end of the frame (not its start).
        assert!(first.timestamp_ns > 0 && first.timestamp_ns < 1_000_000);
        let bus_off = records
            .iter()
            .filter_map(|r| match &r.event {
                Event::Error(e) => Some(e.class()),
                _ => None,
            })
            .collect::<Vec<_>>();
        assert!(bus_off.contains(&error_class::BUS_OFF), "{records:?}");
    }
}
