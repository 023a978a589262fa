//! The LSS slave (CiA 305 §5): the node's side of the layer setting services.
//!
//! The slave is in LSS *waiting* or *configuration* state (§3.4). In waiting it takes part
//! in switch state selective (0x40–0x43 → 0x44), identify remote slave (0x46–0x4B → 0x4F),
//! identify non-configured remote slave (0x4C → 0x50) and fastscan (0x51 → 0x4F); in
//! configuration it serves configure node-ID (0x11), configure and activate bit timing
//! (0x13, 0x15), store configuration (0x17) and the inquiries (0x5A–0x5E). A request the
//! state does not serve gets no answer, as in CANopenNode's `CO_LSSslave_receive`.
//!
//! Configure node-ID sets the *pending* node-ID; it becomes the *active* one at the next
//! reset communication ([`Slave::reset_communication`], CiA 305 §4.4.1). A node without
//! node-ID (0xFF) that gets one and is switched back to waiting asks for that reset itself
//! ([`SlaveEvent::ResetCommunication`]), as CANopenNode's slave does.

use std::collections::VecDeque;

use cantwin_can::{BitRate, Duration, Frame, Instant, Outbox};

use super::store::{Store, Stored};
use super::wire::{
    Address, FASTSCAN_CONFIRM, IdentifyField, Mode, Part, Request, Response, UNCONFIGURED,
    bit_rate_of,
};

/// Something the node around the slave must act on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlaveEvent {
    /// Activate bit timing: the controller runs at this rate from now on.
    BitRateSwitched(BitRate),
    /// A node without node-ID was given one and left configuration: it resets
    /// communication to take it.
    ResetCommunication,
    /// The stored configuration could not be read; the configured one stays in effect.
    StoreLoadFailed,
}

/// An LSS slave. See the [module documentation](self).
pub struct Slave {
    address: Address,
    mode: Mode,
    /// The node-ID the device runs with (0xFF: none).
    active: u8,
    /// The node-ID taken at the next reset communication.
    pending: u8,
    /// The node-ID and bit rate it powers up with when nothing is stored.
    default_node_id: u8,
    default_bit_rate: BitRate,
    bit_rate: BitRate,
    pending_bit_rate: BitRate,
    /// Switch state selective: how many parts matched in order (0–3).
    selective: u8,
    /// Identify remote slave: how many fields matched in order (0–6).
    identify: u8,
    /// Fastscan: the address part the slave compares (LSSPos, CiA 305 §4.7).
    fastscan: u8,
    /// Activate bit timing: when the rate switches, and until when the slave stays silent.
    switch_at: Option<(Instant, BitRate)>,
    silent_until: Option<Instant>,
    store: Box<dyn Store>,
    events: VecDeque<SlaveEvent>,
}

impl core::fmt::Debug for Slave {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Slave")
            .field("address", &self.address)
            .field("mode", &self.mode)
            .field("active", &self.active)
            .field("pending", &self.pending)
            .field("bit_rate", &self.bit_rate)
            .finish_non_exhaustive()
    }
}

impl Slave {
    /// A slave with LSS address `address` (0x1018 sub 1–4) that powers up with `node_id`
    /// (1–127, or 0xFF for none) at `bit_rate` unless `store` holds a stored configuration.
    pub fn new(address: Address, node_id: u8, bit_rate: BitRate, store: Box<dyn Store>) -> Self {
        let mut s = Slave {
            address,
            mode: Mode::Waiting,
            active: node_id,
            pending: node_id,
            default_node_id: node_id,
            default_bit_rate: bit_rate,
            bit_rate,
            pending_bit_rate: bit_rate,
            selective: 0,
            identify: 0,
            fastscan: 0,
            switch_at: None,
            silent_until: None,
            store,
            events: VecDeque::new(),
        };
        s.power_up();
        s.events.clear();
        s
    }

