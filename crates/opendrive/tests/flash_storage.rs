//! Manual §3.3 mux 0x3A and §2.3: what the drive saves reaches its flash storage, and a
//! drive built from that image powers up with it.
#![allow(clippy::unwrap_used)]

mod common;
use std::sync::{Arc, Mutex};

use cantwin_opendrive::params::P68;
use cantwin_opendrive::{Flash, FlashStorage, OpenDrive};
use common::*;

#[derive(Clone, Default)]
struct Memory(Arc<Mutex<Vec<String>>>);

impl FlashStorage for Memory {
    fn store(&mut self, image: &str) -> Result<(), String> {
        self.0.lock().unwrap().push(image.to_string());
        Ok(())
    }
}

#[test]
fn save_reaches_the_storage_and_a_new_drive_starts_from_it() {
    let mem = Memory::default();
    let drive =
        OpenDrive::new(Default::default(), Default::default()).with_storage(Box::new(mem.clone()));
    let mut r = rig_with(drive);
    r.run_ms(5);
    let images = mem.0.lock().unwrap().len();
    assert_eq!(images, 1, "the power-up image, once");
    // A working change alone is not stored; the save is.
    r.exchange(f(1100, &[0x00, 0x7C, 0x15]));
    assert_eq!(mem.0.lock().unwrap().len(), 1);
    r.exchange(f(1100, &[0x3A, 0x01, 0x00]));
    let last = mem.0.lock().unwrap().last().cloned().unwrap();
    assert!(last.contains("P68 = 1100\n"), "{last}");

    let mut next = OpenDrive::new(Default::default(), Default::default());
    next.drive_mut().set_flash(Flash::from_text(&last).unwrap());
    let mut r = rig_with(next);
    r.run_ms(1);
    assert_eq!(r.drive().param(P68), 1100);
    assert_eq!(r.exchange(f(1100, &[0x80])), ["44C#80", "44B#007C15"]);
}
