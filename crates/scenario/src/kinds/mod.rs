//! The device kinds built into cantwin.

pub mod generator;
