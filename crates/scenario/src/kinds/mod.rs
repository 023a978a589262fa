//! The device kinds built into cantwin.

pub mod adv200;
pub mod cia301;
pub mod cia402;
pub mod cia402_master;
mod common;
pub mod eds;
pub mod generator;
pub mod lss;
pub mod master;
pub mod opendrive;
pub mod tm3;

use crate::registry::{DeviceKind, Registry};

/// Every kind built into cantwin, in the order `cantwin scenario kinds` lists them.
fn builtin_kinds() -> Vec<Box<dyn DeviceKind>> {
    vec![
        Box::new(generator::Generator),
        Box::new(master::MasterKind),
        Box::new(cia402_master::Cia402MasterKind),
        Box::new(cia301::Cia301::default()),
        Box::new(opendrive::OpenDriveKind),
        Box::new(adv200::Adv200Kind::default()),
        Box::new(tm3::Tm3Kind::default()),
        Box::new(eds::EdsKind),
        Box::new(cia402::Cia402Kind),
    ]
}

impl Registry {
    /// Every kind built into cantwin.
    pub fn builtin() -> Self {
        let mut r = Registry::new();
        for kind in builtin_kinds() {
            r.register(kind);
        }
        r
    }
}

impl Default for Registry {
    fn default() -> Self {
        Registry::builtin()
    }
}
