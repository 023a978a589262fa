//! The [`DriveMaster`]: the jobs of the module table as small programs of SDO transfers
//! and waits, run per axis, and the cyclic set-points sent after each SYNC.

use super::*;

/// What a waited-for statusword must show.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Cond {
    /// A state other than this (after a controlword of the walk).
    Left(DriveState),
    /// QUICK STOP ACTIVE or SWITCH ON DISABLED.
    QuickStopped,
    /// Not FAULT nor FAULT REACTION ACTIVE.
    FaultCleared,
    /// Not FAULT REACTION ACTIVE (transition 14 done).
    ReactionDone,
    /// 0x6061 shows this mode.
    ModeShown(OpMode),
    /// pp bit 12 at this level.
    SetPointAck(bool),
    /// pp bit 10 with bit 12 cleared.
    PositionReached,
    /// pv bit 10 seen after a statusword without it, or at least a poll interval after
    /// the write.
    VelocityReached { since: Instant, seen_clear: bool },
    /// hm bits 10 and 12. When the drive showed bit 12 before the start (a previous
    /// homing's), only after a statusword without it or one read at least a poll interval
    /// after the start: the drive may not have taken the start yet.
    Homed { armed: bool, since: Instant },
}

enum Verdict {
    Met,
    NotYet,
    Fail(DriveError),
}

impl Cond {
    fn what(&self) -> &'static str {
        match self {
            Cond::Left(_) => "the state to change",
            Cond::QuickStopped => "quick stop active or switch on disabled",
            Cond::FaultCleared => "the fault to clear",
            Cond::ReactionDone => "the fault reaction to end",
            Cond::ModeShown(_) => "0x6061 to show the mode",
            Cond::SetPointAck(true) => "set-point acknowledge (bit 12)",
            Cond::SetPointAck(false) => "set-point acknowledge to clear (bit 12)",
            Cond::PositionReached | Cond::VelocityReached { .. } => "target reached (bit 10)",
            Cond::Homed { .. } => "homing attained (bits 10 and 12)",
        }
    }

    fn reads(&self) -> u16 {
        match self {
            Cond::ModeShown(_) => MODES_OF_OPERATION_DISPLAY,
            _ => STATUSWORD,
        }
    }

    fn check(&mut self, value: u16, now: Instant, poll: Duration) -> Verdict {
        let sw = value;
        let state = DriveState::from_statusword(sw);
        let faulted = state.is_some_and(DriveState::is_fault);
        match self {
            Cond::FaultCleared => {
                return if faulted || state.is_none() {
                    Verdict::NotYet
                } else {
                    Verdict::Met
                };
            }
            Cond::ReactionDone => {
                return if state == Some(DriveState::FaultReactionActive) || state.is_none() {
                    Verdict::NotYet
                } else {
                    Verdict::Met
                };
            }
            Cond::ModeShown(m) => {
                // The value is 0x6061, an INTEGER8 in the low byte.
                return if value as u8 as i8 == m.code() {
                    Verdict::Met
                } else {
                    Verdict::NotYet
                };
            }
            _ => {}
        }
        if faulted {
            return Verdict::Fail(DriveError::Fault { error_code: None });
        }
        let met = match self {
            Cond::Left(from) => state.is_some_and(|s| s != *from),
            Cond::QuickStopped => matches!(
                state,
                Some(DriveState::QuickStopActive | DriveState::SwitchOnDisabled)
            ),
            Cond::SetPointAck(level) => (sw & SW_BIT12 != 0) == *level,
            Cond::PositionReached => {
                if sw & SW_BIT13 != 0 {
                    return Verdict::Fail(DriveError::FollowingError { statusword: sw });
                }
                sw & SW_TARGET_REACHED != 0 && sw & SW_BIT12 == 0
            }
            Cond::VelocityReached { since, seen_clear } => {
                if sw & SW_TARGET_REACHED == 0 {
                    *seen_clear = true;
                    false
                } else {
                    *seen_clear || now.saturating_duration_since(*since) >= poll
                }
            }
            Cond::Homed { armed, since } => {
                if sw & SW_BIT13 != 0 {
                    return Verdict::Fail(DriveError::HomingError { statusword: sw });
                }
                if sw & SW_BIT12 == 0 || now.saturating_duration_since(*since) >= poll {
                    *armed = true;
                }
                *armed && sw & (SW_TARGET_REACHED | SW_BIT12) == SW_TARGET_REACHED | SW_BIT12
            }
            Cond::FaultCleared | Cond::ReactionDone | Cond::ModeShown(_) => false,
        };
        if met { Verdict::Met } else { Verdict::NotYet }
    }
}

/// What a read is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Then {
    /// Kept in the snapshot; an abort fails the job.
    Keep,
    /// Kept; an abort leaves the value unknown.
    Optional,
    /// 0x6041 must show OPERATION ENABLED.
    RequireEnabled,
    /// 0x6061 must show the mode.
    RequireMode(OpMode),
    /// 0x6061: switch to the mode unless shown.
    EnsureMode(OpMode),
    /// 0x6041 before a homing start: arms the wait if bit 12 is clear.
    ArmHoming,
    /// 0x6064: the stream's first set-point.
    StreamFrom,
    /// 0x6041 for a fault reset.
    ResetIfFaulted,
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Step {
    Write(u16, u8, Vec<u8>),
    Controlword(u16),
    Read(u16, u8, Then),
    Await { cond: Cond, timeout: Duration },
    Walk(PowerTarget),
    ReadErrorCode,
    StartStream(StreamConfig),
}

