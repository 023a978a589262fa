//! `kind = "cia402_master"`: a CiA 402 master ([`DriveMaster`]) running a program over
//! several drive axes: NMT, PDO mapping, power states, modes, profile moves, homing and
//! coordinated cyclic synchronous moves on its own SYNC.
//!
//! Keys:
//!
//! | key | default | meaning |
//! |---|---|---|
//! | `axes` | required | the drives' node-IDs (1–127), in the order `targets` lists them |
//! | `steps` | required | the program: an array of tables, run one after the other |
//! | `step_timeout_ms` | 1000 | one state transition, mode switch or set-point acknowledge |
//! | `move_timeout_ms` | 30000 | a profile move to its target, a homing run |
//! | `poll_ms` | 10 | between SDO reads of a statusword waited for |
//! | `statusword_tpdo` | none | 1–4: waits take the statusword from that TPDO (COB-ID 0x180 + 0x100 × (n − 1) + node, the statusword in its first two bytes, as CiA 402-3's pre-defined TPDOs have it) instead of polling; it runs in OPERATIONAL only, so `nmt_start` comes first |
//!
//! A step applies to every axis (or to the `axes` it lists) and ends when every axis has
//! finished it; a failure stops the program. Steps (`op`):
//!
//! | op | keys | what |
//! |---|---|---|
//! | `nmt_start` | | NMT Start to each axis (CiA 301 §7.2.8.3.1) |
//! | `map_rpdo`, `map_tpdo` | `pdo` (1–512), `entries` (0xIIIISSLL each), `transmission` (default 1) | writes the PDO with the CiA 301 §7.4.8.2 sequence on COB-ID 0x200/0x180 + 0x100 × ((`pdo` − 1) mod 4) + node |
//! | `enable`, `switch_on`, `shutdown`, `disable` | | walk the PDS FSA to OPERATION ENABLED, SWITCHED ON, READY TO SWITCH ON, SWITCH ON DISABLED |
//! | `quick_stop`, `fault_reset` | | |
//! | `mode` | `mode` (pp, vl, pv, tq, hm, ip, csp, csv, cst) | 0x6060, waiting for 0x6061 |
//! | `home` | `method`, optional `switch_speed`, `zero_speed`, `acceleration` | homing |
//! | `pp` | `targets` (one per axis), `relative` | profile position move to target reached |
//! | `pv` | `targets` | profile velocity to target reached |
//! | `sync` | `period_ms` | start producing SYNC (0x080) |
//! | `stream` | `rpdo` (1–512), `with_controlword` (default true) | csp/csv set-points (the mode 0x6061 shows) in that RPDO after every SYNC |
//! | `move` | `targets`, `cycles` | coordinated cyclic move: every axis reaches its target at the same SYNC |
//! | `wait` | `ms` | |
//!
//! Results are objects of the master (for `[[expect]] value = …`): 0x5000 sub 0 the
//! program's status (0 running, 1 completed, 2 failed), sub 1 the steps completed, sub 2
//! the failed step (1-based; 0 none). For axis *k* (0-based, in `axes` order) 0x5001 + *k*:
//! sub 1 the last statusword read, sub 2 the last position read (INTEGER64), sub 3 the last
//! set-point sent (INTEGER64), sub 4 the mode 0x6061 showed last.

use cantwin_bus::{BoxedNode, PortConfig};
use cantwin_can::{ControllerEvent, Duration, Frame, Instant, Node, Outbox};
use cantwin_canopen::master::cia402::{
    AxisConfig, CyclicMode, DriveEvent, DriveMaster, Homing, OpMode, PositionMove, PowerTarget,
    StreamConfig, VelocityMove,
};
use cantwin_canopen::master::pdo::{MapEntry, PdoParams, PdoRef};
use cantwin_canopen::master::{MasterEvent, TransferId};
use cantwin_canopen::wire::NmtCs;
use cantwin_twin::{ObjectError, Twin};
use serde::Deserialize;

use crate::error::ScenarioError;
use crate::registry::{BuildEnv, DeviceKind, Settings};
use crate::spec::BusSpec;

