//! Every error cause of the manual's EMCY table (object 1003H): the EMCY frame (code, error
//! register, 0x1002 in bytes 3–6, module number in byte 7), 0x1002 and 0x1003 contents,
//! the 0x1029 reaction and the outputs' failure state.
#![allow(clippy::unwrap_used)]

mod harness;

use cantwin_can::{ControllerEvent, Frame, Instant, Node, Outbox};
use cantwin_canopen::nmt::State;
use cantwin_tm3::catalogue;
use cantwin_tm3::coupler::{CouplerConfig, Fitted, Tm3Coupler};
use cantwin_tm3::diag::Status;
use cantwin_tm3::island::Island;
use harness::*;

fn unpowered(refs: &[&str]) -> Tm3Coupler {
    Tm3Coupler::new(CouplerConfig::new(
        NODE,
        Island::from_references(refs).unwrap(),
    ))
    .unwrap()
}

fn power_up(c: &mut Tm3Coupler, t: Instant) -> Vec<String> {
    let mut out = Outbox::new();
    c.on_power_up(t, &mut out);
    acked(c, t, &mut out)
}

fn event(c: &mut Tm3Coupler, t: Instant, e: ControllerEvent) -> Vec<String> {
    let mut out = Outbox::new();
    c.on_controller_event(e, t, &mut out);
    acked(c, t, &mut out)
}

fn fit(c: &mut Tm3Coupler, t: Instant, module: usize, what: Fitted) -> Vec<String> {
    let mut out = Outbox::new();
    c.fit(module, what, t, &mut out).unwrap();
    acked(c, t, &mut out)
}

/// A started coupler with a digital input and a relay output module whose outputs are
/// all on (RPDO1 = 0xFF at 5 ms).
fn running() -> Tm3Coupler {
    let mut c = coupler(&["TM3DI8", "TM3DQ8R"]);
    start(&mut c, ms(1));
    assert_eq!(send(&mut c, ms(5), 0x203, &[0xFF]), Vec::<String>::new());
    assert_eq!(c.digital_output(2, 7), Ok(true));
    c
}

fn outputs(c: &Tm3Coupler) -> u8 {
    (0..8).fold(0, |acc, ch| {
        acc | u8::from(c.digital_output(2, ch).unwrap()) << ch
    })
}

#[test]
fn manual_7002_missing_module_at_power_up() {
    let mut c = unpowered(&["TM3DI8", "TM3DQ8R"]);
    fit(&mut c, ms(0), 2, Fitted::Empty);
    // Register 0x81: generic + manufacturer-specific; 0x1002 = module 2 status 1, bus
    // status 1 (0x40000004); module 2 in byte 7.
    assert_eq!(power_up(&mut c, ms(0)), ["703#00", "083#0270810400004002"]);
    assert_eq!(c.module_status(2), Some(Status::ConfigurationError));
    assert_eq!(c.bus_status(), Status::ConfigurationError);
    assert_eq!(read_u32(&mut c, ms(1), 0x1002, 0), Ok(0x4000_0004));
    assert_eq!(read(&mut c, ms(1), 0x1003, 0), Ok(vec![1]));
    assert_eq!(read_u32(&mut c, ms(1), 0x1003, 1), Ok(0x0281_7002));
    // Not a communication error: 0x1029 leaves the state alone.
    assert_eq!(c.state(), State::PreOperational);
    assert_eq!(c.digital_output(2, 0), Ok(false));
}

#[test]
fn manual_7002_wrong_module_and_7001_unresponsive_module() {
    let mut c = unpowered(&["TM3DI8", "TM3DQ8R", "TM3AI4"]);
    fit(
        &mut c,
        ms(0),
        1,
        Fitted::Module(catalogue::find("TM3DI16").unwrap()),
    );
    fit(&mut c, ms(0), 3, Fitted::Unresponsive);
    // Module 1 and module 3 status 1 (0x11), bus 1.
    assert_eq!(
        power_up(&mut c, ms(0)),
        ["703#00", "083#0270811100004001", "083#0170811100004003"]
    );
    assert_eq!(read_u32(&mut c, ms(1), 0x1003, 1), Ok(0x0381_7001));
    assert_eq!(read_u32(&mut c, ms(1), 0x1003, 2), Ok(0x0181_7002));
}

