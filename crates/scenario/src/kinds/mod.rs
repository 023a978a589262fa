//! The device kinds built into cantwin.

pub mod cia301;
pub mod generator;
pub mod opendrive;