#[derive(Debug, Clone)]
struct Job {
    kind: JobKind,
    steps: VecDeque<Step>,
    transfer: Option<TransferId>,
    /// The active wait's deadline and next poll.
    deadline: Option<Instant>,
    wake: Option<Instant>,
    snapshot: Snapshot,
    /// Controlwords written by the walk (bounded: a drive that does not follow fails).
    walked: u8,
    /// Set when the job fails on a fault: 0x603F is read before the error is reported.
    failing: Option<DriveError>,
    homing_armed: bool,
    stream_from: Option<i32>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Stream {
    config: StreamConfig,
    trajectory: Trajectory,
    cycle: u32,
    last: i32,
    done_reported: bool,
}

#[derive(Debug, Clone)]
struct Axis {
    config: AxisConfig,
    controlword: u16,
    job: Option<Job>,
    stream: Option<Stream>,
    /// The statusword of the last TPDO ([`AxisConfig::statusword_pdo`]).
    pdo_statusword: Option<u16>,
}

/// The most controlwords one [`DriveMaster::switch`] writes: the longest path (FAULT
/// aside) has four transitions; a drive bouncing back gets a few more before the job fails.
const MAX_WALK: u8 = 8;

/// A CiA 402 master over a CANopen [`Master`] (see the module documentation).
#[derive(Debug, Clone)]
pub struct DriveMaster {
    master: Master,
    axes: BTreeMap<u8, Axis>,
    /// The transfers the jobs started, by axis.
    mine: BTreeMap<TransferId, u8>,
    events: VecDeque<(Instant, DriveEvent)>,
}

impl Default for DriveMaster {
    fn default() -> Self {
        DriveMaster::new()
    }
}

fn is_sync(f: &Frame) -> bool {
    matches!(f.id(), Id::Standard(s) if s.as_raw() == SYNC_COB_ID) && !f.is_remote()
}

fn le_i32(data: &[u8]) -> Option<i32> {
    <[u8; 4]>::try_from(data).ok().map(i32::from_le_bytes)
}

fn le_u16(data: &[u8]) -> Option<u16> {
    <[u8; 2]>::try_from(data).ok().map(u16::from_le_bytes)
}

fn le_i8(data: &[u8]) -> Option<i8> {
    <[u8; 1]>::try_from(data).ok().map(i8::from_le_bytes)
}

impl DriveMaster {
    /// A drive master over a default [`Master`].
    pub fn new() -> Self {
        DriveMaster::with_master(Master::new())
    }

    /// A drive master over `master`.
    pub fn with_master(master: Master) -> Self {
        DriveMaster {
            master,
            axes: BTreeMap::new(),
            mine: BTreeMap::new(),
            events: VecDeque::new(),
        }
    }

    /// The CANopen master (NMT, SYNC, PDO configuration, other transfers).
    pub fn master(&self) -> &Master {
        &self.master
    }

    /// The CANopen master, to start NMT commands, SYNC and PDO configuration; its events
    /// come out of [`Self::poll_event`] as [`DriveEvent::Master`].
    pub fn master_mut(&mut self) -> &mut Master {
        &mut self.master
    }

    /// Adds drive `node` (1–127) as an axis (replacing its settings if present).
    pub fn add_axis(&mut self, node: u8, config: AxisConfig) -> Result<(), DriveError> {
        if !(1..=127).contains(&node) {
            return Err(DriveError::NoAxis(node));
        }
        let axis = self.axes.entry(node).or_insert(Axis {
            config,
            controlword: 0,
            job: None,
            stream: None,
            pdo_statusword: None,
        });
        axis.config = config;
        Ok(())
    }

    /// The next event, oldest first.
    pub fn poll_event(&mut self) -> Option<(Instant, DriveEvent)> {
        self.events.pop_front()
    }

    /// Whether `node` runs a job.
    pub fn is_busy(&self, node: u8) -> bool {
        self.axes.get(&node).is_some_and(|a| a.job.is_some())
    }

    /// The controlword last written to `node`.
    pub fn controlword(&self, node: u8) -> Option<u16> {
        self.axes.get(&node).map(|a| a.controlword)
    }

    /// The statusword of `node`'s last TPDO ([`AxisConfig::statusword_pdo`]).
    pub fn pdo_statusword(&self, node: u8) -> Option<u16> {
        self.axes.get(&node).and_then(|a| a.pdo_statusword)
    }

    /// The set-point `node`'s stream sent last, if it streams.
    pub fn set_point(&self, node: u8) -> Option<i32> {
        self.axes.get(&node)?.stream.map(|s| s.last)
    }

