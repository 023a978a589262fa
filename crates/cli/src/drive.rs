//! `cantwin drive`: CiA 402 drive commands (power state, mode of operation, profile
//! moves, homing), driving the sans-IO [`DriveMaster`] of `cantwin-canopen` over any bus a
//! client command can reach.

use std::time::Duration as WallDuration;

use anyhow::{Context, Result, bail};
use cantwin_can::{Duration, Outbox};
use cantwin_canopen::master::MasterEvent;
use cantwin_canopen::master::cia402::{
    AxisConfig, DriveError, DriveEvent, DriveMaster, DriveState, HOMING_METHOD, Homing,
    MODES_OF_OPERATION, OpMode, PositionMove, PowerTarget, Snapshot, VelocityMove, mode_name,
    state_name,
};
use cantwin_canopen::wire::NmtCs;
use serde_json::json;

use crate::canopen::number;
use crate::connect::{Link, Target};
use crate::output;

#[derive(Debug, clap::Args)]
pub struct DriveArgs {
    #[command(flatten)]
    target: Target,
    /// Seconds one state transition, a mode switch or a set-point acknowledge may take.
    #[arg(long, default_value_t = 1.0, global = true, value_name = "SECONDS")]
    step_timeout: f64,
    /// Seconds a move may take to reach its target, and homing to finish.
    #[arg(long, default_value_t = 60.0, global = true, value_name = "SECONDS")]
    move_timeout: f64,
    /// Milliseconds between two SDO reads of the statusword while waiting.
    #[arg(long, default_value_t = 10, global = true, value_name = "MS", value_parser = clap::value_parser!(u64).range(1..=10_000))]
    poll_ms: u64,
    /// Send NMT Start to the node first (CiA 301): for drives that act on the controlword
    /// only in OPERATIONAL, such as the ADV200 card (it trips on enable otherwise). With
    /// --scenario every command starts the scenario afresh, so give --nmt-start (and
    /// --enable to move and home) on the command that needs it.
    #[arg(long, global = true)]
    nmt_start: bool,
    #[command(subcommand)]
    command: DriveCommand,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum StateAction {
    /// Print the state (0x6041), the mode (0x6061) and the error code (0x603F).
    Show,
    /// Walk to OPERATION ENABLED (shutdown, switch on, enable operation as needed).
    Enable,
    /// Walk to SWITCH ON DISABLED (disable voltage).
    Disable,
    /// Walk to SWITCHED ON (from OPERATION ENABLED: disable operation).
    SwitchOn,
    /// Walk to READY TO SWITCH ON (shutdown).
    Shutdown,
    /// Fault reset: the rising edge of controlword bit 7; the drive must leave FAULT.
    FaultReset,
    /// Quick stop (controlword 0x0002): QUICK STOP ACTIVE, or SWITCH ON DISABLED.
    QuickStop,
}

#[derive(Debug, clap::Subcommand)]
enum DriveCommand {
    /// Show or change the power drive state (CiA 402-2 PDS FSA): NODE [ACTION].
    #[command(
        after_help = "Examples:\n  cantwin drive --socketcand 127.0.0.1:29536 state 2\n  \
                      cantwin drive --socketcand 127.0.0.1:29536 state 2 enable\n  \
                      cantwin drive --socketcand 127.0.0.1:29536 state 2 fault-reset\n\n\
                      Each controlword is written once the statusword shows the state it applies to;\n\
                      a state that does not change within --step-timeout is an error, and so is FAULT."
    )]
    State {
        /// Node-ID (1–127).
        node: String,
        /// What to do.
        #[arg(value_enum, default_value_t = StateAction::Show)]
        action: StateAction,
    },
    /// Show or set the mode of operation: NODE [MODE], MODE one of pp vl pv tq hm ip csp
    /// csv cst or its 0x6060 number. Setting waits until 0x6061 shows it.
    #[command(
        after_help = "Examples:\n  cantwin drive --socketcand 127.0.0.1:29536 mode 2\n  \
                      cantwin drive --socketcand 127.0.0.1:29536 mode 2 pp\n  \
                      cantwin drive --scenario scenarios/adv200-ds402.toml mode 2 vl"
    )]
    Mode {
        /// Node-ID (1–127).
        node: String,
        /// The mode to set.
        mode: Option<String>,
    },
    /// A profile move: `pp NODE TARGET` (position) or `pv NODE VELOCITY`. The mode is set
    /// first if 0x6061 shows another; the drive must be enabled (or give --enable).
    #[command(subcommand)]
    Move(MoveCommand),
    /// Homing: NODE METHOD (0x6098, CiA 402-2 methods 1–35 and 37; negative:
    /// manufacturer-specific). Switches to homing mode, starts, waits for homing attained.
    #[command(
        after_help = "Examples:\n  cantwin drive --socketcand 127.0.0.1:29536 home 2 35\n  \
                      cantwin drive --socketcand 127.0.0.1:29536 home 2 17 --switch-speed 2000 --zero-speed 200 --enable"
    )]
    Home {
        /// Node-ID (1–127).
        node: String,
        /// The homing method.
        #[arg(allow_hyphen_values = true)]
        method: String,
        /// 0x6099 sub 1: speed during search for switch.
        #[arg(long)]
        switch_speed: Option<u32>,
        /// 0x6099 sub 2: speed during search for zero.
        #[arg(long)]
        zero_speed: Option<u32>,
        /// 0x609A: homing acceleration.
        #[arg(long)]
        acceleration: Option<u32>,
        /// Bring the drive to OPERATION ENABLED first.
        #[arg(long)]
        enable: bool,
    },
}

