//! The CRC of SDO block transfers (CiA 301 §7.2.4.3.16): CRC-16-CCITT, polynomial
//! x^16 + x^12 + x^5 + 1 (0x1021), initial value 0, no reflection, no final XOR, over the
//! data bytes only (not the unused bytes of the last segment).

/// An incremental CRC-16-CCITT.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Crc16(u16);

const fn table() -> [u16; 256] {
    let mut t = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = (i as u16) << 8;
        let mut k = 0;
        while k < 8 {
            c = if c & 0x8000 != 0 {
                (c << 1) ^ 0x1021
            } else {
                c << 1
            };
            k += 1;
        }
        t[i] = c;
        i += 1;
    }
    t
}

static TABLE: [u16; 256] = table();

impl Crc16 {
    /// A CRC over no data (0).
    pub const fn new() -> Self {
        Crc16(0)
    }

    /// Resumes a CRC from an earlier [`Crc16::value`].
    pub const fn from_value(value: u16) -> Self {
        Crc16(value)
    }

    /// Feeds bytes.
    pub fn update(&mut self, data: &[u8]) {
        let mut c = self.0;
        for &b in data {
            c = (c << 8) ^ TABLE[usize::from((c >> 8) as u8 ^ b)];
        }
        self.0 = c;
    }

    /// The CRC so far.
    pub const fn value(self) -> u16 {
        self.0
    }

    /// The CRC of `data`.
    pub fn of(data: &[u8]) -> u16 {
        let mut c = Crc16::new();
        c.update(data);
        c.value()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia301_7_2_4_3_16_crc_check_value() {
        // CRC-16/XMODEM (poly 0x1021, init 0) of "123456789" is 0x31C3.
        assert_eq!(Crc16::of(b"123456789"), 0x31C3);
        assert_eq!(Crc16::of(b""), 0);
    }

    #[test]
    fn incremental_equals_one_shot() {
        let data: Vec<u8> = (0..=255).collect();
        let mut c = Crc16::new();
        for chunk in data.chunks(7) {
            c.update(chunk);
        }
        assert_eq!(c.value(), Crc16::of(&data));
    }
}
