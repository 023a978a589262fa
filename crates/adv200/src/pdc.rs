//! The Process Data Channel (§1.3): 16 master→slave (M2S) and 16 slave→master (S2M)
//! channels of 16 or 32 bits, placed into up to four RPDOs and four TPDOs.
//!
//! Placement rules (§1.3.1, §1.3.2), applied at every drive reset:
//!
//! * filling starts at RPDO1 (TPDO1); a PDO holds 4 words, then the next one is filled, up to
//!   4 PDOs (16 words);
//! * a 32-bit item (Count 32, Fill 32, Mdplc 32) never straddles two PDOs: one that would is
//!   a configuration error (the manual says an alarm is raised without naming its code; the
//!   twin uses the channel's "data size is wrong" code, FF34+ / FF54+);
//! * a channel with `ipa = 0` and a value format (Count 16, Count 32, Eu) after an assigned
//!   datum closes the current PDO, so that PDOs shorter than 4 words can be made; it takes no
//!   room itself;
//! * **Fill 16 / Fill 32**: the N.B. of §1.3.1 says a Fill "is inserted all the same", but
//!   the manual's own example ("RPDO1 of 2 words and RPDO2 of 2 words": Eu, Count 16, then
//!   channel 3 `ipa = 0` Fill 32, then Count 32) only comes out as printed if that Fill closes
//!   the PDO. A master configured from the manual expects the example's sizes, so the twin
//!   follows the example: a Fill with `ipa = 0` directly after an assigned datum closes the
//!   PDO and takes no room (RPDO1 = M->S1 + M->S2, RPDO2 = M->S4, 4 bytes each). Elsewhere a
//!   Fill is inserted as padding of its size: in an RPDO a CiA 301 dummy entry (0x0006
//!   UNSIGNED16 / 0x0007 UNSIGNED32 sub 0, §7.4.7.1), whose data the card discards; a TPDO
//!   cannot map a dummy entry (CiA 301 allows them in RPDOs only), so there the Fill maps
//!   the channel's `Fieldbus S->Mn mon`, which the card keeps at 0;
//! * the first channel whose format is Not assigned ends the PDC;
//! * Mdplc 16 / Mdplc 32 channels carry data for an MDPLC application: M2S with `ipa = 0` is
//!   read from `Fieldbus M->Sn mon`; S2M whose `ipa` is `Dig Fieldbus S->Mn` sends that
//!   parameter (writing it as `ipa` sets the format to Mdplc, §1.3.3).
//!
//! * there is no floating-point format: the `sys` values the manual names (§1.3.1–§1.3.3) are
//!   Not assigned, Count 16/32, Eu, Fill 16/32 and Mdplc 16/32, and "32-bit data (long or
//!   float)" of §1.3.1 travels in a 32-bit channel as its bit pattern. Typed float access is
//!   DeviceNet's Drive Parameter Access (DB_T_FLOAT, §3.4.2), not the PDC.
//!
//! Each placed channel is mapped as `0x2000 + mon` sub 1 of its own channel with its width,
//! so the PDO mappings are ordinary CiA 301 mappings a master can read back.

use cantwin_canopen::od::DataType;

use crate::params::{ParamDb, ParamType, def, par};

/// A channel's `sys` format (§1.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Not assigned: ends the PDC.
    NotAssigned,
    /// A 16-bit value in internal units.
    Count16,
    /// A 32-bit value in internal units.
    Count32,
    /// A 16-bit value in engineering units.
    Eu,
    /// 16 bits of padding.
    Fill16,
    /// 32 bits of padding.
    Fill32,
    /// A 16-bit MDPLC variable.
    Mdplc16,
    /// A 32-bit MDPLC variable.
    Mdplc32,
}

impl Format {
    /// The format of a `sys` parameter value (see [`crate::params::CHANNEL_FORMATS`]).
    pub fn from_value(v: i64) -> Format {
        match v {
            1 => Format::Count16,
            2 => Format::Count32,
            3 => Format::Eu,
            4 => Format::Fill16,
            5 => Format::Fill32,
            6 => Format::Mdplc16,
            7 => Format::Mdplc32,
            _ => Format::NotAssigned,
        }
    }

