//! The CiA 402 drive profile, reusable by any drive: the objects ([`objects`],
//! [`dictionary`]), the power drive state machine ([`state`]), the controlword and
//! statusword ([`controlword`], [`statusword`]), the option codes that say how the drive
//! stops ([`options`]), the modes of operation ([`modes`]), velocity mode with its limits
//! and ramps ([`vl`]), and the servo side: the plant ([`physics`]), the factor group
//! ([`units`]), the cascaded controller ([`control`]), the trajectory generator
//! ([`profile`]), one module per operating mode ([`pp`], [`pv`], [`pt`], [`cyclic`] (csp, csv, cst and ip),
//! [`hm`]) and the drive that runs them over a dictionary ([`drive`]).
//!
//! # Modes, objects, statusword bits and the tests that check them
//!
//! Test names are those of `tests/modes.rs` unless a module is named; every test drives a
//! [`drive::Drive`] over a dictionary built by [`dictionary::servo_objects`] in virtual
//! time.
//!
//! | mode (0x6060) | objects it uses | statusword bits 10, 11, 12, 13 | tests |
//! |---|---|---|---|
//! | device control | 0x6040, 0x6041, 0x605A–0x605E, 0x603F | state bits 0–6; 10 target reached on halt | `tests/pds_fsa.rs`; `cia402_605ah_quick_stop_options_stop_and_stay`, `cia402_605ah_quick_stop_option_0_coasts`, `cia402_fsa_halt_605dh_stops_with_target_reached` |
//! | pp, 1 | 0x607A, 0x6081, 0x6082, 0x6083, 0x6084, 0x607F, 0x607D, 0x6062, 0x6064, 0x6065–0x6068, 0x60F4 | 10 target reached (position window for its time), 11 software position limit, 12 set-point acknowledge, 13 following error | `cia402_pp_single_set_point_acknowledge_handshake`, `cia402_pp_absolute_and_relative_targets`, `cia402_pp_change_set_immediately`, `cia402_pp_set_of_set_points_buffers_one`, `cia402_pp_change_on_set_point_passes_through`, `cia402_pp_target_reached_after_position_window_time`, `cia402_pp_607dh_software_position_limit`, `cia402_pp_60f4h_following_error_bit_13_and_fault` |
//! | vl, 2 | 0x6042–0x604F | 10 target reached, 11 velocity limited | `vl` module tests; `cia402_vl_in_the_servo_drive` |
//! | pv, 3 | 0x60FF, 0x6083, 0x6084, 0x607F, 0x606B, 0x606C, 0x606D–0x6070 | 10 target reached (velocity window), 12 speed zero (velocity threshold) | `cia402_pv_acceleration_ramp_and_velocity_window`, `cia402_pv_speed_zero_after_threshold_time`, `cia402_pv_halt_decelerates_with_profile_deceleration` |
//! | pt (tq), 4 | 0x6071, 0x6087, 0x6072, 0x6073, 0x6074, 0x6077, 0x6078, 0x6080 | 10 target reached (torque demand at target), 11 torque or speed limited | `cia402_pt_torque_slope`, `cia402_pt_6072h_max_torque_is_an_internal_limit` |
//! | hm, 6 | 0x6098, 0x6099, 0x609A, 0x607C, 0x60FD | 10 target reached, 12 homing attained, 13 homing error | `cia402_hm_methods_35_37_current_position`, `cia402_hm_methods_1_2_limit_switch_and_index_pulse`, `cia402_hm_methods_3_to_6_home_switch_and_index_pulse`, `cia402_hm_methods_7_to_10_home_switch_with_reversal_and_index_pulse`, `cia402_hm_methods_11_to_14_home_switch_with_reversal_and_index_pulse`, `cia402_hm_methods_17_to_22_switch_transition`, `cia402_hm_methods_23_to_30_home_switch_with_reversal`, `cia402_hm_methods_7_to_14_need_the_limit_switch_they_reverse_at`, `cia402_hm_methods_33_34_index_pulse`, `cia402_hm_error_on_a_limit_switch_in_the_search`, `cia402_hm_interrupted_by_bit_4` |
//! | ip, 7 | 0x60C1, 0x60C2, 0x60C0 (linear) | 10 target reached, 12 ip mode active, 13 following error | `cia402_ip_linear_interpolation_while_enabled` |
//! | csp, 8 | 0x607A, 0x60B0, 0x60B1, 0x60B2, 0x60C2, 0x60F4 | 11 position limit, 12 target position ignored (0) / followed (1), 13 following error | `cia402_csp_interpolates_over_60c2h`, `cia402_csp_target_ignored_while_halted`, `cia402_csp_missing_sync_holds_the_last_set_point` |
//! | csv, 9 | 0x60FF, 0x60B1, 0x60B2 | 12 target velocity ignored / followed | `cia402_csv_follows_target_velocity_at_sync` |
//! | cst, 10 | 0x6071, 0x60B2 | 12 target torque ignored / followed | `cia402_cst_follows_target_torque_at_sync` |
//! | mode switching | 0x6060, 0x6061, 0x6502 | — | `cia402_6061h_follows_when_the_drive_has_switched`, `cia402_6060h_unsupported_mode_is_not_taken` |
//! | limits | 0x60FD, 0x607D, 0x6085 | 11 internal limit active | `cia402_60fdh_limit_switch_stops_and_allows_moving_away` |
//! | power stage | 0x6079, 0x603F | fault | `cia402_603fh_over_current_trips`, `cia402_603fh_dc_link_under_voltage` |
//!
//! Like the other profiles it is sans-IO and pure: a drive model feeds the controlword
//! and its own facts (a fault present, the motor stopped) to a [`PowerStateMachine`],
//! drives its power stage from the [`PowerStage`] it gets back, steps the vl ramp with
//! the time that passed and writes the [`Statusword`] and the velocity demand back.
//!
//! ```
//! use std::sync::Arc;
//! use cantwin_can::Duration;
//! use cantwin_canopen::od::{ObjectDictionary, OdBuilder, Value};
//! use cantwin_cia402::objects::{self, Objects};
//! use cantwin_cia402::vl::{VelocityMode, VlParams};
//! use cantwin_cia402::{Facts, OptionCodes, PowerStateMachine, State, StatusFlags};
//!
//! let desc = objects::add_objects(OdBuilder::new(), &Objects::velocity_drive())
//!     .build()
//!     .expect("valid");
//! let mut od = ObjectDictionary::new(Arc::new(desc), 1);
//! let mut drive = PowerStateMachine::new().with_options(OptionCodes::from_od(&od, OptionCodes::STANDARD));
//! let mut vl = VelocityMode::new();
//!
//! // Transition 1 (initialised), then shutdown (2) and switch on + enable operation (3 + 4),
//! // with the vl ramp function generator bits 4–6 set.
//! drive.update(0x0000, Facts::default());
//! drive.update(0x0006, Facts::default());
//! let step = drive.update(0x007F, Facts::default());
//! assert_eq!(step.transitions, [3, 4]);
//! assert_eq!(drive.state(), State::OperationEnabled);
//!
//! // 1500 rpm at the default 1000 rpm per second: 500 rpm after half a second.
//! od.set(objects::VL_TARGET_VELOCITY, 0, &Value::Integer16(1500)).expect("exists");
//! let params = VlParams::from_od(&od, VlParams::default());
//! let stage = drive.power_stage();
//! for _ in 0..500 {
//!     vl.step(1500, drive.controlword(), &stage, &params, Duration::from_millis(1));
//! }
//! assert_eq!(vl.demand(), 500);
//!
//! let flags = StatusFlags { voltage_enabled: stage.voltage, remote: true, ..StatusFlags::default() };
//! assert_eq!(drive.statusword(flags).0, 0x0237);
//! assert_eq!(drive.statusword(flags).state_name(), "operation enabled");
//! ```
#![forbid(unsafe_code)]

pub mod control;
pub mod controlword;
pub mod cyclic;
pub mod dictionary;
pub mod drive;
pub mod hm;
pub mod index;
pub mod modes;
pub mod objects;
pub mod options;
pub mod physics;
pub mod pp;
pub mod profile;
pub mod pt;
pub mod pv;
pub mod state;
pub mod statusword;
pub mod units;
pub mod vl;

pub use controlword::{Command, Controlword};
pub use modes::{Mode, SupportedModes};
pub use options::{OptionCodes, StopRamp};
pub use state::{Facts, Motion, PowerStage, PowerStateMachine, State, Step, StopReason};
pub use statusword::{StatusFlags, Statusword};
