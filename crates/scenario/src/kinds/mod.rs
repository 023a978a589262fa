//! The device kinds built into cantwin.

pub mod adv200;
pub mod cia301;
mod common;
pub mod eds;
pub mod generator;
pub mod master;
pub mod opendrive;
pub mod tm3;