#[derive(Debug, clap::Subcommand)]
enum MoveCommand {
    /// Profile position: NODE TARGET (0x607A, position units), with the set-point
    /// handshake (controlword bit 4, statusword bit 12); waits for target reached.
    #[command(
        after_help = "Examples:\n  cantwin drive --socketcand 127.0.0.1:29536 move pp 2 100000\n  \
                      cantwin drive --socketcand 127.0.0.1:29536 move pp 2 -5000 --relative --velocity 20000\n  \
                      cantwin drive --socketcand 127.0.0.1:29536 move pp 2 0 --immediately --no-wait"
    )]
    Pp {
        /// Node-ID (1–127).
        node: String,
        /// Target position.
        #[arg(allow_hyphen_values = true)]
        target: i32,
        /// Relative to the previous target (controlword bit 6), else absolute.
        #[arg(long)]
        relative: bool,
        /// Change set immediately (controlword bit 5): abandon the move under way.
        #[arg(long)]
        immediately: bool,
        /// 0x6081 profile velocity.
        #[arg(long)]
        velocity: Option<u32>,
        /// 0x6083 profile acceleration.
        #[arg(long)]
        acceleration: Option<u32>,
        /// 0x6084 profile deceleration.
        #[arg(long)]
        deceleration: Option<u32>,
        /// Return once the set-point is acknowledged, without waiting for target reached.
        #[arg(long)]
        no_wait: bool,
        /// Bring the drive to OPERATION ENABLED first.
        #[arg(long)]
        enable: bool,
    },
    /// Profile velocity: NODE VELOCITY (0x60FF, velocity units); waits for target reached.
    #[command(
        after_help = "Examples:\n  cantwin drive --socketcand 127.0.0.1:29536 move pv 2 3000\n  \
                      cantwin drive --socketcand 127.0.0.1:29536 move pv 2 0 --deceleration 10000"
    )]
    Pv {
        /// Node-ID (1–127).
        node: String,
        /// Target velocity.
        #[arg(allow_hyphen_values = true)]
        velocity: i32,
        /// 0x6083 profile acceleration.
        #[arg(long)]
        acceleration: Option<u32>,
        /// 0x6084 profile deceleration.
        #[arg(long)]
        deceleration: Option<u32>,
        /// Return once the target is written, without waiting for target reached.
        #[arg(long)]
        no_wait: bool,
        /// Bring the drive to OPERATION ENABLED first.
        #[arg(long)]
        enable: bool,
    },
}

