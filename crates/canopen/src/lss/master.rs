//! The LSS master (CiA 305 §6): one service at a time, each request sent at once and its
//! answer awaited for the master's timeout. Sans-IO: it is a [`Node`] that queues its
//! requests into the outbox and takes the slaves' answers from [`Node::on_frame`].
//!
//! Fastscan (§4.7) is a sequence of requests: a reset (BitCheck 0x80) that every
//! non-configured slave answers, then for each address part 32 requests from bit 31 down,
//! a request for a 0 there that no slave answers meaning the bit is 1, and a confirmation of
//! the part that moves the matching slave on to the next one. After the serial number the
//! slave found is in LSS configuration. Every fastscan step lasts the whole timeout, since
//! any number of slaves may answer it (as CANopenNode's master waits).

use cantwin_can::{Duration, Frame, Id, Instant, Node, Outbox};

use super::wire::{
    Address, FASTSCAN_CONFIRM, IdentifyField, Mode, Part, Request, Response, SLAVE_ID,
};

/// A service the master runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Service {
    /// Switch state global (no answer).
    SwitchGlobal(Mode),
    /// Switch state selective to the slave with this address; needs its 0x44.
    SwitchSelective(Address),
    /// Configure node-ID of the slave(s) in configuration.
    ConfigureNodeId(u8),
    /// Configure bit timing: table selector and table index.
    ConfigureBitTiming {
        /// The table selector (0: CiA 301 table).
        table: u8,
        /// The table index.
        index: u8,
    },
    /// Activate bit timing with this switch delay in ms (no answer).
    ActivateBitTiming(u16),
    /// Store configuration.
    StoreConfiguration,
    /// Inquire one part of the address.
    Inquire(Part),
    /// Inquire the whole address (four inquiries).
    InquireAddress,
    /// Inquire node-ID.
    InquireNodeId,
    /// Identify remote slave: the slaves with this vendor-ID and product code whose revision
    /// and serial number lie in the inclusive bounds answer.
    IdentifyRemote {
        /// The vendor-ID.
        vendor: u32,
        /// The product code.
        product: u32,
        /// The revision number bounds.
        revision: (u32, u32),
        /// The serial number bounds.
        serial: (u32, u32),
    },
    /// Identify non-configured remote slave.
    IdentifyNonConfigured,
    /// Fastscan: find one non-configured slave and switch it to configuration.
    Fastscan,
    /// Fastscan with a plan per address part (vendor, product, revision, serial): searched
    /// bit by bit, matched against a known value, or skipped (CANopenNode's `lss_allnodes`
    /// scan types 0, 2 and 1).
    FastscanWith([Scan; 4]),
}

/// How a fastscan treats one part of the address.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scan {
    /// Found bit by bit.
    Search,
    /// Not compared: the slaves move past it (LSSNext skips it). Shown as 0 in the result.
    Skip,
    /// Only a slave with this value goes on (one confirmation, no bit search).
    Match(u32),
}

/// The plan of a fastscan service.
fn plan_of(service: Service) -> [Scan; 4] {
    match service {
        Service::FastscanWith(plan) => plan,
        _ => [Scan::Search; 4],
    }
}

/// The first part after `sub` (or from the start, `None`) that the plan does not skip.
fn part_after(plan: &[Scan; 4], sub: Option<u8>) -> Option<u8> {
    let from = sub.map_or(0, |s| s + 1);
    (from..4).find(|i| plan[usize::from(*i)] != Scan::Skip)
}

/// The LSSNext of the confirmation of `sub`: the next part compared, or the first one again
/// after the last (CiA 305 §4.7: a slave sent back to an earlier part enters configuration).
fn next_of(plan: &[Scan; 4], sub: u8) -> u8 {
    part_after(plan, Some(sub))
        .or_else(|| part_after(plan, None))
        .unwrap_or(0)
}

/// How a service ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Done: sent (services without an answer) or confirmed with error 0.
    Done,
    /// The slave answered with an error code (and manufacturer-specific error).
    Refused {
        /// The error code: 1 not supported / out of range, 2 storage media access error,
        /// 0xFF manufacturer-specific.
        error: u8,
        /// The manufacturer-specific error.
        spec: u8,
    },
    /// An inquired address part.
    Value(u32),
    /// The inquired node-ID (0xFF: none).
    NodeId(u8),
    /// An address: the whole inquired one, or the slave fastscan found (now in LSS
    /// configuration).
    Address(Address),
    /// Identification: how many answers came within the timeout.
    Identified(usize),
    /// No slave answered (fastscan: no non-configured slave is left).
    Timeout,
}

/// The master is running another service.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("the LSS master is busy with another service")]
pub struct Busy;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    /// Awaiting an answer to one request.
    Answer,
    /// Collecting identification answers until the deadline.
    Collect(usize),
    /// Inquiring the address, part by part.
    Address(Address, Part),
    /// Fastscan: the reset.
    ScanReset,
    /// Fastscan: the request for bit `bit` of part `sub`, with the bits found so far.
    ScanBit {
        sub: u8,
        bit: u8,
        found: u32,
        address: Address,
    },
    /// Fastscan: the confirmation of part `sub`.
    ScanConfirm {
        sub: u8,
        found: u32,
        address: Address,
    },
}