    /// Power-up: the stored configuration (or the configured one), LSS waiting.
    pub fn power_up(&mut self) {
        let (node_id, bit_rate) = match self.store.load() {
            Ok(Some(Stored { node_id, bit_rate })) => (node_id, bit_rate),
            Ok(None) => (self.default_node_id, self.default_bit_rate),
            Err(_) => {
                self.events.push_back(SlaveEvent::StoreLoadFailed);
                (self.default_node_id, self.default_bit_rate)
            }
        };
        self.active = node_id;
        self.pending = node_id;
        self.bit_rate = bit_rate;
        self.pending_bit_rate = bit_rate;
        self.mode = Mode::Waiting;
        self.selective = 0;
        self.identify = 0;
        self.fastscan = 0;
        self.switch_at = None;
        self.silent_until = None;
    }

    /// Reset communication: the pending node-ID becomes the active one (CiA 305 §4.4.1).
    /// Returns it.
    pub fn reset_communication(&mut self) -> u8 {
        self.active = self.pending;
        self.active
    }

    /// The LSS state.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The node-ID the device runs with, 0xFF when it has none.
    pub fn active_node_id(&self) -> u8 {
        self.active
    }

    /// The node-ID the next reset communication gives the device.
    pub fn pending_node_id(&self) -> u8 {
        self.pending
    }

    /// The bit rate the controller runs at.
    pub fn bit_rate(&self) -> BitRate {
        self.bit_rate
    }

    /// The bit rate configure bit timing chose, active after activate bit timing or at the
    /// next power-up once stored.
    pub fn pending_bit_rate(&self) -> BitRate {
        self.pending_bit_rate
    }

    /// The LSS address.
    pub fn address(&self) -> Address {
        self.address
    }

    /// Whether the node may transmit at `now`: not during activate bit timing (CiA 305
    /// §4.4.3: no frames from the first switch delay to the end of the second).
    pub fn may_transmit(&self, now: Instant) -> bool {
        self.silent_until.is_none_or(|t| now >= t)
    }

    /// What the node must act on, oldest first.
    pub fn poll_event(&mut self) -> Option<SlaveEvent> {
        self.events.pop_front()
    }

    /// When [`Slave::on_tick`] is due.
    pub fn next_deadline(&self) -> Option<Instant> {
        match (self.switch_at, self.silent_until) {
            (Some((t, _)), _) => Some(t),
            (None, s) => s,
        }
    }

    /// Timers: the bit rate switch and the end of the silence of activate bit timing.
    pub fn on_tick(&mut self, now: Instant) {
        if let Some((t, rate)) = self.switch_at
            && now >= t
        {
            self.switch_at = None;
            self.bit_rate = rate;
            self.events.push_back(SlaveEvent::BitRateSwitched(rate));
        }
        if self.switch_at.is_none() && self.silent_until.is_some_and(|t| now >= t) {
            self.silent_until = None;
        }
    }

    fn unconfigured(&self) -> bool {
        self.active == UNCONFIGURED && self.pending == UNCONFIGURED
    }

