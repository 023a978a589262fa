//! `kind = "cia301"`: a generic CiA 301 device — the communication objects with the
//! standard's defaults, a large DOMAIN, PDOs on a few application objects, and hooks that let
//! an outside tool provoke an EMCY.
//!
//! Keys:
//!
//! | key | default | object |
//! |---|---|---|
//! | `node_id` | required, 1–127 | with `lss`, also 0xFF or `"unconfigured"`: waits for LSS |
//! | `lss` | false | answer LSS (CiA 305) with the address of 0x1018 sub 1–4 |
//! | `heartbeat_ms` | 0 | 0x1017 producer heartbeat time at power-on |
//! | `device_name` | `"cantwin CiA 301 device"` | 0x1008 (any length) |
//! | `hardware_version`, `software_version` | `"1.0"`, the crate version | 0x1009, 0x100A |
//! | `device_type` | 0 | 0x1000 |
//! | `vendor_id`, `product_code`, `revision`, `serial` | 0 | 0x1018 sub 1–4 |
//! | `domain_size` | 65536 | 0x2000: a DOMAIN of that many bytes (at most 16 MiB) |
//! | `rpdos`, `tpdos` | 4, 4 | number of RPDOs and TPDOs (at most 8 each) |
//! | `tpdo_transmission_type` | 1 (every SYNC) | 0x1800.. sub 2 |
//! | `rpdo_transmission_type` | 255 | 0x1400.. sub 2 |
//! | `sdo_timeout_ms` | 1000 | SDO server timeout |
//!
//! Application objects:
//!
//! * 0x2000 DOMAIN, `rw`: initially byte *i* is `i mod 251` (a prime, so the pattern does not
//!   repeat on a power-of-two boundary and a misplaced segment shows); a download replaces
//!   it with up to `domain_size` bytes.
//! * 0x2001 UNSIGNED16 "EMCY trigger", `rw`: writing a code raises that error (EMCY with the
//!   code, error register bit 0 "generic"); writing 0 clears it; writing another code
//!   clears the previous one first. CiA 301 lets the application raise errors (§7.2.7); this
//!   object is how a test outside the process makes the device do it.
//! * 0x2002 UNSIGNED8 "Set point", `rw`, limits 0–100: a value range for abort 0x06090030.
//! * 0x2100 ARRAY of 8 UNSIGNED16 "Inputs", `rw`, mappable: sub 1 counts the SYNCs the
//!   device received (modulo 2¹⁶); the others hold what was written. TPDO *k* (1-based)
//!   maps sub 2*k*−1 and 2*k* (4 bytes).
//! * 0x2200 ARRAY of 8 UNSIGNED16 "Outputs", `rw`, mappable: RPDO *k* maps sub 2*k*−1 and
//!   2*k*; an RPDO shorter than its 4 mapped bytes is not processed and raises EMCY 0x8210
//!   (CiA 301 §7.2.2.3).
//!
//! With `--state-dir`, the device keeps what 0x1010 stores in the directory
//! `STATE_DIR/<device name>/`.
//!
//! With `lss = true` an LSS slave stands in front of the device (see [`super::lss`]): an
//! LSS master can give it a node-ID and a bit rate, and store them (`lss.params` in the same
//! directory with `--state-dir`); a node without node-ID boots only once it has one.
//!
//! Devices whose settings differ only in `node_id`, `heartbeat_ms` and `sdo_timeout_ms`
//! share one object dictionary description (each keeps its own values), so a scenario of
//! many alike devices builds the description, with its DOMAIN default, once.
//!
//! `heartbeat_ms` is the power-on value of 0x1017 when no stored value sets it: after every
//! reset communication (power-up included) the device writes it to 0x1017 if 0x1017 came
//! out 0, so a stored non-zero heartbeat time wins, and a restore of the defaults (0x1011)
//! brings back `heartbeat_ms`.

