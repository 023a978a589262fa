//! Which frames of the ring to show: by node, by service, by identifier range, and the text
//! form a user types (`node=5 svc=emcy,hb id=0x180-0x1FF`).

use std::collections::BTreeSet;
use std::fmt;
use std::ops::RangeInclusive;

use cantwin_can::Frame;
use cantwin_canopen::lss::wire as wire_lss;
use cantwin_canopen::wire::{self, ErrorControl, Message};

/// The CANopen service of a frame, by the pre-defined connection set (CiA 301 §7.3.4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Service {
    /// NMT module control (0x000).
    Nmt,
    /// SYNC (0x080).
    Sync,
    /// EMCY (0x081–0x0FF).
    Emcy,
    /// TIME (0x100).
    Time,
    /// PDOs at the pre-defined COB-IDs (0x180–0x57F).
    Pdo,
    /// SDO requests and responses (0x580–0x67F).
    Sdo,
    /// NMT error control: boot-up, heartbeat, node guarding (0x700–0x77F).
    Heartbeat,
    /// Layer setting services (CiA 305 §4: 0x7E5 master, 0x7E4 slave).
    Lss,
    /// Anything else: extended frames, identifiers outside the set, malformed frames.
    Other,
}

impl Service {
    /// Every service, in identifier order.
    pub const ALL: [Service; 9] = [
        Service::Nmt,
        Service::Sync,
        Service::Emcy,
        Service::Time,
        Service::Pdo,
        Service::Sdo,
        Service::Heartbeat,
        Service::Lss,
        Service::Other,
    ];

    /// The short name used in filters and tables.
    pub fn name(self) -> &'static str {
        match self {
            Service::Nmt => "nmt",
            Service::Sync => "sync",
            Service::Emcy => "emcy",
            Service::Time => "time",
            Service::Pdo => "pdo",
            Service::Sdo => "sdo",
            Service::Heartbeat => "hb",
            Service::Lss => "lss",
            Service::Other => "other",
        }
    }

    /// The service of a decoded message.
    pub fn of(msg: &Message) -> Service {
        match msg {
            Message::Nmt(_) => Service::Nmt,
            Message::Sync(_) => Service::Sync,
            Message::Emcy { .. } => Service::Emcy,
            Message::Time(_) => Service::Time,
            Message::Pdo { .. } => Service::Pdo,
            Message::SdoRequest { .. } | Message::SdoResponse { .. } => Service::Sdo,
            Message::ErrorControl(_) => Service::Heartbeat,
            Message::Malformed { frame, .. } | Message::Other(frame) => {
                let id = frame.id().as_raw();
                let lss = [wire_lss::MASTER_ID, wire_lss::SLAVE_ID].map(u32::from);
                if !frame.is_extended() && lss.contains(&id) {
                    Service::Lss
                } else {
                    Service::Other
                }
            }
        }
    }
}

impl fmt::Display for Service {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Service {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let s = s.to_ascii_lowercase();
        match s.as_str() {
            "heartbeat" | "bootup" | "boot-up" | "guard" => Ok(Service::Heartbeat),
            "rpdo" | "tpdo" => Ok(Service::Pdo),
            _ => Service::ALL
                .into_iter()
                .find(|v| v.name() == s)
                .ok_or_else(|| {
                    format!(
                        "unknown service {s:?}: nmt, sync, emcy, time, pdo, sdo, hb, lss, other"
                    )
                }),
        }
    }
}

/// The node a message is about: the addressee of NMT, SDO and RPDOs, the producer of EMCY,
/// TPDOs, SDO responses and error control; `None` for broadcast and unknown frames.
pub fn node_of(msg: &Message) -> Option<u8> {
    match *msg {
        Message::Nmt(cmd) => (cmd.node != 0).then_some(cmd.node),
        Message::Emcy { node, .. }
        | Message::Pdo { node, .. }
        | Message::SdoRequest { node, .. }
        | Message::SdoResponse { node, .. } => Some(node),
        Message::ErrorControl(
            ErrorControl::GuardRequest { node } | ErrorControl::State { node, .. },
        ) => Some(node),
        Message::Sync(_) | Message::Time(_) | Message::Malformed { .. } | Message::Other(_) => None,
    }
}

/// A frame filter: every set criterion must hold; an empty filter passes every frame.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Filter {
    /// Only frames about these nodes (see [`node_of`]).
    pub nodes: BTreeSet<u8>,
    /// Only these services.
    pub services: BTreeSet<Service>,
    /// Only identifiers in this range (11- or 29-bit values).
    pub ids: Option<RangeInclusive<u32>>,
}

fn number(s: &str) -> Result<u32, String> {
    let parsed = match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(hex) => u32::from_str_radix(hex, 16),
        None => s.parse(),
    };
    parsed.map_err(|_| format!("{s:?} is not a number (decimal or 0x hexadecimal)"))
}

fn node(s: &str) -> Result<u8, String> {
    match number(s)? {
        n @ 1..=127 => Ok(n as u8),
        n => Err(format!("node {n} is not a node-ID 1-127")),
    }
}