/// The program's result object; axis *k*'s is one more than this plus *k*.
pub const RESULTS_INDEX: u16 = 0x5000;

/// The `cia402_master` kind.
pub struct Cia402MasterKind;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStep {
    op: String,
    axes: Option<Vec<u8>>,
    mode: Option<String>,
    method: Option<i8>,
    switch_speed: Option<u32>,
    zero_speed: Option<u32>,
    acceleration: Option<u32>,
    targets: Option<Vec<i32>>,
    relative: Option<bool>,
    cycles: Option<u32>,
    ms: Option<f64>,
    period_ms: Option<f64>,
    pdo: Option<u16>,
    entries: Option<Vec<u32>>,
    transmission: Option<u8>,
    rpdo: Option<u16>,
    with_controlword: Option<bool>,
}

#[derive(Debug, Clone, PartialEq)]
enum Op {
    NmtStart,
    MapPdo {
        rx: bool,
        number: u16,
        entries: Vec<u32>,
        transmission: u8,
    },
    Switch(PowerTarget),
    QuickStop,
    FaultReset,
    Mode(OpMode),
    Home(Homing),
    Pp {
        targets: Vec<i32>,
        relative: bool,
    },
    Pv {
        targets: Vec<i32>,
    },
    Sync(Duration),
    Stream {
        rpdo: u16,
        with_controlword: bool,
    },
    Move {
        targets: Vec<i32>,
        cycles: u32,
    },
    Wait(Duration),
}

#[derive(Debug, Clone, PartialEq)]
struct Step {
    op: Op,
    /// Indices into the axes.
    axes: Vec<usize>,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct AxisResult {
    statusword: u16,
    position: i64,
    set_point: i64,
    mode: i8,
}

/// The master node running the program.
pub struct Cia402MasterNode {
    drives: DriveMaster,
    nodes: Vec<u8>,
    steps: Vec<Step>,
    /// The step running (its index), and what it still waits for.
    current: usize,
    started: bool,
    pending: Vec<usize>,
    pdo_jobs: Vec<(TransferId, usize)>,
    wait_until: Option<Instant>,
    status: u8,
    failed_step: u8,
    results: Vec<AxisResult>,
}

impl core::fmt::Debug for Cia402MasterNode {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Cia402MasterNode")
            .field("axes", &self.nodes)
            .field("step", &self.current)
            .finish_non_exhaustive()
    }
}

/// The COB-ID of PDO `number` of `node` in the predefined connection set's pattern
/// (CiA 301 §7.3.4: 4 PDOs each way; further ones repeat the pattern).
fn pdo_cob_id(rx: bool, number: u16, node: u8) -> u16 {
    let base = if rx { 0x200 } else { 0x180 };
    base + 0x100 * ((number.saturating_sub(1)) % 4) + u16::from(node)
}

impl Cia402MasterNode {
    fn fail(&mut self) {
        self.status = 2;
        // Steps are at most 255 (checked when built).
        self.failed_step = u8::try_from(self.current + 1).unwrap_or(u8::MAX);
        self.pending.clear();
        self.wait_until = None;
    }