use cantwin_bus::{BoxedNode, PortConfig};
use cantwin_can::{ControllerEvent, Frame, Id, Instant, Node, Outbox};
use cantwin_canopen::ObjectAccess;
use cantwin_canopen::device::{Device, DeviceConfig, Event};
use cantwin_canopen::objects::{Cia301Options, cia301_defaults};
use cantwin_canopen::od::{Access, DataType, OdBuilder, OdDescription, SubObject, Value};
use cantwin_canopen::pdo::PdoObjects;
use cantwin_twin::{Context, ObjectError, Twin};
use std::sync::{Arc, Mutex};

use super::common::{canopen_device, check_node_id, sdo_timeout};
use crate::error::ScenarioError;
use crate::registry::{BuildEnv, DeviceKind, Settings};
use crate::spec::BusSpec;

/// The DOMAIN object.
pub const DOMAIN_INDEX: u16 = 0x2000;
/// The EMCY trigger object.
pub const EMCY_TRIGGER_INDEX: u16 = 0x2001;
/// The set point object, limited to 0..=100.
pub const SET_POINT_INDEX: u16 = 0x2002;
/// The inputs array, mapped into the TPDOs.
pub const INPUTS_INDEX: u16 = 0x2100;
/// The outputs array, mapped into the RPDOs.
pub const OUTPUTS_INDEX: u16 = 0x2200;
/// The largest `domain_size` accepted.
pub const MAX_DOMAIN_SIZE: usize = 16 << 20;
/// The most PDOs of each direction (two 16-bit entries each over 8 array entries would run
/// out at 4; up to 8 map the same entries again).
pub const MAX_PDOS: u16 = 8;

/// The device's transmit queue: a full SDO block plus the frames other services queue
/// meanwhile.
pub const TX_QUEUE_DEPTH: usize = 256;

/// Entries of the inputs and outputs arrays.
const IO_ENTRIES: u8 = 8;
/// The default of 0x2000, byte `i`.
fn domain_byte(i: usize) -> u8 {
    (i % 251) as u8
}

/// The `cia301` kind. It remembers the descriptions it built, to share them between devices
/// of the same layout.
#[derive(Default)]
pub struct Cia301 {
    descriptions: Mutex<Vec<(Layout, Arc<OdDescription>)>>,
}

/// A CiA 301 [`Device`] with the scenario's power-on heartbeat time, a SYNC counter in
/// 0x2100 sub 1 and the EMCY trigger 0x2001 (see the [module documentation](self)).
pub struct Cia301Node {
    device: Device,
    heartbeat_ms: u16,
    /// The code raised through 0x2001, 0 if none.
    emcy_code: u16,
    syncs: u16,
}

impl core::fmt::Debug for Cia301Node {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Cia301Node")
            .field("device", &self.device)
            .field("heartbeat_ms", &self.heartbeat_ms)
            .field("emcy_code", &self.emcy_code)
            .finish_non_exhaustive()
    }
}

impl Cia301Node {
    /// The device.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The device, mutably.
    pub fn device_mut(&mut self) -> &mut Device {
        &mut self.device
    }

    /// Reacts to what the device reported and to writes of 0x2001, after every call into it.
    fn after(&mut self, now: Instant, out: &mut Outbox) {
        let mut flush = false;
        while let Some(event) = self.device.poll_event() {
            match event {
                Event::ResetCommunication => {
                    let current = self.device.od().get_unsigned(0x1017, 0).unwrap_or(0);
                    if current == 0 && self.heartbeat_ms != 0 {
                        // Through ObjectAccess so that the producer restarts at once.
                        let _ = self
                            .device
                            .write(0x1017, 0, &self.heartbeat_ms.to_le_bytes());
                    }
                    self.syncs = 0;
                }
                Event::ResetApplication => {
                    // 0x2001 is back at 0 and the error is gone with the reset.
                    self.emcy_code = 0;
                }
                Event::Sync { .. } => {
                    self.syncs = self.syncs.wrapping_add(1);
                    let _ = self
                        .device
                        .set_value(INPUTS_INDEX, 1, &Value::Unsigned16(self.syncs));
                }
                _ => {}
            }
        }
        let wanted = self
            .device
            .od()
            .get_unsigned(EMCY_TRIGGER_INDEX, 0)
            .unwrap_or(0) as u16;
        if wanted != self.emcy_code {
            let mut emcy = self.device.emcy();
            if self.emcy_code != 0 {
                emcy.clear(self.emcy_code);
            }
            if wanted != 0 {
                emcy.raise(wanted, [0; 5]);
            }
            self.emcy_code = wanted;
            flush = true;
        }
        if flush {
            // Raised and cleared errors are sent at the device's next tick.
            self.device.on_tick(now, out);
        }
    }
}

