//! The master against a small CiA 402 drive model in virtual time: an SDO server over
//! the profile's objects and a 1 ms control cycle that follows the PDS FSA, switches
//! modes, runs pp, pv and hm and applies synchronous RPDO set-points at SYNC.
use super::*;
use crate::od::{Access, DataType, ObjectDictionary, OdBuilder, SubObject, Value};
use crate::sdo::SdoServer;
use std::sync::Arc;

const NODE: u8 = 3;
const CYCLE: Duration = Duration::from_millis(1);

fn description() -> crate::od::OdDescription {
    use DataType as T;
    let v = |b: OdBuilder, index, name: &str, ty, access| {
        b.var(index, SubObject::new(name, ty, access))
    };
    let mut b = OdBuilder::new();
    b = v(b, ERROR_CODE, "Error code", T::Unsigned16, Access::Ro);
    b = v(b, CONTROLWORD, "Controlword", T::Unsigned16, Access::Rw);
    b = v(b, STATUSWORD, "Statusword", T::Unsigned16, Access::Ro);
    b = v(
        b,
        MODES_OF_OPERATION,
        "Modes of operation",
        T::Integer8,
        Access::Rw,
    );
    b = v(
        b,
        MODES_OF_OPERATION_DISPLAY,
        "Modes of operation display",
        T::Integer8,
        Access::Ro,
    );
    b = v(
        b,
        POSITION_ACTUAL_VALUE,
        "Position actual value",
        T::Integer32,
        Access::Ro,
    );
    b = v(
        b,
        VELOCITY_ACTUAL_VALUE,
        "Velocity actual value",
        T::Integer32,
        Access::Ro,
    );
    b = v(
        b,
        TARGET_POSITION,
        "Target position",
        T::Integer32,
        Access::Rw,
    );
    b = v(
        b,
        PROFILE_VELOCITY,
        "Profile velocity",
        T::Unsigned32,
        Access::Rw,
    );
    b = v(b, HOMING_METHOD, "Homing method", T::Integer8, Access::Rw);
    b = v(
        b,
        TARGET_VELOCITY,
        "Target velocity",
        T::Integer32,
        Access::Rw,
    );
    b.build().expect("valid")
}

/// The drive model. Quick stop behaves as 0x605A = 2 (stop, then SWITCH ON DISABLED
/// after 3 cycles); pp moves 100 units a cycle at most; pv steps 10 units a cycle;
/// homing takes 5 cycles and sets the position to 0, method −1 fails; 0x6061 follows
/// 0x6060 after 2 cycles.
struct Drive {
    od: ObjectDictionary,
    server: SdoServer,
    state: DriveState,
    next: Instant,
    last_cw: u16,
    mode_delay: u8,
    quick_stop_left: u8,
    fault: bool,
    position: i32,
    velocity: i32,
    target: i32,
    ack: bool,
    homing_left: Option<u8>,
    homed: bool,
    homing_error: bool,
    buffered: Option<i32>,
    tpdo: bool,
    sent_sw: Option<u16>,
    /// Frames the drive ignores (a drive that stopped answering).
    silent: bool,
}

impl Drive {
    fn new() -> Self {
        Drive {
            od: ObjectDictionary::new(Arc::new(description()), NODE),
            server: SdoServer::for_node(NODE),
            state: DriveState::NotReadyToSwitchOn,
            next: Instant::ZERO,
            last_cw: 0,
            mode_delay: 0,
            quick_stop_left: 0,
            fault: false,
            position: 1234,
            velocity: 0,
            target: 0,
            ack: false,
            homing_left: None,
            homed: false,
            homing_error: false,
            buffered: None,
            tpdo: false,
            sent_sw: None,
            silent: false,
        }
    }

    fn u(&self, index: u16) -> u64 {
        self.od.get_unsigned(index, 0).unwrap_or(0)
    }

    fn i(&self, index: u16) -> i64 {
        match self.od.get(index, 0) {
            Ok(Value::Integer8(v)) => i64::from(v),
            Ok(Value::Integer32(v)) => i64::from(v),
            _ => 0,
        }
    }

    fn mode(&self) -> i8 {
        self.i(MODES_OF_OPERATION_DISPLAY) as i8
    }