    /// Width in bits (0 for Not assigned).
    pub const fn bits(self) -> u8 {
        match self {
            Format::NotAssigned => 0,
            Format::Count16 | Format::Eu | Format::Fill16 | Format::Mdplc16 => 16,
            Format::Count32 | Format::Fill32 | Format::Mdplc32 => 32,
        }
    }

    const fn is_fill(self) -> bool {
        matches!(self, Format::Fill16 | Format::Fill32)
    }

    const fn is_mdplc(self) -> bool {
        matches!(self, Format::Mdplc16 | Format::Mdplc32)
    }
}

/// Which way a channel goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dir {
    /// Master to slave (RPDOs).
    M2S,
    /// Slave to master (TPDOs).
    S2M,
}

/// A PDC configuration error: the sub-code of Opt Bus Fault (§1.5 table), per channel
/// n = 1..=16.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PdcFault {
    /// FF14 + (n−1): wrong object selected for mapping in M2S channel n.
    #[error("wrong object selected for mapping in channel M2S {0}")]
    M2sWrongObject(u16),
    /// FF24 + (n−1): more than one src points to M2S channel n.
    #[error("more than one src pointing to M2S channel {0}")]
    M2sMultipleSources(u16),
    /// FF34 + (n−1): M2S channel n data size is wrong (also a 32-bit item that would
    /// straddle two PDOs).
    #[error("M2S channel {0}: data size is wrong")]
    M2sSize(u16),
    /// FF44 + (n−1): invalid parameter in S2M channel n.
    #[error("invalid parameter in channel S2M {0}")]
    S2mInvalidParameter(u16),
    /// FF54 + (n−1): S2M channel n data size is wrong (or straddling).
    #[error("S2M channel {0}: data size is wrong")]
    S2mSize(u16),
    /// FF64 + (n−1): wrong object selected for mapping in S2M channel n.
    #[error("wrong object selected for mapping in channel S2M {0}")]
    S2mWrongObject(u16),
    /// FF74 + (n−1): M2S channel n makes the PDC longer than 16 words.
    #[error("M2S channel {0}: too many words in PDC")]
    M2sTooManyWords(u16),
    /// FF84 + (n−1): S2M channel n makes the PDC longer than 16 words.
    #[error("S2M channel {0}: too many words in PDC")]
    S2mTooManyWords(u16),
}

impl PdcFault {
    /// The Opt Bus Fault sub-code.
    pub const fn code(self) -> u16 {
        let (base, n) = match self {
            PdcFault::M2sWrongObject(n) => (0xFF14, n),
            PdcFault::M2sMultipleSources(n) => (0xFF24, n),
            PdcFault::M2sSize(n) => (0xFF34, n),
            PdcFault::S2mInvalidParameter(n) => (0xFF44, n),
            PdcFault::S2mSize(n) => (0xFF54, n),
            PdcFault::S2mWrongObject(n) => (0xFF64, n),
            PdcFault::M2sTooManyWords(n) => (0xFF74, n),
            PdcFault::S2mTooManyWords(n) => (0xFF84, n),
        };
        base + n - 1
    }
}

/// One channel placed in a PDO.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Item {
    /// Channel number, 1..=16.
    pub channel: u16,
    /// Width in bits, 16 or 32.
    pub bits: u8,
    /// Whether the value is signed: always for M2S (the master's data lands sign-extended
    /// in the channel's 32-bit `mon`), for S2M as the parameter the channel sends.
    pub signed: bool,
    /// Whether the channel is a Fill: padding, no datum (see the [module documentation](self)).
    pub fill: bool,
}

impl Item {
    /// The type of the channel's `mon` in the dictionary: as wide as the channel.
    pub const fn data_type(self) -> DataType {
        match (self.bits, self.signed) {
            (32, true) => DataType::Integer32,
            (32, false) => DataType::Unsigned32,
            (_, true) => DataType::Integer16,
            (_, false) => DataType::Unsigned16,
        }
    }

