//! CiA 402-2 device control: the PDS FSA (power drive system finite state automaton), its
//! controlword commands and statusword coding, and vl mode driven by it. Each test is
//! named after the part of the standard it checks.
#![allow(clippy::unwrap_used)]

use cantwin_can::Duration;
use cantwin_cia402::options::{FaultReactionOption, QuickStopOption};
use cantwin_cia402::state::{TRANSITIONS, is_transition};
use cantwin_cia402::statusword::{self, StatusFlags, Statusword};
use cantwin_cia402::vl::{Ramp, VelocityMode, VlParams};
use cantwin_cia402::{
    Command, Controlword, Facts, Motion, OptionCodes, PowerStateMachine, State, StopRamp,
    StopReason,
};
use proptest::prelude::*;
use std::collections::BTreeSet;

const SHUTDOWN: u16 = 0x0006;
const SWITCH_ON: u16 = 0x0007;
const ENABLE: u16 = 0x000F;
const DISABLE_VOLTAGE: u16 = 0x0000;
const QUICK_STOP: u16 = 0x000B;
const FAULT_RESET: u16 = 0x0080;

const NONE: Facts = Facts {
    fault: false,
    fault_reaction_done: false,
    stopped: false,
};
const STOPPED: Facts = Facts {
    stopped: true,
    ..NONE
};
const FAULT: Facts = Facts {
    fault: true,
    ..NONE
};

/// A machine brought to a state by controlwords, with nothing happening on the drive.
fn at(path: &[u16]) -> PowerStateMachine {
    let mut m = PowerStateMachine::switch_on_disabled();
    for cw in path {
        m.update(*cw, NONE);
    }
    m
}

fn in_state(state: State) -> PowerStateMachine {
    let m = match state {
        State::NotReadyToSwitchOn => PowerStateMachine::new(),
        State::SwitchOnDisabled => at(&[]),
        State::ReadyToSwitchOn => at(&[SHUTDOWN]),
        State::SwitchedOn => at(&[SHUTDOWN, SWITCH_ON]),
        State::OperationEnabled => at(&[SHUTDOWN, ENABLE]),
        State::QuickStopActive => at(&[SHUTDOWN, ENABLE, QUICK_STOP]),
        State::FaultReactionActive => {
            let mut m = at(&[]);
            m.update(DISABLE_VOLTAGE, FAULT);
            m
        }
        State::Fault => {
            let mut m = in_state(State::FaultReactionActive);
            m.refresh(Facts {
                fault_reaction_done: true,
                ..FAULT
            });
            m
        }
    };
    assert_eq!(m.state(), state);
    m
}

/// Evaluates `cw` with `facts` and checks the single transition `number` to `to`.
fn check(mut m: PowerStateMachine, cw: u16, facts: Facts, number: u8, to: State) {
    let from = m.state();
    let step = m.update(cw, facts);
    assert_eq!(step.transitions, [number], "from {from} with {cw:#06x}");
    assert_eq!((step.from, step.to), (from, to));
    assert_eq!(m.state(), to);
    assert!(is_transition(number, from, to));
}

#[test]
fn cia402_pds_fsa_transition_0_start_is_not_ready_to_switch_on() {
    let m = PowerStateMachine::new();
    assert_eq!(m.state(), State::NotReadyToSwitchOn);
    assert_eq!(m.power_stage().motion, Motion::Disabled);
    assert!(!m.power_stage().voltage);
}

#[test]
fn cia402_pds_fsa_transition_1_initialised_is_switch_on_disabled() {
    check(
        PowerStateMachine::new(),
        DISABLE_VOLTAGE,
        NONE,
        1,
        State::SwitchOnDisabled,
    );
}

#[test]
fn cia402_pds_fsa_transition_2_shutdown() {
    check(
        in_state(State::SwitchOnDisabled),
        SHUTDOWN,
        NONE,
        2,
        State::ReadyToSwitchOn,
    );
}

#[test]
fn cia402_pds_fsa_transition_3_switch_on() {
    check(
        in_state(State::ReadyToSwitchOn),
        SWITCH_ON,
        NONE,
        3,
        State::SwitchedOn,
    );
}

