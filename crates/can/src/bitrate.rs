//! The bit rates of classic CAN used by CANopen (CiA 301 §7.2, CiA 305 table 1) and
//! DeviceNet (125/250/500 kbit/s).

use crate::time::Duration;
use core::{fmt, str::FromStr};

/// A bit rate that is not one of the supported nine.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unsupported CAN bit rate {0:?}: use one of 10k, 20k, 50k, 100k, 125k, 250k, 500k, 800k, 1M"
)]
pub struct BitRateError(pub String);

/// A CAN bit rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum BitRate {
    /// 10 kbit/s
    R10K,
    /// 20 kbit/s
    R20K,
    /// 50 kbit/s
    R50K,
    /// 100 kbit/s
    R100K,
    /// 125 kbit/s
    R125K,
    /// 250 kbit/s
    R250K,
    /// 500 kbit/s
    R500K,
    /// 800 kbit/s
    R800K,
    /// 1 Mbit/s
    R1M,
}

impl BitRate {
    /// All supported rates, slowest first.
    pub const ALL: [BitRate; 9] = [
        BitRate::R10K,
        BitRate::R20K,
        BitRate::R50K,
        BitRate::R100K,
        BitRate::R125K,
        BitRate::R250K,
        BitRate::R500K,
        BitRate::R800K,
        BitRate::R1M,
    ];

    /// Bits per second.
    pub const fn bits_per_second(self) -> u32 {
        match self {
            BitRate::R10K => 10_000,
            BitRate::R20K => 20_000,
            BitRate::R50K => 50_000,
            BitRate::R100K => 100_000,
            BitRate::R125K => 125_000,
            BitRate::R250K => 250_000,
            BitRate::R500K => 500_000,
            BitRate::R800K => 800_000,
            BitRate::R1M => 1_000_000,
        }
    }

    /// The rate for a number of bits per second, if supported.
    pub fn from_bits_per_second(bps: u32) -> Option<BitRate> {
        BitRate::ALL
            .into_iter()
            .find(|r| r.bits_per_second() == bps)
    }

    /// The nominal bit time. Every supported rate divides a second into whole nanoseconds.
    pub const fn bit_time(self) -> Duration {
        Duration::from_nanos(1_000_000_000 / self.bits_per_second() as u64)
    }

    /// How long `bits` bits occupy the bus.
    pub const fn duration_of(self, bits: u32) -> Duration {
        Duration::from_nanos(self.bit_time().as_nanos() * bits as u64)
    }
}

impl fmt::Display for BitRate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BitRate::R1M => f.write_str("1M"),
            other => write!(f, "{}k", other.bits_per_second() / 1000),
        }
    }
}

impl FromStr for BitRate {
    type Err = BitRateError;

    /// Accepts `500k`, `500K`, `500kbit`, `1M`, `1m`, `1000k` or a plain `500000`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim().to_ascii_lowercase();
        let t = t
            .strip_suffix("bit/s")
            .or_else(|| t.strip_suffix("bps"))
            .unwrap_or(&t);
        let t = t.strip_suffix("bit").unwrap_or(t);
        let bps = if let Some(k) = t.strip_suffix('k') {
            k.parse::<u32>().ok().and_then(|k| k.checked_mul(1_000))
        } else if let Some(m) = t.strip_suffix('m') {
            m.parse::<u32>().ok().and_then(|m| m.checked_mul(1_000_000))
        } else {
            t.parse::<u32>().ok()
        };
        bps.and_then(BitRate::from_bits_per_second)
            .ok_or_else(|| BitRateError(s.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bit_times_are_exact() {
        let ns: Vec<u64> = BitRate::ALL
            .iter()
            .map(|r| r.bit_time().as_nanos())
            .collect();
        assert_eq!(
            ns,
            [
                100_000, 50_000, 20_000, 10_000, 8_000, 4_000, 2_000, 1_250, 1_000
            ]
        );
        for r in BitRate::ALL {
            assert_eq!(
                r.bit_time().as_nanos() * u64::from(r.bits_per_second()),
                1_000_000_000
            );
        }
    }

    #[test]
    fn parses_common_spellings() {
        assert_eq!("500k".parse::<BitRate>().unwrap(), BitRate::R500K);
        assert_eq!("1M".parse::<BitRate>().unwrap(), BitRate::R1M);
        assert_eq!("1000k".parse::<BitRate>().unwrap(), BitRate::R1M);
        assert_eq!("125000".parse::<BitRate>().unwrap(), BitRate::R125K);
        assert_eq!("800kbit/s".parse::<BitRate>().unwrap(), BitRate::R800K);
        assert!("33k".parse::<BitRate>().is_err());
        assert!("fast".parse::<BitRate>().is_err());
        for r in BitRate::ALL {
            assert_eq!(r.to_string().parse::<BitRate>().unwrap(), r);
        }
    }
}