    /// The CiA 301 mapping entry: the channel's `mon` parameter (0x2000 + PAR, sub 1); for a
    /// Fill in an RPDO the dummy entry of its size (CiA 301 §7.4.7.1: the index of the
    /// UNSIGNED16 or UNSIGNED32 data type, sub-index 0).
    pub fn mapping_entry(self, dir: Dir) -> u32 {
        if self.fill && dir == Dir::M2S {
            let ty: u32 = if self.bits == 32 { 0x0007 } else { 0x0006 };
            return (ty << 16) | u32::from(self.bits);
        }
        let mon = match dir {
            Dir::M2S => par::m2s_mon(self.channel),
            Dir::S2M => par::s2m_mon(self.channel),
        };
        (u32::from(0x2000 + mon) << 16) | (1 << 8) | u32::from(self.bits)
    }
}

/// The placement of one direction's channels: up to four PDOs of up to four words.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Layout {
    /// The channels of PDO 1, 2, … (empty PDOs are not listed).
    pub pdos: Vec<Vec<Item>>,
}

impl Layout {
    /// The channels placed, in order.
    pub fn items(&self) -> impl Iterator<Item = Item> + '_ {
        self.pdos.iter().flatten().copied()
    }
}

/// Words per PDO (§1.3.1: "4 word").
pub const WORDS_PER_PDO: u32 = 4;
/// PDOs per direction.
pub const MAX_PDOS: u32 = 4;

/// Places `channels` (format and `ipa` of channel 1 first) by the rules of §1.3.
pub fn place(dir: Dir, channels: &[(Format, u16)]) -> Result<Layout, PdcFault> {
    let mut layout = Layout::default();
    let mut words = 0u32;
    // The channel before placed an assigned datum (not a Fill, not a placeholder).
    let mut after_datum = false;
    for (i, (f, ipa)) in channels.iter().enumerate() {
        let n = i as u16 + 1;
        if *f == Format::NotAssigned {
            break;
        }
        let placeholder = matches!(f, Format::Count16 | Format::Count32 | Format::Eu);
        if *ipa == 0 && (placeholder || (f.is_fill() && after_datum)) {
            if words % WORDS_PER_PDO != 0 {
                words = words.next_multiple_of(WORDS_PER_PDO);
            }
            after_datum = false;
            continue;
        }
        after_datum = !f.is_fill();
        let w = u32::from(f.bits()) / 16;
        if words + w > WORDS_PER_PDO * MAX_PDOS {
            return Err(match dir {
                Dir::M2S => PdcFault::M2sTooManyWords(n),
                Dir::S2M => PdcFault::S2mTooManyWords(n),
            });
        }
        let used = words % WORDS_PER_PDO;
        if used + w > WORDS_PER_PDO {
            return Err(match dir {
                Dir::M2S => PdcFault::M2sSize(n),
                Dir::S2M => PdcFault::S2mSize(n),
            });
        }
        let pdo = (words / WORDS_PER_PDO) as usize;
        if layout.pdos.len() <= pdo {
            layout.pdos.push(Vec::new());
        }
        layout.pdos[pdo].push(Item {
            channel: n,
            bits: f.bits(),
            signed: true,
            fill: f.is_fill(),
        });
        words += w;
    }
    Ok(layout)
}

/// Both directions' layouts, checked against the parameters.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Pdc {
    /// Master → slave (RPDOs).
    pub m2s: Layout,
    /// Slave → master (TPDOs).
    pub s2m: Layout,
}

fn channels(db: &ParamDb, sys: fn(u16) -> u16) -> Vec<(Format, u16)> {
    (1..=crate::params::CHANNELS)
        .map(|n| {
            (
                Format::from_value(db.value(sys(n))),
                db.value(sys(n) + 2) as u16,
            )
        })
        .collect()
}