    fn begin(
        &mut self,
        node: u8,
        kind: JobKind,
        steps: Vec<Step>,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        let axis = self.axes.get_mut(&node).ok_or(DriveError::NoAxis(node))?;
        if axis.job.is_some() {
            return Err(DriveError::Busy(node));
        }
        axis.job = Some(Job {
            kind,
            steps: steps.into(),
            transfer: None,
            deadline: None,
            wake: None,
            snapshot: Snapshot {
                statusword: None,
                mode: None,
                error_code: None,
                position: None,
                velocity: None,
            },
            walked: 0,
            failing: None,
            homing_armed: false,
            stream_from: None,
        });
        let mut local = Outbox::new();
        self.advance(node, now, &mut local);
        self.relay(local, now, out);
        Ok(())
    }

    /// Brings `node` to `target` along the PDS FSA: each controlword is written after the
    /// statusword shows the state it applies to (CiA 402-2, transitions 2–12, 16).
    pub fn switch(
        &mut self,
        node: u8,
        target: PowerTarget,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        self.begin(
            node,
            JobKind::Switch(target),
            vec![Step::Walk(target)],
            now,
            out,
        )
    }

    /// Quick stop (controlword 0x0002: transition 11 from OPERATION ENABLED, 7 or 10 from
    /// READY TO SWITCH ON and SWITCHED ON); done when the drive shows QUICK STOP ACTIVE or
    /// SWITCH ON DISABLED.
    pub fn quick_stop(
        &mut self,
        node: u8,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        let timeout = self.step_timeout(node)?;
        let steps = vec![
            Step::Controlword(command::QUICK_STOP),
            Step::Await {
                cond: Cond::QuickStopped,
                timeout,
            },
        ];
        self.begin(node, JobKind::QuickStop, steps, now, out)
    }

    /// Fault reset (transition 15): reads the statusword; in FAULT writes controlword
    /// 0x0000 then 0x0080, so that bit 7 rises whatever was written before (0x0000 commands
    /// nothing in FAULT), and waits until the drive has left FAULT (a fault still present
    /// keeps it there: [`DriveError::Timeout`]). In FAULT REACTION ACTIVE it first waits
    /// for the reaction to end (transition 14); a drive not in fault is left alone.
    pub fn fault_reset(
        &mut self,
        node: u8,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        let steps = vec![Step::Read(STATUSWORD, 0, Then::ResetIfFaulted)];
        self.begin(node, JobKind::FaultReset, steps, now, out)
    }

    /// Writes 0x6060 and waits until 0x6061 shows the mode (CiA 402-2, object 6061h: the
    /// display follows once the drive has switched).
    pub fn set_mode(
        &mut self,
        node: u8,
        mode: OpMode,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        let timeout = self.step_timeout(node)?;
        let steps = vec![
            Step::Write(MODES_OF_OPERATION, 0, vec![mode.code() as u8]),
            Step::Await {
                cond: Cond::ModeShown(mode),
                timeout,
            },
        ];
        self.begin(node, JobKind::SetMode(mode), steps, now, out)
    }

    /// A profile position move (CiA 402-2, pp: the set-point handshake of controlword
    /// bit 4 and statusword bit 12). Needs OPERATION ENABLED and pp.
    pub fn profile_position(
        &mut self,
        node: u8,
        mv: PositionMove,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        let (step, moving) = self.timeouts(node)?;
        let mut steps = vec![
            Step::Read(STATUSWORD, 0, Then::RequireEnabled),
            Step::Read(
                MODES_OF_OPERATION_DISPLAY,
                0,
                Then::RequireMode(OpMode::ProfilePosition),
            ),
        ];
        for (index, value) in [
            (PROFILE_VELOCITY, mv.profile_velocity),
            (PROFILE_ACCELERATION, mv.acceleration),
            (PROFILE_DECELERATION, mv.deceleration),
        ] {
            if let Some(v) = value {
                steps.push(Step::Write(index, 0, v.to_le_bytes().to_vec()));
            }
        }
        let mut flags = command::ENABLE_OPERATION;
        if mv.relative {
            flags |= CW_RELATIVE;
        }
        if mv.immediately {
            flags |= CW_CHANGE_SET_IMMEDIATELY;
        }
        steps.extend([
            Step::Write(TARGET_POSITION, 0, mv.target.to_le_bytes().to_vec()),
            // Bit 4 low first: the drive takes the set-point on its rising edge.
            Step::Controlword(flags),
            Step::Controlword(flags | CW_BIT4),
            Step::Await {
                cond: Cond::SetPointAck(true),
                timeout: step,
            },
            Step::Controlword(flags),
        ]);
        if mv.wait {
            steps.push(Step::Await {
                cond: Cond::PositionReached,
                timeout: moving,
            });
        }
        steps.push(Step::Read(POSITION_ACTUAL_VALUE, 0, Then::Optional));
        self.begin(node, JobKind::ProfilePosition, steps, now, out)
    }