    /// Starts step `self.current` on its axes.
    fn start_step(&mut self, now: Instant, out: &mut Outbox) {
        self.started = true;
        let Some(step) = self.steps.get(self.current).cloned() else {
            self.status = 1;
            return;
        };
        self.pending = step.axes.clone();
        let mut failed = false;
        for &k in &step.axes {
            let node = self.nodes[k];
            let r = match &step.op {
                Op::NmtStart => {
                    let _ = self.drives.master_mut().nmt(NmtCs::Start, node, out);
                    self.pending.retain(|p| *p != k);
                    Ok(())
                }
                Op::MapPdo {
                    rx,
                    number,
                    entries,
                    transmission,
                } => {
                    let params = PdoParams {
                        cob_id: u32::from(pdo_cob_id(*rx, *number, node)),
                        transmission_type: *transmission,
                        inhibit_time: None,
                        event_timer: None,
                        mapping: entries.iter().map(|e| MapEntry::from_u32(*e)).collect(),
                    };
                    let pdo = if *rx {
                        PdoRef::rpdo(*number)
                    } else {
                        PdoRef::tpdo(*number)
                    };
                    match self
                        .drives
                        .master_mut()
                        .write_pdo(node, pdo, &params, now, out)
                    {
                        Ok(id) => {
                            self.pdo_jobs.push((id, k));
                            Ok(())
                        }
                        Err(e) => Err(e.into()),
                    }
                }
                Op::Switch(t) => self.drives.switch(node, *t, now, out),
                Op::QuickStop => self.drives.quick_stop(node, now, out),
                Op::FaultReset => self.drives.fault_reset(node, now, out),
                Op::Mode(m) => self.drives.set_mode(node, *m, now, out),
                Op::Home(h) => self.drives.home(node, *h, now, out),
                Op::Pp { targets, relative } => self.drives.profile_position(
                    node,
                    PositionMove {
                        target: targets[k],
                        relative: *relative,
                        wait: true,
                        ..PositionMove::default()
                    },
                    now,
                    out,
                ),
                Op::Pv { targets } => self.drives.profile_velocity(
                    node,
                    VelocityMove {
                        target: targets[k],
                        wait: true,
                        ..VelocityMove::default()
                    },
                    now,
                    out,
                ),
                Op::Stream {
                    rpdo,
                    with_controlword,
                } => {
                    let mode = match self.results[k].mode {
                        m if m == OpMode::CyclicSyncVelocity.code() => CyclicMode::Velocity,
                        _ => CyclicMode::Position,
                    };
                    let config = StreamConfig {
                        mode,
                        rpdo: pdo_cob_id(true, *rpdo, node),
                        with_controlword: *with_controlword,
                    };
                    self.drives.start_stream(node, config, now, out)
                }
                Op::Sync(_) | Op::Move { .. } | Op::Wait(_) => Ok(()),
            };
            if r.is_err() {
                failed = true;
            }
        }
        match &step.op {
            Op::Sync(period) => {
                let _ = self.drives.master_mut().set_sync(Some((*period, 0)), now);
                self.pending.clear();
            }
            Op::Wait(d) => {
                self.pending.clear();
                self.wait_until = Some(now.checked_add(*d).unwrap_or(Instant::MAX));
            }
            Op::Move { targets, cycles } => {
                let moves: Vec<(u8, i32)> = step
                    .axes
                    .iter()
                    .map(|&k| (self.nodes[k], targets[k]))
                    .collect();
                if self.drives.move_cyclic(&moves, *cycles).is_err() {
                    failed = true;
                }
            }
            _ => {}
        }
        if failed {
            self.fail();
        }
    }

    /// Moves the program on: events in, next steps out.
    fn after(&mut self, now: Instant, out: &mut Outbox) {
        loop {
            while let Some((_, event)) = self.drives.poll_event() {
                self.on_event(event);
            }
            if self.status != 0 {
                return;
            }
            if !self.started {
                self.start_step(now, out);
                continue;
            }
            if let Some(t) = self.wait_until {
                if now < t {
                    return;
                }
                self.wait_until = None;
            }
            if !self.pending.is_empty() {
                return;
            }
            self.current += 1;
            self.started = false;
            if self.current >= self.steps.len() {
                self.status = 1;
                return;
            }
        }
    }

    fn axis_of(&self, node: u8) -> Option<usize> {
        self.nodes.iter().position(|n| *n == node)
    }

    fn on_event(&mut self, event: DriveEvent) {
        match event {
            DriveEvent::Finished { node, result, .. } => {
                let Some(k) = self.axis_of(node) else {
                    return;
                };
                match result {
                    Ok(s) => {
                        let r = &mut self.results[k];
                        if let Some(sw) = s.statusword {
                            r.statusword = sw;
                        }
                        if let Some(p) = s.position {
                            r.position = i64::from(p);
                        }
                        if let Some(m) = s.mode {
                            r.mode = m;
                        }
                        if let Some(p) = self.drives.set_point(node) {
                            r.set_point = i64::from(p);
                        }
                        self.pending.retain(|p| *p != k);
                    }
                    Err(_) => self.fail(),
                }
            }
            DriveEvent::TrajectoryDone { node, set_point } => {
                if let Some(k) = self.axis_of(node) {
                    self.results[k].set_point = i64::from(set_point);
                    self.pending.retain(|p| *p != k);
                }
            }
            DriveEvent::Master(MasterEvent::Pdo { id, result, .. }) => {
                let Some(pos) = self.pdo_jobs.iter().position(|(j, _)| *j == id) else {
                    return;
                };
                let (_, k) = self.pdo_jobs.remove(pos);
                match result {
                    Ok(_) => self.pending.retain(|p| *p != k),
                    Err(_) => self.fail(),
                }
            }
            DriveEvent::Master(_) => {}
        }
    }