fn node_id(text: &str) -> Result<u8> {
    let n = number(text, "node-ID")?;
    u8::try_from(n)
        .ok()
        .filter(|n| (1..=127).contains(n))
        .with_context(|| format!("node-ID {text} is outside 1–127"))
}

fn seconds(value: f64, flag: &str) -> Result<Duration> {
    if !(value.is_finite() && value > 0.0 && value <= 86_400.0) {
        bail!("{flag} must be a positive number of seconds (at most a day)");
    }
    Ok(Duration::from_secs_f64(value))
}

fn parse_mode(text: &str) -> Result<OpMode> {
    if let Some(m) = OpMode::from_abbreviation(text) {
        return Ok(m);
    }
    let code: Option<i8> = text.trim().parse().ok();
    code.and_then(OpMode::from_code).with_context(|| {
        format!(
            "unknown mode {text:?}: one of pp vl pv tq hm ip csp csv cst, or 1–4, 6–10 (0x6060)"
        )
    })
}

/// The drive master and its bus.
struct Session {
    link: Link,
    drives: DriveMaster,
    node: u8,
    wall_limit: WallDuration,
    /// The emergency messages of the node seen during the jobs (error code, register).
    emcy: Vec<(u16, u8)>,
}

impl Session {
    fn open(args: &DriveArgs, node: u8) -> Result<Session> {
        let config = AxisConfig {
            step_timeout: seconds(args.step_timeout, "--step-timeout")?,
            move_timeout: seconds(args.move_timeout, "--move-timeout")?,
            poll_interval: Duration::from_millis(args.poll_ms),
            statusword_pdo: None,
        };
        let mut drives = DriveMaster::new();
        drives
            .add_axis(node, config)
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        // The jobs' own timeouts decide; this only ends a run whose bus went away. Each
        // job has a handful of steps, each bounded by the SDO timeout and the job's
        // timeouts.
        let wall_limit = WallDuration::from_secs_f64(
            (args.step_timeout * 8.0 + args.move_timeout + 30.0).min(200_000.0),
        );
        let mut s = Session {
            link: Link::open(&args.target)?,
            drives,
            node,
            wall_limit,
            emcy: Vec::new(),
        };
        if args.nmt_start {
            let mut out = Outbox::new();
            s.drives
                .master_mut()
                .nmt(NmtCs::Start, node, &mut out)
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            for f in out.drain() {
                s.link.send(f)?;
            }
        }
        Ok(s)
    }

    /// Runs one job (started by `start`) to its end.
    fn run(
        &mut self,
        what: &str,
        start: impl FnOnce(
            &mut DriveMaster,
            u8,
            cantwin_can::Instant,
            &mut Outbox,
        ) -> Result<(), DriveError>,
    ) -> Result<Snapshot> {
        let mut out = Outbox::new();
        let node = self.node;
        start(&mut self.drives, node, self.link.now(), &mut out)
            .map_err(|e| anyhow::anyhow!("node {node}: {what}: {e}"))?;
        for f in out.drain() {
            self.link.send(f)?;
        }
        let mut result = None;
        let emcy = &mut self.emcy;
        let finished = self.link.run(
            &mut self.drives,
            |d| {
                while let Some((_, e)) = d.poll_event() {
                    match e {
                        DriveEvent::Finished {
                            node: n, result: r, ..
                        } if n == node => result = Some(r),
                        DriveEvent::Master(MasterEvent::Emcy { node: n, emcy: m })
                            if n == node && m.code != 0 =>
                        {
                            emcy.push((m.code, m.register));
                        }
                        _ => {}
                    }
                }
                result.is_some()
            },
            self.wall_limit,
        )?;
        match result {
            Some(Ok(s)) => Ok(s),
            Some(Err(
                e @ DriveError::Sdo {
                    index: MODES_OF_OPERATION,
                    ..
                },
            )) => bail!(
                "node {node}: {what}: {e}: the drive does not take this mode (0x6502 lists the modes it supports)"
            ),
            Some(Err(
                e @ DriveError::Sdo {
                    index: HOMING_METHOD,
                    ..
                },
            )) => bail!("node {node}: {what}: {e}: the drive does not run this homing method"),
            Some(Err(e)) if self.emcy.is_empty() => bail!("node {node}: {what}: {e}"),
            Some(Err(e)) => {
                let seen: Vec<String> = self
                    .emcy
                    .iter()
                    .map(|(c, r)| format!("{c:#06X} (register {r:#04X})"))
                    .collect();
                bail!(
                    "node {node}: {what}: {e}; EMCY from the node: {}",
                    seen.join(", ")
                )
            }
            None if !finished => bail!("node {node}: {what}: no answer from the bus"),
            None => bail!("node {node}: {what}: ended without a result"),
        }
    }