    fn statusword(&self) -> u16 {
        let mut sw = self.state.pattern().1;
        if self.state != DriveState::NotReadyToSwitchOn
            && self.state != DriveState::SwitchOnDisabled
        {
            sw |= 1 << 4;
        }
        let enabled = self.state == DriveState::OperationEnabled;
        match OpMode::from_code(self.mode()) {
            Some(OpMode::ProfilePosition) => {
                if self.position == self.target {
                    sw |= SW_TARGET_REACHED;
                }
                if self.ack {
                    sw |= SW_BIT12;
                }
            }
            Some(OpMode::ProfileVelocity) if self.velocity == self.i(TARGET_VELOCITY) as i32 => {
                sw |= SW_TARGET_REACHED;
            }
            Some(OpMode::Homing) => {
                if self.homed && self.homing_left.is_none() {
                    sw |= SW_TARGET_REACHED | SW_BIT12;
                }
                if self.homing_error {
                    sw |= SW_BIT13;
                }
            }
            Some(OpMode::CyclicSyncPosition) if enabled => sw |= SW_BIT12,
            _ => {}
        }
        sw
    }

    /// One control cycle: the PDS FSA (CiA 402-2), then the mode's motion.
    fn cycle(&mut self) {
        use DriveState as S;
        let cw = self.u(CONTROLWORD) as u16;
        let rising = |bit: u16| cw & bit != 0 && self.last_cw & bit == 0;
        let cmd = cw & 0x8F;
        self.state = match self.state {
            _ if self.fault && !self.state.is_fault() => S::FaultReactionActive,
            S::FaultReactionActive => S::Fault,
            S::Fault if rising(0x80) && !self.fault => S::SwitchOnDisabled,
            S::Fault => S::Fault,
            S::NotReadyToSwitchOn => S::SwitchOnDisabled,
            S::SwitchOnDisabled if cmd & 0x87 == 0x06 => S::ReadyToSwitchOn,
            S::ReadyToSwitchOn if cmd & 0x8F == 0x07 => S::SwitchedOn,
            S::ReadyToSwitchOn if cmd & 0x82 == 0 || cmd & 0x86 == 0x02 => S::SwitchOnDisabled,
            S::SwitchedOn if cmd & 0x8F == 0x0F => S::OperationEnabled,
            S::SwitchedOn if cmd & 0x87 == 0x06 => S::ReadyToSwitchOn,
            S::SwitchedOn if cmd & 0x82 == 0 || cmd & 0x86 == 0x02 => S::SwitchOnDisabled,
            S::OperationEnabled if cmd & 0x8F == 0x07 => S::SwitchedOn,
            S::OperationEnabled if cmd & 0x87 == 0x06 => S::ReadyToSwitchOn,
            S::OperationEnabled if cmd & 0x82 == 0 => S::SwitchOnDisabled,
            S::OperationEnabled if cmd & 0x86 == 0x02 => {
                self.quick_stop_left = 3;
                S::QuickStopActive
            }
            S::QuickStopActive if cmd & 0x82 == 0 => S::SwitchOnDisabled,
            S::QuickStopActive => {
                self.quick_stop_left = self.quick_stop_left.saturating_sub(1);
                if self.quick_stop_left == 0 {
                    S::SwitchOnDisabled
                } else {
                    S::QuickStopActive
                }
            }
            s => s,
        };
        let wanted = self.i(MODES_OF_OPERATION) as i8;
        if wanted != self.mode() {
            self.mode_delay += 1;
            if self.mode_delay >= 2 {
                self.mode_delay = 0;
                let _ = self
                    .od
                    .set(MODES_OF_OPERATION_DISPLAY, 0, &Value::Integer8(wanted));
            }
        }
        if self.state == S::OperationEnabled {
            match OpMode::from_code(self.mode()) {
                Some(OpMode::ProfilePosition) => {
                    if rising(CW_BIT4) {
                        let t = self.i(TARGET_POSITION) as i32;
                        self.target = if cw & CW_RELATIVE != 0 {
                            self.target + t
                        } else {
                            t
                        };
                        self.ack = true;
                    } else if cw & CW_BIT4 == 0 {
                        self.ack = false;
                    }
                    let d = (self.target - self.position).clamp(-100, 100);
                    self.position += d;
                }
                Some(OpMode::ProfileVelocity) => {
                    let t = self.i(TARGET_VELOCITY) as i32;
                    self.velocity += (t - self.velocity).clamp(-10, 10);
                }
                Some(OpMode::Homing) => {
                    if rising(CW_BIT4) {
                        self.homed = false;
                        self.homing_error = false;
                        if self.i(HOMING_METHOD) == -1 {
                            self.homing_error = true;
                        } else {
                            self.homing_left = Some(5);
                        }
                    }
                    if let Some(left) = self.homing_left {
                        if left == 0 {
                            self.homing_left = None;
                            self.homed = true;
                            self.position = 0;
                            self.target = 0;
                        } else {
                            self.homing_left = Some(left - 1);
                        }
                    }
                }
                _ => {}
            }
        }
        self.last_cw = cw;
        self.publish();
    }

