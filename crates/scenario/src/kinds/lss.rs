//! An LSS slave (CiA 305) in front of a generic CiA 301 device, for the `cia301` and `eds`
//! kinds with `lss = true`.
//!
//! The node answers LSS on 0x7E5/0x7E4 with the LSS address of its 0x1018 sub 1–4. A node
//! without node-ID (`node_id = 0xFF` or `"unconfigured"`) waits for LSS: no boot-up,
//! heartbeat, SDO or NMT until it has been given a node-ID (CiA 305 §3.3; CANopenNode does
//! the same: its NMT does not run before, so an NMT reset does not apply a node-ID
//! configured in that state; leaving LSS configuration does). A configured node-ID becomes active at reset communication or reset node
//! (§4.4.1) and when a node that had none leaves LSS configuration; the device then starts
//! with the new node-ID as after its boot (a reset communication keeps the values of the
//! manufacturer and profile objects, a reset node does not). Store configuration keeps the
//! pending node-ID and bit rate for the next power-up: in `STATE_DIR/<device name>/lss.params`
//! with `--state-dir`, in memory for the run without.
//!
//! Bit rate: the virtual bus runs at the rate of its `[[bus]]` table, so the node keeps its
//! own rate as a setting of its attachment. After activate bit timing (or a power-up with a
//! stored rate) the node runs at its rate; while that differs from the bus's, its
//! controller can neither receive nor send (as on a real bus, where it would only see
//! errors), until a power-up at the bus's rate. During the two switch delays of activate
//! bit timing the node sends nothing (§4.4.3).

use cantwin_can::{BitRate, ControllerEvent, Frame, Id, Instant, Node, Outbox};
use cantwin_canopen::device::Device;
use cantwin_canopen::lss::{
    Address, FileStore, MemoryStore, Slave, SlaveEvent, Store, UNCONFIGURED, wire,
};
use cantwin_canopen::od::ObjectDictionary;
use cantwin_canopen::storage::{self, Group, MemoryStorage, Storage};
use cantwin_twin::{
    Context, LiveValue, ObjectError, SignalDescription, SignalError, SignalId, SignalValue,
    SummaryEntry, Twin,
};

use crate::error::ScenarioError;
use crate::registry::{BuildEnv, Settings};
use crate::spec::BusSpec;

/// A device an LSS slave can give another node-ID: built anew for it, with the parameter
/// storage handed over.
pub trait Commissionable: Node + Twin + Send + 'static {
    /// The CiA 301 device inside.
    fn device_mut(&mut self) -> &mut Device;
}

impl Commissionable for Device {
    fn device_mut(&mut self) -> &mut Device {
        self
    }
}

/// Builds the device for a node-ID (1–127).
pub type Make<D> = Box<dyn Fn(u8) -> Option<D> + Send>;

/// An LSS slave in front of a device. See the [module documentation](self).
pub struct LssNode<D> {
    slave: Slave,
    device: Option<D>,
    make: Make<D>,
    bus_rate: BitRate,
    /// The parameter storage while there is no device.
    spare: Option<Box<dyn Storage>>,
    scratch: Outbox,
}

impl<D> core::fmt::Debug for LssNode<D> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("LssNode")
            .field("slave", &self.slave)
            .field("configured", &self.device.is_some())
            .finish_non_exhaustive()
    }
}

fn is_std(id: Id, raw: u16) -> bool {
    !id.is_extended() && id.as_raw() == u32::from(raw)
}

/// The NMT command specifiers that reset communication (CiA 301 §7.2.8.3.1.1).
const RESET_NODE: u8 = 0x81;
const RESET_COMMUNICATION: u8 = 0x82;

impl<D: Commissionable> LssNode<D> {
    /// A node with `slave` in front of the devices `make` builds, whose parameters live in
    /// `storage`, on a bus at `bus_rate`.
    pub(crate) fn new(
        slave: Slave,
        make: Make<D>,
        storage: Box<dyn Storage>,
        bus_rate: BitRate,
    ) -> Self {
        LssNode {
            slave,
            device: None,
            make,
            bus_rate,
            spare: Some(storage),
            scratch: Outbox::new(),
        }
    }