    fn enable(&mut self) -> Result<Snapshot> {
        self.run("enable", |d, n, now, out| {
            d.switch(n, PowerTarget::OperationEnabled, now, out)
        })
    }
}

fn sw_text(s: &Snapshot) -> String {
    match s.statusword {
        Some(sw) => format!("{} (statusword {sw:#06X})", state_name(sw)),
        None => "state not read".to_string(),
    }
}

fn snapshot_json(node: u8, job: &str, s: &Snapshot) -> serde_json::Value {
    json!({
        "node": node,
        "job": job,
        "statusword": s.statusword,
        "state": s.statusword.map(state_name),
        "mode": s.mode,
        "mode_name": s.mode.map(mode_name),
        "error_code": s.error_code,
        "position": s.position,
        "velocity": s.velocity,
    })
}

pub fn run(args: &DriveArgs) -> Result<()> {
    match &args.command {
        DriveCommand::State { node, action } => {
            let node = node_id(node)?;
            let mut s = Session::open(args, node)?;
            let (what, snap) = match action {
                StateAction::Show => (
                    "show",
                    s.run("show", |d, n, now, out| d.inspect(n, now, out))?,
                ),
                StateAction::Enable => ("enable", s.enable()?),
                StateAction::Disable => (
                    "disable",
                    s.run("disable", |d, n, now, out| {
                        d.switch(n, PowerTarget::SwitchOnDisabled, now, out)
                    })?,
                ),
                StateAction::SwitchOn => (
                    "switch-on",
                    s.run("switch on", |d, n, now, out| {
                        d.switch(n, PowerTarget::SwitchedOn, now, out)
                    })?,
                ),
                StateAction::Shutdown => (
                    "shutdown",
                    s.run("shutdown", |d, n, now, out| {
                        d.switch(n, PowerTarget::ReadyToSwitchOn, now, out)
                    })?,
                ),
                StateAction::FaultReset => (
                    "fault-reset",
                    s.run("fault reset", |d, n, now, out| d.fault_reset(n, now, out))?,
                ),
                StateAction::QuickStop => (
                    "quick-stop",
                    s.run("quick stop", |d, n, now, out| d.quick_stop(n, now, out))?,
                ),
            };
            let mut text = format!("node {node}: {}", sw_text(&snap));
            if let Some(m) = snap.mode {
                text.push_str(&format!(", mode {}", mode_name(m)));
            }
            if let Some(e) = snap.error_code
                && e != 0
            {
                text.push_str(&format!(", error code {e:#06X}"));
            }
            if snap.state() == Some(DriveState::Fault) && *action != StateAction::FaultReset {
                text.push_str(" (clear it with: state NODE fault-reset)");
            }
            output::result(text, || snapshot_json(node, what, &snap))?;
            Ok(())
        }
        DriveCommand::Mode { node, mode } => {
            let node = node_id(node)?;
            let wanted = mode.as_deref().map(parse_mode).transpose()?;
            let mut s = Session::open(args, node)?;
            let snap = match wanted {
                None => s.run("show", |d, n, now, out| d.inspect(n, now, out))?,
                Some(m) => s.run(&format!("mode {}", m.abbreviation()), |d, n, now, out| {
                    d.set_mode(n, m, now, out)
                })?,
            };
            let shown = snap.mode.map_or("not readable".to_string(), mode_name);
            output::result(format!("node {node}: mode {shown}"), || {
                snapshot_json(node, "mode", &snap)
            })?;
            Ok(())
        }
        DriveCommand::Move(MoveCommand::Pp {
            node,
            target,
            relative,
            immediately,
            velocity,
            acceleration,
            deceleration,
            no_wait,
            enable,
        }) => {
            let node = node_id(node)?;
            let mut s = Session::open(args, node)?;
            prepare(&mut s, "pp move", *enable, OpMode::ProfilePosition)?;
            let mv = PositionMove {
                target: *target,
                relative: *relative,
                immediately: *immediately,
                profile_velocity: *velocity,
                acceleration: *acceleration,
                deceleration: *deceleration,
                wait: !*no_wait,
            };
            let snap = s.run("pp move", |d, n, now, out| {
                d.profile_position(n, mv, now, out)
            })?;
            let verb = if *no_wait {
                "set-point acknowledged"
            } else {
                "target reached"
            };
            let at = snap
                .position
                .map_or(String::new(), |p| format!(", position {p}"));
            output::result(format!("node {node}: {verb}{at}"), || {
                snapshot_json(node, "pp", &snap)
            })?;
            Ok(())
        }
        DriveCommand::Move(MoveCommand::Pv {
            node,
            velocity,
            acceleration,
            deceleration,
            no_wait,
            enable,
        }) => {
            let node = node_id(node)?;
            let mut s = Session::open(args, node)?;
            prepare(&mut s, "pv move", *enable, OpMode::ProfileVelocity)?;
            let mv = VelocityMove {
                target: *velocity,
                acceleration: *acceleration,
                deceleration: *deceleration,
                wait: !*no_wait,
            };
            let snap = s.run("pv move", |d, n, now, out| {
                d.profile_velocity(n, mv, now, out)
            })?;
            let verb = if *no_wait {
                "target velocity set"
            } else {
                "target velocity reached"
            };
            let at = snap
                .velocity
                .map_or(String::new(), |v| format!(", velocity {v}"));
            output::result(format!("node {node}: {verb}{at}"), || {
                snapshot_json(node, "pv", &snap)
            })?;
            Ok(())
        }
        DriveCommand::Home {
            node,
            method,
            switch_speed,
            zero_speed,
            acceleration,
            enable,
        } => {
            let node = node_id(node)?;
            let method: i8 = method.trim().parse().with_context(|| {
                format!("homing method {method:?} is not a number in −128..=127")
            })?;
            let mut s = Session::open(args, node)?;
            if *enable {
                s.enable()?;
            }
            let h = Homing {
                method,
                switch_speed: *switch_speed,
                zero_speed: *zero_speed,
                acceleration: *acceleration,
            };
            let snap = s.run(&format!("homing method {method}"), |d, n, now, out| {
                d.home(n, h, now, out)
            })?;
            let at = snap
                .position
                .map_or(String::new(), |p| format!(", position {p}"));
            output::result(format!("node {node}: homing attained{at}"), || {
                snapshot_json(node, "home", &snap)
            })?;
            Ok(())
        }
    }
}

/// Enables the drive if asked, checks that it is enabled, and switches to `mode` unless
/// 0x6061 shows it.
fn prepare(s: &mut Session, what: &str, enable: bool, mode: OpMode) -> Result<()> {
    if enable {
        s.enable()?;
    }
    let snap = s.run("read the state", |d, n, now, out| d.inspect(n, now, out))?;
    if snap.state() != Some(DriveState::OperationEnabled) {
        bail!(
            "node {}: {what}: the drive is in {}, not operation enabled (enable it first: \
             state NODE enable, or give --enable)",
            s.node,
            snap.state().map_or("no defined state", DriveState::name)
        );
    }
    if snap.mode != Some(mode.code()) {
        s.run(
            &format!("mode {}", mode.abbreviation()),
            |d, n, now, out| d.set_mode(n, mode, now, out),
        )?;
    }
    Ok(())
}