    /// The result object `index`/`sub` (see the module documentation).
    pub fn result(&self, index: u16, sub: u8) -> Option<Vec<u8>> {
        if index == RESULTS_INDEX {
            let done = if self.status == 1 {
                self.steps.len()
            } else {
                self.current
            };
            return match sub {
                0 => Some(vec![self.status]),
                1 => Some(vec![u8::try_from(done).unwrap_or(u8::MAX)]),
                2 => Some(vec![self.failed_step]),
                _ => None,
            };
        }
        let k = usize::from(index.checked_sub(RESULTS_INDEX + 1)?);
        let r = self.results.get(k)?;
        match sub {
            1 => Some(r.statusword.to_le_bytes().to_vec()),
            2 => Some(r.position.to_le_bytes().to_vec()),
            3 => Some(r.set_point.to_le_bytes().to_vec()),
            4 => Some(r.mode.to_le_bytes().to_vec()),
            _ => None,
        }
    }
}

/// The master's results are its objects (see the module documentation).
impl Twin for Cia402MasterNode {
    fn read_object(&self, index: u16, sub: u8) -> Result<Vec<u8>, ObjectError> {
        self.result(index, sub).ok_or(ObjectError::NoDictionary)
    }
}

impl Node for Cia402MasterNode {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.drives.on_power_up(now, out);
        self.after(now, out);
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.drives.on_frame(frame, now, out);
        self.after(now, out);
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        self.drives.on_tick(now, out);
        self.after(now, out);
    }

    fn next_deadline(&self) -> Option<Instant> {
        Instant::earliest(self.drives.next_deadline(), self.wait_until)
    }

    fn on_sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.drives.on_sent(frame, now, out);
        self.after(now, out);
    }

    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        self.drives.on_controller_event(event, now, out);
        self.after(now, out);
    }
}

fn millis(ms: f64) -> Option<Duration> {
    (ms.is_finite() && (0.0..=86_400_000.0).contains(&ms))
        .then(|| Duration::from_nanos((ms * 1e6) as u64))
}