#[test]
fn manual_1002_absent_optional_module_is_status_3_without_error() {
    let island = Island::new(vec![
        cantwin_tm3::island::ModuleSlot {
            spec: catalogue::find("TM3DI8").unwrap(),
            optional: false,
        },
        cantwin_tm3::island::ModuleSlot {
            spec: catalogue::find("TM3AQ2").unwrap(),
            optional: true,
        },
    ])
    .unwrap();
    let mut c = Tm3Coupler::new(CouplerConfig::new(NODE, island)).unwrap();
    fit(&mut c, ms(0), 2, Fitted::Empty);
    assert_eq!(power_up(&mut c, ms(0)), ["703#00"]);
    assert_eq!(c.module_status(2), Some(Status::NotConfigured));
    assert_eq!(read_u32(&mut c, ms(1), 0x1002, 0), Ok(0x0000_000C));
    assert_eq!(read(&mut c, ms(1), 0x1001, 0), Ok(vec![0]));
}

#[test]
fn manual_7003_module_removed_at_runtime() {
    let mut c = running();
    // Module 2 (the outputs) goes: runtime error, status 2 (bits 2-3), bus status 2.
    assert_eq!(
        fit(&mut c, ms(10), 2, Fitted::Empty),
        ["083#0370810800008002"]
    );
    assert_eq!(outputs(&c), 0, "a removed module's outputs are off");
    assert_eq!(c.module_status(2), Some(Status::RuntimeError));
    // Module 1 goes too: same code, its own EMCY and 0x1003 entry.
    assert_eq!(
        fit(&mut c, ms(11), 1, Fitted::Empty),
        ["083#0370810A00008001"]
    );
    assert_eq!(read_u32(&mut c, ms(12), 0x1003, 1), Ok(0x0181_7003));
    assert_eq!(read_u32(&mut c, ms(12), 0x1003, 2), Ok(0x0281_7003));
    // Its inputs no longer reach 0x6000.
    c.set_digital_input(1, 0, true).unwrap();
    assert_eq!(tick(&mut c, ms(13)), Vec::<String>::new());
    assert_eq!(read(&mut c, ms(14), 0x6000, 1), Ok(vec![0]));
    assert_eq!(c.state(), State::Operational);
    // A reset communication keeps the error (raised again after the boot-up).
    assert_eq!(
        send(&mut c, ms(20), 0, &[0x82, NODE]),
        ["703#00", "083#0370810A00008001", "083#0370810A00008002"]
    );
}

#[test]
fn manual_1000_internal_communication_error_sets_safe_outputs() {
    let mut c = running();
    let mut out = Outbox::new();
    c.set_internal_error(true, ms(10), &mut out);
    assert_eq!(take(&mut out), ["083#0010010000008000"]);
    assert!(c.in_failure_state());
    assert_eq!(outputs(&c), 0, "0x6206 = 0xFF, 0x6207 = 0");
    c.set_internal_error(false, ms(20), &mut out);
    assert_eq!(take(&mut out), ["083#0000000000000000"]);
    // The failure state ends with the next RPDO once nothing is wrong.
    send(&mut c, ms(21), 0x203, &[0x0F]);
    assert!(!c.in_failure_state());
    assert_eq!(outputs(&c), 0x0F);
}

#[test]
fn manual_6101_receive_queue_overrun_under_overload() {
    let mut c = coupler(&["TM3DI8"]);
    // 64 frames fill the queue (served at 50 µs each); the 65th in the same instant is lost.
    for _ in 0..64 {
        assert_eq!(send(&mut c, ms(1), 0x7FF, &[0]), Vec::<String>::new());
    }
    assert_eq!(send(&mut c, ms(1), 0x7FF, &[0]), ["083#0161010000000000"]);
    // Lost means lost: an SDO request in the full queue gets no answer.
    assert_eq!(
        send(&mut c, ms(1), 0x603, &[0x40, 0, 0x10, 0, 0, 0, 0, 0]),
        Vec::<String>::new()
    );
    // 64 × 50 µs later the queue is empty: the frame is served (0x1000 = 0x00810191) and
    // the error reset follows.
    assert_eq!(
        send(
            &mut c,
            us(1_000 + 3_200),
            0x603,
            &[0x40, 0, 0x10, 0, 0, 0, 0, 0]
        ),
        ["583#4300100091018100", "083#0000000000000000"]
    );
    assert_eq!(read_u32(&mut c, ms(6), 0x1003, 1), Ok(0x0001_6101));
}

#[test]
fn manual_6102_transmit_queue_overrun() {
    let mut c = coupler(&["TM3DI8"]);
    // The EMCY itself is the next frame that makes it onto the bus: the error reset
    // follows it.
    assert_eq!(
        event(&mut c, ms(1), ControllerEvent::TxDropped),
        ["083#0261010000000000", "083#0000000000000000"]
    );
}