#[test]
fn cia402_pds_fsa_transition_3_and_4_switch_on_and_enable_operation() {
    let mut m = in_state(State::ReadyToSwitchOn);
    let step = m.update(ENABLE, NONE);
    assert_eq!(step.transitions, [3, 4]);
    assert_eq!(m.state(), State::OperationEnabled);
}

#[test]
fn cia402_pds_fsa_transition_4_enable_operation() {
    check(
        in_state(State::SwitchedOn),
        ENABLE,
        NONE,
        4,
        State::OperationEnabled,
    );
    let m = in_state(State::OperationEnabled);
    assert_eq!(m.power_stage().motion, Motion::Operate);
}

#[test]
fn cia402_pds_fsa_transition_5_disable_operation() {
    check(
        in_state(State::OperationEnabled),
        SWITCH_ON,
        NONE,
        5,
        State::SwitchedOn,
    );
}

#[test]
fn cia402_pds_fsa_transition_6_shutdown() {
    check(
        in_state(State::SwitchedOn),
        SHUTDOWN,
        NONE,
        6,
        State::ReadyToSwitchOn,
    );
}

#[test]
fn cia402_pds_fsa_transition_7_disable_voltage_or_quick_stop() {
    for cw in [DISABLE_VOLTAGE, 0x0002, 0x0001, QUICK_STOP] {
        check(
            in_state(State::ReadyToSwitchOn),
            cw,
            NONE,
            7,
            State::SwitchOnDisabled,
        );
    }
}

#[test]
fn cia402_pds_fsa_transition_8_shutdown() {
    check(
        in_state(State::OperationEnabled),
        SHUTDOWN,
        NONE,
        8,
        State::ReadyToSwitchOn,
    );
}

#[test]
fn cia402_pds_fsa_transition_9_disable_voltage() {
    check(
        in_state(State::OperationEnabled),
        DISABLE_VOLTAGE,
        NONE,
        9,
        State::SwitchOnDisabled,
    );
    let mut m = in_state(State::OperationEnabled);
    m.update(DISABLE_VOLTAGE, NONE);
    // The drive function is off at once: the motor coasts.
    assert_eq!(m.power_stage().motion, Motion::Disabled);
}

#[test]
fn cia402_pds_fsa_transition_10_disable_voltage_or_quick_stop() {
    for cw in [DISABLE_VOLTAGE, QUICK_STOP] {
        check(
            in_state(State::SwitchedOn),
            cw,
            NONE,
            10,
            State::SwitchOnDisabled,
        );
    }
}

#[test]
fn cia402_pds_fsa_transition_11_quick_stop() {
    check(
        in_state(State::OperationEnabled),
        QUICK_STOP,
        NONE,
        11,
        State::QuickStopActive,
    );
    let m = in_state(State::QuickStopActive);
    assert!(m.power_stage().quick_stopping());
    assert_eq!(
        m.power_stage().motion,
        Motion::Stop {
            ramp: StopRamp::QuickStop,
            reason: StopReason::QuickStop
        }
    );
}

#[test]
fn cia402_pds_fsa_transition_12_quick_stop_complete_or_disable_voltage() {
    check(
        in_state(State::QuickStopActive),
        QUICK_STOP,
        STOPPED,
        12,
        State::SwitchOnDisabled,
    );
    check(
        in_state(State::QuickStopActive),
        DISABLE_VOLTAGE,
        NONE,
        12,
        State::SwitchOnDisabled,
    );
    // Not before the stop is complete.
    let mut m = in_state(State::QuickStopActive);
    assert_eq!(m.update(QUICK_STOP, NONE).transitions, [0u8; 0]);
    assert_eq!(m.state(), State::QuickStopActive);
}

#[test]
fn cia402_pds_fsa_transition_13_fault_from_every_state() {
    for state in State::ALL {
        if matches!(state, State::FaultReactionActive | State::Fault) {
            continue;
        }
        for cw in [DISABLE_VOLTAGE, SHUTDOWN, ENABLE, FAULT_RESET] {
            check(in_state(state), cw, FAULT, 13, State::FaultReactionActive);
        }
    }
}