    /// A profile velocity command (CiA 402-2, pv): 0x60FF and enable operation without
    /// halt. Needs OPERATION ENABLED and pv.
    pub fn profile_velocity(
        &mut self,
        node: u8,
        mv: VelocityMove,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        let (_, moving) = self.timeouts(node)?;
        let mut steps = vec![
            Step::Read(STATUSWORD, 0, Then::RequireEnabled),
            Step::Read(
                MODES_OF_OPERATION_DISPLAY,
                0,
                Then::RequireMode(OpMode::ProfileVelocity),
            ),
        ];
        for (index, value) in [
            (PROFILE_ACCELERATION, mv.acceleration),
            (PROFILE_DECELERATION, mv.deceleration),
        ] {
            if let Some(v) = value {
                steps.push(Step::Write(index, 0, v.to_le_bytes().to_vec()));
            }
        }
        steps.push(Step::Write(
            TARGET_VELOCITY,
            0,
            mv.target.to_le_bytes().to_vec(),
        ));
        steps.push(Step::Controlword(command::ENABLE_OPERATION));
        if mv.wait {
            steps.push(Step::Await {
                cond: Cond::VelocityReached {
                    since: Instant::ZERO,
                    seen_clear: false,
                },
                timeout: moving,
            });
        }
        steps.push(Step::Read(VELOCITY_ACTUAL_VALUE, 0, Then::Optional));
        self.begin(node, JobKind::ProfileVelocity, steps, now, out)
    }

    /// Homing (CiA 402-2, hm): switches to hm if 0x6061 shows another mode, writes the
    /// method and the optional speeds and acceleration, starts with the rising edge of
    /// controlword bit 4 and waits for homing attained. Needs OPERATION ENABLED.
    pub fn home(
        &mut self,
        node: u8,
        homing: Homing,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        let (_, moving) = self.timeouts(node)?;
        let mut steps = vec![
            Step::Read(STATUSWORD, 0, Then::RequireEnabled),
            Step::Read(
                MODES_OF_OPERATION_DISPLAY,
                0,
                Then::EnsureMode(OpMode::Homing),
            ),
            Step::Write(HOMING_METHOD, 0, vec![homing.method as u8]),
        ];
        for (index, sub, value) in [
            (HOMING_SPEEDS, 1, homing.switch_speed),
            (HOMING_SPEEDS, 2, homing.zero_speed),
            (HOMING_ACCELERATION, 0, homing.acceleration),
        ] {
            if let Some(v) = value {
                steps.push(Step::Write(index, sub, v.to_le_bytes().to_vec()));
            }
        }
        steps.extend([
            Step::Controlword(command::ENABLE_OPERATION),
            Step::Read(STATUSWORD, 0, Then::ArmHoming),
            Step::Controlword(command::ENABLE_OPERATION | CW_BIT4),
            Step::Await {
                cond: Cond::Homed {
                    armed: false,
                    since: Instant::ZERO,
                },
                timeout: moving,
            },
            Step::Controlword(command::ENABLE_OPERATION),
            Step::Read(POSITION_ACTUAL_VALUE, 0, Then::Optional),
        ]);
        self.begin(node, JobKind::Home, steps, now, out)
    }

    /// Starts cyclic set-points for `node` (csp or csv, which 0x6061 must show): csp holds
    /// the position 0x6064 reads, csv holds 0; from the next SYNC the master sends, the
    /// set-point goes out in the RPDO after every SYNC. Change it with
    /// [`Self::move_cyclic`]; stop with [`Self::stop_stream`].
    pub fn start_stream(
        &mut self,
        node: u8,
        config: StreamConfig,
        now: Instant,
        out: &mut Outbox,
    ) -> Result<(), DriveError> {
        let mut steps = vec![Step::Read(
            MODES_OF_OPERATION_DISPLAY,
            0,
            Then::RequireMode(config.mode.mode()),
        )];
        if config.mode == CyclicMode::Position {
            steps.push(Step::Read(POSITION_ACTUAL_VALUE, 0, Then::StreamFrom));
        }
        steps.push(Step::StartStream(config));
        self.begin(node, JobKind::Stream, steps, now, out)
    }

    /// Stops `node`'s stream (no more set-points: a drive in csp or csv reacts as CiA 402
    /// and its manufacturer say for a missing set-point).
    pub fn stop_stream(&mut self, node: u8) {
        if let Some(a) = self.axes.get_mut(&node) {
            a.stream = None;
        }
    }

    /// Gives every listed axis a new target reached in `cycles` SYNC periods, starting at
    /// the next SYNC for all of them (a coordinated move). Each axis must stream.
    /// [`DriveEvent::TrajectoryDone`] reports each end.
    pub fn move_cyclic(&mut self, targets: &[(u8, i32)], cycles: u32) -> Result<(), DriveError> {
        for (node, _) in targets {
            if self.axes.get(node).and_then(|a| a.stream).is_none() {
                return Err(DriveError::NoAxis(*node));
            }
        }
        for (node, to) in targets {
            if let Some(s) = self.axes.get_mut(node).and_then(|a| a.stream.as_mut()) {
                s.trajectory = Trajectory {
                    from: s.last,
                    to: *to,
                    cycles,
                };
                s.cycle = 0;
                s.done_reported = false;
            }
        }
        Ok(())
    }

    /// Reads 0x6041, 0x6061, 0x603F, 0x6064 and 0x606C (the last four optional: a drive
    /// without them leaves them unknown).
    pub fn inspect(&mut self, node: u8, now: Instant, out: &mut Outbox) -> Result<(), DriveError> {
        let steps = vec![
            Step::Read(STATUSWORD, 0, Then::Keep),
            Step::Read(MODES_OF_OPERATION_DISPLAY, 0, Then::Optional),
            Step::Read(ERROR_CODE, 0, Then::Optional),
            Step::Read(POSITION_ACTUAL_VALUE, 0, Then::Optional),
            Step::Read(VELOCITY_ACTUAL_VALUE, 0, Then::Optional),
        ];
        self.begin(node, JobKind::Inspect, steps, now, out)
    }