#[test]
fn manual_8110_message_lost_and_8120_error_passive() {
    let mut c = coupler(&["TM3DI8"]);
    assert_eq!(
        event(&mut c, ms(1), ControllerEvent::RxOverrun),
        ["083#1081110000000000"]
    );
    assert_eq!(
        event(&mut c, ms(2), ControllerEvent::ErrorPassive),
        ["083#2081110000000000"]
    );
    assert_eq!(
        event(&mut c, ms(3), ControllerEvent::ErrorActive),
        ["083#0000110000000000"]
    );
    assert_eq!(read_u32(&mut c, ms(4), 0x1003, 1), Ok(0x0011_8120));
    assert_eq!(read_u32(&mut c, ms(4), 0x1003, 2), Ok(0x0011_8110));
}

#[test]
fn manual_8130_heartbeat_loss_safe_outputs_and_1029_pre_operational() {
    let mut c = running();
    // Monitor node 1 every 100 ms (manual: 1016H).
    assert_eq!(
        write(&mut c, ms(6), 0x1016, 1, &0x0001_0064u32.to_le_bytes()),
        Ok(())
    );
    assert_eq!(send(&mut c, ms(10), 0x701, &[0x05]), Vec::<String>::new());
    assert_eq!(c.next_deadline(), Some(ms(110)));
    assert_eq!(tick(&mut c, ms(110)), ["083#3081110000000000"]);
    assert_eq!(c.state(), State::PreOperational);
    assert!(c.in_failure_state());
    let events: Vec<_> = std::iter::from_fn(|| c.poll_event()).collect();
    assert!(events.contains(&cantwin_canopen::device::Event::HeartbeatLost { node: 1 }));
    assert_eq!(outputs(&c), 0);
    assert_eq!(read_u32(&mut c, ms(111), 0x1003, 1), Ok(0x0011_8130));
}

#[test]
fn manual_8130_heartbeat_loss_with_1029_no_change_keeps_operational_but_safe() {
    let mut c = running();
    assert_eq!(write(&mut c, ms(6), 0x1029, 1, &[1]), Ok(()));
    assert_eq!(write(&mut c, ms(6), 0x6207, 1, &[0x81]), Ok(()));
    assert_eq!(
        write(&mut c, ms(6), 0x1016, 1, &0x0001_0064u32.to_le_bytes()),
        Ok(())
    );
    send(&mut c, ms(10), 0x701, &[0x05]);
    assert_eq!(tick(&mut c, ms(110)), ["083#3081110000000000"]);
    assert_eq!(c.state(), State::Operational);
    assert_eq!(outputs(&c), 0x81, "error value 0x81");
    // An RPDO while the producer is still lost does not end the failure state.
    send(&mut c, ms(120), 0x203, &[0x00]);
    assert_eq!(outputs(&c), 0x81);
    // The producer is back: 0x8130 is reset, and the next RPDO drives the outputs again.
    assert_eq!(
        send(&mut c, ms(130), 0x701, &[0x05]),
        ["083#0000000000000000"]
    );
    send(&mut c, ms(131), 0x203, &[0x3C]);
    assert_eq!(outputs(&c), 0x3C);
}

#[test]
fn manual_8130_life_guarding_loss() {
    let mut c = running();
    assert_eq!(
        write(&mut c, ms(6), 0x100C, 0, &100u16.to_le_bytes()),
        Ok(())
    );
    assert_eq!(write(&mut c, ms(6), 0x100D, 0, &[2]), Ok(()));
    let mut out = Outbox::new();
    c.on_frame(
        &Frame::remote(cantwin_can::Id::standard(0x703).unwrap(), 1).unwrap(),
        ms(10),
        &mut out,
    );
    assert_eq!(take(&mut out), ["703#05"]);
    // Life time 2 × 100 ms from the last request.
    assert_eq!(tick(&mut c, ms(210)), ["083#3081110000000000"]);
    assert!(c.in_failure_state());
    assert_eq!(c.state(), State::PreOperational);
}

#[test]
fn manual_8140_bus_off_recovered() {
    let mut c = running();
    assert_eq!(
        event(&mut c, ms(10), ControllerEvent::BusOff),
        Vec::<String>::new()
    );
    assert!(c.in_failure_state());
    assert_eq!(c.state(), State::PreOperational, "0x1029 = 0");
    // The recovery is complete once a frame of the coupler is on the bus: its own EMCY
    // 0x8140 is that frame, and the error reset follows it.
    assert_eq!(
        event(&mut c, ms(20), ControllerEvent::BusOffRecovered),
        ["083#4081110000000000", "083#0000000000000000"]
    );
}

