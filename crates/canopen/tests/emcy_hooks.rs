//! EMCY manufacturer bytes and 0x1003 entries from the device's hooks (CiA 301 §7.2.7,
//! §7.5.2.4), as CANopenNode's `CO_errorReport` carries an info code.
#![allow(clippy::unwrap_used)]

use cantwin_can::{ControllerEvent, Frame, Instant, Node, Outbox};
use cantwin_canopen::device::{Device, DeviceConfig};
use cantwin_canopen::objects::{Cia301Options, cia301_defaults};
use cantwin_canopen::od::{ObjectDictionary, OdBuilder, OdHooks};
use std::sync::Arc;

/// A device whose EMCYs carry a status word (bytes 3–6) and the failing unit (byte 7,
/// the fifth raised byte), and whose 0x1003 entries hold code, register and unit.
struct Units {
    status: u32,
}

impl OdHooks for Units {
    fn emcy_manufacturer(&mut self, _: &ObjectDictionary, _: u16, _: u8, info: [u8; 5]) -> [u8; 5] {
        let s = self.status.to_le_bytes();
        [s[0], s[1], s[2], s[3], info[4]]
    }

    fn error_entry(&mut self, _: &ObjectDictionary, code: u16, register: u8, info: [u8; 5]) -> u32 {
        u32::from(code) | u32::from(register) << 16 | u32::from(info[4]) << 24
    }
}

fn device() -> Device<Units> {
    let options = Cia301Options {
        error_history: 4,
        ..Cia301Options::default()
    };
    let desc = cia301_defaults(OdBuilder::new(), &options).build().unwrap();
    Device::with_hooks(
        Arc::new(desc),
        DeviceConfig::new(3),
        Units {
            status: 0x8000_0008,
        },
    )
    .unwrap()
}

fn ms(v: u64) -> Instant {
    Instant::from_nanos(v * 1_000_000)
}

/// Powers the device up and confirms its boot-up message as the bus would: EMCYs wait for
/// it (CiA 301 §7.2.7.1).
fn boot(dev: &mut Device<Units>, out: &mut Outbox) {
    dev.on_power_up(ms(0), out);
    let sent: Vec<Frame> = out.drain().collect();
    for f in &sent {
        dev.on_sent(f, ms(0), out);
    }
    out.clear();
}

fn frames(out: &mut Outbox) -> Vec<String> {
    out.drain().map(|f| f.to_string()).collect()
}

#[test]
fn cia301_7_2_7_emcy_manufacturer_bytes_come_from_the_hooks_when_sent() {
    let mut dev = device();
    let mut out = Outbox::new();
    boot(&mut dev, &mut out);
    dev.emcy().raise(0x7003, [0, 0, 0, 0, 2]);
    // The status at the moment of sending, not at the raise.
    dev.hooks_mut().status = 0x8000_0020;
    dev.on_tick(ms(1), &mut out);
    // The stack's own errors go through the same hook.
    dev.on_controller_event(ControllerEvent::ErrorPassive, ms(2), &mut out);
    dev.emcy().clear(0x7003);
    dev.on_tick(ms(3), &mut out);
    assert_eq!(
        frames(&mut out),
        [
            Frame::std(0x083, &[0x03, 0x70, 0x01, 0x20, 0, 0, 0x80, 0x02])
                .unwrap()
                .to_string(),
            Frame::std(0x083, &[0x20, 0x81, 0x11, 0x20, 0, 0, 0x80, 0x00])
                .unwrap()
                .to_string(),
            Frame::std(0x083, &[0x00, 0x00, 0x11, 0x20, 0, 0, 0x80, 0x00])
                .unwrap()
                .to_string(),
        ]
    );
}

#[test]
fn cia301_7_5_2_4_error_field_entries_come_from_the_hooks() {
    let mut dev = device();
    let mut out = Outbox::new();
    boot(&mut dev, &mut out);
    dev.emcy().raise(0x7003, [0, 0, 0, 0, 2]);
    // Another module fails with the same code: one more entry and EMCY, one active error.
    assert!(dev.emcy().report(0x7003, [0, 0, 0, 0, 5]));
    dev.emcy().raise(0xFF03, [0; 5]);
    out.clear();
    dev.on_tick(ms(1), &mut out);
    assert_eq!(frames(&mut out).len(), 3);
    let od = dev.od();
    assert_eq!(od.get_unsigned(0x1003, 0), Some(3));
    assert_eq!(od.get_unsigned(0x1003, 1), Some(0x0081_FF03));
    assert_eq!(od.get_unsigned(0x1003, 2), Some(0x0501_7003));
    assert_eq!(od.get_unsigned(0x1003, 3), Some(0x0201_7003));
    // One clear ends the code for both modules.
    assert!(dev.emcy().clear(0x7003));
    assert!(!dev.emcy().is_active(0x7003));
}

#[test]
fn cia301_7_2_7_1_no_emcy_before_the_boot_up_message_is_on_the_bus() {
    let mut dev = device();
    let mut out = Outbox::new();
    boot(&mut dev, &mut out);
    // Error passive (EMCY 0x8120) stays active through a reset communication, which
    // raises it again: the EMCY (0x083) outranks the boot-up (0x703), so it must wait until
    // the boot-up message has been sent.
    dev.on_controller_event(ControllerEvent::ErrorPassive, ms(1), &mut out);
    out.clear();
    dev.on_frame(&Frame::std(0x000, &[0x82, 3]).unwrap(), ms(2), &mut out);
    dev.on_tick(ms(3), &mut out);
    let queued: Vec<Frame> = out.drain().collect();
    assert_eq!(queued, [Frame::std(0x703, &[0]).unwrap()]);
    dev.on_sent(&queued[0], ms(4), &mut out);
    dev.on_tick(ms(4), &mut out);
    let after: Vec<Frame> = out.drain().collect();
    assert_eq!(after.len(), 1, "{after:?}");
    assert_eq!(after[0].id().as_raw(), 0x083);
    assert_eq!(after[0].data_bytes()[..2], [0x20, 0x81]);
}

#[test]
fn cia301_7_2_7_an_emcy_raised_by_an_sdo_write_follows_the_sdo_answer() {
    let mut dev = device();
    let mut out = Outbox::new();
    boot(&mut dev, &mut out);
    out.clear();
    // Expedited download of 0x1017 (the application raises an error in reaction to the
    // write, in the same instant): the answer 0x583 goes out, the EMCY (0x083, whose
    // identifier would win arbitration) waits until the answer is on the bus.
    let request = Frame::std(0x603, &[0x2B, 0x17, 0x10, 0x00, 0xE8, 0x03, 0, 0]).unwrap();
    dev.on_frame(&request, ms(2), &mut out);
    dev.emcy().raise(0xFF00, [0; 5]);
    dev.on_tick(ms(2), &mut out);
    let queued: Vec<Frame> = out.drain().collect();
    assert_eq!(queued.len(), 1, "{queued:?}");
    assert_eq!(queued[0].id().as_raw(), 0x583);
    assert_eq!(queued[0].data_bytes()[0], 0x60);
    assert_eq!(
        dev.next_deadline().filter(|d| *d <= ms(2)),
        None,
        "nothing due until the answer is sent"
    );
    dev.on_sent(&queued[0], ms(3), &mut out);
    let after: Vec<Frame> = out.drain().collect();
    assert_eq!(after.len(), 1, "{after:?}");
    assert_eq!(after[0].id().as_raw(), 0x083);
    assert_eq!(after[0].data_bytes()[..2], [0x00, 0xFF]);
}
