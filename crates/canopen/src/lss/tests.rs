//! The master and slaves on one virtual bus: each frame one master or slave queues reaches
//! every other one 250 µs later (about one 8-byte frame at 500 kbit/s), timers fire in
//! virtual time.

use cantwin_can::{BitRate, Duration, Instant, Node, Outbox};

use super::*;

/// A master and slaves exchanging frames in virtual time.
struct Net {
    now: Instant,
    master: Master,
    slaves: Vec<Slave>,
    /// Frames in flight: (arrival, from the master?, frame).
    wire: Vec<(Instant, bool, cantwin_can::Frame)>,
}

const HOP: Duration = Duration::from_micros(250);

impl Net {
    fn new(slaves: Vec<Slave>) -> Net {
        Net {
            now: Instant::ZERO,
            master: Master::new(Duration::from_millis(10)),
            slaves,
            wire: Vec::new(),
        }
    }

    fn queue(&mut self, out: &mut Outbox, from_master: bool) {
        for f in out.drain() {
            self.wire.push((self.now + HOP, from_master, f));
        }
    }

    /// Runs `service` to its end, in virtual time.
    fn run(&mut self, service: Service) -> Outcome {
        let mut out = Outbox::new();
        self.master.start(service, self.now, &mut out).unwrap();
        self.queue(&mut out, true);
        for _ in 0..100_000 {
            if let Some(o) = self.master.poll() {
                return o;
            }
            let next_frame = self.wire.iter().map(|w| w.0).min();
            let next_tick = self
                .slaves
                .iter()
                .filter_map(Slave::next_deadline)
                .chain(self.master.next_deadline())
                .min();
            let Some(t) = next_frame.into_iter().chain(next_tick).min() else {
                panic!("nothing left to happen and no outcome");
            };
            self.now = self.now.max(t);
            if let Some(i) = self.wire.iter().position(|w| w.0 <= self.now) {
                let (_, from_master, f) = self.wire.remove(i);
                if from_master {
                    for s in &mut self.slaves {
                        s.on_frame(&f, self.now, &mut out);
                    }
                    self.queue(&mut out, false);
                } else {
                    self.master.on_frame(&f, self.now, &mut out);
                    self.queue(&mut out, true);
                }
                continue;
            }
            for s in &mut self.slaves {
                s.on_tick(self.now);
            }
            self.master.on_tick(self.now, &mut out);
            self.queue(&mut out, true);
        }
        panic!("the service did not end");
    }
}

fn slave(serial: u32, node_id: u8) -> Slave {
    let address = Address {
        vendor: 0x5A5A_0001,
        product: 0x0000_0402,
        revision: 0x0001_0000,
        serial,
    };
    Slave::new(
        address,
        node_id,
        BitRate::R500K,
        Box::new(MemoryStore::new()),
    )
}

#[test]
fn cia305_master_commissions_two_unconfigured_slaves_by_fastscan() {
    let mut net = Net::new(vec![
        slave(0x0000_1234, UNCONFIGURED),
        slave(0x8000_0001, UNCONFIGURED),
    ]);
    let mut found = Vec::new();
    for node_id in [10u8, 11] {
        let Outcome::Address(a) = net.run(Service::Fastscan) else {
            panic!("fastscan found no slave");
        };
        found.push(a.serial);
        assert_eq!(net.run(Service::ConfigureNodeId(node_id)), Outcome::Done);
        assert_eq!(net.run(Service::StoreConfiguration), Outcome::Done);
        assert_eq!(net.run(Service::SwitchGlobal(Mode::Waiting)), Outcome::Done);
    }
    // The lower serial wins the scan (a 0 bit is answered first).
    assert_eq!(found, [0x0000_1234, 0x8000_0001]);
    assert_eq!(net.run(Service::Fastscan), Outcome::Timeout);
    for (s, id) in net.slaves.iter_mut().zip([10, 11]) {
        assert_eq!(s.poll_event(), Some(SlaveEvent::ResetCommunication));
        assert_eq!(s.reset_communication(), id);
    }
    assert_eq!(
        net.run(Service::IdentifyNonConfigured),
        Outcome::Identified(0)
    );
}