    /// The LSS slave.
    pub fn slave(&self) -> &Slave {
        &self.slave
    }

    /// The device, while the node has a node-ID.
    pub fn device(&self) -> Option<&D> {
        self.device.as_ref()
    }

    /// Whether the controller runs at the bus's bit rate.
    fn in_step(&self) -> bool {
        self.slave.bit_rate() == self.bus_rate
    }

    /// The device for `node_id` (none for 0xFF), the storage handed over.
    fn rebuild(&mut self, node_id: u8) {
        if self
            .device
            .as_mut()
            .is_some_and(|d| d.device_mut().node_id() == node_id)
        {
            return;
        }
        let storage = match self.device.take() {
            Some(mut d) => d.device_mut().take_storage(),
            None => self
                .spare
                .take()
                .unwrap_or_else(|| Box::new(MemoryStorage::new())),
        };
        if node_id == UNCONFIGURED {
            self.spare = Some(storage);
            return;
        }
        match (self.make)(node_id) {
            Some(mut d) => {
                d.device_mut().set_storage(storage);
                self.device = Some(d);
            }
            // Only a node-ID outside 1–127 makes a device fail, and the slave takes none.
            None => self.spare = Some(storage),
        }
    }

    /// The pending node-ID becomes the active one: the device starts with it; `keep`
    /// carries the manufacturer and profile values over (reset communication).
    fn take_pending(&mut self, keep: bool, now: Instant) {
        let kept: Vec<(Group, Vec<u8>)> = match (&mut self.device, keep) {
            (Some(d), true) => [Group::Manufacturer, Group::Application]
                .into_iter()
                .map(|g| (g, storage::encode(d.device_mut().od(), g)))
                .collect(),
            _ => Vec::new(),
        };
        let id = self.slave.reset_communication();
        self.rebuild(id);
        if let Some(d) = &mut self.device {
            d.on_power_up(now, &mut self.scratch);
            for (g, blob) in &kept {
                // The blob was made from a dictionary of the same description a moment ago.
                let _ = storage::apply(d.device_mut().od_mut(), *g, blob);
            }
        }
    }

    fn slave_events(&mut self, now: Instant) {
        while let Some(e) = self.slave.poll_event() {
            match e {
                SlaveEvent::ResetCommunication => self.take_pending(true, now),
                // The rate is read from the slave whenever the node is called.
                SlaveEvent::BitRateSwitched(_) | SlaveEvent::StoreLoadFailed => {}
            }
        }
    }

    /// The frames of this call go out unless the node must be silent.
    fn flush(&mut self, now: Instant, out: &mut Outbox) {
        if self.in_step() && self.slave.may_transmit(now) {
            for f in self.scratch.drain() {
                out.push(f);
            }
        } else {
            self.scratch.clear();
        }
    }

    /// Whether `frame` is an NMT reset addressed to this node while another node-ID is
    /// pending, and which.
    fn nmt_reset(&self, frame: &Frame) -> Option<u8> {
        let d = frame.data_bytes();
        let active = self.slave.active_node_id();
        (is_std(frame.id(), 0)
            && d.len() == 2
            && matches!(d[0], RESET_NODE | RESET_COMMUNICATION)
            && (d[1] == 0 || d[1] == active)
            && self.slave.pending_node_id() != active)
            .then_some(d[0])
    }
}