impl super::lss::Commissionable for Cia301Node {
    fn device_mut(&mut self) -> &mut Device {
        &mut self.device
    }
}

impl Node for Cia301Node {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.emcy_code = 0;
        self.syncs = 0;
        self.device.on_power_up(now, out);
        self.after(now, out);
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.device.on_frame(frame, now, out);
        self.after(now, out);
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        self.device.on_tick(now, out);
        self.after(now, out);
    }

    fn next_deadline(&self) -> Option<Instant> {
        self.device.next_deadline()
    }

    fn on_sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.device.on_sent(frame, now, out);
        self.after(now, out);
    }

    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        self.device.on_controller_event(event, now, out);
        self.after(now, out);
    }

    fn accepts(&self, id: Id) -> bool {
        self.device.accepts(id)
    }

    fn acceptance_version(&self) -> Option<u64> {
        self.device.acceptance_version()
    }
}

/// The device's twin (its dictionary, node-ID and writes through its own checks), and the
/// node reacts to a write at once (a code written to 0x2001 raises its EMCY).
impl Twin for Cia301Node {
    fn dictionary(&self) -> Option<&cantwin_canopen::od::ObjectDictionary> {
        self.device.dictionary()
    }

    fn write_object(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
        cx: &mut Context<'_>,
    ) -> Result<(), ObjectError> {
        let r = self.device.write_object(index, sub, data, cx);
        self.after(cx.now, cx.out);
        r
    }

    fn canopen_node_id(&self) -> Option<u8> {
        self.device.canopen_node_id()
    }

    fn dictionary_heap_bytes(&self) -> Option<usize> {
        self.device.dictionary_heap_bytes()
    }
}

/// The object dictionary of the kind, from its settings.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Layout {
    options: Cia301Options,
    domain_size: usize,
    rpdos: u16,
    tpdos: u16,
    rpdo_type: u8,
    tpdo_type: u8,
}

fn mapping(index: u16, k: u16) -> [u32; 2] {
    // Entries wrap around the 8-entry array for PDOs 5..8.
    let first = ((2 * k) % u16::from(IO_ENTRIES) + 1) as u32;
    let entry = |sub: u32| (u32::from(index) << 16) | (sub << 8) | 16;
    [entry(first), entry(first + 1)]
}

fn description(l: &Layout) -> Result<OdDescription, String> {
    let mut pdos = PdoObjects::new(l.rpdos, l.tpdos);
    for k in 0..l.rpdos {
        pdos = pdos.rpdo(k, l.rpdo_type, &mapping(OUTPUTS_INDEX, k));
    }
    for k in 0..l.tpdos {
        pdos = pdos.tpdo(k, l.tpdo_type, &mapping(INPUTS_INDEX, k));
    }
    let domain: Vec<u8> = (0..l.domain_size).map(domain_byte).collect();
    let io = |name: &str| {
        SubObject::new(name, DataType::Unsigned16, Access::Rw)
            .mappable()
            .default(Value::Unsigned16(0))
    };
    let b = cia301_defaults(OdBuilder::new(), &l.options)
        .var(
            DOMAIN_INDEX,
            SubObject::new("Domain", DataType::Domain, Access::Rw)
                .default(Value::Domain(domain))
                .max_len(l.domain_size),
        )
        .var(
            EMCY_TRIGGER_INDEX,
            SubObject::new("EMCY trigger", DataType::Unsigned16, Access::Rw),
        )
        .var(
            SET_POINT_INDEX,
            SubObject::new("Set point", DataType::Unsigned8, Access::Rw)
                .limits(Value::Unsigned8(0), Value::Unsigned8(100)),
        )
        .array_of(INPUTS_INDEX, "Inputs", IO_ENTRIES, io("Input"))
        .array_of(OUTPUTS_INDEX, "Outputs", IO_ENTRIES, io("Output"));
    pdos.add_to(b).build().map_err(|e| e.to_string())
}