    fn publish(&mut self) {
        let sw = self.statusword();
        let _ = self.od.set(STATUSWORD, 0, &Value::Unsigned16(sw));
        let _ = self
            .od
            .set(POSITION_ACTUAL_VALUE, 0, &Value::Integer32(self.position));
        let _ = self
            .od
            .set(VELOCITY_ACTUAL_VALUE, 0, &Value::Integer32(self.velocity));
        let _ = self.od.set(
            ERROR_CODE,
            0,
            &Value::Unsigned16(if self.fault { 0x2310 } else { 0 }),
        );
    }
}

impl Node for Drive {
    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        if self.silent {
            return;
        }
        let raw = frame.id().as_raw();
        if raw == 0x600 + u32::from(NODE) {
            self.server.on_frame(frame, now, &mut self.od, out);
        } else if raw == 0x200 + u32::from(NODE) {
            // RPDO: controlword + target position, synchronous.
            let d = frame.data_bytes();
            if d.len() >= 6 {
                let _ = self.od.set(
                    CONTROLWORD,
                    0,
                    &Value::Unsigned16(u16::from_le_bytes([d[0], d[1]])),
                );
                self.buffered = Some(i32::from_le_bytes([d[2], d[3], d[4], d[5]]));
            }
        } else if raw == u32::from(SYNC_COB_ID)
            && self.mode() == OpMode::CyclicSyncPosition.code()
            && let Some(p) = self.buffered.take()
            && self.state == DriveState::OperationEnabled
        {
            self.position = p;
        }
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        self.server.on_tick(now, &mut self.od, out);
        if now >= self.next {
            self.next = now + CYCLE;
            self.cycle();
            let sw = self.statusword();
            if self.tpdo && self.sent_sw != Some(sw) {
                self.sent_sw = Some(sw);
                out.push(Frame::std(0x180 + u16::from(NODE), &sw.to_le_bytes()).expect("valid"));
            }
        }
    }

    fn next_deadline(&self) -> Option<Instant> {
        Some(match self.server.next_deadline() {
            Some(d) => d.min(self.next),
            None => self.next,
        })
    }
}

/// The master and the drive; every frame reaches the other side 200 µs after it is
/// sent, in order.
struct Net {
    master: DriveMaster,
    drive: Drive,
    now: Instant,
    wire: VecDeque<(Instant, bool, Frame)>,
    log: Vec<(Instant, String)>,
}

const LATENCY: Duration = Duration::from_micros(200);

impl Net {
    fn new(config: AxisConfig) -> Self {
        let mut master = DriveMaster::new();
        master.add_axis(NODE, config).expect("valid node");
        Net {
            master,
            drive: Drive::new(),
            now: Instant::ZERO,
            wire: VecDeque::new(),
            log: Vec::new(),
        }
    }

    fn send(&mut self, out: &mut Outbox, from_master: bool) {
        for f in out.drain().collect::<Vec<_>>() {
            self.log.push((self.now, f.to_string()));
            self.wire.push_back((self.now + LATENCY, from_master, f));
            if from_master {
                let mut more = Outbox::new();
                self.master.on_sent(&f, self.now, &mut more);
                self.send(&mut more, true);
            }
        }
    }

    fn with<R>(&mut self, f: impl FnOnce(&mut DriveMaster, Instant, &mut Outbox) -> R) -> R {
        let mut out = Outbox::new();
        let r = f(&mut self.master, self.now, &mut out);
        self.send(&mut out, true);
        r
    }