#[derive(Debug, Clone, Copy)]
struct Running {
    service: Service,
    step: Step,
    deadline: Instant,
    /// Fastscan: an answer to the current step came.
    answered: bool,
}

/// An LSS master. See the [module documentation](self).
#[derive(Debug, Clone)]
pub struct Master {
    timeout: Duration,
    running: Option<Running>,
    outcome: Option<Outcome>,
}

impl Master {
    /// A master that waits `timeout` for each answer.
    pub fn new(timeout: Duration) -> Self {
        Master {
            timeout,
            running: None,
            outcome: None,
        }
    }

    /// The time each answer is awaited.
    pub fn timeout(&self) -> Duration {
        self.timeout
    }

    /// Changes the time each answer is awaited (from the next request on).
    pub fn set_timeout(&mut self, timeout: Duration) {
        self.timeout = timeout;
    }

    /// Whether no service is running.
    pub fn is_idle(&self) -> bool {
        self.running.is_none()
    }

    /// How the last service ended, once it has.
    pub fn poll(&mut self) -> Option<Outcome> {
        self.outcome.take()
    }

    /// Starts `service` at `now`; its first requests go to `out`.
    pub fn start(&mut self, service: Service, now: Instant, out: &mut Outbox) -> Result<(), Busy> {
        if self.running.is_some() {
            return Err(Busy);
        }
        self.outcome = None;
        let deadline = now + self.timeout;
        let step = match service {
            Service::SwitchGlobal(mode) => {
                out.push(Request::SwitchGlobal(mode).encode());
                self.outcome = Some(Outcome::Done);
                return Ok(());
            }
            Service::ActivateBitTiming(delay_ms) => {
                out.push(Request::ActivateBitTiming { delay_ms }.encode());
                self.outcome = Some(Outcome::Done);
                return Ok(());
            }
            Service::SwitchSelective(a) => {
                for p in Part::ALL {
                    out.push(Request::SwitchSelective(p, a.part(p)).encode());
                }
                Step::Answer
            }
            Service::ConfigureNodeId(n) => {
                out.push(Request::ConfigureNodeId(n).encode());
                Step::Answer
            }
            Service::ConfigureBitTiming { table, index } => {
                out.push(Request::ConfigureBitTiming { table, index }.encode());
                Step::Answer
            }
            Service::StoreConfiguration => {
                out.push(Request::StoreConfiguration.encode());
                Step::Answer
            }
            Service::Inquire(p) => {
                out.push(Request::Inquire(p).encode());
                Step::Answer
            }
            Service::InquireNodeId => {
                out.push(Request::InquireNodeId.encode());
                Step::Answer
            }
            Service::InquireAddress => {
                out.push(Request::Inquire(Part::Vendor).encode());
                Step::Address(Address::default(), Part::Vendor)
            }
            Service::IdentifyRemote {
                vendor,
                product,
                revision,
                serial,
            } => {
                let values = [vendor, product, revision.0, revision.1, serial.0, serial.1];
                for (f, v) in IdentifyField::ALL.into_iter().zip(values) {
                    out.push(Request::IdentifyRemote(f, v).encode());
                }
                Step::Collect(0)
            }
            Service::IdentifyNonConfigured => {
                out.push(Request::IdentifyNonConfigured.encode());
                Step::Collect(0)
            }
            Service::Fastscan | Service::FastscanWith(_) => {
                out.push(scan(0, FASTSCAN_CONFIRM, 0, 0).encode());
                Step::ScanReset
            }
        };
        self.running = Some(Running {
            service,
            step,
            deadline,
            answered: false,
        });
        Ok(())
    }

    fn finish(&mut self, outcome: Outcome) {
        self.running = None;
        self.outcome = Some(outcome);
    }