impl Cia301 {
    /// The description of `layout`, built once and shared.
    fn description_for(&self, layout: Layout) -> Result<Arc<OdDescription>, String> {
        // A poisoned lock only means another build panicked; the list is still valid.
        let mut known = self
            .descriptions
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some((_, d)) = known.iter().find(|(l, _)| *l == layout) {
            return Ok(Arc::clone(d));
        }
        let d = Arc::new(description(&layout)?);
        known.push((layout, Arc::clone(&d)));
        Ok(d)
    }
}

impl DeviceKind for Cia301 {
    fn name(&self) -> &'static str {
        "cia301"
    }

    fn summary(&self) -> &'static str {
        "generic CiA 301 device: node_id, heartbeat_ms, device_name, 64 KiB DOMAIN at 0x2000, 4 RPDOs/TPDOs, lss (CiA 305)"
    }

    fn build(
        &self,
        s: &Settings<'_>,
        bus: &BusSpec,
        env: &BuildEnv,
    ) -> Result<(BoxedNode, PortConfig), ScenarioError> {
        let lss: bool = s.get_or("lss", false)?;
        let node_id = super::lss::node_id(s, lss)?
            .ok_or_else(|| s.error("node_id", "a cia301 device needs `node_id`"))?;
        let heartbeat_ms: u16 = s.get_or("heartbeat_ms", 0)?;
        let defaults = Cia301Options::default();
        let options = Cia301Options {
            device_type: s.get_or("device_type", 0)?,
            vendor_id: s.get_or("vendor_id", 0)?,
            product_code: s.get_or("product_code", 0)?,
            revision: s.get_or("revision", 0)?,
            serial: s.get_or("serial", 0)?,
            device_name: s.get_or("device_name", "cantwin CiA 301 device".to_string())?,
            hardware_version: s.get_or("hardware_version", defaults.hardware_version.clone())?,
            software_version: s.get_or("software_version", defaults.software_version.clone())?,
            ..defaults
        };
        let domain_size: usize = s.get_or("domain_size", 65536)?;
        if domain_size > MAX_DOMAIN_SIZE {
            return Err(s.error(
                "domain_size",
                format!("`domain_size` is at most {MAX_DOMAIN_SIZE} bytes"),
            ));
        }
        let rpdos: u16 = s.get_or("rpdos", 4)?;
        let tpdos: u16 = s.get_or("tpdos", 4)?;
        for (key, n) in [("rpdos", rpdos), ("tpdos", tpdos)] {
            if n > MAX_PDOS {
                return Err(s.error(key, format!("`{key}` is at most {MAX_PDOS}")));
            }
        }
        let tpdo_type: u8 = s.get_or("tpdo_transmission_type", 1)?;
        let rpdo_type: u8 = s.get_or("rpdo_transmission_type", 255)?;
        // CiA 301 §7.5.2.35, §7.5.2.37: 241..=251 are reserved; RPDOs know no 252/253 (RTR-only).
        for (key, t, rx) in [
            ("tpdo_transmission_type", tpdo_type, false),
            ("rpdo_transmission_type", rpdo_type, true),
        ] {
            if (241..=251).contains(&t) || (rx && (252..=253).contains(&t)) {
                return Err(s.error(
                    key,
                    format!("transmission type {t} is reserved (CiA 301 §7.5.2.35, §7.5.2.37)"),
                ));
            }
        }
        let sdo_timeout = sdo_timeout(s)?;
        let layout = Layout {
            options,
            domain_size,
            rpdos,
            tpdos,
            rpdo_type,
            tpdo_type,
        };
        let desc = self.description_for(layout).map_err(|e| {
            s.error(
                "node_id",
                format!("the device's dictionary is invalid: {e}"),
            )
        })?;
        // The SDO server queues a whole upload block (up to 127 segments, CiA 301
        // §7.2.4.3.10) at once, on top of heartbeat, EMCY and TPDOs; a controller queue of
        // the default depth would drop most of the block.
        let port = PortConfig {
            queue_depth: TX_QUEUE_DEPTH,
            ..PortConfig::default()
        };
        let node = move |device| Cia301Node {
            device,
            heartbeat_ms,
            emcy_code: 0,
            syncs: 0,
        };
        if lss {
            let make: super::lss::Make<Cia301Node> = Box::new(move |id| {
                let config = DeviceConfig {
                    sdo_timeout,
                    ..DeviceConfig::new(id)
                };
                Device::new(Arc::clone(&desc), config).ok().map(node)
            });
            let lss_node = super::lss::build(s, env, bus, node_id, make)?;
            return Ok((BoxedNode::twin(lss_node), port));
        }
        check_node_id(s, node_id)?;
        let device = canopen_device(s, env, desc, node_id, sdo_timeout)?;
        Ok((BoxedNode::twin(node(device)), port))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinds::common::testing::{build_error, built};
    use cantwin_can::Duration;
    use cantwin_canopen::nmt::State;

    fn scenario(extra: &str) -> String {
        format!(
            "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\n\
             [[device]]\nname = \"dev\"\nkind = \"cia301\"\nbus = \"can0\"\n{extra}\n\
             [[device]]\nname = \"peer\"\nkind = \"generator\"\nbus = \"can0\"\nid = 0x7FF\nperiod_ms = 1000\ncount = 0\n"
        )
    }

    fn error_of(extra: &str) -> String {
        build_error(&scenario(extra))
    }

    #[test]
    fn duplicate_node_id_on_one_bus_names_the_second_device() {
        let two = |bus_b: &str| {
            format!(
                "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\
                 [[bus]]\nname = \"can1\"\nbit_rate = \"500k\"\n\
                 [[device]]\nname = \"a\"\nkind = \"cia301\"\nbus = \"can0\"\nnode_id = 5\n\
                 [[device]]\nname = \"b\"\nkind = \"tm3\"\nbus = \"{bus_b}\"\nnode_id = 5\n"
            )
        };
        let e = build_error(&two("can0"));
        assert!(
            e.contains(":16: key `device[1].node_id`")
                && e.contains("node-ID 5 is already used by device \"a\" on bus \"can0\""),
            "{e}"
        );
        // The same node-ID on another bus is another network.
        let built = built(&two("can1"));
        let ids: Vec<Option<u8>> = built.devices.iter().map(|d| d.node_id).collect();
        assert_eq!(ids, [Some(5), Some(5)]);
    }

    #[test]
    fn node_id_out_of_range_names_the_key() {
        let e = error_of("node_id = 0");
        assert!(e.contains("node_id") && e.contains("1–127"), "{e}");
        let e = error_of("node_id = 128");
        assert!(e.contains("node_id"), "{e}");
        let e = error_of("heartbeat_ms = 100");
        assert!(e.contains("needs `node_id`"), "{e}");
    }

    #[test]
    fn unknown_key_and_bad_values_are_reported() {
        let e = error_of("node_id = 5\nheartbeat = 100");
        assert!(e.contains("unknown key `heartbeat`"), "{e}");
        let e = error_of("node_id = 5\ndomain_size = 999999999");
        assert!(e.contains("domain_size"), "{e}");
        let e = error_of("node_id = 5\ntpdo_transmission_type = 245");
        assert!(e.contains("reserved"), "{e}");
        let e = error_of("node_id = 5\nrpdos = 9");
        assert!(e.contains("rpdos"), "{e}");
    }

    /// Alike devices share one description; a device whose dictionary differs gets its own.
    #[test]
    fn devices_of_the_same_layout_share_their_description() {
        let text = "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\
            [[device]]\nname = \"a\"\nkind = \"cia301\"\nbus = \"can0\"\nnode_id = 1\ndomain_size = 16\n\
            [[device]]\nname = \"b\"\nkind = \"cia301\"\nbus = \"can0\"\nnode_id = 2\ndomain_size = 16\nheartbeat_ms = 50\n\
            [[device]]\nname = \"c\"\nkind = \"cia301\"\nbus = \"can0\"\nnode_id = 3\ndomain_size = 32\n";
        let built = built(text);
        let desc = |name: &str| {
            let port = built.device(name).unwrap().port;
            Arc::clone(
                built
                    .sim
                    .node::<Cia301Node>(port)
                    .unwrap()
                    .device()
                    .od()
                    .description(),
            )
        };
        assert!(Arc::ptr_eq(&desc("a"), &desc("b")));
        assert!(!Arc::ptr_eq(&desc("a"), &desc("c")));
        // Values stay per device.
        let port_a = built.device("a").unwrap().port;
        let node_a = built.sim.node::<Cia301Node>(port_a).unwrap();
        assert_eq!(node_a.device().node_id(), 1);
    }

    /// The boot-up message (CiA 301 §7.2.8.3.2.1: COB-ID 0x700 + node-ID, one byte 0) at
    /// power-up, then heartbeats every `heartbeat_ms` with state 127 (pre-operational).
    #[test]
    fn boot_up_then_heartbeat_every_heartbeat_ms() {
        let text = scenario("node_id = 5\nheartbeat_ms = 100\ndomain_size = 16");
        let mut built = built(&text);
        let bus = built.bus("can0").unwrap();
        built.sim.run_for(Duration::from_millis(350));
        let frames = built.sim.bus(bus).unwrap().stats().frames();
        // Boot-up at 0, heartbeats at 100, 200 and 300 ms.
        assert_eq!(frames, 4);
        let port = built.device("dev").unwrap().port;
        let node = built.sim.node::<Cia301Node>(port).unwrap();
        assert_eq!(node.device().state(), State::PreOperational);
        assert_eq!(node.device().node_id(), 5);
    }

    #[test]
    fn domain_default_pattern_and_identity_from_settings() {
        let text = scenario(
            "node_id = 5\ndomain_size = 300\nvendor_id = 0x1234\nproduct_code = 7\ndevice_name = \"a rather long device name\"",
        );
        let built = built(&text);
        let port = built.device("dev").unwrap().port;
        let node = built.sim.node::<Cia301Node>(port).unwrap();
        let od = node.device().od();
        let Value::Domain(bytes) = od.get(DOMAIN_INDEX, 0).unwrap() else {
            panic!("0x2000 is not a DOMAIN");
        };
        assert_eq!(bytes.len(), 300);
        assert_eq!(bytes[250], 250);
        assert_eq!(bytes[251], 0);
        assert_eq!(od.get(0x1018, 1).unwrap(), Value::Unsigned32(0x1234));
        assert_eq!(od.get(0x1018, 2).unwrap(), Value::Unsigned32(7));
        assert_eq!(
            od.get(0x1008, 0).unwrap(),
            Value::VisibleString("a rather long device name".into())
        );
        // TPDO1 maps inputs 1 and 2, RPDO2 outputs 3 and 4, 16 bits each.
        assert_eq!(od.get(0x1A00, 1).unwrap(), Value::Unsigned32(0x2100_0110));
        assert_eq!(od.get(0x1A00, 2).unwrap(), Value::Unsigned32(0x2100_0210));
        assert_eq!(od.get(0x1601, 1).unwrap(), Value::Unsigned32(0x2200_0310));
        assert_eq!(od.get(0x1800, 2).unwrap(), Value::Unsigned8(1));
    }

    /// A built scenario with a recorder on the bus; frames are sent from the peer's port.
    struct Rig {
        built: crate::Built,
        tap: cantwin_bus::TapId,
        peer: cantwin_bus::PortId,
    }

    impl Rig {
        fn new(extra: &str) -> Rig {
            let mut built = built(&scenario(extra));
            let bus = built.bus("can0").unwrap();
            let tap = built
                .sim
                .bus_mut(bus)
                .unwrap()
                .add_tap(cantwin_bus::Recorder::new());
            let peer = built.device("peer").unwrap().port;
            Rig { built, tap, peer }
        }

        /// Sends `data` on `id` from the peer and runs 10 ms.
        fn send(&mut self, id: u16, data: &[u8]) {
            self.built
                .sim
                .transmit(self.peer, Frame::std(id, data).unwrap())
                .unwrap();
            self.built.sim.run_for(Duration::from_millis(10));
        }

        /// The end of the last frame the peer sent.
        fn peer_end(&self) -> Instant {
            let bus = self.built.bus("can0").unwrap();
            self.built
                .sim
                .bus(bus)
                .unwrap()
                .tap::<cantwin_bus::Recorder>(self.tap)
                .unwrap()
                .frames()
                .filter(|f| f.sender == self.peer)
                .map(|f| f.end)
                .last()
                .unwrap()
        }

        /// Every frame the device sent so far, as (id, data, start of frame).
        fn device_frames(&self) -> Vec<(u16, Vec<u8>, Instant)> {
            let bus = self.built.bus("can0").unwrap();
            let dev = self.built.device("dev").unwrap().port;
            self.built
                .sim
                .bus(bus)
                .unwrap()
                .tap::<cantwin_bus::Recorder>(self.tap)
                .unwrap()
                .frames()
                .filter(|f| f.sender == dev)
                .map(|f| {
                    let Id::Standard(id) = f.frame.id() else {
                        panic!("extended frame from the device");
                    };
                    (id.as_raw(), f.frame.data_bytes().to_vec(), f.start)
                })
                .collect()
        }
    }

    /// Writing a code to 0x2001 raises it: SDO download response (CiA 301 §7.2.4.3.3), then,
    /// once the response is on the bus, EMCY on 0x80 + node-ID with the code, error register bit 0 and five zero bytes
    /// (§7.2.7.3.1); writing 0 sends the error reset EMCY 0x0000 with register 0.
    #[test]
    fn emcy_trigger_object_raises_and_clears_the_code() {
        let mut rig = Rig::new("node_id = 5\ndomain_size = 16");
        rig.built.sim.run_for(Duration::from_millis(1));
        rig.send(0x605, &[0x2B, 0x01, 0x20, 0x00, 0x00, 0x50, 0, 0]);
        rig.send(0x605, &[0x2B, 0x01, 0x20, 0x00, 0x00, 0x00, 0, 0]);
        let frames: Vec<(u16, Vec<u8>)> = rig
            .device_frames()
            .into_iter()
            .map(|(id, d, _)| (id, d))
            .collect();
        let sdo_ok = (0x585, vec![0x60, 0x01, 0x20, 0x00, 0, 0, 0, 0]);
        // The EMCY follows the answer to the write that raised it, although its lower
        // identifier would win arbitration were both queued together.
        assert_eq!(
            frames,
            vec![
                (0x705, vec![0x00]),
                sdo_ok.clone(),
                (0x085, vec![0x00, 0x50, 0x01, 0, 0, 0, 0, 0]),
                sdo_ok,
                (0x085, vec![0; 8]),
            ]
        );
    }

    /// After NMT start (§7.2.8.3.1.1) every SYNC is answered by TPDO1..4 (transmission
    /// type 1); TPDO1 carries 0x2100 sub 1, the count of SYNCs before this one.
    #[test]
    fn tpdos_answer_each_sync_with_the_sync_count() {
        let mut rig = Rig::new("node_id = 5\ndomain_size = 16");
        rig.send(0x000, &[0x01, 5]);
        for _ in 0..3 {
            rig.send(0x080, &[]);
        }
        let frames: Vec<(u16, Vec<u8>)> = rig
            .device_frames()
            .into_iter()
            .map(|(id, d, _)| (id, d))
            .collect();
        let expected: Vec<(u16, Vec<u8>)> = (0u8..3)
            .flat_map(|n| {
                [
                    (0x185, vec![n, 0, 0, 0]),
                    (0x285, vec![0; 4]),
                    (0x385, vec![0; 4]),
                    (0x485, vec![0; 4]),
                ]
            })
            .collect();
        assert_eq!(frames[0], (0x705, vec![0x00]));
        assert_eq!(frames[1..], expected[..]);
    }

    /// Reset communication (§7.2.8.3.1.1, command 0x82) brings 0x1017 back to `heartbeat_ms`
    /// after it was written 0: boot-up, then a heartbeat 50 ms later.
    #[test]
    fn reset_communication_restores_heartbeat_ms() {
        let mut rig = Rig::new("node_id = 5\nheartbeat_ms = 50\ndomain_size = 16");
        rig.built.sim.run_for(Duration::from_millis(1));
        rig.send(0x605, &[0x2B, 0x17, 0x10, 0x00, 0x00, 0x00, 0, 0]);
        rig.built.sim.run_for(Duration::from_millis(200));
        rig.send(0x000, &[0x82, 5]);
        let reset_at = rig.peer_end();
        rig.built.sim.run_for(Duration::from_millis(100));
        let frames = rig.device_frames();
        let ids: Vec<(u16, Vec<u8>)> = frames.iter().map(|(id, d, _)| (*id, d.clone())).collect();
        assert_eq!(
            ids[..4],
            [
                (0x705, vec![0x00]),
                (0x585, vec![0x60, 0x17, 0x10, 0x00, 0, 0, 0, 0]),
                (0x705, vec![0x00]),
                (0x705, vec![0x7F]),
            ]
        );
        // The reset happens when the NMT frame completes; the heartbeat timer starts then, and
        // on the idle bus each heartbeat starts when it is queued.
        assert_eq!(frames[3].2, reset_at + Duration::from_millis(50));
        assert_eq!(frames[4].2, reset_at + Duration::from_millis(100));
    }
}