    /// Runs until the next event, at most `limit` of virtual time.
    fn event(&mut self, limit: Duration) -> Option<(Instant, DriveEvent)> {
        let end = self.now + limit;
        loop {
            if let Some(e) = self.master.poll_event() {
                return Some(e);
            }
            let times = [
                self.wire.front().map(|w| w.0),
                self.master.next_deadline(),
                self.drive.next_deadline(),
            ];
            let t = times.into_iter().flatten().min()?;
            if t > end {
                self.now = end;
                return None;
            }
            self.now = self.now.max(t);
            let mut out = Outbox::new();
            if self.wire.front().is_some_and(|w| w.0 <= self.now) {
                let (_, from_master, f) = self.wire.pop_front().expect("present");
                if from_master {
                    self.drive.on_frame(&f, self.now, &mut out);
                    self.send(&mut out, false);
                } else {
                    self.master.on_frame(&f, self.now, &mut out);
                    self.send(&mut out, true);
                }
            } else if self.master.next_deadline().is_some_and(|d| d <= self.now) {
                self.master.on_tick(self.now, &mut out);
                self.send(&mut out, true);
            } else {
                self.drive.on_tick(self.now, &mut out);
                self.send(&mut out, false);
            }
        }
    }

    /// The end of the running job.
    fn finished(&mut self) -> Result<Snapshot, DriveError> {
        loop {
            match self.event(Duration::from_secs(120)) {
                Some((_, DriveEvent::Finished { result, .. })) => return result,
                Some(_) => {}
                None => panic!("no job ended"),
            }
        }
    }

    fn enable(&mut self) {
        self.with(|m, now, out| m.switch(NODE, PowerTarget::OperationEnabled, now, out))
            .expect("started");
        let s = self.finished().expect("enabled");
        assert_eq!(s.state(), Some(DriveState::OperationEnabled));
    }

    fn mode(&mut self, mode: OpMode) {
        self.with(|m, now, out| m.set_mode(NODE, mode, now, out))
            .expect("started");
        assert_eq!(self.finished().expect("switched").mode, Some(mode.code()));
    }

    /// The controlwords written by SDO, in order.
    fn controlwords(&self) -> Vec<u16> {
        self.log
            .iter()
            .filter_map(|(_, f)| {
                let rest = f.strip_prefix(&format!("{:03X}#2B4060", 0x600 + u16::from(NODE)))?;
                u16::from_str_radix(&rest[2..6], 16)
                    .ok()
                    .map(u16::swap_bytes)
            })
            .collect()
    }
}

#[test]
fn cia402_6041h_state_coding_decodes_every_state() {
    for s in DriveState::ALL {
        assert_eq!(DriveState::from_statusword(s.pattern().1), Some(s));
        // Bits outside the pattern do not change the state.
        assert_eq!(
            DriveState::from_statusword(s.pattern().1 | 0xFF90 & !s.pattern().0),
            Some(s)
        );
    }
    assert_eq!(DriveState::from_statusword(0x0001), None);
    assert_eq!(state_name(0x0637), "operation enabled");
}

#[test]
fn cia402_pds_fsa_paths_reach_every_target() {
    // From every state but the fault ones, following toward() through the drive's
    // transitions reaches each target within four controlwords.
    for from in DriveState::ALL {
        for to in [
            PowerTarget::SwitchOnDisabled,
            PowerTarget::ReadyToSwitchOn,
            PowerTarget::SwitchedOn,
            PowerTarget::OperationEnabled,
        ] {
            let mut d = Drive::new();
            d.state = from;
            let mut steps = 0;
            loop {
                match toward(d.state, to) {
                    Toward::Arrived => break,
                    Toward::Faulted => {
                        assert!(from.is_fault());
                        break;
                    }
                    Toward::Send(cw) => {
                        d.od.set(CONTROLWORD, 0, &Value::Unsigned16(cw))
                            .expect("exists");
                        for _ in 0..4 {
                            d.cycle();
                        }
                    }
                    Toward::Wait => d.cycle(),
                }
                steps += 1;
                assert!(steps <= 4, "{from:?} -> {to:?}");
            }
            if !from.is_fault() {
                assert_eq!(d.state, to.state(), "{from:?} -> {to:?}");
            }
        }
    }
}