#[test]
fn cia402_pds_fsa_transition_14_fault_reaction_complete() {
    check(
        in_state(State::FaultReactionActive),
        ENABLE,
        Facts {
            fault_reaction_done: true,
            ..FAULT
        },
        14,
        State::Fault,
    );
    assert_eq!(
        in_state(State::Fault).power_stage().motion,
        Motion::Disabled
    );
}

#[test]
fn cia402_pds_fsa_transition_15_fault_reset() {
    let mut m = in_state(State::Fault);
    m.update(DISABLE_VOLTAGE, NONE);
    check(m, FAULT_RESET, NONE, 15, State::SwitchOnDisabled);
}

#[test]
fn cia402_pds_fsa_transition_16_enable_operation_with_quick_stop_option_5_to_8() {
    for code in 5..=8 {
        let options = OptionCodes {
            quick_stop: QuickStopOption::from_code(code).unwrap(),
            ..OptionCodes::STANDARD
        };
        let mut m = in_state(State::OperationEnabled).with_options(options);
        m.update(QUICK_STOP, NONE);
        // 5–8: the drive stays in QUICK STOP ACTIVE after the stop, enabled.
        assert_eq!(m.refresh(STOPPED).transitions, [0u8; 0]);
        assert!(m.power_stage().enabled());
        check(m, ENABLE, STOPPED, 16, State::OperationEnabled);
    }
    // 0–4: enable operation does not leave QUICK STOP ACTIVE.
    let mut m = in_state(State::QuickStopActive);
    assert_eq!(m.update(ENABLE, NONE).transitions, [0u8; 0]);
    assert_eq!(m.state(), State::QuickStopActive);
}

#[test]
fn cia402_pds_fsa_commands_that_do_not_apply_leave_the_state() {
    // (state, controlwords that take no transition there)
    let table: &[(State, &[u16])] = &[
        (
            State::SwitchOnDisabled,
            &[SWITCH_ON, ENABLE, DISABLE_VOLTAGE, QUICK_STOP],
        ),
        (State::ReadyToSwitchOn, &[SHUTDOWN]),
        (State::SwitchedOn, &[SWITCH_ON]),
        (State::OperationEnabled, &[ENABLE, 0x010F]),
        (
            State::Fault,
            &[SHUTDOWN, SWITCH_ON, ENABLE, DISABLE_VOLTAGE],
        ),
    ];
    for (state, cws) in table {
        for cw in *cws {
            let mut m = in_state(*state);
            if *state == State::Fault {
                // Without a rising edge of bit 7 nothing leaves FAULT.
                m.update(*cw, NONE);
            } else {
                assert_eq!(
                    m.update(*cw, NONE).transitions,
                    [0u8; 0],
                    "{state} {cw:#06x}"
                );
            }
            assert_eq!(m.state(), *state, "{cw:#06x}");
        }
    }
}

#[test]
fn cia402_6040h_fault_reset_acts_on_the_rising_edge_of_bit_7_only() {
    let mut m = in_state(State::Fault);
    // Bit 7 set while the fault is still present: the edge is spent, the drive stays.
    let step = m.update(FAULT_RESET, FAULT);
    assert!(step.fault_reset);
    assert_eq!(m.state(), State::Fault);
    // The fault is gone but bit 7 has stayed set: no edge, no reset.
    let step = m.update(FAULT_RESET, NONE);
    assert!(!step.fault_reset);
    assert_eq!(m.state(), State::Fault);
    // Bit 7 falls and rises again: transition 15.
    m.update(0x0000, NONE);
    assert!(m.fault_reset_edge(FAULT_RESET));
    let step = m.update(FAULT_RESET, NONE);
    assert!(step.fault_reset);
    assert_eq!(step.transitions, [15]);
}