    /// A frame from the bus: an LSS request is served (answers go to `out`). Returns
    /// whether the frame was an LSS request.
    pub fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) -> bool {
        let Ok(req) = Request::decode(frame) else {
            return false;
        };
        self.on_tick(now);
        if let Some(r) = self.serve(req, now) {
            out.push(r.encode());
        }
        true
    }

    fn serve(&mut self, req: Request, now: Instant) -> Option<Response> {
        let configuring = self.mode == Mode::Configuration;
        match req {
            Request::SwitchGlobal(Mode::Configuration) => {
                self.mode = Mode::Configuration;
                None
            }
            Request::SwitchGlobal(Mode::Waiting) => {
                if configuring && self.active == UNCONFIGURED && self.pending != UNCONFIGURED {
                    self.events.push_back(SlaveEvent::ResetCommunication);
                }
                self.mode = Mode::Waiting;
                None
            }
            Request::SwitchSelective(part, value) if !configuring => {
                // §4.3.2: the four parts in order; a mismatch or a part out of order starts
                // the sequence again.
                // The vendor-ID always starts a new sequence.
                let expected = if part == Part::Vendor {
                    0
                } else {
                    self.selective
                };
                self.selective = 0;
                if part.position() != expected || self.address.part(part) != value {
                    return None;
                }
                if part == Part::Serial {
                    self.mode = Mode::Configuration;
                    return Some(Response::SwitchSelective);
                }
                self.selective = expected + 1;
                None
            }
            Request::IdentifyRemote(field, value) if !configuring => {
                let expected = self.identify;
                self.identify = 0;
                let a = &self.address;
                let matches = match field {
                    IdentifyField::Vendor => a.vendor == value,
                    IdentifyField::Product => a.product == value,
                    IdentifyField::RevisionLow => a.revision >= value,
                    IdentifyField::RevisionHigh => a.revision <= value,
                    IdentifyField::SerialLow => a.serial >= value,
                    IdentifyField::SerialHigh => a.serial <= value,
                };
                if field.position() != expected || !matches {
                    return None;
                }
                if field == IdentifyField::SerialHigh {
                    return Some(Response::IdentifySlave);
                }
                self.identify = expected + 1;
                None
            }
            Request::IdentifyNonConfigured if self.unconfigured() => {
                Some(Response::NonConfiguredSlave)
            }
            Request::Fastscan {
                id_number,
                bit_check,
                sub,
                next,
            } if !configuring && self.unconfigured() => {
                if bit_check == FASTSCAN_CONFIRM {
                    self.fastscan = 0;
                    return Some(Response::IdentifySlave);
                }
                if sub != self.fastscan {
                    return None;
                }
                let part = Part::at(sub)?;
                let mask = u32::MAX << bit_check;
                if (self.address.part(part) ^ id_number) & mask != 0 {
                    return None;
                }
                // §4.7: a confirmed part (BitCheck 0) moves the slave on to LSSNext; back
                // to an earlier part means the whole address matched.
                if bit_check == 0 && next < sub {
                    self.mode = Mode::Configuration;
                }
                self.fastscan = next;
                Some(Response::IdentifySlave)
            }
            Request::ConfigureNodeId(n) if configuring => {
                let error = if (1..=127).contains(&n) || n == UNCONFIGURED {
                    self.pending = n;
                    0
                } else {
                    1
                };
                Some(Response::ConfigureNodeId { error, spec: 0 })
            }
            Request::ConfigureBitTiming { table, index } if configuring => {
                // §4.4.2: error 1 "bit timing not supported" for another table, a reserved
                // entry or automatic detection, which a twin on a virtual bus cannot do.
                let error = match (table, bit_rate_of(index)) {
                    (0, Some(rate)) => {
                        self.pending_bit_rate = rate;
                        0
                    }
                    _ => 1,
                };
                Some(Response::ConfigureBitTiming { error, spec: 0 })
            }
            Request::ActivateBitTiming { delay_ms } if configuring => {
                let delay = Duration::from_millis(u64::from(delay_ms));
                self.switch_at = Some((now + delay, self.pending_bit_rate));
                self.silent_until = Some(now + delay + delay);
                self.on_tick(now);
                None
            }
            Request::StoreConfiguration if configuring => {
                let stored = Stored {
                    node_id: self.pending,
                    bit_rate: self.pending_bit_rate,
                };
                // §4.4.4: error 2 "storage media access error".
                let error = match self.store.save(&stored) {
                    Ok(()) => 0,
                    Err(_) => 2,
                };
                Some(Response::StoreConfiguration { error, spec: 0 })
            }
            Request::Inquire(part) if configuring => {
                Some(Response::Address(part, self.address.part(part)))
            }
            Request::InquireNodeId if configuring => Some(Response::NodeId(self.active)),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lss::store::MemoryStore;

    const ADDR: Address = Address {
        vendor: 0x0000_0123,
        product: 0x0000_4567,
        revision: 0x0002_0001,
        serial: 0x00AB_CDEF,
    };

    fn slave(node_id: u8) -> Slave {
        Slave::new(ADDR, node_id, BitRate::R500K, Box::new(MemoryStore::new()))
    }

    /// The answers of `s` to `reqs`, at time 0.
    fn answers(s: &mut Slave, reqs: &[Request]) -> Vec<Response> {
        let mut out = Outbox::new();
        for r in reqs {
            assert!(s.on_frame(&r.encode(), Instant::ZERO, &mut out));
        }
        out.drain().map(|f| Response::decode(&f).unwrap()).collect()
    }

    #[test]
    fn cia305_4_5_inquiries_are_served_only_in_configuration() {
        let mut s = slave(5);
        assert!(answers(&mut s, &[Request::InquireNodeId]).is_empty());
        let got = answers(
            &mut s,
            &[
                Request::SwitchGlobal(Mode::Configuration),
                Request::Inquire(Part::Vendor),
                Request::Inquire(Part::Product),
                Request::Inquire(Part::Revision),
                Request::Inquire(Part::Serial),
                Request::InquireNodeId,
            ],
        );
        assert_eq!(
            got,
            [
                Response::Address(Part::Vendor, ADDR.vendor),
                Response::Address(Part::Product, ADDR.product),
                Response::Address(Part::Revision, ADDR.revision),
                Response::Address(Part::Serial, ADDR.serial),
                Response::NodeId(5),
            ]
        );
    }

    #[test]
    fn cia305_4_3_2_selective_switch_needs_the_four_parts_in_order() {
        let mut s = slave(5);
        let seq = |serial| {
            [
                Request::SwitchSelective(Part::Vendor, ADDR.vendor),
                Request::SwitchSelective(Part::Product, ADDR.product),
                Request::SwitchSelective(Part::Revision, ADDR.revision),
                Request::SwitchSelective(Part::Serial, serial),
            ]
        };
        assert!(answers(&mut s, &seq(ADDR.serial + 1)).is_empty());
        assert_eq!(s.mode(), Mode::Waiting);
        // Out of order: serial first does not count.
        let mut bad = seq(ADDR.serial).to_vec();
        bad.swap(0, 3);
        assert!(answers(&mut s, &bad).is_empty());
        assert_eq!(
            answers(&mut s, &seq(ADDR.serial)),
            [Response::SwitchSelective]
        );
        assert_eq!(s.mode(), Mode::Configuration);
    }

    #[test]
    fn cia305_4_4_1_node_id_is_pending_until_reset_communication() {
        let mut s = slave(UNCONFIGURED);
        let got = answers(
            &mut s,
            &[
                Request::SwitchGlobal(Mode::Configuration),
                Request::ConfigureNodeId(0),
                Request::ConfigureNodeId(128),
                Request::ConfigureNodeId(42),
                Request::InquireNodeId,
            ],
        );
        assert_eq!(
            got,
            [
                Response::ConfigureNodeId { error: 1, spec: 0 },
                Response::ConfigureNodeId { error: 1, spec: 0 },
                Response::ConfigureNodeId { error: 0, spec: 0 },
                Response::NodeId(UNCONFIGURED),
            ]
        );
        assert_eq!(s.pending_node_id(), 42);
        assert_eq!(s.poll_event(), None);
        answers(&mut s, &[Request::SwitchGlobal(Mode::Waiting)]);
        assert_eq!(s.poll_event(), Some(SlaveEvent::ResetCommunication));
        assert_eq!(s.reset_communication(), 42);
    }

    #[test]
    fn cia305_4_4_2_bit_timing_table_and_4_4_3_activation_delay() {
        let mut s = slave(5);
        let got = answers(
            &mut s,
            &[
                Request::SwitchGlobal(Mode::Configuration),
                Request::ConfigureBitTiming { table: 0, index: 5 },
                Request::ConfigureBitTiming { table: 1, index: 0 },
                Request::ConfigureBitTiming { table: 0, index: 9 },
                Request::ConfigureBitTiming { table: 0, index: 3 },
            ],
        );
        let err = |error| Response::ConfigureBitTiming { error, spec: 0 };
        assert_eq!(got, [err(1), err(1), err(1), err(0)]);
        assert_eq!(s.pending_bit_rate(), BitRate::R250K);
        assert_eq!(s.bit_rate(), BitRate::R500K);
        let mut out = Outbox::new();
        let t0 = Instant::ZERO + Duration::from_millis(10);
        let req = Request::ActivateBitTiming { delay_ms: 100 }.encode();
        assert!(s.on_frame(&req, t0, &mut out));
        assert!(out.is_empty());
        assert!(!s.may_transmit(t0));
        let t1 = t0 + Duration::from_millis(100);
        assert_eq!(s.next_deadline(), Some(t1));
        s.on_tick(t1);
        assert_eq!(
            s.poll_event(),
            Some(SlaveEvent::BitRateSwitched(BitRate::R250K))
        );
        assert!(!s.may_transmit(t1));
        let t2 = t1 + Duration::from_millis(100);
        assert_eq!(s.next_deadline(), Some(t2));
        s.on_tick(t2);
        assert!(s.may_transmit(t2));
        assert_eq!(s.next_deadline(), None);
    }

    #[test]
    fn cia305_4_4_4_store_configuration_survives_power_up() {
        let mut s = slave(5);
        let got = answers(
            &mut s,
            &[
                Request::SwitchGlobal(Mode::Configuration),
                Request::ConfigureNodeId(9),
                Request::ConfigureBitTiming { table: 0, index: 4 },
                Request::StoreConfiguration,
            ],
        );
        assert_eq!(got[2], Response::StoreConfiguration { error: 0, spec: 0 });
        s.power_up();
        assert_eq!(s.active_node_id(), 9);
        assert_eq!(s.bit_rate(), BitRate::R125K);
        assert_eq!(s.mode(), Mode::Waiting);
    }

    #[test]
    fn cia305_4_6_identify_remote_and_non_configured_slave() {
        let mut s = slave(UNCONFIGURED);
        let seq = |rev_lo, rev_hi| {
            [
                Request::IdentifyRemote(IdentifyField::Vendor, ADDR.vendor),
                Request::IdentifyRemote(IdentifyField::Product, ADDR.product),
                Request::IdentifyRemote(IdentifyField::RevisionLow, rev_lo),
                Request::IdentifyRemote(IdentifyField::RevisionHigh, rev_hi),
                Request::IdentifyRemote(IdentifyField::SerialLow, 0),
                Request::IdentifyRemote(IdentifyField::SerialHigh, u32::MAX),
            ]
        };
        assert_eq!(
            answers(&mut s, &seq(ADDR.revision, ADDR.revision)),
            [Response::IdentifySlave]
        );
        assert!(answers(&mut s, &seq(ADDR.revision + 1, u32::MAX)).is_empty());
        assert_eq!(
            answers(&mut s, &[Request::IdentifyNonConfigured]),
            [Response::NonConfiguredSlave]
        );
        let mut configured = slave(3);
        assert!(answers(&mut configured, &[Request::IdentifyNonConfigured]).is_empty());
    }

    #[test]
    fn cia305_4_7_fastscan_finds_the_address_bit_by_bit() {
        let mut s = slave(UNCONFIGURED);
        let scan = |id_number, bit_check, sub, next| Request::Fastscan {
            id_number,
            bit_check,
            sub,
            next,
        };
        assert_eq!(
            answers(&mut s, &[scan(0, FASTSCAN_CONFIRM, 0, 0)]),
            [Response::IdentifySlave]
        );
        // The master's search: a bit is 0 when the slave answers for 0 there.
        for sub in 0..4u8 {
            let mut found = 0u32;
            for bit in (0..32u8).rev() {
                if answers(&mut s, &[scan(found, bit, sub, sub)]).is_empty() {
                    found |= 1 << bit;
                }
            }
            let part = Part::at(sub).unwrap();
            assert_eq!(found, ADDR.part(part));
            assert_eq!(
                answers(&mut s, &[scan(found, 0, sub, (sub + 1) & 3)]),
                [Response::IdentifySlave]
            );
        }
        assert_eq!(s.mode(), Mode::Configuration);
        // A configured node does not take part.
        let mut configured = slave(3);
        assert!(answers(&mut configured, &[scan(0, FASTSCAN_CONFIRM, 0, 0)]).is_empty());
    }
}