impl<D: Commissionable> Node for LssNode<D> {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.slave.power_up();
        self.slave_events(now);
        let id = self.slave.active_node_id();
        self.rebuild(id);
        if let Some(d) = &mut self.device {
            d.on_power_up(now, &mut self.scratch);
        }
        self.flush(now, out);
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        if !self.in_step() {
            return;
        }
        if self.slave.on_frame(frame, now, &mut self.scratch) {
            self.slave_events(now);
        } else if let Some(cs) = self.nmt_reset(frame) {
            if self.device.is_some() {
                self.take_pending(cs == RESET_COMMUNICATION, now);
            }
        } else if let Some(d) = &mut self.device {
            d.on_frame(frame, now, &mut self.scratch);
        }
        self.flush(now, out);
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        self.slave.on_tick(now);
        self.slave_events(now);
        if let Some(d) = &mut self.device
            && d.next_deadline().is_some_and(|t| t <= now)
        {
            d.on_tick(now, &mut self.scratch);
        }
        self.flush(now, out);
    }

    fn next_deadline(&self) -> Option<Instant> {
        let d = self.device.as_ref().and_then(Node::next_deadline);
        Instant::earliest(d, self.slave.next_deadline())
    }

    fn on_sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        if let Some(d) = &mut self.device {
            d.on_sent(frame, now, &mut self.scratch);
        }
        self.flush(now, out);
    }

    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        if let Some(d) = &mut self.device {
            d.on_controller_event(event, now, &mut self.scratch);
        }
        self.flush(now, out);
    }

    fn accepts(&self, id: Id) -> bool {
        is_std(id, wire::MASTER_ID)
            || is_std(id, 0)
            || self.device.as_ref().is_some_and(|d| d.accepts(id))
    }
}

impl<D: Commissionable> Twin for LssNode<D> {
    fn dictionary(&self) -> Option<&ObjectDictionary> {
        self.device.as_ref()?.dictionary()
    }

    fn read_object(&self, index: u16, sub: u8) -> Result<Vec<u8>, ObjectError> {
        match &self.device {
            Some(d) => d.read_object(index, sub),
            None => Err(ObjectError::NoDictionary),
        }
    }

    fn write_object(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
        cx: &mut Context<'_>,
    ) -> Result<(), ObjectError> {
        match &mut self.device {
            Some(d) => d.write_object(index, sub, data, cx),
            None => Err(ObjectError::NoDictionary),
        }
    }

    fn dictionary_heap_bytes(&self) -> Option<usize> {
        self.device.as_ref()?.dictionary_heap_bytes()
    }

    fn lss_slave(&self) -> bool {
        true
    }

    fn canopen_node_id(&self) -> Option<u8> {
        self.device.as_ref()?.canopen_node_id()
    }

    fn signals(&self) -> Vec<SignalDescription> {
        self.device.as_ref().map(Twin::signals).unwrap_or_default()
    }

    fn set_signal(
        &mut self,
        id: &SignalId,
        value: &SignalValue,
        cx: &mut Context<'_>,
    ) -> Result<(), SignalError> {
        match &mut self.device {
            Some(d) => d.set_signal(id, value, cx),
            None => Err(SignalError::unknown(id, cantwin_twin::Direction::Set, "")),
        }
    }

    fn read_signal(&self, id: &SignalId) -> Result<SignalValue, SignalError> {
        match &self.device {
            Some(d) => d.read_signal(id),
            None => Err(SignalError::unknown(id, cantwin_twin::Direction::Read, "")),
        }
    }

    fn live_values(&self) -> Vec<LiveValue> {
        self.device
            .as_ref()
            .map(Twin::live_values)
            .unwrap_or_default()
    }

    fn summary(&self) -> Vec<SummaryEntry> {
        self.device.as_ref().map(Twin::summary).unwrap_or_default()
    }
}

/// The `node_id` key: 1–127, and with `lss` also 0xFF or `"unconfigured"` (a node that
/// waits for LSS). `None` when the key is absent.
pub(crate) fn node_id(s: &Settings<'_>, lss: bool) -> Result<Option<u8>, ScenarioError> {
    #[derive(serde::Deserialize)]
    #[serde(untagged)]
    enum Key {
        Number(i64),
        Word(String),
    }
    let Some(key) = s.get::<Key>("node_id")? else {
        return Ok(None);
    };
    let id = match key {
        Key::Number(n) if (1..=127).contains(&n) => n as u8,
        Key::Number(0xFF) if lss => UNCONFIGURED,
        Key::Word(w) if lss && w == "unconfigured" => UNCONFIGURED,
        Key::Number(n) if lss => {
            return Err(s.error(
                "node_id",
                format!(
                    "`node_id` is 1–127 (CiA 301 §7.3.2.1), or 0xFF / \"unconfigured\" for a node that waits for LSS (CiA 305), not {n}"
                ),
            ));
        }
        Key::Number(n) => {
            return Err(s.error(
                "node_id",
                format!("`node_id` is 1–127 (CiA 301 §7.3.2.1), not {n}"),
            ));
        }
        Key::Word(w) => {
            let hint = if lss {
                ", 0xFF or \"unconfigured\""
            } else {
                " (\"unconfigured\" needs `lss = true`)"
            };
            return Err(s.error(
                "node_id",
                format!("`node_id` is a number 1–127{hint}, not {w:?}"),
            ));
        }
    };
    Ok(Some(id))
}

