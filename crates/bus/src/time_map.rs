//! The mapping between bus time and wall time, which paced simulations publish and captures
//! use to stamp frames.

use std::time::SystemTime;

use cantwin_can::{Duration, Instant};

/// The mapping between bus time and wall time in a paced simulation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimeMap {
    /// A bus instant …
    pub bus_origin: Instant,
    /// … and the wall time it corresponds to.
    pub wall_origin: SystemTime,
}

impl TimeMap {
    /// The wall time of a bus instant.
    pub fn wall_time(&self, t: Instant) -> SystemTime {
        if t >= self.bus_origin {
            self.wall_origin + std::time::Duration::from(t - self.bus_origin)
        } else {
            self.wall_origin - std::time::Duration::from(self.bus_origin - t)
        }
    }

    /// The bus instant of a wall time (saturating at the bus's start and end of time).
    pub fn bus_time(&self, wall: SystemTime) -> Instant {
        match wall.duration_since(self.wall_origin) {
            Ok(after) => self.bus_origin + Duration::from(after),
            Err(e) => self.bus_origin - Duration::from(e.duration()),
        }
    }

    /// The wall time of a bus instant in nanoseconds since the UNIX epoch (0 before it).
    pub fn unix_nanos(&self, t: Instant) -> u128 {
        self.wall_time(t)
            .duration_since(SystemTime::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos())
    }
}