#[cfg(test)]
mod stored_parameters {
    use super::Cia301Node;
    use crate::{BuildEnv, Registry, Scenario};
    use cantwin_can::Instant;
    use cantwin_canopen::storage::STORE_FILE;

    const SCENARIO: &str = "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\n[[device]]\nname = \"io\"\nkind = \"cia301\"\nbus = \"can0\"\nnode_id = 5\n";

    #[test]
    fn cia301_7_5_2_10_an_unreadable_store_is_a_build_warning_naming_the_file_and_an_emcy() {
        let dir = std::env::temp_dir().join(format!("cantwin-warn-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("io")).unwrap();
        let file = dir.join("io").join(STORE_FILE);
        std::fs::write(&file, b"").unwrap();
        let env = BuildEnv {
            state_dir: Some(dir.clone()),
        };
        let scenario = Scenario::parse(SCENARIO, "t.toml").unwrap();
        let mut built = scenario.build(&Registry::builtin(), &env).unwrap();
        assert_eq!(built.warnings.len(), 1, "{:?}", built.warnings);
        let w = &built.warnings[0];
        assert!(
            w.contains("\"io\"") && w.contains(&file.display().to_string()) && w.contains("empty"),
            "{w}"
        );
        built.sim.run_until(Instant::from_nanos(10_000_000));
        let port = built.device("io").unwrap().port;
        let node = built.sim.node::<Cia301Node>(port).unwrap();
        // EMCY 0x5000 is active and sets the generic bit of the error register (CiA 301
        // §7.5.2.2); alone on the bus the device is error passive too (0x8120, bit 4).
        assert!(node.device().emcy_active(0x5000));
        assert_eq!(node.device().error_register() & 0x01, 0x01);
        // A whole store builds without a warning.
        std::fs::remove_file(&file).unwrap();
        let built = scenario.build(&Registry::builtin(), &env).unwrap();
        assert!(built.warnings.is_empty(), "{:?}", built.warnings);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