    fn step_timeout(&self, node: u8) -> Result<Duration, DriveError> {
        Ok(self.timeouts(node)?.0)
    }

    fn timeouts(&self, node: u8) -> Result<(Duration, Duration), DriveError> {
        let a = self.axes.get(&node).ok_or(DriveError::NoAxis(node))?;
        Ok((a.config.step_timeout, a.config.move_timeout))
    }

    // ---- the job interpreter ----

    fn finish(&mut self, node: u8, result: Result<(), DriveError>, now: Instant) {
        let Some(axis) = self.axes.get_mut(&node) else {
            return;
        };
        let Some(job) = axis.job.take() else {
            return;
        };
        let result = result.map(|()| job.snapshot);
        self.events.push_back((
            now,
            DriveEvent::Finished {
                node,
                job: job.kind,
                result,
            },
        ));
    }

    /// Fails the job; a fault first reads 0x603F.
    fn fail(&mut self, node: u8, error: DriveError, now: Instant, out: &mut Outbox) {
        let Some(job) = self.axes.get_mut(&node).and_then(|a| a.job.as_mut()) else {
            return;
        };
        if matches!(error, DriveError::Fault { .. }) && job.failing.is_none() {
            job.failing = Some(error);
            job.steps.clear();
            job.steps.push_back(Step::ReadErrorCode);
            job.deadline = None;
            job.wake = None;
            self.advance(node, now, out);
            return;
        }
        self.finish(node, Err(error), now);
    }

    fn sdo(
        &mut self,
        node: u8,
        index: u16,
        sub: u8,
        data: Option<Vec<u8>>,
        now: Instant,
        out: &mut Outbox,
    ) {
        let mux = Mux::new(index, sub);
        let r = match data {
            None => self.master.upload(node, mux, Mode::Auto, now, out),
            Some(d) => self.master.download(node, mux, d, Mode::Auto, now, out),
        };
        match r {
            Ok(id) => {
                self.mine.insert(id, node);
                if let Some(job) = self.axes.get_mut(&node).and_then(|a| a.job.as_mut()) {
                    job.transfer = Some(id);
                }
            }
            Err(e) => self.fail(node, e.into(), now, out),
        }
    }

    /// Runs `node`'s job until it waits for a transfer, a poll or a statusword.
    fn advance(&mut self, node: u8, now: Instant, out: &mut Outbox) {
        loop {
            let Some(axis) = self.axes.get_mut(&node) else {
                return;
            };
            let pdo = axis.config.statusword_pdo.is_some();
            let pdo_sw = axis.pdo_statusword;
            let Some(job) = axis.job.as_mut() else {
                return;
            };
            if job.transfer.is_some() || job.wake.is_some_and(|w| now < w) {
                return;
            }
            job.wake = None;
            let Some(step) = job.steps.front_mut() else {
                let failing = job.failing;
                match failing {
                    Some(e) => self.finish(node, Err(e), now),
                    None => self.finish(node, Ok(()), now),
                }
                return;
            };
            match step {
                Step::Write(index, sub, data) => {
                    let (index, sub, data) = (*index, *sub, data.clone());
                    self.sdo(node, index, sub, Some(data), now, out);
                    return;
                }
                Step::Controlword(cw) => {
                    let cw = *cw;
                    axis.controlword = cw;
                    self.sdo(
                        node,
                        CONTROLWORD,
                        0,
                        Some(cw.to_le_bytes().to_vec()),
                        now,
                        out,
                    );
                    return;
                }
                Step::Read(index, sub, _) => {
                    let (index, sub) = (*index, *sub);
                    self.sdo(node, index, sub, None, now, out);
                    return;
                }
                Step::ReadErrorCode => {
                    self.sdo(node, ERROR_CODE, 0, None, now, out);
                    return;
                }
                Step::Walk(_) => {
                    self.sdo(node, STATUSWORD, 0, None, now, out);
                    return;
                }
                Step::StartStream(config) => {
                    let config = *config;
                    let from = job.stream_from.unwrap_or(0);
                    job.steps.pop_front();
                    axis.stream = Some(Stream {
                        config,
                        trajectory: Trajectory::hold(from),
                        cycle: 0,
                        last: from,
                        done_reported: true,
                    });
                    continue;
                }
                Step::Await { cond, timeout } => {
                    if job.deadline.is_none() {
                        job.deadline = Some(now.checked_add(*timeout).unwrap_or(Instant::MAX));
                        if let Cond::VelocityReached { since, .. } = cond {
                            *since = now;
                        }
                        if let Cond::Homed { armed, since } = cond {
                            *armed = job.homing_armed;
                            *since = now;
                        }
                    }
                    if pdo && cond.reads() == STATUSWORD {
                        // The TPDO may have come before the write's confirmation: the
                        // last one counts (every condition here is one the statusword
                        // before the write does not meet, or is armed against it).
                        if let Some(sw) = pdo_sw {
                            self.judge(node, sw, now, out);
                            if self.waiting_on_pdo(node) {
                                return;
                            }
                            continue;
                        }
                        return;
                    }
                    let index = cond.reads();
                    self.sdo(node, index, 0, None, now, out);
                    return;
                }
            }
        }
    }