/// Checks the channel parameters, applies the M2S "export" wiring (a channel whose `ipa`
/// names a src parameter sets that src to the channel's `mon` and shows it in `dest`) and
/// places both directions. The first error found is returned (M2S before S2M, lower channels
/// first).
pub fn configure(db: &mut ParamDb) -> Result<Pdc, PdcFault> {
    // The export wiring below rewrites src parameters.
    db.touch();
    let m2s_channels = channels(db, par::m2s_sys);
    let m2s = place(Dir::M2S, &m2s_channels)?;
    for item in m2s.items() {
        let n = item.channel;
        let f = m2s_channels[usize::from(n) - 1].0;
        let ipa = db.value(par::m2s_ipa(n)) as u16;
        let _ = db.force(par::m2s_dest(n), 0);
        if ipa == 0 || f.is_fill() {
            continue;
        }
        let Some(d) = def(ipa).filter(|_| !f.is_mdplc()) else {
            return Err(PdcFault::M2sWrongObject(n));
        };
        match d.ty {
            ParamType::Src { bits } if bits == item.bits => {
                let _ = db.force(ipa, i64::from(par::m2s_mon(n)));
                let _ = db.force(par::m2s_dest(n), i64::from(ipa));
            }
            ParamType::Src { bits: 16 | 32 } => return Err(PdcFault::M2sSize(n)),
            _ => return Err(PdcFault::M2sWrongObject(n)),
        }
    }
    for item in m2s.items() {
        let n = item.channel;
        let mon = i64::from(par::m2s_mon(n));
        let mut count = 0;
        for d in crate::params::catalog() {
            if let ParamType::Src { bits } = d.ty
                && db.value(d.par) == mon
            {
                count += 1;
                if bits != 1 && bits != item.bits {
                    return Err(PdcFault::M2sSize(n));
                }
            }
        }
        if count > 1 {
            return Err(PdcFault::M2sMultipleSources(n));
        }
    }
    let s2m_channels = channels(db, par::s2m_sys);
    let mut s2m = place(Dir::S2M, &s2m_channels)?;
    for item in s2m.pdos.iter_mut().flatten() {
        let n = item.channel;
        let f = s2m_channels[usize::from(n) - 1].0;
        let ipa = db.value(par::s2m_ipa(n)) as u16;
        if ipa == 0 || f.is_fill() || ipa == par::s2m_dig(n) {
            continue;
        }
        let Some(d) = def(ipa) else {
            return Err(PdcFault::S2mInvalidParameter(n));
        };
        if matches!(d.ty, ParamType::Src { .. }) || f.is_mdplc() {
            return Err(PdcFault::S2mWrongObject(n));
        }
        if d.ty.size() * 8 != usize::from(item.bits) {
            return Err(PdcFault::S2mSize(n));
        }
        item.signed = d.ty.signed();
    }
    Ok(Pdc { m2s, s2m })
}

/// The value an S2M channel sends: its `ipa` parameter (or `Dig Fieldbus S->Mn`), 0 for a
/// placeholder or fill.
pub fn s2m_value(db: &ParamDb, n: u16) -> i64 {
    let f = Format::from_value(db.value(par::s2m_sys(n)));
    let ipa = db.value(par::s2m_ipa(n)) as u16;
    if f.is_fill() || ipa == 0 {
        0
    } else {
        db.value(ipa)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use Format::*;

    #[test]
    fn fault_codes_span_the_manual_ranges() {
        assert_eq!(PdcFault::M2sWrongObject(1).code(), 0xFF14);
        assert_eq!(PdcFault::M2sWrongObject(16).code(), 0xFF23);
        assert_eq!(PdcFault::S2mTooManyWords(16).code(), 0xFF93);
    }

    #[test]
    fn placement_fills_four_words_per_pdo() {
        let l = place(
            Dir::M2S,
            &[
                (Count16, 1),
                (Count32, 1),
                (Count16, 1),
                (Eu, 1),
                (NotAssigned, 1),
                (Eu, 1),
            ],
        )
        .unwrap();
        assert_eq!(l.pdos.len(), 2);
        assert_eq!(l.pdos[0].len(), 3);
        assert_eq!(
            l.pdos[1],
            vec![Item {
                channel: 4,
                bits: 16,
                signed: true,
                fill: false,
            }]
        );
    }
}