#[test]
fn cia402_pds_fsa_enable_walks_transitions_2_3_4() {
    let mut n = Net::new(AxisConfig::default());
    n.enable();
    assert_eq!(n.controlwords(), [0x0006, 0x0007, 0x000F]);
    // And back down: disable voltage (transition 9) in one step.
    n.with(|m, now, out| m.switch(NODE, PowerTarget::SwitchOnDisabled, now, out))
        .expect("started");
    assert_eq!(
        n.finished().expect("done").state(),
        Some(DriveState::SwitchOnDisabled)
    );
    assert_eq!(n.controlwords()[3..], [0x0000]);
    // Disable operation (5) from OPERATION ENABLED.
    n.enable();
    n.with(|m, now, out| m.switch(NODE, PowerTarget::SwitchedOn, now, out))
        .expect("started");
    assert_eq!(
        n.finished().expect("done").state(),
        Some(DriveState::SwitchedOn)
    );
    assert_eq!(n.controlwords().last(), Some(&0x0007));
}

#[test]
fn cia402_pds_fsa_with_statusword_from_a_tpdo() {
    let mut n = Net::new(AxisConfig {
        statusword_pdo: Some(0x180 + u16::from(NODE)),
        ..AxisConfig::default()
    });
    n.drive.tpdo = true;
    n.enable();
    assert_eq!(n.controlwords(), [0x0006, 0x0007, 0x000F]);
    // Only the walk's reads of the statusword go by SDO (one per step), no polls.
    let reads = n
        .log
        .iter()
        .filter(|(_, f)| f.starts_with("603#4041600"))
        .count();
    assert_eq!(reads, 4);
}

#[test]
fn cia402_quick_stop_then_fault_reset() {
    let mut n = Net::new(AxisConfig::default());
    n.enable();
    n.with(|m, now, out| m.quick_stop(NODE, now, out))
        .expect("started");
    let s = n.finished().expect("stopped");
    assert_eq!(s.state(), Some(DriveState::QuickStopActive));
    // 0x605A = 2 here: the drive goes to SWITCH ON DISABLED by itself; enable walks
    // from there again (transitions 12, then 2, 3, 4).
    n.enable();
    assert_eq!(
        n.controlwords()[3..],
        [0x0002, 0x000F, 0x0006, 0x0007, 0x000F]
    );

    // A fault while enabling: the job fails with 0x603F.
    n.drive.fault = true;
    n.with(|m, now, out| m.switch(NODE, PowerTarget::SwitchedOn, now, out))
        .expect("started");
    assert_eq!(
        n.finished(),
        Err(DriveError::Fault {
            error_code: Some(0x2310)
        })
    );
    // Fault reset while the fault is present: the drive stays in FAULT.
    n.with(|m, now, out| m.fault_reset(NODE, now, out))
        .expect("started");
    assert!(matches!(
        n.finished(),
        Err(DriveError::Timeout { waiting_for: "the fault to clear", statusword: Some(sw) }) if sw & 0x4F == 0x08
    ));
    n.drive.fault = false;
    n.with(|m, now, out| m.fault_reset(NODE, now, out))
        .expect("started");
    assert_eq!(
        n.finished().expect("reset").state(),
        Some(DriveState::SwitchOnDisabled)
    );
    // Bit 7 rose from 0: 0x0000 before each 0x0080.
    let cws = n.controlwords();
    assert_eq!(cws[cws.len() - 4..], [0x0000, 0x0080, 0x0000, 0x0080]);
    // A fault reset of a drive without fault writes nothing.
    let before = n.controlwords().len();
    n.with(|m, now, out| m.fault_reset(NODE, now, out))
        .expect("started");
    assert!(n.finished().is_ok());
    assert_eq!(n.controlwords().len(), before);
}

#[test]
fn cia402_6061h_mode_switch_waits_for_the_display() {
    let mut n = Net::new(AxisConfig::default());
    let start = n.now;
    n.mode(OpMode::ProfilePosition);
    // The model shows the mode two cycles after the write: at least one poll more.
    assert!(n.now - start >= Duration::from_millis(2));
    let polls = n
        .log
        .iter()
        .filter(|(_, f)| f.starts_with("603#4061600"))
        .count();
    assert!(polls >= 2, "{polls}");
}