    /// Whether `node`'s job waits for a statusword from its TPDO.
    fn waiting_on_pdo(&self, node: u8) -> bool {
        let Some(a) = self.axes.get(&node) else {
            return false;
        };
        a.config.statusword_pdo.is_some()
            && a.job.as_ref().is_some_and(|j| {
                j.transfer.is_none()
                    && j.deadline.is_some()
                    && matches!(j.steps.front(), Some(Step::Await { cond, .. }) if cond.reads() == STATUSWORD)
            })
    }

    /// A statusword (or 0x6061 value) for the job's wait.
    fn judge(&mut self, node: u8, value: u16, now: Instant, out: &mut Outbox) {
        let Some(axis) = self.axes.get_mut(&node) else {
            return;
        };
        let poll = axis.config.poll_interval;
        let pdo = axis.config.statusword_pdo.is_some();
        let Some(job) = axis.job.as_mut() else {
            return;
        };
        let Some(Step::Await { cond, .. }) = job.steps.front_mut() else {
            return;
        };
        let by_pdo = pdo && cond.reads() == STATUSWORD;
        if cond.reads() == STATUSWORD {
            job.snapshot.statusword = Some(value);
        } else {
            job.snapshot.mode = Some(value as u8 as i8);
        }
        let what = cond.what();
        match cond.check(value, now, poll) {
            Verdict::Met => {
                job.steps.pop_front();
                job.deadline = None;
            }
            Verdict::NotYet => {
                if job.deadline.is_some_and(|d| now >= d) {
                    let statusword = job.snapshot.statusword;
                    self.fail(
                        node,
                        DriveError::Timeout {
                            waiting_for: what,
                            statusword,
                        },
                        now,
                        out,
                    );
                } else if !by_pdo {
                    job.wake = Some(now.checked_add(poll).unwrap_or(Instant::MAX));
                }
            }
            Verdict::Fail(e) => self.fail(node, e, now, out),
        }
    }

    /// The end of one of the jobs' transfers.
    fn on_transfer(
        &mut self,
        node: u8,
        id: TransferId,
        event: SdoEvent,
        now: Instant,
        out: &mut Outbox,
    ) {
        let Some(axis) = self.axes.get_mut(&node) else {
            return;
        };
        let step_timeout = axis.config.step_timeout;
        let Some(job) = axis.job.as_mut() else {
            return;
        };
        if job.transfer != Some(id) {
            // A poll that outlived its job's wait.
            return;
        }
        job.transfer = None;
        let (mux, result) = match event {
            SdoEvent::Completed { mux, data } => (mux, Ok(data)),
            SdoEvent::Aborted { mux, code, .. } => (mux, Err(code)),
            SdoEvent::Progress { .. } | SdoEvent::FellBack { .. } => return,
        };
        let Some(step) = job.steps.front().cloned() else {
            return;
        };
        let aborted = |code| DriveError::Sdo {
            index: mux.index,
            sub: mux.sub,
            code,
        };
        let malformed = DriveError::Malformed {
            index: mux.index,
            sub: mux.sub,
        };
        match step {
            Step::Write(..) | Step::Controlword(_) => match result {
                Ok(_) => {
                    job.steps.pop_front();
                }
                Err(code) => return self.fail(node, aborted(code), now, out),
            },
            Step::ReadErrorCode => {
                job.snapshot.error_code = result.ok().and_then(|d| le_u16(&d));
                job.steps.pop_front();
                if let Some(DriveError::Fault { error_code }) = job.failing.as_mut() {
                    *error_code = job.snapshot.error_code;
                }
            }
            Step::Read(index, _, then) => {
                let data = match (result, then) {
                    (Ok(d), _) => d,
                    (Err(_), Then::Optional) => {
                        job.steps.pop_front();
                        return self.advance(node, now, out);
                    }
                    (Err(code), _) => return self.fail(node, aborted(code), now, out),
                };
                job.steps.pop_front();
                if let Err(e) = Self::take_read(job, index, then, &data, step_timeout) {
                    return self.fail(node, e, now, out);
                }
            }
            Step::Walk(target) => {
                let sw = match result {
                    Ok(d) => match le_u16(&d) {
                        Some(sw) => sw,
                        None => return self.fail(node, malformed, now, out),
                    },
                    Err(code) => return self.fail(node, aborted(code), now, out),
                };
                job.snapshot.statusword = Some(sw);
                let Some(state) = DriveState::from_statusword(sw) else {
                    return self.fail(node, DriveError::NoProgress { statusword: sw }, now, out);
                };
                let timeout = step_timeout;
                match toward(state, target) {
                    Toward::Arrived => {
                        job.steps.pop_front();
                    }
                    Toward::Faulted => {
                        return self.fail(node, DriveError::Fault { error_code: None }, now, out);
                    }
                    Toward::Send(_) | Toward::Wait if job.walked >= MAX_WALK => {
                        return self.fail(
                            node,
                            DriveError::NoProgress { statusword: sw },
                            now,
                            out,
                        );
                    }
                    Toward::Send(cw) => {
                        job.walked += 1;
                        job.steps.push_front(Step::Await {
                            cond: Cond::Left(state),
                            timeout,
                        });
                        job.steps.push_front(Step::Controlword(cw));
                    }
                    Toward::Wait => {
                        job.walked += 1;
                        job.steps.push_front(Step::Await {
                            cond: Cond::Left(state),
                            timeout,
                        });
                    }
                }
            }
            Step::Await { cond, .. } => {
                let width = if cond.reads() == STATUSWORD { 2 } else { 1 };
                let value = match result {
                    Ok(d) if d.len() == width => {
                        if width == 2 {
                            le_u16(&d).unwrap_or(0)
                        } else {
                            u16::from(d[0])
                        }
                    }
                    Ok(_) => return self.fail(node, malformed, now, out),
                    Err(code) => return self.fail(node, aborted(code), now, out),
                };
                self.judge(node, value, now, out);
            }
            Step::StartStream(_) => {}
        }
        self.advance(node, now, out);
    }