/// The storage of the device's 0x1010 parameters: under the state directory, one folder per
/// device name, or in memory.
fn parameter_storage(s: &Settings<'_>, env: &BuildEnv) -> Result<Box<dyn Storage>, ScenarioError> {
    Ok(match super::common::parameter_file(s, env)? {
        Some(file) => Box::new(file),
        None => Box::new(MemoryStorage::new()),
    })
}

/// Where store configuration keeps the node-ID and bit rate: beside the parameters, or in
/// memory.
fn lss_store(s: &Settings<'_>, env: &BuildEnv) -> Result<Box<dyn Store>, ScenarioError> {
    Ok(
        match super::common::in_state_dir(s, env, "the LSS configuration", FileStore::new)? {
            Some(file) => Box::new(file),
            None => Box::new(MemoryStore::new()),
        },
    )
}

/// The LSS node of a device kind: `make` builds the device for a node-ID; `node_id` is the
/// scenario's (0xFF: none), which a stored configuration overrides at power-up.
pub(crate) fn build<D: Commissionable>(
    s: &Settings<'_>,
    env: &BuildEnv,
    bus: &BusSpec,
    node_id: u8,
    make: Make<D>,
) -> Result<LssNode<D>, ScenarioError> {
    // The LSS address is the identity object (CiA 305 §3.2), the same for any node-ID.
    let mut probe = make(1).ok_or_else(|| s.error("node_id", "the device cannot be built"))?;
    let od = probe.device_mut().od();
    let part = |sub| od.get_unsigned(0x1018, sub).unwrap_or(0) as u32;
    let address = Address {
        vendor: part(1),
        product: part(2),
        revision: part(3),
        serial: part(4),
    };
    let slave = Slave::new(address, node_id, bus.bit_rate, lss_store(s, env)?);
    Ok(LssNode::new(
        slave,
        make,
        parameter_storage(s, env)?,
        bus.bit_rate,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::Built;
    use crate::kinds::common::testing::{build_error, built};
    use cantwin_bus::{PortConfig, PortId};
    use cantwin_can::Duration;
    use cantwin_canopen::lss::{Master, Mode, Outcome, Service};

    /// An LSS master that also keeps every frame it sees.
    struct Probe {
        master: Master,
        seen: Vec<Frame>,
    }

    impl Node for Probe {
        fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
            self.seen.push(*frame);
            self.master.on_frame(frame, now, out);
        }
        fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
            self.master.on_tick(now, out);
        }
        fn next_deadline(&self) -> Option<Instant> {
            self.master.next_deadline()
        }
    }

    fn scenario(dev: &str) -> String {
        format!(
            "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\n\
             [[device]]\nname = \"dev\"\nkind = \"cia301\"\nbus = \"can0\"\nlss = true\n\
             heartbeat_ms = 100\ndomain_size = 16\nvendor_id = 0xCA7\nproduct_code = 301\n\
             revision = 0x10000\nserial = 77\n{dev}\n"
        )
    }

    fn with_probe(text: &str) -> (Built, PortId) {
        let mut b = built(text);
        let bus = b.bus("can0").unwrap();
        let probe = Probe {
            master: Master::new(Duration::from_millis(20)),
            seen: Vec::new(),
        };
        let port = b.sim.attach(bus, probe, PortConfig::default()).unwrap();
        (b, port)
    }

    /// Runs `service` from the probe and returns its outcome.
    fn run(b: &mut Built, port: PortId, service: Service) -> Outcome {
        let now = b.sim.now();
        let mut out = Outbox::new();
        let p = b.sim.node_mut::<Probe>(port).unwrap();
        p.master.start(service, now, &mut out).unwrap();
        for f in out.drain() {
            b.sim.transmit(port, f).unwrap();
        }
        for _ in 0..1000 {
            b.sim.run_for(Duration::from_millis(5));
            if let Some(o) = b.sim.node_mut::<Probe>(port).unwrap().master.poll() {
                return o;
            }
        }
        panic!("{service:?} did not end");
    }

    /// The identifiers of the frames the probe saw since `from` (its own are not echoed).
    fn ids_since(b: &Built, port: PortId, from: usize) -> Vec<u32> {
        b.sim.node::<Probe>(port).unwrap().seen[from..]
            .iter()
            .map(|f| f.id().as_raw())
            .collect()
    }

    fn seen(b: &Built, port: PortId) -> usize {
        b.sim.node::<Probe>(port).unwrap().seen.len()
    }

    #[test]
    fn cia305_3_3_unconfigured_node_waits_for_lss_then_boots_with_its_node_id() {
        let (mut b, port) = with_probe(&scenario("node_id = \"unconfigured\""));
        b.sim.run_for(Duration::from_millis(300));
        // No boot-up, no heartbeat.
        assert_eq!(ids_since(&b, port, 0), Vec::<u32>::new());
        let dev = b.device("dev").unwrap().port;
        assert_eq!(b.sim.twin(dev).unwrap().canopen_node_id(), None);
        assert_eq!(
            run(&mut b, port, Service::IdentifyNonConfigured),
            Outcome::Identified(1)
        );
        assert_eq!(
            run(&mut b, port, Service::SwitchGlobal(Mode::Configuration)),
            Outcome::Done
        );
        assert_eq!(
            run(&mut b, port, Service::InquireAddress),
            Outcome::Address(Address {
                vendor: 0xCA7,
                product: 301,
                revision: 0x10000,
                serial: 77
            })
        );
        assert_eq!(
            run(&mut b, port, Service::InquireNodeId),
            Outcome::NodeId(0xFF)
        );
        assert_eq!(
            run(&mut b, port, Service::ConfigureNodeId(42)),
            Outcome::Done
        );
        assert_eq!(
            run(
                &mut b,
                port,
                Service::ConfigureBitTiming { table: 0, index: 2 }
            ),
            Outcome::Done
        );
        assert_eq!(
            run(&mut b, port, Service::StoreConfiguration),
            Outcome::Done
        );
        let before = seen(&b, port);
        run(&mut b, port, Service::SwitchGlobal(Mode::Waiting));
        b.sim.run_for(Duration::from_millis(150));
        // Boot-up 0x700 + 42, then the heartbeat.
        let ids = ids_since(&b, port, before);
        assert_eq!(ids.first(), Some(&0x72A), "{ids:x?}");
        assert!(ids.iter().skip(1).all(|i| *i == 0x72A), "{ids:x?}");
        assert_eq!(b.sim.twin(dev).unwrap().canopen_node_id(), Some(42));
        let twin = b.sim.twin(dev).unwrap();
        let id = twin.read_object(0x1018, 4).unwrap();
        assert_eq!(id, 77u32.to_le_bytes());
    }

    #[test]
    fn cia305_4_4_1_configured_node_id_becomes_active_at_nmt_reset_communication() {
        let (mut b, port) = with_probe(&scenario("node_id = 5"));
        b.sim.run_for(Duration::from_millis(50));
        assert_eq!(ids_since(&b, port, 0), [0x705]);
        run(&mut b, port, Service::SwitchGlobal(Mode::Configuration));
        assert_eq!(
            run(&mut b, port, Service::ConfigureNodeId(9)),
            Outcome::Done
        );
        run(&mut b, port, Service::SwitchGlobal(Mode::Waiting));
        // Still node 5 until the reset.
        let before = seen(&b, port);
        b.sim.run_for(Duration::from_millis(100));
        assert_eq!(ids_since(&b, port, before), [0x705]);
        b.sim
            .transmit(port, Frame::std(0, &[0x82, 5]).unwrap())
            .unwrap();
        let before = seen(&b, port);
        b.sim.run_for(Duration::from_millis(10));
        assert_eq!(ids_since(&b, port, before), [0x709]);
        let dev = b.device("dev").unwrap().port;
        assert_eq!(b.sim.twin(dev).unwrap().canopen_node_id(), Some(9));
    }

    #[test]
    fn cia305_4_4_3_activated_bit_rate_other_than_the_bus_silences_the_node() {
        let (mut b, port) = with_probe(&scenario("node_id = 5"));
        run(&mut b, port, Service::SwitchGlobal(Mode::Configuration));
        run(
            &mut b,
            port,
            Service::ConfigureBitTiming { table: 0, index: 3 },
        );
        run(&mut b, port, Service::ActivateBitTiming(20));
        let before = seen(&b, port);
        b.sim.run_for(Duration::from_millis(300));
        assert_eq!(ids_since(&b, port, before), Vec::<u32>::new());
        assert_eq!(run(&mut b, port, Service::InquireNodeId), Outcome::Timeout);
    }

    #[test]
    fn node_id_key_with_and_without_lss() {
        let e = build_error(
            "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n[[device]]\nname = \"d\"\n\
             kind = \"cia301\"\nbus = \"can0\"\nnode_id = \"unconfigured\"\n",
        );
        assert!(e.contains("needs `lss = true`"), "{e}");
        let e = build_error(&scenario("node_id = 200"));
        assert!(e.contains("0xFF"), "{e}");
    }

    fn attach_probe(mut b: Built) -> (Built, PortId) {
        let bus = b.bus("can0").unwrap();
        let probe = Probe {
            master: Master::new(Duration::from_millis(20)),
            seen: Vec::new(),
        };
        let port = b.sim.attach(bus, probe, PortConfig::default()).unwrap();
        (b, port)
    }

    /// None of the three seed devices' manuals mentions LSS: they do not answer it.
    #[test]
    fn seed_devices_do_not_answer_lss() {
        for file in ["adv200-example.toml", "tm3-island.toml", "opendrive.toml"] {
            let (mut b, port) = attach_probe(crate::kinds::common::testing::shipped(file));
            b.sim.run_for(Duration::from_millis(50));
            run(&mut b, port, Service::SwitchGlobal(Mode::Configuration));
            assert_eq!(
                run(&mut b, port, Service::InquireNodeId),
                Outcome::Timeout,
                "{file}"
            );
            assert_eq!(
                run(&mut b, port, Service::IdentifyNonConfigured),
                Outcome::Identified(0),
                "{file}"
            );
            let seen = &b.sim.node::<Probe>(port).unwrap().seen;
            assert!(
                seen.iter()
                    .all(|f| f.id().as_raw() != u32::from(wire::SLAVE_ID)),
                "{file}"
            );
        }
    }

    #[test]
    fn cia305_eds_device_with_lss_waits_for_its_node_id() {
        let eds = format!(
            "{}/../../scenarios/eds/example-io.eds",
            env!("CARGO_MANIFEST_DIR")
        );
        let text = format!(
            "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\n\
             [[device]]\nname = \"io\"\nkind = \"eds\"\nbus = \"can0\"\nfile = {eds:?}\n\
             lss = true\nnode_id = 0xFF\n"
        );
        let (mut b, port) = attach_probe(built(&text));
        b.sim.run_for(Duration::from_millis(100));
        assert_eq!(ids_since(&b, port, 0), Vec::<u32>::new());
        run(&mut b, port, Service::SwitchGlobal(Mode::Configuration));
        assert_eq!(
            run(&mut b, port, Service::ConfigureNodeId(9)),
            Outcome::Done
        );
        let before = seen(&b, port);
        run(&mut b, port, Service::SwitchGlobal(Mode::Waiting));
        b.sim.run_for(Duration::from_millis(5));
        assert_eq!(ids_since(&b, port, before).first(), Some(&0x709));
        let dev = b.device("io").unwrap().port;
        assert_eq!(b.sim.twin(dev).unwrap().canopen_node_id(), Some(9));
    }
}