/// One step from its table (`n` axes; errors say what is wrong).
fn parse_step(r: RawStep, nodes: &[u8]) -> Result<Step, String> {
    let axes = match &r.axes {
        None => (0..nodes.len()).collect(),
        Some(list) => list
            .iter()
            .map(|n| {
                nodes
                    .iter()
                    .position(|x| x == n)
                    .ok_or_else(|| format!("node {n} is not one of `axes`"))
            })
            .collect::<Result<Vec<_>, _>>()?,
    };
    let targets = |what: &str| -> Result<Vec<i32>, String> {
        let t = r
            .targets
            .clone()
            .ok_or_else(|| format!("`{what}` needs `targets`, one per axis"))?;
        if t.len() != nodes.len() {
            return Err(format!(
                "`targets` has {} values for {} axes (one per axis, in `axes` order)",
                t.len(),
                nodes.len()
            ));
        }
        Ok(t)
    };
    let op = match r.op.as_str() {
        "nmt_start" => Op::NmtStart,
        op @ ("map_rpdo" | "map_tpdo") => {
            let number = r.pdo.ok_or("`pdo` (1–512) is needed")?;
            if !(1..=512).contains(&number) {
                return Err(format!("`pdo` is 1–512, not {number}"));
            }
            let entries = r.entries.clone().ok_or("`entries` is needed")?;
            if entries.len() > 64 {
                return Err("at most 64 `entries`".into());
            }
            let bits: u32 = entries.iter().map(|e| e & 0xFF).sum();
            if bits > 64 {
                return Err(format!("the entries map {bits} bits, more than 64"));
            }
            Op::MapPdo {
                rx: op == "map_rpdo",
                number,
                entries,
                transmission: r.transmission.unwrap_or(1),
            }
        }
        "enable" => Op::Switch(PowerTarget::OperationEnabled),
        "switch_on" => Op::Switch(PowerTarget::SwitchedOn),
        "shutdown" => Op::Switch(PowerTarget::ReadyToSwitchOn),
        "disable" => Op::Switch(PowerTarget::SwitchOnDisabled),
        "quick_stop" => Op::QuickStop,
        "fault_reset" => Op::FaultReset,
        "mode" => {
            let m = r.mode.clone().ok_or("`mode` is needed")?;
            Op::Mode(OpMode::from_abbreviation(&m).ok_or_else(|| {
                format!("unknown `mode` {m:?} (pp, vl, pv, tq, hm, ip, csp, csv, cst)")
            })?)
        }
        "home" => Op::Home(Homing {
            method: r.method.ok_or("`method` is needed")?,
            switch_speed: r.switch_speed,
            zero_speed: r.zero_speed,
            acceleration: r.acceleration,
        }),
        "pp" => Op::Pp {
            targets: targets("pp")?,
            relative: r.relative.unwrap_or(false),
        },
        "pv" => Op::Pv {
            targets: targets("pv")?,
        },
        "sync" => {
            let p = r.period_ms.ok_or("`period_ms` is needed")?;
            match millis(p) {
                Some(d) if !d.is_zero() => Op::Sync(d),
                _ => return Err(format!("`period_ms` must be a positive number, not {p}")),
            }
        }
        "stream" => {
            let rpdo = r.rpdo.ok_or("`rpdo` (1–512) is needed")?;
            if !(1..=512).contains(&rpdo) {
                return Err(format!("`rpdo` is 1–512, not {rpdo}"));
            }
            Op::Stream {
                rpdo,
                with_controlword: r.with_controlword.unwrap_or(true),
            }
        }
        "move" => Op::Move {
            targets: targets("move")?,
            cycles: r.cycles.ok_or("`cycles` is needed")?,
        },
        "wait" => {
            let ms = r.ms.ok_or("`ms` is needed")?;
            Op::Wait(millis(ms).ok_or_else(|| format!("`ms` must be a number ≥ 0, not {ms}"))?)
        }
        o => {
            return Err(format!(
                "unknown `op` {o:?} (nmt_start, map_rpdo, map_tpdo, enable, switch_on, shutdown, \
                 disable, quick_stop, fault_reset, mode, home, pp, pv, sync, stream, move, wait)"
            ));
        }
    };
    Ok(Step { op, axes })
}