    /// Applies a completed read to the job.
    fn take_read(
        job: &mut Job,
        index: u16,
        then: Then,
        data: &[u8],
        step_timeout: Duration,
    ) -> Result<(), DriveError> {
        let malformed = DriveError::Malformed { index, sub: 0 };
        match index {
            STATUSWORD => job.snapshot.statusword = Some(le_u16(data).ok_or(malformed)?),
            MODES_OF_OPERATION_DISPLAY => job.snapshot.mode = Some(le_i8(data).ok_or(malformed)?),
            ERROR_CODE => job.snapshot.error_code = Some(le_u16(data).ok_or(malformed)?),
            POSITION_ACTUAL_VALUE => job.snapshot.position = Some(le_i32(data).ok_or(malformed)?),
            VELOCITY_ACTUAL_VALUE => job.snapshot.velocity = Some(le_i32(data).ok_or(malformed)?),
            _ => {}
        }
        match then {
            Then::Keep | Then::Optional => Ok(()),
            Then::RequireEnabled => {
                let sw = job.snapshot.statusword.unwrap_or(0);
                match DriveState::from_statusword(sw) {
                    Some(DriveState::OperationEnabled) => Ok(()),
                    Some(s) if s.is_fault() => Err(DriveError::Fault { error_code: None }),
                    _ => Err(DriveError::NotEnabled { statusword: sw }),
                }
            }
            Then::RequireMode(wanted) => {
                let shown = job.snapshot.mode.unwrap_or(0);
                if shown == wanted.code() {
                    Ok(())
                } else {
                    Err(DriveError::WrongMode { wanted, shown })
                }
            }
            Then::EnsureMode(wanted) => {
                if job.snapshot.mode != Some(wanted.code()) {
                    job.steps.push_front(Step::Await {
                        cond: Cond::ModeShown(wanted),
                        timeout: step_timeout,
                    });
                    job.steps.push_front(Step::Write(
                        MODES_OF_OPERATION,
                        0,
                        vec![wanted.code() as u8],
                    ));
                }
                Ok(())
            }
            Then::ArmHoming => {
                job.homing_armed = job.snapshot.statusword.is_some_and(|sw| sw & SW_BIT12 == 0);
                Ok(())
            }
            Then::StreamFrom => {
                job.stream_from = job.snapshot.position;
                Ok(())
            }
            Then::ResetIfFaulted => {
                let sw = job.snapshot.statusword.unwrap_or(0);
                match DriveState::from_statusword(sw) {
                    Some(DriveState::FaultReactionActive) => {
                        job.steps
                            .push_front(Step::Read(STATUSWORD, 0, Then::ResetIfFaulted));
                        job.steps.push_front(Step::Await {
                            cond: Cond::ReactionDone,
                            timeout: step_timeout,
                        });
                    }
                    Some(DriveState::Fault) => {
                        job.steps.push_front(Step::Await {
                            cond: Cond::FaultCleared,
                            timeout: step_timeout,
                        });
                        job.steps
                            .push_front(Step::Controlword(command::FAULT_RESET));
                        job.steps
                            .push_front(Step::Controlword(command::DISABLE_VOLTAGE));
                    }
                    _ => {}
                }
                Ok(())
            }
        }
    }

    /// Hands the master's frames on; after each SYNC, every stream's RPDO.
    fn relay(&mut self, mut local: Outbox, now: Instant, out: &mut Outbox) {
        let frames: Vec<Frame> = local.drain().collect();
        for f in frames {
            out.push(f);
            if is_sync(&f) {
                self.on_sync(now, out);
            }
        }
        self.collect(now, out);
    }

