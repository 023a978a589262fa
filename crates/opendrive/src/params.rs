//! The parameters (P) and connections (C) of application 003 with their ranges, defaults and
//! internal units (manual §1.1, §1.2, §2.3 defaults table).
//!
//! Values are integers in the internal unit of the manual's "rappresentazione interna"
//! column: a value with `decimals = 2` is stored in hundredths (P21 = 300 is 3.00 s).

use core::fmt;

/// Parameter (`P`) or connection (`C`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Class {
    /// A parameter, `Pnn`.
    P,
    /// A connection, `Cnn`.
    C,
}

/// A parameter or connection number, e.g. `P21` or `C48`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ParId {
    /// P or C.
    pub class: Class,
    /// The number.
    pub number: u16,
}

impl fmt::Display for ParId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = match self.class {
            Class::P => 'P',
            Class::C => 'C',
        };
        write!(f, "{c}{:02}", self.number)
    }
}

impl core::str::FromStr for ParId {
    type Err = ParamError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || ParamError::Unknown(s.to_string());
        let mut chars = s.trim().chars();
        let class = match chars.next().map(|c| c.to_ascii_uppercase()) {
            Some('P') => Class::P,
            Some('C') => Class::C,
            _ => return Err(bad()),
        };
        let number: u16 = chars.as_str().parse().map_err(|_| bad())?;
        let id = ParId { class, number };
        def(id).map(|d| d.id).ok_or_else(bad)
    }
}

const fn p(number: u16) -> ParId {
    ParId {
        class: Class::P,
        number,
    }
}
const fn c(number: u16) -> ParId {
    ParId {
        class: Class::C,
        number,
    }
}

/// P21 acceleration time CW (0.01 s).
pub const P21: ParId = p(21);
/// P22 deceleration time CW (0.01 s).
pub const P22: ParId = p(22);
/// P23 acceleration time CCW (0.01 s).
pub const P23: ParId = p(23);
/// P24 deceleration time CCW (0.01 s).
pub const P24: ParId = p(24);
/// P31 speed regulator proportional gain KpV (0.1).
pub const P31: ParId = p(31);
/// P32 speed regulator lead time constant TiV (0.1 ms).
pub const P32: ParId = p(32);
/// P61 motor rated current (0.1 % of the drive's rated current).
pub const P61: ParId = p(61);
/// P66 voltage drop on Rs (0.1 % of the motor's rated voltage).
pub const P66: ParId = p(66);
/// P68 maximum working frequency of the motor fMAX (0.1 % of its rated frequency), message
/// 2 mux 0x00.
pub const P68: ParId = p(68);
/// P70 thermal current limit (0.1 % of the motor's rated current), message 2 mux 0x19.
pub const P70: ParId = p(70);
/// P72 voltage of V/f point 1 (0.1 % of Vmax).
pub const P72: ParId = p(72);
/// P73 frequency of V/f point 1 (0.1 % of fmax).
pub const P73: ParId = p(73);
/// P94 time in limit before a STOP (0.1 s), message 2 mux 0x1B.
pub const P94: ParId = p(94);
/// P180 COB-ID of message 0's receive box.
pub const P180: ParId = p(180);
/// P181 COB-ID of message 0's transmit box.
pub const P181: ParId = p(181);
/// P183 COB-ID of message 1's receive box.
pub const P183: ParId = p(183);
/// P184 COB-ID of message 1's transmit box.
pub const P184: ParId = p(184);
/// P186 COB-ID of message 2's receive box.
pub const P186: ParId = p(186);
/// P187 COB-ID of message 2's transmit box.
pub const P187: ParId = p(187);
/// C00 automatic display of internal quantities.
pub const C00: ParId = c(0);
/// C01 meaning of logic input 1 (function 100 + value).
pub const C01: ParId = c(1);
/// C32 motor thermal protection blocks the drive.
pub const C32: ParId = c(32);
/// C35 automatic alarm reset at mains return.
pub const C35: ParId = c(35);
/// C40 reaction to the current threshold (0 none, 1 STOP), message 2 mux 0x18.
pub const C40: ParId = c(40);
/// C47 intelligent braking.
pub const C47: ParId = c(47);
/// C48 CAN bit rate (0 = 1M … 7 = 10k).
pub const C48: ParId = c(48);
/// C50 flying restart (search of a rotating motor).
pub const C50: ParId = c(50);
/// C52 references from the field bus.
pub const C52: ParId = c(52);
/// C63 save the parameters (message 2 mux 0x3A).
pub const C63: ParId = c(63);

/// The logic input meaning connection of input `n` (1–8): C01…C08.
pub const fn input_connection(n: u8) -> ParId {
    c(n as u16)
}

