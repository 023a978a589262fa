//! `kind = "master"`: a CANopen master ([`Master`]) running scripted SDO transfers, for
//! fault scenarios whose recovery depends on what was lost (a block transfer under random
//! loss needs a client that reacts).
//!
//! Keys: `transfers`, an array of tables, each:
//!
//! | key | default | meaning |
//! |---|---|---|
//! | `time_ms` | required | when the transfer is started (queued behind the node's others) |
//! | `node` | required, 1–127 | the server |
//! | `op` | required | `"upload"` or `"download"` |
//! | `index`, `sub` | required, 0 | the object |
//! | `mode` | `"auto"` | `"auto"`, `"expedited"`, `"segmented"`, `"block"` |
//! | `blksize` | 127 | segments per block in block mode |
//! | `size` | 0 | download: that many bytes, byte *i* = (*i* × 7 + 3) mod 256 |
//! | `verify` | none | upload: `"mod251"` checks byte *i* = *i* mod 251 (the `cia301` DOMAIN) |
//! | `retries` | 0 | start an aborted transfer again this many times |
//! | `timeout_ms` | 1000 | the SDO client's response timeout |
//!
//! Results are objects of the master (for `[[expect]] value = …`): for transfer *k*
//! (0-based, in file order) index 0x5000 + *k*, sub 0: 0 pending, 1 completed (and
//! verified), 2 failed, 3 completed with wrong data; sub 1: attempts; sub 2: bytes
//! transferred; sub 3: the last abort code.

use cantwin_bus::{BoxedNode, PortConfig};
use cantwin_can::{ControllerEvent, Duration, Frame, Instant, Node, Outbox};
use cantwin_canopen::master::sdo_client::{ClientConfig, Mode, SdoEvent};
use cantwin_canopen::master::{Master, MasterConfig, MasterEvent, TransferId};
use cantwin_canopen::sdo::wire::Mux;
use cantwin_twin::{ObjectError, Twin};
use serde::Deserialize;

use crate::error::ScenarioError;
use crate::registry::{BuildEnv, DeviceKind, Settings};
use crate::spec::BusSpec;

/// The first result object.
pub const RESULTS_INDEX: u16 = 0x5000;

/// The `master` kind.
pub struct MasterKind;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTransfer {
    time_ms: f64,
    node: u8,
    op: String,
    index: u16,
    #[serde(default)]
    sub: u8,
    mode: Option<String>,
    blksize: Option<u8>,
    size: Option<u32>,
    verify: Option<String>,
    retries: Option<u32>,
}

#[derive(Debug, Clone)]
struct Transfer {
    at: Instant,
    node: u8,
    upload: bool,
    mux: Mux,
    mode: Mode,
    data: Vec<u8>,
    verify: bool,
    retries: u32,
    // Results.
    started: bool,
    running: Option<TransferId>,
    status: u8,
    attempts: u32,
    bytes: u32,
    abort: u32,
}

/// A master node running the scripted transfers.
pub struct MasterNode {
    master: Master,
    transfers: Vec<Transfer>,
}

impl core::fmt::Debug for MasterNode {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("MasterNode")
            .field("transfers", &self.transfers.len())
            .finish_non_exhaustive()
    }
}

impl MasterNode {
    fn start(&mut self, i: usize, now: Instant, out: &mut Outbox) {
        let Some(t) = self.transfers.get_mut(i) else {
            return;
        };
        t.started = true;
        t.attempts += 1;
        let r = if t.upload {
            self.master.upload(t.node, t.mux, t.mode, now, out)
        } else {
            self.master
                .download(t.node, t.mux, t.data.clone(), t.mode, now, out)
        };
        match r {
            Ok(id) => t.running = Some(id),
            Err(_) => t.status = 2,
        }
    }