impl Filter {
    /// Whether nothing is filtered.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty() && self.services.is_empty() && self.ids.is_none()
    }

    /// Whether a frame with this identifier, service and node passes.
    pub fn matches(&self, id: u32, service: Service, node: Option<u8>) -> bool {
        (self.nodes.is_empty() || node.is_some_and(|n| self.nodes.contains(&n)))
            && (self.services.is_empty() || self.services.contains(&service))
            && self.ids.as_ref().is_none_or(|r| r.contains(&id))
    }

    /// Whether `frame` passes.
    pub fn matches_frame(&self, frame: &Frame) -> bool {
        let msg = wire::decode(frame);
        self.matches(frame.id().as_raw(), Service::of(&msg), node_of(&msg))
    }

    /// Parse the text form: space-separated terms, each `node=N[,N…]`, `svc=NAME[,NAME…]`
    /// (nmt, sync, emcy, time, pdo, sdo, hb, lss, other), `id=ID` or `id=LOW-HIGH` (decimal or
    /// 0x hexadecimal); a bare service name or node number is a shorthand. Terms of the
    /// same key add up.
    pub fn parse(text: &str) -> Result<Filter, String> {
        let mut f = Filter::default();
        for term in text.split_whitespace() {
            match term.split_once('=') {
                Some(("node", v)) => {
                    for n in v.split(',') {
                        f.nodes.insert(node(n)?);
                    }
                }
                Some(("svc" | "service", v)) => {
                    for s in v.split(',') {
                        f.services.insert(s.parse()?);
                    }
                }
                Some(("id", v)) => {
                    let (lo, hi) = match v.split_once('-') {
                        Some((lo, hi)) => (number(lo)?, number(hi)?),
                        None => (number(v)?, number(v)?),
                    };
                    if lo > hi {
                        return Err(format!("id={v}: the range is empty"));
                    }
                    f.ids = Some(lo..=hi);
                }
                Some((key, _)) => {
                    return Err(format!("unknown filter key {key:?}: node, svc or id"));
                }
                None if term.chars().all(|c| c.is_ascii_alphanumeric()) && number(term).is_ok() => {
                    f.nodes.insert(node(term)?);
                }
                None => {
                    f.services.insert(term.parse()?);
                }
            }
        }
        Ok(f)
    }
}

impl fmt::Display for Filter {
    /// The text form [`Filter::parse`] reads back.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut terms = Vec::new();
        if !self.nodes.is_empty() {
            let list: Vec<String> = self.nodes.iter().map(u8::to_string).collect();
            terms.push(format!("node={}", list.join(",")));
        }
        if !self.services.is_empty() {
            let list: Vec<&str> = self.services.iter().map(|s| s.name()).collect();
            terms.push(format!("svc={}", list.join(",")));
        }
        if let Some(r) = &self.ids {
            terms.push(format!("id=0x{:X}-0x{:X}", r.start(), r.end()));
        }
        f.write_str(&terms.join(" "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_terms_and_shorthands() {
        let f = Filter::parse("node=5,12 svc=emcy,hb id=0x180-0x1FF").unwrap();
        assert_eq!(f.nodes, BTreeSet::from([5, 12]));
        assert_eq!(
            f.services,
            BTreeSet::from([Service::Emcy, Service::Heartbeat])
        );
        assert_eq!(f.ids, Some(0x180..=0x1FF));
        assert_eq!(Filter::parse(&f.to_string()).unwrap(), f);
        let short = Filter::parse("5 sdo").unwrap();
        assert_eq!(short.nodes, BTreeSet::from([5]));
        assert_eq!(short.services, BTreeSet::from([Service::Sdo]));
        assert_eq!(Filter::parse("id=0x705").unwrap().ids, Some(0x705..=0x705));
        assert!(Filter::parse("   ").unwrap().is_empty());
        assert_eq!(
            Filter::parse("svc=lss").unwrap().services,
            BTreeSet::from([Service::Lss])
        );
    }

    #[test]
    fn parse_errors_say_what_is_wrong() {
        assert!(Filter::parse("node=0").unwrap_err().contains("1-127"));
        assert!(
            Filter::parse("node=x")
                .unwrap_err()
                .contains("not a number")
        );
        assert!(
            Filter::parse("svc=foo")
                .unwrap_err()
                .contains("unknown service")
        );
        assert!(
            Filter::parse("id=0x200-0x100")
                .unwrap_err()
                .contains("empty")
        );
        assert!(
            Filter::parse("colour=red")
                .unwrap_err()
                .contains("unknown filter key")
        );
    }

    #[test]
    fn matching_needs_every_criterion() {
        let f = Filter::parse("node=5 svc=hb").unwrap();
        assert!(f.matches(0x705, Service::Heartbeat, Some(5)));
        assert!(!f.matches(0x706, Service::Heartbeat, Some(6)));
        assert!(!f.matches(0x085, Service::Emcy, Some(5)));
        assert!(!f.matches(0x080, Service::Heartbeat, None));
        let sync = Frame::data(cantwin_can::Id::standard(0x80).unwrap(), &[]).unwrap();
        assert!(Filter::default().matches_frame(&sync));
        assert!(Filter::parse("sync").unwrap().matches_frame(&sync));
        assert!(
            !Filter::parse("id=0x100-0x7FF")
                .unwrap()
                .matches_frame(&sync)
        );
        // CiA 305 §4.2: LSS frames on 0x7E4/0x7E5 are their own service, even malformed.
        let lss = Frame::data(cantwin_can::Id::standard(0x7E5).unwrap(), &[0x5E]).unwrap();
        assert!(Filter::parse("lss").unwrap().matches_frame(&lss));
        let near = Frame::data(cantwin_can::Id::standard(0x7E6).unwrap(), &[0; 8]).unwrap();
        assert!(Filter::parse("other").unwrap().matches_frame(&near));
    }
}