impl DeviceKind for Cia402MasterKind {
    fn name(&self) -> &'static str {
        "cia402_master"
    }

    fn summary(&self) -> &'static str {
        "CiA 402 master running a program over drive axes (axes = [..], steps = [{ op = \"enable\" }, { op = \"home\", method = 35 }, …])"
    }

    fn build(
        &self,
        s: &Settings<'_>,
        _bus: &BusSpec,
        _env: &BuildEnv,
    ) -> Result<(BoxedNode, PortConfig), ScenarioError> {
        let nodes: Vec<u8> = s.require("axes")?;
        if nodes.is_empty() || nodes.len() > 64 {
            return Err(s.error("axes", "`axes` lists 1 to 64 node-IDs"));
        }
        for (i, n) in nodes.iter().enumerate() {
            if !(1..=127).contains(n) {
                return Err(s.error("axes", format!("node-ID {n} is outside 1–127")));
            }
            if nodes[..i].contains(n) {
                return Err(s.error("axes", format!("node-ID {n} is listed twice")));
            }
        }
        let raw: Vec<RawStep> = s.require("steps")?;
        if raw.len() > 255 {
            return Err(s.error("steps", "at most 255 steps"));
        }
        let mut steps = Vec::new();
        for (k, r) in raw.into_iter().enumerate() {
            steps.push(
                parse_step(r, &nodes).map_err(|m| s.error("steps", format!("steps[{k}]: {m}")))?,
            );
        }
        let ms = |key: &str, default: u64| -> Result<Duration, ScenarioError> {
            let v: u64 = s.get_or(key, default)?;
            if v == 0 || v > 86_400_000 {
                return Err(s.error(key, format!("`{key}` is 1 to 86400000 ms")));
            }
            Ok(Duration::from_millis(v))
        };
        let tpdo: Option<u16> = s.get("statusword_tpdo")?;
        if tpdo.is_some_and(|n| !(1..=4).contains(&n)) {
            return Err(s.error("statusword_tpdo", "`statusword_tpdo` is 1–4"));
        }
        let config = AxisConfig {
            step_timeout: ms("step_timeout_ms", 1000)?,
            move_timeout: ms("move_timeout_ms", 30_000)?,
            poll_interval: ms("poll_ms", 10)?,
            statusword_pdo: None,
        };
        let mut drives = DriveMaster::new();
        for n in &nodes {
            let config = AxisConfig {
                statusword_pdo: tpdo.map(|t| pdo_cob_id(false, t, *n)),
                ..config
            };
            drives
                .add_axis(*n, config)
                .map_err(|e| s.error("axes", e.to_string()))?;
        }
        let node = Cia402MasterNode {
            drives,
            results: vec![AxisResult::default(); nodes.len()],
            nodes,
            steps,
            current: 0,
            started: false,
            pending: Vec::new(),
            pdo_jobs: Vec::new(),
            wait_until: None,
            status: 0,
            failed_step: 0,
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

    /// The ADV200 card in its CiA 402 personality (velocity mode) driven by the master.
    fn scenario(steps: &str, expect: &str) -> String {
        format!(
            "[[bus]]\nname = \"can0\"\nbit_rate = \"500k\"\n\n\
             [[device]]\nname = \"drive\"\nkind = \"adv200\"\nbus = \"can0\"\n\
             params = {{ 4000 = \"DS402\", 4004 = \"500k\", 4006 = 2 }}\n\n\
             [[device]]\nname = \"master\"\nkind = \"cia402_master\"\nbus = \"can0\"\n\
             axes = [2]\nsteps = [{steps}]\n\n{expect}"
        )
    }

    fn expect(at_ms: u32, index: u16, sub: u8, equals: i64) -> String {
        format!(
            "[[expect]]\nat_ms = {at_ms}\nvalue = {{ device = \"master\", index = {index:#06X}, sub = {sub}, equals = {equals} }}\n\n"
        )
    }

    fn run(text: &str) -> crate::CheckReport {
        let s = Scenario::parse(text, "m.toml").unwrap();
        check(&s, &Registry::builtin(), &BuildEnv::default()).unwrap()
    }

    #[test]
    fn cia402_pds_fsa_program_enables_the_adv200_after_nmt_start() {
        let steps = "{ op = \"nmt_start\" }, { op = \"mode\", mode = \"vl\" }, { op = \"enable\" }, \
                     { op = \"quick_stop\" }, { op = \"enable\" }, { op = \"disable\" }";
        let mut e = expect(2000, 0x5000, 0, 1);
        e += &expect(2000, 0x5000, 1, 6);
        // SWITCH ON DISABLED at the end, vl shown.
        e += &expect(2000, 0x5001, 1, 0x0240);
        e += &expect(2000, 0x5001, 4, 2);
        let r = run(&scenario(steps, &e));
        assert!(r.passed(), "{r}");
    }

    #[test]
    fn cia402_a_failed_step_stops_the_program() {
        // Without NMT Start the card trips on enable (Opt Bus Fault): step 1 fails.
        let steps = "{ op = \"enable\" }, { op = \"disable\" }";
        let mut e = expect(2000, 0x5000, 0, 2);
        e += &expect(2000, 0x5000, 2, 1);
        let r = run(&scenario(steps, &e));
        assert!(r.passed(), "{r}");
        // And a mode the card lacks.
        let steps = "{ op = \"nmt_start\" }, { op = \"mode\", mode = \"pp\" }";
        let mut e = expect(2000, 0x5000, 0, 2);
        e += &expect(2000, 0x5000, 2, 2);
        let r = run(&scenario(steps, &e));
        assert!(r.passed(), "{r}");
    }

    /// A `cia402` servo at node 3 driven by the master (`extra`: more master keys).
    fn servo(extra: &str, steps: &str, expect: &str) -> String {
        format!(
            "[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n\n\
             [[device]]\nname = \"servo\"\nkind = \"cia402\"\nbus = \"can0\"\nnode_id = 3\n\n\
             [[device]]\nname = \"master\"\nkind = \"cia402_master\"\nbus = \"can0\"\n\
             axes = [3]\n{extra}\nsteps = [{steps}]\n\n{expect}"
        )
    }

    #[test]
    fn cia402_pp_and_pv_steps_on_the_servo_twin_by_sdo_poll_and_by_tpdo() {
        let steps = "{ op = \"nmt_start\" }, { op = \"enable\" }, { op = \"mode\", mode = \"pp\" }, \
                     { op = \"pp\", targets = [8192] }, { op = \"pp\", targets = [-4096], relative = true }, \
                     { op = \"mode\", mode = \"pv\" }, { op = \"pv\", targets = [4096] }, \
                     { op = \"pv\", targets = [0] }, { op = \"disable\" }";
        let mut e = expect(3000, 0x5000, 0, 1);
        e += &expect(3000, 0x5000, 1, 9);
        e += &expect(3000, 0x5001, 1, 0x0240);
        e += &expect(3000, 0x5001, 4, 3);
        e += "[[expect]]\nat_ms = 3000\nsignal = { device = \"servo\", name = \"position\", equals = 4096, tolerance = 2000 }\n";
        for extra in ["", "statusword_tpdo = 1"] {
            let r = run(&servo(extra, steps, &e));
            assert!(r.passed(), "{extra}: {r}");
        }
    }

    #[test]
    fn cia402_csv_stream_ramps_the_velocity_on_sync() {
        // RPDO4 (controlword + 0x60FF) synchronous, then a cyclic ramp to 8192 increments/s
        // in 200 cycles of 1 ms, held.
        let steps = "{ op = \"map_rpdo\", pdo = 4, entries = [0x60400010, 0x60FF0020] }, \
                     { op = \"nmt_start\" }, { op = \"enable\" }, { op = \"mode\", mode = \"csv\" }, \
                     { op = \"stream\", rpdo = 4 }, { op = \"sync\", period_ms = 1 }, \
                     { op = \"move\", targets = [8192], cycles = 200 }, { op = \"wait\", ms = 300 }";
        let mut e = expect(1000, 0x5000, 0, 1);
        e += &expect(1000, 0x5001, 3, 8192);
        e += &expect(1000, 0x5001, 4, 9);
        e += "[[expect]]\nat_ms = 1000\nsignal = { device = \"servo\", name = \"velocity\", equals = 8192, tolerance = 100 }\n";
        let r = run(&servo("", steps, &e));
        assert!(r.passed(), "{r}");
    }

    #[test]
    fn bad_steps_name_the_key() {
        for (steps, wanted) in [
            ("{ op = \"fly\" }", "unknown `op` \"fly\""),
            (
                "{ op = \"pp\", targets = [1, 2] }",
                "`targets` has 2 values for 1 axes",
            ),
            ("{ op = \"mode\", mode = \"xx\" }", "unknown `mode` \"xx\""),
            (
                "{ op = \"home\", axes = [9], method = 35 }",
                "node 9 is not one of `axes`",
            ),
            (
                "{ op = \"sync\", period_ms = 0 }",
                "`period_ms` must be a positive number",
            ),
        ] {
            let s = Scenario::parse(&scenario(steps, ""), "m.toml").unwrap();
            let e = s
                .build(&Registry::builtin(), &BuildEnv::default())
                .err()
                .unwrap()
                .to_string();
            assert!(e.contains("device[1].steps") && e.contains(wanted), "{e}");
        }
    }
}