#[test]
fn cia305_master_selective_switch_inquiry_and_identify_remote() {
    let mut net = Net::new(vec![slave(7, 3), slave(8, 4)]);
    let a = net.slaves[1].address();
    assert_eq!(net.run(Service::SwitchSelective(a)), Outcome::Done);
    assert_eq!(net.run(Service::InquireNodeId), Outcome::NodeId(4));
    assert_eq!(net.run(Service::InquireAddress), Outcome::Address(a));
    assert_eq!(net.run(Service::Inquire(Part::Serial)), Outcome::Value(8));
    assert_eq!(
        net.run(Service::ConfigureNodeId(200)),
        Outcome::Refused { error: 1, spec: 0 }
    );
    assert_eq!(
        net.run(Service::ConfigureBitTiming { table: 0, index: 5 }),
        Outcome::Refused { error: 1, spec: 0 }
    );
    assert_eq!(net.run(Service::SwitchGlobal(Mode::Waiting)), Outcome::Done);
    let missing = Address { serial: 9, ..a };
    assert_eq!(net.run(Service::SwitchSelective(missing)), Outcome::Timeout);
    let both = Service::IdentifyRemote {
        vendor: a.vendor,
        product: a.product,
        revision: (0, u32::MAX),
        serial: (7, 8),
    };
    assert_eq!(net.run(both), Outcome::Identified(2));
    // A master with a service running refuses another.
    let mut out = Outbox::new();
    net.master
        .start(Service::InquireNodeId, net.now, &mut out)
        .unwrap();
    assert_eq!(
        net.master.start(Service::Fastscan, net.now, &mut out),
        Err(Busy)
    );
}

#[test]
fn cia305_4_7_fastscan_matches_known_parts_and_skips_others() {
    let other = Slave::new(
        Address {
            vendor: 0x0000_0099,
            product: 1,
            revision: 1,
            serial: 1,
        },
        UNCONFIGURED,
        BitRate::R500K,
        Box::new(MemoryStore::new()),
    );
    let mut net = Net::new(vec![slave(0x0000_0500, UNCONFIGURED), other]);
    let plan = [
        Scan::Match(0x5A5A_0001),
        Scan::Skip,
        Scan::Search,
        Scan::Search,
    ];
    let Outcome::Address(a) = net.run(Service::FastscanWith(plan)) else {
        panic!("no slave found");
    };
    assert_eq!(
        a,
        Address {
            vendor: 0x5A5A_0001,
            product: 0,
            revision: 0x0001_0000,
            serial: 0x0000_0500
        }
    );
    assert_eq!(net.slaves[0].mode(), Mode::Configuration);
    assert_eq!(net.slaves[1].mode(), Mode::Waiting);
    // Nothing matches an absent vendor.
    net.run(Service::SwitchGlobal(Mode::Waiting));
    let none = [Scan::Match(0x1234), Scan::Search, Scan::Skip, Scan::Skip];
    assert_eq!(net.run(Service::FastscanWith(none)), Outcome::Timeout);
}

mod properties {
    use super::*;
    use cantwin_can::Frame;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        /// Any 0–8 bytes on 0x7E5: a request decodes only from 8 bytes and encodes back to
        /// the same frame where its unused bytes are 0; a slave given it never panics and
        /// answers at most one frame, always on 0x7E4.
        #[test]
        fn cia305_4_2_any_master_frame_is_decoded_or_dropped(
            data in proptest::collection::vec(any::<u8>(), 0..=8),
            node_id in prop_oneof![Just(UNCONFIGURED), 1u8..=127],
            configuration in any::<bool>(),
        ) {
            let f = Frame::std(wire::MASTER_ID, &data).unwrap();
            if let Ok(req) = Request::decode(&f) {
                prop_assert_eq!(data.len(), 8);
                prop_assert_eq!(Request::decode(&req.encode()), Ok(req));
            }
            let mut s = Slave::new(Address::default(), node_id, BitRate::R500K, Box::new(MemoryStore::new()));
            let mut out = Outbox::new();
            if configuration {
                s.on_frame(&Request::SwitchGlobal(Mode::Configuration).encode(), Instant::ZERO, &mut out);
            }
            s.on_frame(&f, Instant::ZERO, &mut out);
            prop_assert!(out.len() <= 1);
            for a in out.drain() {
                prop_assert_eq!(a.id().as_raw(), u32::from(wire::SLAVE_ID));
                prop_assert!(Response::decode(&a).is_ok());
            }
        }

        /// Any 0–8 bytes on 0x7E4 while a master waits: it never panics and a service
        /// ends with an outcome by its deadline.
        #[test]
        fn cia305_master_takes_any_slave_frame(
            data in proptest::collection::vec(any::<u8>(), 0..=8),
            pick in 0usize..4,
        ) {
            let services = [
                Service::InquireNodeId,
                Service::InquireAddress,
                Service::StoreConfiguration,
                Service::Fastscan,
            ];
            let mut m = Master::new(Duration::from_millis(10));
            let mut out = Outbox::new();
            m.start(services[pick], Instant::ZERO, &mut out).unwrap();
            let f = Frame::std(wire::SLAVE_ID, &data).unwrap();
            m.on_frame(&f, Instant::ZERO, &mut out);
            for _ in 0..200 {
                let Some(now) = m.next_deadline() else {
                    break;
                };
                m.on_tick(now, &mut out);
            }
            prop_assert!(m.is_idle());
        }
    }
}