    fn after(&mut self, now: Instant, out: &mut Outbox) {
        while let Some((_, event)) = self.master.poll_event() {
            let MasterEvent::Sdo { id, event, .. } = event else {
                continue;
            };
            let Some(i) = self.transfers.iter().position(|t| t.running == Some(id)) else {
                continue;
            };
            match event {
                SdoEvent::Completed { data, .. } => {
                    let t = &mut self.transfers[i];
                    t.running = None;
                    t.bytes = if t.upload {
                        data.len() as u32
                    } else {
                        t.data.len() as u32
                    };
                    let good = !t.verify
                        || data
                            .iter()
                            .enumerate()
                            .all(|(k, b)| usize::from(*b) == k % 251);
                    t.status = if good { 1 } else { 3 };
                }
                SdoEvent::Aborted { code, .. } => {
                    let t = &mut self.transfers[i];
                    t.running = None;
                    t.abort = code.to_u32();
                    if t.attempts <= t.retries {
                        self.start(i, now, out);
                    } else {
                        t.status = 2;
                    }
                }
                _ => {}
            }
        }
    }

    fn due(&mut self, now: Instant, out: &mut Outbox) {
        for i in 0..self.transfers.len() {
            if !self.transfers[i].started && self.transfers[i].at <= now {
                self.start(i, now, out);
            }
        }
        self.after(now, out);
    }

    /// The result object `index`/`sub` (see the module documentation).
    pub fn result(&self, index: u16, sub: u8) -> Option<Vec<u8>> {
        let t = self
            .transfers
            .get(usize::from(index.checked_sub(RESULTS_INDEX)?))?;
        match sub {
            0 => Some(vec![t.status]),
            1 => Some(t.attempts.to_le_bytes().to_vec()),
            2 => Some(t.bytes.to_le_bytes().to_vec()),
            3 => Some(t.abort.to_le_bytes().to_vec()),
            _ => None,
        }
    }
}

/// The master's results are its objects (see the module documentation); it has no
/// dictionary otherwise.
impl Twin for MasterNode {
    fn read_object(&self, index: u16, sub: u8) -> Result<Vec<u8>, ObjectError> {
        self.result(index, sub).ok_or(ObjectError::NoDictionary)
    }
}

impl Node for MasterNode {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.master.on_power_up(now, out);
        self.due(now, out);
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.master.on_frame(frame, now, out);
        self.after(now, out);
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        self.master.on_tick(now, out);
        self.due(now, out);
    }

    fn next_deadline(&self) -> Option<Instant> {
        let next = self
            .transfers
            .iter()
            .filter(|t| !t.started)
            .map(|t| t.at)
            .min();
        Instant::earliest(self.master.next_deadline(), next)
    }

    fn on_sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.master.on_sent(frame, now, out);
        self.after(now, out);
    }

    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        self.master.on_controller_event(event, now, out);
        self.after(now, out);
    }
}