#[test]
fn manual_8210_pdo_length() {
    let mut c = running();
    assert_eq!(send(&mut c, ms(10), 0x203, &[]), ["083#1082110000000000"]);
    assert_eq!(outputs(&c), 0xFF, "not processed");
    assert_eq!(
        send(&mut c, ms(11), 0x203, &[0x01]),
        ["083#0000000000000000"]
    );
    assert_eq!(outputs(&c), 0x01);
}

#[test]
fn manual_f001_sync_timeout() {
    let mut c = running();
    assert_eq!(
        write(&mut c, ms(6), 0x1006, 0, &10_000u32.to_le_bytes()),
        Ok(())
    );
    // Armed by the first SYNC; 1.5 periods without one is a timeout.
    assert_eq!(c.next_deadline(), None);
    send(&mut c, ms(20), 0x080, &[]);
    assert_eq!(c.next_deadline(), Some(ms(35)));
    assert_eq!(tick(&mut c, ms(35)), ["083#01F0110000000000"]);
    assert!(c.in_failure_state());
    assert_eq!(c.state(), State::PreOperational, "0x1029 = 0");
    assert_eq!(send(&mut c, ms(40), 0x080, &[]), ["083#0000000000000000"]);
    assert_eq!(read_u32(&mut c, ms(41), 0x1003, 1), Ok(0x0011_F001));
}

#[test]
fn manual_ff03_rotary_switch_changed() {
    let mut c = coupler(&["TM3DI8"]);
    let mut out = Outbox::new();
    c.set_rotary_switch(5, ms(1), &mut out);
    assert_eq!(take(&mut out), ["083#03FF810000000000"]);
    c.set_rotary_switch(NODE, ms(2), &mut out);
    assert_eq!(take(&mut out), ["083#0000000000000000"]);
    // The node-ID is read at power-up.
    c.set_rotary_switch(5, ms(3), &mut out);
    out.clear();
    assert_eq!(power_up(&mut c, ms(4)), ["705#00"]);
    assert_eq!(c.device().node_id(), 5);
}

#[test]
fn manual_ff04_not_configured_in_operational() {
    let island = Island::from_references(&["TM3DI8"]).unwrap();
    let mut config = CouplerConfig::new(NODE, island);
    config.configured = false;
    let mut c = Tm3Coupler::new(config).unwrap();
    assert_eq!(power_up(&mut c, ms(0)), ["703#00"]);
    assert_eq!(read_u32(&mut c, ms(1), 0x1002, 0), Ok(0xC000_0000));
    assert_eq!(start(&mut c, ms(2)), ["183#00", "083#04FF81000000C000"]);
}

#[test]
fn manual_1003_newest_first_and_cleared_by_writing_0() {
    let mut c = coupler(&["TM3DI8"]);
    event(&mut c, ms(1), ControllerEvent::RxOverrun);
    event(&mut c, ms(2), ControllerEvent::TxDropped);
    assert_eq!(read(&mut c, ms(3), 0x1003, 0), Ok(vec![2]));
    assert_eq!(read_u32(&mut c, ms(3), 0x1003, 1), Ok(0x0011_6102));
    assert_eq!(read_u32(&mut c, ms(3), 0x1003, 2), Ok(0x0011_8110));
    assert_eq!(write(&mut c, ms(4), 0x1003, 0, &[0]), Ok(()));
    assert_eq!(read(&mut c, ms(5), 0x1003, 0), Ok(vec![0]));
    // Cleared: sub 1 holds no error any more (CiA 301 §7.5.2.4).
    assert_eq!(read_u32(&mut c, ms(5), 0x1003, 1), Err(0x0800_0024));
    // More than ten errors keep the ten newest.
    for k in 0..12u64 {
        event(&mut c, ms(10 + 2 * k), ControllerEvent::ErrorPassive);
        event(&mut c, ms(11 + 2 * k), ControllerEvent::ErrorActive);
    }
    assert_eq!(read(&mut c, ms(40), 0x1003, 0), Ok(vec![10]));
}

#[test]
fn manual_1029_stopped_on_sync_timeout_sends_the_emcy_first() {
    let mut c = running();
    assert_eq!(write(&mut c, ms(6), 0x1029, 1, &[2]), Ok(()));
    assert_eq!(
        write(&mut c, ms(6), 0x1006, 0, &20_000u32.to_le_bytes()),
        Ok(())
    );
    send(&mut c, ms(10), 0x080, &[]);
    assert_eq!(tick(&mut c, ms(40)), ["083#01F0110000000000"]);
    assert_eq!(c.state(), State::Stopped);
    assert_eq!(outputs(&c), 0);
}