/// What the twin knows of one parameter or connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParDef {
    /// Its number.
    pub id: ParId,
    /// The manual's description (Italian, as printed).
    pub name: &'static str,
    /// Lowest value (internal unit).
    pub min: i32,
    /// Highest value (internal unit).
    pub max: i32,
    /// Default of application 003 (internal unit).
    pub default: i32,
    /// Decimal places of the internal unit.
    pub decimals: u8,
    /// Unit as the manual prints it.
    pub unit: &'static str,
    /// Reserved to TDE MACNO: DIP S1 does not load its default (manual §2.3).
    pub reserved: bool,
}

const fn d(
    id: ParId,
    name: &'static str,
    (min, max, default): (i32, i32, i32),
    decimals: u8,
    unit: &'static str,
    reserved: bool,
) -> ParDef {
    ParDef {
        id,
        name,
        min,
        max,
        default,
        decimals,
        unit,
        reserved,
    }
}

/// Every parameter and connection of the twin. Reserved ones are those the §2.3 table marks
/// with `r`; P70 and C40 (reached through message 2) and C63 are not in the manual's
/// tables and take the ranges documented in the crate docs.
pub const TABLE: &[ParDef] = &[
    d(
        P21,
        "Tempo di accelerazione CW",
        (1, 19999, 300),
        2,
        "s",
        false,
    ),
    d(
        P22,
        "Tempo di decelerazione CW",
        (1, 19999, 300),
        2,
        "s",
        false,
    ),
    d(
        P23,
        "Tempo di accelerazione CCW",
        (1, 19999, 300),
        2,
        "s",
        false,
    ),
    d(
        P24,
        "Tempo di decelerazione CCW",
        (1, 19999, 300),
        2,
        "s",
        false,
    ),
    d(
        P31,
        "KpV guadagno proporzionale regolatore di velocita",
        (5, 1000, 800),
        1,
        "",
        false,
    ),
    d(
        P32,
        "TiV costante di anticipo regolatore di velocita",
        (40, 3000, 100),
        1,
        "ms",
        false,
    ),
    d(
        P61,
        "Corrente nominale del motore",
        (100, 1000, 500),
        1,
        "% I nom Az",
        true,
    ),
    d(
        P66,
        "Caduta di tensione su Rs",
        (0, 200, 57),
        1,
        "% V nom mot",
        true,
    ),
    d(
        P68,
        "Frequenza massima lavoro del motore",
        (200, 4000, 1200),
        1,
        "% f nom mot",
        true,
    ),
    d(
        P70,
        "Limite corrente termica",
        (100, 2000, 1000),
        1,
        "% I nom mot",
        false,
    ),
    d(
        P72,
        "Tensione del punto 1 della caratteristica V/f",
        (0, 1000, 1000),
        1,
        "% Vmax",
        true,
    ),
    d(
        P73,
        "Frequenza del punto 1 della caratteristica V/f",
        (0, 948, 833),
        1,
        "% fmax",
        true,
    ),
    d(
        P94,
        "Tempo di funzionamento in limite",
        (10, 1000, 150),
        1,
        "s",
        true,
    ),
    d(
        P180,
        "Identificatore-COB receive box Messaggio 0",
        (0, 1760, 440),
        0,
        "",
        false,
    ),
    d(
        P181,
        "Identificatore-COB transmit box Messaggio 0",
        (0, 1760, 439),
        0,
        "",
        false,
    ),
    d(
        P183,
        "Identificatore-COB receive box Messaggio 1",
        (0, 1760, 430),
        0,
        "",
        false,
    ),
    d(
        P184,
        "Identificatore-COB transmit box Messaggio 1",
        (0, 1760, 429),
        0,
        "",
        false,
    ),
    d(
        P186,
        "Identificatore-COB receive box Messaggio 2",
        (0, 1760, 1100),
        0,
        "",
        false,
    ),
    d(
        P187,
        "Identificatore-COB transmit box Messaggio 2",
        (0, 1760, 1099),
        0,
        "",
        false,
    ),
    d(
        C00,
        "Visione automatica grandezze interne",
        (0, 63, 21),
        0,
        "",
        false,
    ),
    d(
        c(1),
        "Significato ingresso logico 1",
        (0, 28, 23),
        0,
        "",
        true,
    ),
    d(
        c(2),
        "Significato ingresso logico 2",
        (0, 28, 24),
        0,
        "",
        true,
    ),
    d(
        c(3),
        "Significato ingresso logico 3",
        (0, 28, 25),
        0,
        "",
        true,
    ),
    d(
        c(4),
        "Significato ingresso logico 4",
        (0, 28, 0),
        0,
        "",
        true,
    ),
    d(
        c(5),
        "Significato ingresso logico 5",
        (0, 28, 26),
        0,
        "",
        true,
    ),
    d(
        c(6),
        "Significato ingresso logico 6",
        (0, 28, 27),
        0,
        "",
        true,
    ),
    d(
        c(7),
        "Significato ingresso logico 7",
        (0, 28, 28),
        0,
        "",
        true,
    ),
    d(
        c(8),
        "Significato ingresso logico 8",
        (0, 28, 20),
        0,
        "",
        true,
    ),
    d(
        C32,
        "Termico motore = Blocco azionamento",
        (0, 1, 1),
        0,
        "",
        false,
    ),
    d(
        C35,
        "Reset automatico degli allarmi al rientro della rete",
        (0, 1, 1),
        0,
        "",
        false,
    ),
    d(
        C40,
        "Reazione alla soglia di corrente",
        (0, 1, 0),
        0,
        "",
        false,
    ),
    d(
        C47,
        "Abilita frenatura intelligente",
        (0, 1, 1),
        0,
        "",
        true,
    ),
    d(
        C48,
        "Configurazione BAUD RATE CAN Bus",
        (0, 7, 1),
        0,
        "",
        true,
    ),
    d(
        C50,
        "Abilitazione ricerca motore in rotazione",
        (0, 1, 1),
        0,
        "",
        true,
    ),
    d(
        C52,
        "Abilitazione dei riferimenti da FIELD-BUS",
        (0, 1, 1),
        0,
        "",
        true,
    ),
    d(C63, "Salvataggio dei dati", (0, 1, 0), 0, "", false),
];