#[test]
fn cia402_6040h_fault_reset_takes_priority_and_is_never_chained() {
    // 0x0086 (fault reset + shutdown) in FAULT: transition 15 only, not 15 then 2.
    let mut m = in_state(State::Fault);
    m.update(0x0006, NONE);
    let step = m.update(0x0086, NONE);
    assert_eq!(step.transitions, [15]);
    assert_eq!(m.state(), State::SwitchOnDisabled);
    // Evaluated again with bit 7 still set, nothing more happens.
    assert_eq!(m.refresh(NONE).transitions, [0u8; 0]);
    assert_eq!(m.state(), State::SwitchOnDisabled);
    // Only once bit 7 is cleared does the shutdown act.
    assert_eq!(m.update(0x0006, NONE).transitions, [2]);
    // 0x0087 in READY TO SWITCH ON does not switch on.
    let mut m = in_state(State::ReadyToSwitchOn);
    let step = m.update(0x0087, NONE);
    assert!(step.fault_reset);
    assert_eq!(step.transitions, [0u8; 0]);
    assert_eq!(m.state(), State::ReadyToSwitchOn);
}

#[test]
fn cia402_pds_fsa_fault_reaction_active_is_observable() {
    let mut m = in_state(State::OperationEnabled).with_options(OptionCodes {
        fault_reaction: FaultReactionOption::Stop(StopRamp::QuickStop),
        ..OptionCodes::STANDARD
    });
    // Even with the reaction reported done at once, 13 and 14 take two evaluations.
    let done = Facts {
        fault_reaction_done: true,
        ..FAULT
    };
    assert_eq!(m.update(ENABLE, done).transitions, [13]);
    let sw = m.statusword(StatusFlags::default());
    assert_eq!(sw.0 & 0x004F, 0x000F, "xxxx xxxx x0xx 1111");
    assert_eq!(sw.state(), Some(State::FaultReactionActive));
    assert_eq!(
        m.power_stage().motion,
        Motion::Stop {
            ramp: StopRamp::QuickStop,
            reason: StopReason::FaultReaction
        }
    );
    // While the reaction runs, the drive stays there.
    assert_eq!(m.refresh(FAULT).transitions, [0u8; 0]);
    assert_eq!(m.refresh(done).transitions, [14]);
    assert_eq!(m.statusword(StatusFlags::default()).0 & 0x004F, 0x0008);
    // 0x605E = 0 disables the drive function during the reaction.
    let mut m = in_state(State::OperationEnabled).with_options(OptionCodes {
        fault_reaction: FaultReactionOption::DisableDriveFunction,
        ..OptionCodes::STANDARD
    });
    m.update(ENABLE, FAULT);
    assert_eq!(m.power_stage().motion, Motion::Disabled);
}

#[test]
fn cia402_605ah_quick_stop_ramps_down_on_604ah_then_switch_on_disabled() {
    let params = VlParams {
        acceleration: Ramp::new(1000, 1),
        quick_stop: Ramp::new(3000, 1),
        rfg_bits: false,
        ..VlParams::default()
    };
    let ms = Duration::from_millis(1);
    let mut m = in_state(State::OperationEnabled);
    let mut vl = VelocityMode::new();
    for _ in 0..1500 {
        vl.step(1500, ENABLE, &m.power_stage(), &params, ms);
    }
    assert_eq!(vl.demand(), 1500);
    assert_eq!(m.update(QUICK_STOP, NONE).transitions, [11]);
    assert_eq!(m.statusword(StatusFlags::default()).0 & 0x006F, 0x0007);
    assert!(m.statusword(StatusFlags::default()).quick_stopping());
    // 3000 per second: 250 ms to 750, 500 ms to zero.
    let mut t = 0;
    while vl.demand() != 0 {
        vl.step(1500, QUICK_STOP, &m.power_stage(), &params, ms);
        t += 1;
        if t == 250 {
            assert_eq!(vl.demand(), 750);
        }
        let facts = Facts {
            stopped: vl.demand() == 0,
            ..NONE
        };
        let step = m.refresh(facts);
        if vl.demand() != 0 {
            assert_eq!(m.state(), State::QuickStopActive);
        } else {
            assert_eq!(step.transitions, [12]);
        }
    }
    assert_eq!(t, 500);
    assert_eq!(m.state(), State::SwitchOnDisabled);
    // 0x605A = 0: the drive function is disabled and the quick stop is complete at once.
    let mut m = in_state(State::OperationEnabled).with_options(OptionCodes {
        quick_stop: QuickStopOption::DisableDriveFunction,
        ..OptionCodes::STANDARD
    });
    m.update(QUICK_STOP, NONE);
    assert_eq!(m.power_stage().motion, Motion::Disabled);
    assert_eq!(m.refresh(NONE).transitions, [12]);
}