    fn on_sync(&mut self, now: Instant, out: &mut Outbox) {
        for (&node, axis) in self.axes.iter_mut() {
            let Some(s) = axis.stream.as_mut() else {
                continue;
            };
            s.cycle = s.cycle.saturating_add(1);
            let value = s.trajectory.at(s.cycle);
            s.last = value;
            let mut data = [0u8; 6];
            let len = if s.config.with_controlword {
                data[..2].copy_from_slice(&axis.controlword.to_le_bytes());
                data[2..6].copy_from_slice(&value.to_le_bytes());
                6
            } else {
                data[..4].copy_from_slice(&value.to_le_bytes());
                4
            };
            if let Ok(f) = Frame::std(s.config.rpdo, &data[..len]) {
                out.push(f);
            }
            if !s.done_reported && s.cycle >= s.trajectory.cycles {
                s.done_reported = true;
                self.events.push_back((
                    now,
                    DriveEvent::TrajectoryDone {
                        node,
                        set_point: value,
                    },
                ));
            }
        }
    }

    /// Routes the master's events: the jobs' transfers to the jobs, the rest out.
    fn collect(&mut self, now: Instant, out: &mut Outbox) {
        while let Some((at, event)) = self.master.poll_event() {
            match event {
                MasterEvent::Sdo { id, event, .. } if self.mine.contains_key(&id) => {
                    let terminal =
                        matches!(event, SdoEvent::Completed { .. } | SdoEvent::Aborted { .. });
                    let node = if terminal {
                        self.mine.remove(&id)
                    } else {
                        self.mine.get(&id).copied()
                    };
                    if let Some(node) = node {
                        let mut local = Outbox::new();
                        self.on_transfer(node, id, event, now, &mut local);
                        self.relay_plain(local, now, out);
                    }
                }
                other => self.events.push_back((at, DriveEvent::Master(other))),
            }
        }
    }

    /// Like [`Self::relay`] for frames the jobs queued (SDO requests, never SYNC).
    fn relay_plain(&mut self, mut local: Outbox, now: Instant, out: &mut Outbox) {
        let frames: Vec<Frame> = local.drain().collect();
        for f in frames {
            out.push(f);
            if is_sync(&f) {
                self.on_sync(now, out);
            }
        }
    }

    fn is_stream_frame(&self, frame: &Frame) -> bool {
        let raw = frame.id().as_raw();
        matches!(frame.id(), Id::Standard(_))
            && self
                .axes
                .values()
                .any(|a| a.stream.is_some_and(|s| u32::from(s.config.rpdo) == raw))
    }
}

impl Node for DriveMaster {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        let mut local = Outbox::new();
        self.master.on_power_up(now, &mut local);
        self.relay(local, now, out);
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        if let Id::Standard(sid) = frame.id()
            && !frame.is_remote()
        {
            let raw = sid.as_raw();
            let hit: Vec<u8> = self
                .axes
                .iter()
                .filter(|(_, a)| a.config.statusword_pdo == Some(raw))
                .map(|(n, _)| *n)
                .collect();
            if let Some(sw) = le_u16(frame.data_bytes().get(..2).unwrap_or(&[])) {
                for node in hit {
                    let mut local = Outbox::new();
                    if let Some(a) = self.axes.get_mut(&node) {
                        a.pdo_statusword = Some(sw);
                    }
                    if self.waiting_on_pdo(node) {
                        self.judge(node, sw, now, &mut local);
                        self.advance(node, now, &mut local);
                    }
                    self.relay_plain(local, now, out);
                }
            }
        }
        let mut local = Outbox::new();
        self.master.on_frame(frame, now, &mut local);
        self.relay(local, now, out);
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        let mut local = Outbox::new();
        self.master.on_tick(now, &mut local);
        self.relay(local, now, out);
        let nodes: Vec<u8> = self.axes.keys().copied().collect();
        for node in nodes {
            let mut local = Outbox::new();
            let Some(job) = self.axes.get_mut(&node).and_then(|a| a.job.as_mut()) else {
                continue;
            };
            // A wait whose deadline passed with no answer (a silent drive, or a TPDO that
            // never came).
            if job.deadline.is_some_and(|d| now >= d) && job.transfer.is_none() {
                let waiting_for = match job.steps.front() {
                    Some(Step::Await { cond, .. }) => cond.what(),
                    _ => "the drive",
                };
                let statusword = job.snapshot.statusword;
                self.fail(
                    node,
                    DriveError::Timeout {
                        waiting_for,
                        statusword,
                    },
                    now,
                    &mut local,
                );
            } else if job.wake.is_some_and(|w| now >= w) {
                self.advance(node, now, &mut local);
            }
            self.relay_plain(local, now, out);
        }
        self.collect(now, out);
    }

    fn next_deadline(&self) -> Option<Instant> {
        let mut next = self.master.next_deadline();
        for a in self.axes.values() {
            if let Some(job) = &a.job {
                for t in [job.wake, job.deadline.filter(|_| job.transfer.is_none())]
                    .into_iter()
                    .flatten()
                {
                    next = Some(next.map_or(t, |n| n.min(t)));
                }
            }
        }
        next
    }

    fn on_sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        // The master counts its own frames in its transmit window; the streams' RPDOs are
        // not its.
        if self.is_stream_frame(frame) {
            return;
        }
        let mut local = Outbox::new();
        self.master.on_sent(frame, now, &mut local);
        self.relay(local, now, out);
    }

    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        let mut local = Outbox::new();
        self.master.on_controller_event(event, now, &mut local);
        self.relay(local, now, out);
    }
}