/// The definition of `id`.
pub fn def(id: ParId) -> Option<&'static ParDef> {
    TABLE.iter().find(|d| d.id == id)
}

/// A bad parameter access.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ParamError {
    /// No such parameter or connection.
    #[error("no parameter or connection {0}")]
    Unknown(String),
    /// Outside its range.
    #[error("{id} = {value} is outside {min}..={max} (internal units)")]
    OutOfRange {
        /// Which.
        id: ParId,
        /// The value refused.
        value: i32,
        /// Lowest allowed.
        min: i32,
        /// Highest allowed.
        max: i32,
    },
}

/// A set of values, one per [`TABLE`] entry.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Params {
    values: Vec<i32>,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            values: TABLE.iter().map(|d| d.default).collect(),
        }
    }
}

impl Params {
    fn index(id: ParId) -> Result<usize, ParamError> {
        TABLE
            .iter()
            .position(|d| d.id == id)
            .ok_or_else(|| ParamError::Unknown(id.to_string()))
    }

    /// The value of `id` (0 for an unknown id, which the constants never are).
    pub fn get(&self, id: ParId) -> i32 {
        Self::index(id)
            .ok()
            .and_then(|i| self.values.get(i))
            .copied()
            .unwrap_or(0)
    }

    /// Set `id` within its range.
    pub fn set(&mut self, id: ParId, value: i32) -> Result<(), ParamError> {
        let i = Self::index(id)?;
        let d = &TABLE[i];
        if !(d.min..=d.max).contains(&value) {
            return Err(ParamError::OutOfRange {
                id,
                value,
                min: d.min,
                max: d.max,
            });
        }
        self.values[i] = value;
        Ok(())
    }

    /// Load the defaults of every non-reserved entry (DIP S1, manual §2.3).
    pub fn load_free_defaults(&mut self) {
        for (v, d) in self.values.iter_mut().zip(TABLE) {
            if !d.reserved {
                *v = d.default;
            }
        }
    }

    /// Every entry with its value.
    pub fn iter(&self) -> impl Iterator<Item = (&'static ParDef, i32)> + '_ {
        TABLE.iter().zip(self.values.iter().copied())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_of_the_manual() {
        let p = Params::default();
        assert_eq!(p.get(P21), 300);
        assert_eq!(p.get(P180), 440);
        assert_eq!(p.get(P187), 1099);
        assert_eq!(p.get(C48), 1);
        assert_eq!(p.get(input_connection(4)), 0);
        assert_eq!(p.get(input_connection(8)), 20);
        assert!(TABLE.iter().all(|d| (d.min..=d.max).contains(&d.default)));
    }

    #[test]
    fn set_checks_the_range_and_ids_parse() {
        let mut p = Params::default();
        assert!(matches!(
            p.set(P180, 1761),
            Err(ParamError::OutOfRange { max: 1760, .. })
        ));
        p.set(P21, 1).unwrap();
        assert_eq!(p.get(P21), 1);
        assert_eq!("p21".parse::<ParId>(), Ok(P21));
        assert_eq!("C48".parse::<ParId>(), Ok(C48));
        assert!("P99".parse::<ParId>().is_err());
        assert_eq!(C01.to_string(), "C01");
    }
}