#[test]
fn cia402_605dh_halt_stops_on_the_slow_down_ramp_and_resumes() {
    let params = VlParams {
        deceleration: Ramp::new(2000, 1),
        rfg_bits: false,
        ..VlParams::default()
    };
    let mut m = in_state(State::OperationEnabled);
    let mut vl = VelocityMode::new();
    vl.step(
        1000,
        ENABLE,
        &m.power_stage(),
        &params,
        Duration::from_secs(2),
    );
    m.update(ENABLE | 0x0100, NONE);
    assert!(m.power_stage().halted());
    assert_eq!(m.state(), State::OperationEnabled);
    vl.step(
        1000,
        m.controlword(),
        &m.power_stage(),
        &params,
        Duration::from_millis(250),
    );
    assert_eq!(vl.demand(), 500);
    assert!(!vl.target_reached(1000, &m.power_stage(), &params));
    vl.step(
        1000,
        m.controlword(),
        &m.power_stage(),
        &params,
        Duration::from_millis(250),
    );
    assert!(vl.target_reached(1000, &m.power_stage(), &params));
    m.update(ENABLE, NONE);
    assert_eq!(m.power_stage().motion, Motion::Operate);
}

#[test]
fn cia402_6041h_statusword_of_every_state() {
    // With voltage enabled and remote, as a drive with its DC link up reports them.
    let table = [
        (State::NotReadyToSwitchOn, 0x0000, 0x0200),
        (State::SwitchOnDisabled, 0x0040, 0x0240),
        (State::ReadyToSwitchOn, 0x0021, 0x0231),
        (State::SwitchedOn, 0x0023, 0x0233),
        (State::OperationEnabled, 0x0027, 0x0237),
        (State::QuickStopActive, 0x0007, 0x0217),
        (State::FaultReactionActive, 0x000F, 0x021F),
        (State::Fault, 0x0008, 0x0218),
    ];
    for (state, bare, drive) in table {
        let m = in_state(state);
        assert_eq!(m.statusword(StatusFlags::default()).0, bare, "{state}");
        let flags = StatusFlags {
            voltage_enabled: m.power_stage().voltage,
            remote: true,
            ..StatusFlags::default()
        };
        assert_eq!(m.statusword(flags).0, drive, "{state}");
        assert_eq!(Statusword(drive).state(), Some(state));
        assert_eq!(Statusword(drive).state_name(), state.name());
    }
}

#[test]
fn cia402_6041h_flag_bits() {
    let flags = StatusFlags {
        voltage_enabled: true,
        warning: true,
        remote: true,
        target_reached: true,
        internal_limit_active: true,
        mode_specific: 0b11,
        manufacturer_specific: 0xFFFF,
    };
    let sw = Statusword::encode(State::OperationEnabled, flags);
    assert_eq!(sw.0, 0xFFB7);
    assert_eq!(
        sw.flags().manufacturer_specific,
        statusword::MANUFACTURER_SPECIFIC
    );
    assert!(Statusword(0x0400).flags().target_reached);
    assert!(Statusword(0x0800).flags().internal_limit_active);
    assert_eq!(Statusword(0x1000).flags().mode_specific, 1);
    assert_eq!(Statusword(0x2000).flags().mode_specific, 2);
    assert!(Statusword(0x0218).fault());
}

#[test]
fn cia402_pds_fsa_every_state_is_reachable() {
    // Breadth-first over controlwords and facts from the start.
    let cws = [
        SHUTDOWN,
        SWITCH_ON,
        ENABLE,
        DISABLE_VOLTAGE,
        QUICK_STOP,
        FAULT_RESET,
    ];
    let facts = [
        NONE,
        STOPPED,
        FAULT,
        Facts {
            fault_reaction_done: true,
            ..FAULT
        },
    ];
    let mut seen = BTreeSet::new();
    let mut frontier = vec![PowerStateMachine::new()];
    seen.insert(State::NotReadyToSwitchOn);
    while let Some(m) = frontier.pop() {
        for cw in cws {
            for f in facts {
                let mut next = m.clone();
                next.update(cw, f);
                if seen.insert(next.state()) {
                    frontier.push(next);
                }
            }
        }
    }
    assert_eq!(seen.len(), State::ALL.len());
}