#[test]
fn cia402_pp_set_point_handshake_and_target_reached() {
    let mut n = Net::new(AxisConfig::default());
    // Not enabled: a clear refusal before anything is written.
    let mv = PositionMove {
        target: 5000,
        wait: true,
        ..PositionMove::default()
    };
    n.with(|m, now, out| m.profile_position(NODE, mv, now, out))
        .expect("started");
    assert!(matches!(n.finished(), Err(DriveError::NotEnabled { .. })));
    n.enable();
    n.with(|m, now, out| m.profile_position(NODE, mv, now, out))
        .expect("started");
    assert_eq!(
        n.finished(),
        Err(DriveError::WrongMode {
            wanted: OpMode::ProfilePosition,
            shown: 0
        })
    );
    n.mode(OpMode::ProfilePosition);
    n.with(|m, now, out| m.profile_position(NODE, mv, now, out))
        .expect("started");
    let s = n.finished().expect("moved");
    assert_eq!(s.position, Some(5000));
    assert_eq!(n.drive.position, 5000);
    // Bit 4 low, high (new set-point), low after the acknowledge.
    assert_eq!(n.controlwords()[3..], [0x000F, 0x001F, 0x000F]);
    // Relative, change immediately.
    let rel = PositionMove {
        target: -2000,
        relative: true,
        immediately: true,
        wait: true,
        ..PositionMove::default()
    };
    n.with(|m, now, out| m.profile_position(NODE, rel, now, out))
        .expect("started");
    assert_eq!(n.finished().expect("moved").position, Some(3000));
    assert_eq!(n.controlwords()[6..], [0x006F, 0x007F, 0x006F]);
}

#[test]
fn cia402_pv_target_velocity_reached() {
    let mut n = Net::new(AxisConfig::default());
    n.enable();
    n.mode(OpMode::ProfileVelocity);
    let mv = VelocityMove {
        target: 300,
        wait: true,
        ..VelocityMove::default()
    };
    n.with(|m, now, out| m.profile_velocity(NODE, mv, now, out))
        .expect("started");
    assert_eq!(n.finished().expect("reached").velocity, Some(300));
}

#[test]
fn cia402_hm_homing_attained_and_homing_error() {
    let mut n = Net::new(AxisConfig::default());
    n.enable();
    // Homing switches the mode itself.
    let h = Homing {
        method: 35,
        ..Homing::default()
    };
    n.with(|m, now, out| m.home(NODE, h, now, out))
        .expect("started");
    let s = n.finished().expect("homed");
    assert_eq!(s.position, Some(0));
    assert_eq!(n.drive.mode(), OpMode::Homing.code());
    assert_eq!(n.controlwords()[3..], [0x000F, 0x001F, 0x000F]);
    // Homing again: the previous run's "attained" does not end the new one early.
    n.drive.position = 77;
    n.with(|m, now, out| m.home(NODE, h, now, out))
        .expect("started");
    assert_eq!(n.finished().expect("homed").position, Some(0));
    let bad = Homing {
        method: -1,
        ..Homing::default()
    };
    n.with(|m, now, out| m.home(NODE, bad, now, out))
        .expect("started");
    assert!(matches!(n.finished(), Err(DriveError::HomingError { .. })));
}

#[test]
fn cia402_csp_set_points_follow_each_sync() {
    let mut n = Net::new(AxisConfig::default());
    n.enable();
    n.mode(OpMode::CyclicSyncPosition);
    let cfg = StreamConfig {
        mode: CyclicMode::Position,
        rpdo: 0x200 + u16::from(NODE),
        with_controlword: true,
    };
    n.with(|m, now, out| m.start_stream(NODE, cfg, now, out))
        .expect("started");
    let s = n.finished().expect("streaming");
    assert_eq!(s.position, Some(1234));
    n.with(|m, now, _| {
        m.master_mut()
            .set_sync(Some((Duration::from_millis(1), 0)), now)
    })
    .expect("sync");
    n.master.move_cyclic(&[(NODE, 2234)], 10).expect("streams");
    let done = loop {
        match n.event(Duration::from_secs(1)) {
            Some((t, DriveEvent::TrajectoryDone { set_point, .. })) => break (t, set_point),
            Some(_) => {}
            None => panic!("no end"),
        }
    };
    assert_eq!(done.1, 2234);
    // Each SYNC is followed by the RPDO with the next set-point of the profile.
    let after: Vec<&str> = n
        .log
        .iter()
        .map(|(_, f)| f.as_str())
        .skip_while(|f| *f != "080#")
        .take(4)
        .collect();
    let traj = Trajectory {
        from: 1234,
        to: 2234,
        cycles: 10,
    };
    let rpdo = |k| {
        let mut d = vec![0x0F, 0x00];
        d.extend(traj.at(k).to_le_bytes());
        Frame::std(0x203, &d).expect("valid").to_string()
    };
    assert_eq!(after, ["080#", rpdo(1).as_str(), "080#", rpdo(2).as_str()]);
    // The drive applied the set-point at the SYNC after the one it came with.
    n.event(Duration::from_millis(3));
    assert_eq!(n.drive.position, 2234);
    // Moves are monotonic and symmetric.
    let pts: Vec<i32> = (0..=10).map(|k| traj.at(k)).collect();
    assert!(pts.windows(2).all(|w| w[0] <= w[1]), "{pts:?}");
    assert_eq!(traj.at(5), 1734);
}

