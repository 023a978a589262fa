//! The network access state machine: the duplicate MAC ID check (DeviceNet Vol. 1 §6,
//! "Network Access State Machine"; summarised publicly by ODVA's "Dr. DeviceNet",
//! can-wiki "DeviceNet Duplicate MAC ID Protocol Summary").
//!
//! At power-up the node sends a request on `0x407 | MAC << 3`, listens one second, sends a
//! second request and listens another second, then goes on-line. A request or response for
//! its MAC ID during the check means another node owns the address: the node goes to
//! *communication faulted* and stays there until reset. On-line, a request is answered with
//! a response (the requester is the duplicate); a response means two powered segments were
//! joined, and the node faults.

use crate::wire::{DnId, DupMac, MacId, group2};
use cantwin_can::{Duration, Frame, Instant};

/// The listening window after each request.
pub const DUP_MAC_WINDOW: Duration = Duration::from_secs(1);

/// Where the node stands on the network.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkState {
    /// Not powered or not started.
    Offline,
    /// Duplicate MAC ID check running; `requests` have been sent.
    Checking {
        /// Requests sent so far (1 or 2).
        requests: u8,
        /// End of the current listening window.
        until: Instant,
    },
    /// The MAC ID is ours: the node communicates.
    Online,
    /// Duplicate MAC ID detected (or bus-off with BOI = hold): silent until reset.
    CommFaulted,
}

/// The duplicate MAC ID check of one node.
#[derive(Debug, Clone)]
pub struct DupMacCheck {
    mac: MacId,
    vendor: u16,
    serial: u32,
    state: LinkState,
}

impl DupMacCheck {
    /// A check for `mac`, identifying the node by vendor ID and serial number.
    pub fn new(mac: MacId, vendor: u16, serial: u32) -> Self {
        DupMacCheck {
            mac,
            vendor,
            serial,
            state: LinkState::Offline,
        }
    }

    /// The checked MAC ID.
    pub fn mac(&self) -> MacId {
        self.mac
    }

    /// The current state.
    pub fn state(&self) -> LinkState {
        self.state
    }

    /// Whether the node may communicate.
    pub fn is_online(&self) -> bool {
        self.state == LinkState::Online
    }

    fn message(&self, response: bool) -> Frame {
        let m = DupMac {
            response,
            port: 0,
            vendor: self.vendor,
            serial: self.serial,
        };
        DnId::g2(self.mac, group2::DUP_MAC_CHECK).frame(&m.encode())
    }

    /// Start (or restart) the check: returns the first request.
    pub fn start(&mut self, now: Instant) -> Frame {
        self.state = LinkState::Checking {
            requests: 1,
            until: now + DUP_MAC_WINDOW,
        };
        self.message(false)
    }

    /// Go faulted (bus-off with BOI = hold, or a duplicate).
    pub fn fault(&mut self) {
        self.state = LinkState::CommFaulted;
    }

    /// Stop: the node is off the network.
    pub fn stop(&mut self) {
        self.state = LinkState::Offline;
    }

    /// When the current window ends.
    pub fn deadline(&self) -> Option<Instant> {
        match self.state {
            LinkState::Checking { until, .. } => Some(until),
            _ => None,
        }
    }

    /// Time passed: sends the second request or goes on-line.
    pub fn on_tick(&mut self, now: Instant) -> Option<Frame> {
        match self.state {
            LinkState::Checking { requests, until } if now >= until => {
                if requests < 2 {
                    self.state = LinkState::Checking {
                        requests: requests + 1,
                        until: now + DUP_MAC_WINDOW,
                    };
                    Some(self.message(false))
                } else {
                    self.state = LinkState::Online;
                    None
                }
            }
            _ => None,
        }
    }

    /// A duplicate MAC ID message for our MAC ID arrived. Returns the response to send.
    pub fn on_message(&mut self, msg: &DupMac) -> Option<Frame> {
        match self.state {
            LinkState::Checking { .. } => {
                self.state = LinkState::CommFaulted;
                None
            }
            LinkState::Online if msg.response => {
                self.state = LinkState::CommFaulted;
                None
            }
            LinkState::Online => Some(self.message(true)),
            LinkState::Offline | LinkState::CommFaulted => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_requests_one_second_apart_then_online() {
        let mut c = DupMacCheck::new(MacId::new(12).unwrap(), 0x1234, 7);
        let f = c.start(Instant::ZERO);
        assert_eq!(f.to_string(), "467#00341207000000");
        assert_eq!(c.on_tick(Instant::from_nanos(999_999_999)), None);
        let f2 = c.on_tick(Instant::from_nanos(1_000_000_000)).unwrap();
        assert_eq!(f2, f);
        assert_eq!(c.on_tick(Instant::from_nanos(2_000_000_000)), None);
        assert!(c.is_online());
        let req = DupMac {
            response: false,
            port: 0,
            vendor: 1,
            serial: 2,
        };
        assert_eq!(
            c.on_message(&req).unwrap().to_string(),
            "467#80341207000000"
        );
        let resp = DupMac {
            response: true,
            ..req
        };
        assert_eq!(c.on_message(&resp), None);
        assert_eq!(c.state(), LinkState::CommFaulted);
    }
}