    /// Moves a running step on: `answered` says whether its answer came.
    fn advance(&mut self, r: Running, answered: bool, now: Instant, out: &mut Outbox) {
        let next = |step| Running {
            service: r.service,
            step,
            deadline: now + self.timeout,
            answered: false,
        };
        let plan = plan_of(r.service);
        match r.step {
            Step::ScanReset => {
                if !answered {
                    return self.finish(Outcome::Timeout);
                }
                match part_after(&plan, None) {
                    Some(sub) => {
                        self.running = Some(next(begin(&plan, sub, Address::default(), out)))
                    }
                    None => self.finish(Outcome::Timeout),
                }
            }
            Step::ScanBit {
                sub,
                bit,
                found,
                address,
            } => {
                // No answer for a 0 in this bit: every candidate has a 1 there.
                let found = if answered { found } else { found | (1 << bit) };
                if bit == 0 {
                    out.push(scan(found, 0, sub, next_of(&plan, sub)).encode());
                    self.running = Some(next(Step::ScanConfirm {
                        sub,
                        found,
                        address,
                    }));
                } else {
                    out.push(scan(found, bit - 1, sub, sub).encode());
                    self.running = Some(next(Step::ScanBit {
                        sub,
                        bit: bit - 1,
                        found,
                        address,
                    }));
                }
            }
            Step::ScanConfirm {
                sub,
                found,
                mut address,
            } => {
                if !answered {
                    return self.finish(Outcome::Timeout);
                }
                let Some(part) = Part::at(sub) else {
                    return self.finish(Outcome::Timeout);
                };
                address.set_part(part, found);
                match part_after(&plan, Some(sub)) {
                    Some(n) => self.running = Some(next(begin(&plan, n, address, out))),
                    None => self.finish(Outcome::Address(address)),
                }
            }
            Step::Answer | Step::Address(..) | Step::Collect(_) => {
                self.finish(Outcome::Timeout);
            }
        }
    }
}

/// The first request for part `sub` of a fastscan: its bit 31, or the confirmation of the
/// value it must match.
fn begin(plan: &[Scan; 4], sub: u8, address: Address, out: &mut Outbox) -> Step {
    match plan[usize::from(sub)] {
        Scan::Match(v) => {
            out.push(scan(v, 0, sub, next_of(plan, sub)).encode());
            Step::ScanConfirm {
                sub,
                found: v,
                address,
            }
        }
        Scan::Search | Scan::Skip => {
            out.push(scan(0, 31, sub, sub).encode());
            Step::ScanBit {
                sub,
                bit: 31,
                found: 0,
                address,
            }
        }
    }
}

fn scan(id_number: u32, bit_check: u8, sub: u8, next: u8) -> Request {
    Request::Fastscan {
        id_number,
        bit_check,
        sub,
        next,
    }
}

impl Node for Master {
    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        let Some(r) = self.running else {
            return;
        };
        let Ok(resp) = Response::decode(frame) else {
            return;
        };
        let refused = |error, spec| {
            if error == 0 {
                Outcome::Done
            } else {
                Outcome::Refused { error, spec }
            }
        };
        match (r.step, r.service, resp) {
            (Step::Answer, Service::SwitchSelective(_), Response::SwitchSelective) => {
                self.finish(Outcome::Done);
            }
            (
                Step::Answer,
                Service::ConfigureNodeId(_),
                Response::ConfigureNodeId { error, spec },
            )
            | (
                Step::Answer,
                Service::ConfigureBitTiming { .. },
                Response::ConfigureBitTiming { error, spec },
            )
            | (
                Step::Answer,
                Service::StoreConfiguration,
                Response::StoreConfiguration { error, spec },
            ) => self.finish(refused(error, spec)),
            (Step::Answer, Service::Inquire(p), Response::Address(got, v)) if got == p => {
                self.finish(Outcome::Value(v));
            }
            (Step::Answer, Service::InquireNodeId, Response::NodeId(n)) => {
                self.finish(Outcome::NodeId(n));
            }
            (Step::Address(mut a, p), _, Response::Address(got, v)) if got == p => {
                a.set_part(p, v);
                match Part::at(p.position() + 1) {
                    Some(next) => {
                        out.push(Request::Inquire(next).encode());
                        self.running = Some(Running {
                            step: Step::Address(a, next),
                            deadline: now + self.timeout,
                            ..r
                        });
                    }
                    None => self.finish(Outcome::Address(a)),
                }
            }
            (Step::Collect(n), Service::IdentifyRemote { .. }, Response::IdentifySlave)
            | (Step::Collect(n), Service::IdentifyNonConfigured, Response::NonConfiguredSlave) => {
                self.running = Some(Running {
                    step: Step::Collect(n + 1),
                    ..r
                });
            }
            (
                Step::ScanReset | Step::ScanBit { .. } | Step::ScanConfirm { .. },
                _,
                Response::IdentifySlave,
            ) => {
                // Several slaves may answer one step: the step ends at its deadline.
                self.running = Some(Running {
                    answered: true,
                    ..r
                });
            }
            _ => {}
        }
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        let Some(r) = self.running else {
            return;
        };
        if now < r.deadline {
            return;
        }
        match r.step {
            Step::Collect(n) => self.finish(Outcome::Identified(n)),
            _ => self.advance(r, r.answered, now, out),
        }
    }

    fn next_deadline(&self) -> Option<Instant> {
        self.running.map(|r| r.deadline)
    }

    fn accepts(&self, id: Id) -> bool {
        id == Id::Standard(SLAVE_ID_STD)
    }

    fn acceptance_version(&self) -> Option<u64> {
        Some(0)
    }
}

const SLAVE_ID_STD: cantwin_can::StandardId = match cantwin_can::StandardId::new(SLAVE_ID) {
    Ok(id) => id,
    Err(_) => panic!("0x7E4 is a standard identifier"),
};