fn facts() -> impl Strategy<Value = Facts> {
    (any::<bool>(), any::<bool>(), any::<bool>()).prop_map(|(fault, done, stopped)| Facts {
        fault,
        fault_reaction_done: done,
        stopped,
    })
}

fn controlword() -> impl Strategy<Value = u16> {
    prop_oneof![
        any::<u16>(),
        prop::sample::select(Command::ALL.map(Command::controlword).to_vec()),
    ]
}

proptest! {
    #[test]
    fn cia402_6041h_encode_then_decode_round_trips(
        state in prop::sample::select(State::ALL.to_vec()),
        voltage_enabled in any::<bool>(),
        warning in any::<bool>(),
        remote in any::<bool>(),
        target_reached in any::<bool>(),
        internal_limit_active in any::<bool>(),
        mode_specific in 0u8..4,
        manufacturer in any::<u16>(),
    ) {
        let flags = StatusFlags {
            voltage_enabled,
            warning,
            remote,
            target_reached,
            internal_limit_active,
            mode_specific,
            manufacturer_specific: manufacturer & statusword::MANUFACTURER_SPECIFIC,
        };
        let sw = Statusword::encode(state, flags);
        prop_assert_eq!(sw.state(), Some(state));
        prop_assert_eq!(sw.flags(), flags);
    }

    #[test]
    fn cia402_6041h_decode_then_encode_is_stable(sw in any::<u16>()) {
        let w = Statusword(sw);
        if let Some(state) = w.state() {
            let again = Statusword::encode(state, w.flags());
            prop_assert_eq!(again.state(), Some(state));
            prop_assert_eq!(again.flags(), w.flags());
            // Only the bits outside the state's pattern may differ.
            let (mask, _) = state.statusword_pattern();
            prop_assert_eq!(again.0 | mask | statusword::QUICK_STOP, sw | mask | statusword::QUICK_STOP);
        } else {
            prop_assert_eq!(w.state_name(), "no defined state");
        }
    }

    #[test]
    fn cia402_6040h_every_controlword_is_one_command(cw in any::<u16>()) {
        let c = Controlword(cw).command();
        // Encoding the command again gives the same command back.
        prop_assert_eq!(Controlword(c.controlword()).command(), c);
        prop_assert_eq!(c == Command::FaultReset, cw & 0x80 != 0);
    }

    #[test]
    fn cia402_pds_fsa_takes_only_legal_transitions(
        steps in prop::collection::vec((controlword(), facts()), 1..64),
        qs in 0i16..=8,
    ) {
        let options = OptionCodes {
            quick_stop: QuickStopOption::from_code(qs).unwrap(),
            ..OptionCodes::STANDARD
        };
        let mut m = PowerStateMachine::new().with_options(options);
        for (cw, f) in steps {
            let edge = m.fault_reset_edge(cw);
            let step = m.update(cw, f);
            prop_assert_eq!(step.fault_reset, edge);
            prop_assert_eq!(step.to, m.state());
            // The transitions chain from `from` to `to` through legal edges.
            let mut s = step.from;
            for n in step.transitions {
                let to = TRANSITIONS
                    .iter()
                    .find(|(k, f, _)| k == n && *f == s)
                    .map(|(_, _, t)| *t);
                prop_assert!(to.is_some(), "transition {} from {}", n, s);
                s = to.unwrap();
            }
            prop_assert_eq!(s, step.to);
            prop_assert!(step.transitions.len() <= 1 || step.transitions == [3, 4]);
            // A fault present never leaves the drive outside the fault states.
            if f.fault {
                prop_assert!(matches!(m.state(), State::FaultReactionActive | State::Fault));
            }
            // Transition 15 only on the edge of bit 7 with no fault.
            if step.transitions == [15] {
                prop_assert!(edge && !f.fault);
            }
            // The drive function is enabled only where CiA 402-2 allows it.
            if m.power_stage().enabled() {
                prop_assert!(!matches!(
                    m.state(),
                    State::NotReadyToSwitchOn | State::SwitchOnDisabled | State::Fault
                ));
            }
        }
    }
}