impl DeviceKind for MasterKind {
    fn name(&self) -> &'static str {
        "master"
    }

    fn summary(&self) -> &'static str {
        "CANopen master running scripted SDO transfers (transfers = [{ time_ms, node, op, index, sub, mode, … }])"
    }

    fn build(
        &self,
        s: &Settings<'_>,
        _bus: &BusSpec,
        _env: &BuildEnv,
    ) -> Result<(BoxedNode, PortConfig), ScenarioError> {
        let raw: Vec<RawTransfer> = s.get_or("transfers", Vec::new())?;
        let timeout_ms: u64 = s.get_or("timeout_ms", 1000)?;
        if timeout_ms == 0 {
            return Err(s.error("timeout_ms", "`timeout_ms` must be greater than 0"));
        }
        let mut transfers = Vec::new();
        for (k, r) in raw.into_iter().enumerate() {
            let bad = |m: String| s.error("transfers", format!("transfers[{k}]: {m}"));
            if !(r.time_ms.is_finite() && r.time_ms >= 0.0) {
                return Err(bad("`time_ms` must be a number ≥ 0".into()));
            }
            if !(1..=127).contains(&r.node) {
                return Err(bad(format!("`node` is 1–127, not {}", r.node)));
            }
            let upload = match r.op.as_str() {
                "upload" => true,
                "download" => false,
                o => {
                    return Err(bad(format!(
                        "`op` is \"upload\" or \"download\", not {o:?}"
                    )));
                }
            };
            let blksize = r.blksize.unwrap_or(127);
            let mode = match r.mode.as_deref().unwrap_or("auto") {
                "auto" => Mode::Auto,
                "expedited" => Mode::Expedited,
                "segmented" => Mode::Segmented,
                "block" if (1..=127).contains(&blksize) => Mode::Block { blksize },
                "block" => return Err(bad(format!("`blksize` is 1–127, not {blksize}"))),
                m => return Err(bad(format!("unknown `mode` {m:?}"))),
            };
            let size = r.size.unwrap_or(0);
            if size > 16 << 20 {
                return Err(bad("`size` is at most 16 MiB".into()));
            }
            let verify = match r.verify.as_deref() {
                None => false,
                Some("mod251") => true,
                Some(v) => return Err(bad(format!("unknown `verify` {v:?} (known: mod251)"))),
            };
            transfers.push(Transfer {
                at: Instant::from_nanos((r.time_ms * 1e6) as u64),
                node: r.node,
                upload,
                mux: Mux::new(r.index, r.sub),
                mode,
                data: (0..size)
                    .map(|i| (i.wrapping_mul(7).wrapping_add(3)) as u8)
                    .collect(),
                verify,
                retries: r.retries.unwrap_or(0),
                started: false,
                running: None,
                status: 0,
                attempts: 0,
                bytes: 0,
                abort: 0,
            });
        }
        let config = MasterConfig {
            sdo: ClientConfig {
                timeout: Duration::from_millis(timeout_ms),
                ..ClientConfig::default()
            },
            ..MasterConfig::default()
        };
        let node = MasterNode {
            master: Master::with_config(config),
            transfers,
        };
        Ok((
            BoxedNode::twin(node),
            PortConfig::default().with_queue_depth(64),
        ))
    }
}

#[cfg(test)]
mod tests {
    use crate::{BuildEnv, Registry, Scenario, check};

    fn scenario(transfers: &str) -> String {
        format!(
            "[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n\n\
             [[device]]\nname = \"node5\"\nkind = \"cia301\"\nbus = \"can0\"\nnode_id = 5\ndomain_size = 1000\n\n\
             [[device]]\nname = \"master\"\nkind = \"master\"\nbus = \"can0\"\ntransfers = [{transfers}]\n\n\
             [[expect]]\nat_ms = 100\nvalue = {{ device = \"master\", index = 0x5000, sub = 0, equals = 1 }}\n\n\
             [[expect]]\nat_ms = 100\nvalue = {{ device = \"master\", index = 0x5000, sub = 2, equals = 1000 }}\n"
        )
    }

    #[test]
    fn cia301_7_2_4_3_block_upload_completes_and_verifies_the_domain() {
        let s = Scenario::parse(
            &scenario("{ time_ms = 1, node = 5, op = \"upload\", index = 0x2000, mode = \"block\", blksize = 10, verify = \"mod251\" }"),
            "m.toml",
        )
        .unwrap();
        let r = check(&s, &Registry::builtin(), &BuildEnv::default()).unwrap();
        assert!(r.passed(), "{r}");
    }

    #[test]
    fn a_bad_transfer_names_the_key() {
        let s = Scenario::parse(
            &scenario("{ time_ms = 1, node = 5, op = \"fetch\", index = 0x2000 }"),
            "m.toml",
        )
        .unwrap();
        let e = s
            .build(&Registry::builtin(), &BuildEnv::default())
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("device[1].transfers") && e.contains("\"fetch\""),
            "{e}"
        );
    }
}