#[test]
fn cia402_a_silent_drive_times_out() {
    let mut n = Net::new(AxisConfig {
        step_timeout: Duration::from_millis(50),
        ..AxisConfig::default()
    });
    n.drive.silent = true;
    n.with(|m, now, out| m.switch(NODE, PowerTarget::OperationEnabled, now, out))
        .expect("started");
    // The SDO client's own timeout (1 s) ends the first read.
    assert!(matches!(
        n.finished(),
        Err(DriveError::Sdo { index: STATUSWORD, code, .. }) if code == AbortCode::TIMEOUT
    ));
    assert_eq!(
        n.with(|m, now, out| m.switch(99, PowerTarget::OperationEnabled, now, out)),
        Err(DriveError::NoAxis(99))
    );
}

#[test]
fn a_second_job_on_a_busy_axis_is_refused() {
    let mut n = Net::new(AxisConfig::default());
    n.with(|m, now, out| m.switch(NODE, PowerTarget::OperationEnabled, now, out))
        .expect("started");
    assert_eq!(
        n.with(|m, now, out| m.set_mode(NODE, OpMode::Homing, now, out)),
        Err(DriveError::Busy(NODE))
    );
    assert!(n.finished().is_ok());
}

mod props {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// Any traffic while jobs run on two axes (one taking its statusword from a TPDO)
        /// under a running SYNC: no panic, and every job ends within its timeouts.
        #[test]
        fn any_traffic_ends_every_job(
            frames in proptest::collection::vec(
                (0u16..0x800, proptest::collection::vec(any::<u8>(), 0..=8)),
                0..200,
            ),
        ) {
            let mut m = DriveMaster::new();
            let fast = AxisConfig {
                step_timeout: Duration::from_millis(20),
                move_timeout: Duration::from_millis(50),
                poll_interval: Duration::from_millis(1),
                statusword_pdo: None,
            };
            m.add_axis(3, fast).expect("valid");
            m.add_axis(4, AxisConfig { statusword_pdo: Some(0x184), ..fast }).expect("valid");
            let mut out = Outbox::new();
            m.switch(3, PowerTarget::OperationEnabled, Instant::ZERO, &mut out).expect("idle");
            m.home(4, Homing { method: 35, ..Homing::default() }, Instant::ZERO, &mut out)
                .expect("idle");
            m.master_mut().set_sync(Some((Duration::from_millis(1), 0)), Instant::ZERO).expect("period");
            let mut now = Instant::ZERO;
            for (id, data) in frames {
                now += Duration::from_micros(100);
                let f = Frame::std(id, &data).expect("valid");
                m.on_frame(&f, now, &mut out);
                for f in out.drain().collect::<Vec<_>>() {
                    m.on_sent(&f, now, &mut out);
                }
                if m.next_deadline().is_some_and(|d| d <= now) {
                    m.on_tick(now, &mut out);
                }
            }
            // Silence afterwards: the SDO timeouts (1 s) and the job timeouts end the jobs.
            let end = now + Duration::from_secs(10);
            while let Some(d) = m.next_deadline().filter(|d| *d <= end) {
                m.on_tick(d, &mut out);
                for f in out.drain().collect::<Vec<_>>() {
                    m.on_sent(&f, d, &mut out);
                }
                if !m.is_busy(3) && !m.is_busy(4) {
                    break;
                }
            }
            prop_assert!(!m.is_busy(3) && !m.is_busy(4));
        }
    }
}
