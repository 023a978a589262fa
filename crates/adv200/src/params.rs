//! The drive's parameter database: every parameter the EXP-CAN/DN-ADV manual names, and the
//! command, reference, I/O and motor parameters its worked example (§1.6) uses.
//!
//! Parameter numbers the manual prints are used as printed: the fieldbus menu 4000–4014
//! (§1.2), `Dig Ramp ref 1` 600 and `Ramp ref 1 src` 610 (§1.3, §1.4), `Compare input 1 src`
//! 3660 (§1.3.1), `Word decomp src` 4452 (§1.3.1), `Dig Fieldbus S->Mn` 4184 + (n−1)·10
//! (§1.3.3) and `Slot 3 card type` 534. Where the OCR'd tables are garbled, the twin chooses,
//! consistently:
//!
//! * M2S channel *n* occupies 4020 + (n−1)·10: `sys` +0, `ipa` +2, `mon` +4, `dest` +6;
//!   S2M channel *n* occupies 4180 + (n−1)·10: `sys` +0, `ipa` +2, `Dig Fieldbus S->Mn` +4
//!   (4184, as §1.3.3 prints), `mon` +6. The 16 M2S blocks end where S2M begins.
//! * WordComp: `Bit k src` at 4400 + 2k (k = 0..15) and its output `Word comp mon` at 4432;
//!   WordDecomp: `Word decomp mon` 4450, `Word decomp src` 4452, `Word bit k decomp` at
//!   4454 + 2k.
//! * Commands, I/O and motor parameters (numbers the manual does not print) are listed in
//!   [`catalog`]; every one is the twin's own numbering.
//! * A "src" parameter holds the number of the parameter it takes its value from (0 = Null);
//!   internal units equal engineering units (the MDPlc conversion tables the manual refers to
//!   are not part of it), so `Eu` and `Count` formats carry the same numbers.
//! * Booleans and enumerations are 16-bit unsigned on the bus.

use std::sync::LazyLock;

use cantwin_canopen::AbortCode;
use cantwin_canopen::od::DataType;

/// A parameter's type on the bus and in the drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamType {
    /// 16-bit unsigned.
    U16,
    /// 16-bit signed.
    I16,
    /// 32-bit unsigned.
    U32,
    /// 32-bit signed.
    I32,
    /// A boolean (0/1), 16-bit on the bus.
    Bool,
    /// An enumeration, 16-bit on the bus: its values and names.
    Enum(&'static [(u16, &'static str)]),
    /// A source selector: the number of the parameter feeding it (0 = Null); the value it
    /// feeds is `bits` wide (1 for a boolean input).
    Src {
        /// Width of the value fed: 1, 16 or 32.
        bits: u8,
    },
}

impl ParamType {
    /// Bytes on the bus (the size an EDS declares and an upload returns).
    pub const fn size(self) -> usize {
        match self {
            ParamType::U32 | ParamType::I32 => 4,
            _ => 2,
        }
    }

    /// Whether the value is signed.
    pub const fn signed(self) -> bool {
        matches!(self, ParamType::I16 | ParamType::I32)
    }

    /// The CANopen data type of 0x2000 + PAR sub 1.
    pub const fn data_type(self) -> DataType {
        match self {
            ParamType::I16 => DataType::Integer16,
            ParamType::U32 => DataType::Unsigned32,
            ParamType::I32 => DataType::Integer32,
            _ => DataType::Unsigned16,
        }
    }

    /// The widest range the type holds.
    pub const fn range(self) -> (i64, i64) {
        match self {
            ParamType::I16 => (i16::MIN as i64, i16::MAX as i64),
            ParamType::U32 => (0, u32::MAX as i64),
            ParamType::I32 => (i32::MIN as i64, i32::MAX as i64),
            ParamType::Bool => (0, 1),
            _ => (0, u16::MAX as i64),
        }
    }
}

/// Who may write a parameter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamAccess {
    /// Read and write.
    Rw,
    /// Read only (a monitor).
    Ro,
}

/// One parameter's definition.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParamDef {
    /// Its number (PAR).
    pub par: u16,
    /// Its name as the drive's menu shows it.
    pub name: String,
    /// Its type.
    pub ty: ParamType,
    /// Its unit ("" when it has none).
    pub unit: &'static str,
    /// Factory default.
    pub default: i64,
    /// Lowest value accepted.
    pub min: i64,
    /// Highest value accepted.
    pub max: i64,
    /// Who may write it.
    pub access: ParamAccess,
    /// Whether a write only takes effect after the next drive reset (§1.2: every fieldbus
    /// parameter).
    pub after_reset: bool,
}

impl ParamDef {
    fn new(par: u16, name: impl Into<String>, ty: ParamType) -> Self {
        let (min, max) = match ty {
            ParamType::Enum(values) => (
                values.iter().map(|v| i64::from(v.0)).min().unwrap_or(0),
                values.iter().map(|v| i64::from(v.0)).max().unwrap_or(0),
            ),
            ParamType::Src { .. } => (0, 16383),
            _ => ty.range(),
        };
        ParamDef {
            par,
            name: name.into(),
            ty,
            unit: "",
            default: 0,
            min,
            max,
            access: ParamAccess::Rw,
            after_reset: false,
        }
    }
    fn unit(mut self, unit: &'static str) -> Self {
        self.unit = unit;
        self
    }
    fn default(mut self, v: i64) -> Self {
        self.default = v;
        self
    }
    fn limits(mut self, min: i64, max: i64) -> Self {
        self.min = min;
        self.max = max;
        self
    }
    fn ro(mut self) -> Self {
        self.access = ParamAccess::Ro;
        self
    }
    fn after_reset(mut self) -> Self {
        self.after_reset = true;
        self
    }

    /// The SDO index of the parameter: PAR + 0x2000 (§1.4).
    pub const fn sdo_index(&self) -> u16 {
        0x2000 + self.par
    }

    /// The name of an enumeration value.
    pub fn enum_name(&self, value: i64) -> Option<&'static str> {
        match self.ty {
            ParamType::Enum(values) => values.iter().find(|v| i64::from(v.0) == value).map(|v| v.1),
            _ => None,
        }
    }

    /// The value of an enumeration's name (case-insensitive, blanks ignored).
    pub fn enum_value(&self, name: &str) -> Option<i64> {
        let norm = |s: &str| s.to_ascii_lowercase().replace([' ', '_', '-'], "");
        let want = norm(name);
        match self.ty {
            ParamType::Enum(values) => values
                .iter()
                .find(|v| norm(v.1) == want)
                .map(|v| i64::from(v.0)),
            _ => None,
        }
    }
}

/// Values of PAR 4000 `Fieldbus type`.
pub const FIELDBUS_TYPES: &[(u16, &str)] = &[
    (0, "Off"),
    (1, "CANopen"),
    (2, "DeviceNet"),
    (3, "DS402"),
    (4, "Profibus"),
];
/// Values of PAR 4004 `Fieldbus baudrate` (§1.2: CANopen uses 125k, 250k, 500k, 1M).
pub const BAUDRATES: &[(u16, &str)] = &[
    (0, "None"),
    (1, "125k"),
    (2, "250k"),
    (3, "500k"),
    (4, "1M"),
];
/// Off/On.
pub const OFF_ON: &[(u16, &str)] = &[(0, "Off"), (1, "On")];
/// Values of PAR 4014 `Fieldbus state` (§1.2).
pub const FIELDBUS_STATES: &[(u16, &str)] =
    &[(0, "Stop"), (1, "Pre-Operational"), (2, "Operational")];
/// Values of a channel's `sys` (format) parameter (§1.3).
pub const CHANNEL_FORMATS: &[(u16, &str)] = &[
    (0, "Not assigned"),
    (1, "Count 16"),
    (2, "Count 32"),
    (3, "Eu"),
    (4, "Fill 16"),
    (5, "Fill 32"),
    (6, "Mdplc 16"),
    (7, "Mdplc 32"),
];
/// Values of PAR 1000 `Commands remote sel`.
pub const COMMAND_SOURCES: &[(u16, &str)] = &[(0, "Terminals"), (1, "Digital")];
/// Values of PAR 534 `Slot 3 card type`.
pub const CARD_TYPES: &[(u16, &str)] = &[(0, "None"), (4, "Can/Dnet"), (255, "Unknown")];

/// Parameter numbers the model uses.
pub mod par {
    /// Ramp output, rpm.
    pub const RAMP_OUTPUT: u16 = 250;
    /// Motor speed, rpm.
    pub const MOTOR_SPEED: u16 = 260;
    /// Output current, 0.1 A.
    pub const OUTPUT_CURRENT: u16 = 270;
    /// Motor thermal load, %.
    pub const MOTOR_THERMAL: u16 = 280;
    /// Slot 3 card type.
    pub const SLOT3_CARD: u16 = 534;
    /// Dig ramp ref 1, rpm.
    pub const DIG_RAMP_REF_1: u16 = 600;
    /// Ramp ref 1 src.
    pub const RAMP_REF_1_SRC: u16 = 610;
    /// Full scale speed, rpm.
    pub const FULL_SCALE_SPEED: u16 = 680;
    /// Acceleration 0, rpm/s.
    pub const ACCELERATION: u16 = 700;
    /// Deceleration 0, rpm/s.
    pub const DECELERATION: u16 = 702;
    /// Fast stop deceleration, rpm/s.
    pub const FAST_STOP_DECEL: u16 = 710;
    /// Speed zero threshold, rpm.
    pub const SPEED_ZERO_THR: u16 = 900;
    /// Speed is zero (monitor).
    pub const SPEED_IS_ZERO: u16 = 902;
    /// Commands remote sel.
    pub const COMMANDS_REMOTE_SEL: u16 = 1000;
    /// Dig enable src.
    pub const DIG_ENABLE_SRC: u16 = 1040;
    /// Dig start src.
    pub const DIG_START_SRC: u16 = 1042;
    /// Enable state (monitor).
    pub const ENABLE_STATE: u16 = 1050;
    /// Drive ok (monitor).
    pub const DRIVE_OK: u16 = 1052;
    /// Run state (monitor).
    pub const RUN_STATE: u16 = 1054;
    /// Alarm reset (command: write 1).
    pub const ALARM_RESET: u16 = 1070;
    /// Active alarm (monitor, EMCY code).
    pub const ACTIVE_ALARM: u16 = 1072;
    /// Digital input mon (bit k−1 = input k).
    pub const DIGITAL_INPUT_MON: u16 = 1100;
    /// Digital output mon (bit k−1 = output k).
    pub const DIGITAL_OUTPUT_MON: u16 = 1300;
    /// Analog input 1 mon.
    pub const ANALOG_INPUT_1: u16 = 1500;
    /// Analog input 2 mon.
    pub const ANALOG_INPUT_2: u16 = 1550;
    /// Rated current, 0.1 A.
    pub const RATED_CURRENT: u16 = 2000;
    /// Motor thermal time constant, s.
    pub const THERMAL_TC: u16 = 2004;
    /// Load torque (simulation input), % of rated.
    pub const LOAD: u16 = 2010;
    /// Compare input 1 src (§1.3.1).
    pub const COMPARE_INPUT_1_SRC: u16 = 3660;
    /// Fieldbus type.
    pub const FIELDBUS_TYPE: u16 = 4000;
    /// Fieldbus baudrate.
    pub const FIELDBUS_BAUDRATE: u16 = 4004;
    /// Fieldbus address.
    pub const FIELDBUS_ADDRESS: u16 = 4006;
    /// Fieldbus M->S enable.
    pub const FIELDBUS_MS_ENABLE: u16 = 4010;
    /// Fieldbus alarm mode.
    pub const FIELDBUS_ALARM_MODE: u16 = 4012;
    /// Fieldbus state.
    pub const FIELDBUS_STATE: u16 = 4014;
    /// Word comp mon.
    pub const WORD_COMP_MON: u16 = 4432;
    /// Word decomp mon.
    pub const WORD_DECOMP_MON: u16 = 4450;
    /// Word decomp src.
    pub const WORD_DECOMP_SRC: u16 = 4452;

    /// Digital input k mon (k = 1..=8).
    pub const fn digital_input(k: u16) -> u16 {
        1110 + 2 * (k - 1)
    }
    /// Digital output k src (k = 1..=4).
    pub const fn digital_output_src(k: u16) -> u16 {
        1310 + 2 * (k - 1)
    }
    /// WordComp `Bit k src` (k = 0..=15).
    pub const fn word_comp_bit_src(k: u16) -> u16 {
        4400 + 2 * k
    }
    /// WordDecomp `Word bit k decomp` (k = 0..=15).
    pub const fn word_decomp_bit(k: u16) -> u16 {
        4454 + 2 * k
    }
    /// First parameter of M2S channel n (1..=16): its `sys`.
    pub const fn m2s_sys(n: u16) -> u16 {
        4020 + 10 * (n - 1)
    }
    /// M2S channel n `ipa`.
    pub const fn m2s_ipa(n: u16) -> u16 {
        m2s_sys(n) + 2
    }
    /// M2S channel n `mon`.
    pub const fn m2s_mon(n: u16) -> u16 {
        m2s_sys(n) + 4
    }
    /// M2S channel n `dest`.
    pub const fn m2s_dest(n: u16) -> u16 {
        m2s_sys(n) + 6
    }
    /// S2M channel n (1..=16) `sys`.
    pub const fn s2m_sys(n: u16) -> u16 {
        4180 + 10 * (n - 1)
    }
    /// S2M channel n `ipa`.
    pub const fn s2m_ipa(n: u16) -> u16 {
        s2m_sys(n) + 2
    }
    /// `Dig Fieldbus S->Mn` = 4184 + (n−1)·10 (§1.3.3).
    pub const fn s2m_dig(n: u16) -> u16 {
        s2m_sys(n) + 4
    }
    /// S2M channel n `mon`.
    pub const fn s2m_mon(n: u16) -> u16 {
        s2m_sys(n) + 6
    }
}

/// Number of PDC channels each way (§1.3).
pub const CHANNELS: u16 = 16;

fn build_catalog() -> Vec<ParamDef> {
    use ParamType::*;
    let mut v = vec![
        ParamDef::new(par::RAMP_OUTPUT, "Ramp output", I16)
            .unit("rpm")
            .ro(),
        ParamDef::new(par::MOTOR_SPEED, "Motor speed", I16)
            .unit("rpm")
            .ro(),
        ParamDef::new(par::OUTPUT_CURRENT, "Output current", I16)
            .unit("0.1 A")
            .ro(),
        ParamDef::new(par::MOTOR_THERMAL, "Motor thermal load", U16)
            .unit("%")
            .ro(),
        ParamDef::new(par::SLOT3_CARD, "Slot 3 card type", Enum(CARD_TYPES))
            .default(4)
            .ro(),
        ParamDef::new(par::DIG_RAMP_REF_1, "Dig ramp ref 1", I16)
            .unit("rpm")
            .limits(-8000, 8000),
        ParamDef::new(par::RAMP_REF_1_SRC, "Ramp ref 1 src", Src { bits: 16 })
            .default(i64::from(par::DIG_RAMP_REF_1)),
        ParamDef::new(par::FULL_SCALE_SPEED, "Full scale speed", U16)
            .unit("rpm")
            .default(1500)
            .limits(50, 8000),
        ParamDef::new(par::ACCELERATION, "Acceleration 0", U16)
            .unit("rpm/s")
            .default(1000)
            .limits(1, 32000),
        ParamDef::new(par::DECELERATION, "Deceleration 0", U16)
            .unit("rpm/s")
            .default(1000)
            .limits(1, 32000),
        ParamDef::new(par::FAST_STOP_DECEL, "Fast stop decel", U16)
            .unit("rpm/s")
            .default(3000)
            .limits(1, 32000),
        ParamDef::new(par::SPEED_ZERO_THR, "Speed zero thr", U16)
            .unit("rpm")
            .default(10)
            .limits(0, 1000),
        ParamDef::new(par::SPEED_IS_ZERO, "Speed is zero", Bool).ro(),
        ParamDef::new(
            par::COMMANDS_REMOTE_SEL,
            "Commands remote sel",
            Enum(COMMAND_SOURCES),
        ),
        ParamDef::new(par::DIG_ENABLE_SRC, "Dig enable src", Src { bits: 1 }),
        ParamDef::new(par::DIG_START_SRC, "Dig start src", Src { bits: 1 }),
        ParamDef::new(par::ENABLE_STATE, "Enable state", Bool).ro(),
        ParamDef::new(par::DRIVE_OK, "Drive ok", Bool).ro(),
        ParamDef::new(par::RUN_STATE, "Run state", Bool).ro(),
        ParamDef::new(par::ALARM_RESET, "Alarm reset", Bool),
        ParamDef::new(par::ACTIVE_ALARM, "Active alarm", U16).ro(),
        ParamDef::new(par::DIGITAL_INPUT_MON, "Digital input mon", U16).ro(),
        ParamDef::new(par::DIGITAL_OUTPUT_MON, "Digital output mon", U16).ro(),
        ParamDef::new(par::ANALOG_INPUT_1, "Analog inp 1 mon", I16)
            .unit("cnt")
            .limits(-16384, 16384)
            .ro(),
        ParamDef::new(par::ANALOG_INPUT_2, "Analog inp 2 mon", I16)
            .unit("cnt")
            .limits(-16384, 16384)
            .ro(),
        ParamDef::new(par::RATED_CURRENT, "Rated current", U16)
            .unit("0.1 A")
            .default(100)
            .limits(1, 30000),
        ParamDef::new(par::THERMAL_TC, "Motor thermal tc", U16)
            .unit("s")
            .default(120)
            .limits(1, 3600),
        ParamDef::new(par::LOAD, "Load torque sim", I16)
            .unit("%")
            .limits(-300, 300),
        ParamDef::new(
            par::COMPARE_INPUT_1_SRC,
            "Compare input 1 src",
            Src { bits: 32 },
        ),
        ParamDef::new(par::FIELDBUS_TYPE, "Fieldbus type", Enum(FIELDBUS_TYPES)).after_reset(),
        ParamDef::new(par::FIELDBUS_BAUDRATE, "Fieldbus baudrate", Enum(BAUDRATES)).after_reset(),
        // §1.2: "valori ammessi da 1 a 127"; 0 is the factory value, no address (FF03).
        ParamDef::new(par::FIELDBUS_ADDRESS, "Fieldbus address", U16)
            .limits(0, 127)
            .after_reset(),
        ParamDef::new(
            par::FIELDBUS_MS_ENABLE,
            "Fieldbus M->S enable",
            Enum(OFF_ON),
        )
        .default(1)
        .after_reset(),
        ParamDef::new(par::FIELDBUS_ALARM_MODE, "Fieldbus alarm mode", U16)
            .limits(0, 1)
            .after_reset(),
        ParamDef::new(par::FIELDBUS_STATE, "Fieldbus state", Enum(FIELDBUS_STATES)).ro(),
        ParamDef::new(par::WORD_COMP_MON, "Word comp mon", U16).ro(),
        ParamDef::new(par::WORD_DECOMP_MON, "Word decomp mon", U16).ro(),
        ParamDef::new(par::WORD_DECOMP_SRC, "Word decomp src", Src { bits: 16 }),
    ];
    for k in 1..=8 {
        v.push(
            ParamDef::new(
                par::digital_input(k),
                format!("Digital input {k} mon"),
                Bool,
            )
            .ro(),
        );
    }
    for k in 1..=4 {
        v.push(ParamDef::new(
            par::digital_output_src(k),
            format!("Digital output {k} src"),
            Src { bits: 1 },
        ));
    }
    for k in 0..16 {
        v.push(ParamDef::new(
            par::word_comp_bit_src(k),
            format!("Bit{k} src"),
            Src { bits: 1 },
        ));
        v.push(ParamDef::new(par::word_decomp_bit(k), format!("Word bit{k} decomp"), Bool).ro());
    }
    for n in 1..=CHANNELS {
        v.push(
            ParamDef::new(
                par::m2s_sys(n),
                format!("Fieldbus M->S{n} sys"),
                Enum(CHANNEL_FORMATS),
            )
            .after_reset(),
        );
        v.push(
            ParamDef::new(par::m2s_ipa(n), format!("Fieldbus M->S{n} ipa"), U16)
                .limits(0, 16383)
                .after_reset(),
        );
        v.push(ParamDef::new(par::m2s_mon(n), format!("Fieldbus M->S{n} mon"), I32).ro());
        v.push(ParamDef::new(par::m2s_dest(n), format!("Fieldbus M->S{n} dest"), U16).ro());
        v.push(
            ParamDef::new(
                par::s2m_sys(n),
                format!("Fieldbus S->M{n} sys"),
                Enum(CHANNEL_FORMATS),
            )
            .after_reset(),
        );
        v.push(
            ParamDef::new(par::s2m_ipa(n), format!("Fieldbus S->M{n} ipa"), U16)
                .limits(0, 16383)
                .after_reset(),
        );
        v.push(ParamDef::new(
            par::s2m_dig(n),
            format!("Dig Fieldbus S->M{n}"),
            I32,
        ));
        v.push(ParamDef::new(par::s2m_mon(n), format!("Fieldbus S->M{n} mon"), I32).ro());
    }
    v.sort_by_key(|d| d.par);
    v
}

/// Parameter numbers stay below this (the §1.4 SDO window 0x2000 + PAR ends at 0x5FFF).
pub const PAR_LIMIT: u16 = 0x4000;

/// No parameter at this number (in [`Catalog::slots`]).
const NONE: u16 = u16::MAX;

/// The definitions, and for every number below [`PAR_LIMIT`] the position of its
/// definition: the drive's control task reads some sixty parameters every millisecond, so a
/// parameter is found by one table look-up rather than a search.
#[derive(Debug)]
struct Catalog {
    defs: Vec<ParamDef>,
    slots: Vec<u16>,
    /// The range of each definition's type (what [`ParamDb::force`] clamps to).
    ranges: Vec<(i64, i64)>,
}

impl Catalog {
    #[inline]
    fn slot(&self, par: u16) -> Option<usize> {
        match self.slots.get(usize::from(par)) {
            Some(&s) if s != NONE => Some(usize::from(s)),
            _ => None,
        }
    }
}

fn index_catalog() -> Catalog {
    let defs = build_catalog();
    let mut slots = vec![NONE; usize::from(PAR_LIMIT)];
    for (i, d) in defs.iter().enumerate() {
        if let Some(s) = slots.get_mut(usize::from(d.par)) {
            *s = i as u16;
        }
    }
    let ranges = defs.iter().map(|d| d.ty.range()).collect();
    Catalog {
        defs,
        slots,
        ranges,
    }
}

static CATALOG: LazyLock<Catalog> = LazyLock::new(index_catalog);

/// Every parameter of the drive, sorted by number.
pub fn catalog() -> &'static [ParamDef] {
    &CATALOG.defs
}

/// The definition of parameter `par`.
pub fn def(par: u16) -> Option<&'static ParamDef> {
    CATALOG.slot(par).map(|i| &CATALOG.defs[i])
}

/// Where a parameter sits in a [`ParamDb`], found once: for code that reads and sets the
/// same parameters every millisecond (the drive's control task). A slot of no parameter
/// reads 0 and ignores writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Slot(u16);

impl Slot {
    /// The slot of parameter `par`.
    pub fn of(par: u16) -> Slot {
        Slot(CATALOG.slot(par).map_or(NONE, |i| i as u16))
    }
}

/// Why a parameter access failed; each maps to the CiA 301 abort code with the meaning of
/// the §1.4 table (whose OCR'd codes are damaged).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ParamError {
    /// No such parameter (0x06020000).
    #[error("parameter does not exist")]
    Missing,
    /// The parameter cannot be written now (0x08000022).
    #[error("access failed because of the present device state")]
    DeviceState,
    /// Written to a read-only parameter (0x06010002).
    #[error("parameter is read-only")]
    ReadOnly,
    /// Above the maximum (0x06090031).
    #[error("value above the maximum")]
    AboveMax,
    /// Below the minimum (0x06090032).
    #[error("value below the minimum")]
    BelowMin,
    /// Not a value the parameter accepts (0x06090030).
    #[error("invalid value")]
    Invalid,
    /// Wrong length (0x06070010).
    #[error("wrong data length")]
    Length,
}

impl ParamError {
    /// The SDO abort code (CiA 301 codes with the meanings of the §1.4 table).
    pub const fn abort_code(self) -> AbortCode {
        AbortCode::from_u32(match self {
            ParamError::Missing => 0x0602_0000,
            ParamError::DeviceState => 0x0800_0022,
            ParamError::ReadOnly => 0x0601_0002,
            ParamError::AboveMax => 0x0609_0031,
            ParamError::BelowMin => 0x0609_0032,
            ParamError::Invalid => 0x0609_0030,
            ParamError::Length => 0x0607_0010,
        })
    }
}

/// The values of every parameter.
#[derive(Clone)]
pub struct ParamDb {
    values: Vec<i64>,
    /// Counts the writes of settings ([`ParamDb::set`], [`ParamDb::touch`]), so that code
    /// deriving something from the settings knows when to derive it again.
    generation: u64,
    /// The catalogue, held so that an access is one look-up without a check of its
    /// initialisation.
    catalog: &'static Catalog,
}

impl PartialEq for ParamDb {
    fn eq(&self, other: &Self) -> bool {
        self.values == other.values
    }
}

impl Eq for ParamDb {}

impl core::fmt::Debug for ParamDb {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ParamDb")
            .field("values", &self.values)
            .finish_non_exhaustive()
    }
}

impl Default for ParamDb {
    fn default() -> Self {
        ParamDb::new()
    }
}

impl ParamDb {
    /// Every parameter at its factory default.
    pub fn new() -> Self {
        let catalog: &'static Catalog = &CATALOG;
        ParamDb {
            values: catalog.defs.iter().map(|d| d.default).collect(),
            generation: 0,
            catalog,
        }
    }

    #[inline]
    fn slot(&self, par: u16) -> Result<usize, ParamError> {
        self.catalog.slot(par).ok_or(ParamError::Missing)
    }

    /// The value of `par`.
    #[inline]
    pub fn get(&self, par: u16) -> Result<i64, ParamError> {
        let i = self.slot(par)?;
        Ok(self.values.get(i).copied().unwrap_or(0))
    }

    /// The value of `par`, 0 if it does not exist (a Null source).
    #[inline]
    pub fn value(&self, par: u16) -> i64 {
        self.get(par).unwrap_or(0)
    }

    /// The value in slot `s` ([`ParamDb::value`] by slot).
    #[inline]
    pub fn at(&self, s: Slot) -> i64 {
        self.values.get(usize::from(s.0)).copied().unwrap_or(0)
    }

    /// Sets the value in slot `s` ([`ParamDb::force`] by slot).
    #[inline]
    pub fn force_at(&mut self, s: Slot, value: i64) {
        let i = usize::from(s.0);
        if let (Some(v), Some(&(lo, hi))) = (self.values.get_mut(i), self.catalog.ranges.get(i)) {
            *v = value.clamp(lo, hi);
        }
    }

    /// Sets bit k of `word` into slot k of `slots`: the one-bit monitors of a word (the
    /// digital inputs, WordDecomp), each ranging over 0..=1, so nothing is clamped. The
    /// control task sets two dozen of them every millisecond.
    #[inline]
    pub fn force_bits_at(&mut self, slots: &[Slot], word: i64) {
        for (k, s) in slots.iter().enumerate() {
            if let Some(v) = self.values.get_mut(usize::from(s.0)) {
                *v = word >> k & 1;
            }
        }
    }

    /// Checks a write as the keypad or the bus would make it: access, limits, and for a
    /// source selector that the source exists.
    pub fn check(&self, par: u16, value: i64) -> Result<(), ParamError> {
        let d = def(par).ok_or(ParamError::Missing)?;
        if d.access == ParamAccess::Ro {
            return Err(ParamError::ReadOnly);
        }
        // An enumeration has values, not a range: any other number is "invalid value"
        // (§1.4 table; code 11 "valore non ammesso" of table 3.4.1), never "too high".
        if let ParamType::Enum(values) = d.ty
            && !values.iter().any(|v| i64::from(v.0) == value)
        {
            return Err(ParamError::Invalid);
        }
        if value > d.max {
            return Err(ParamError::AboveMax);
        }
        if value < d.min {
            return Err(ParamError::BelowMin);
        }
        match d.ty {
            ParamType::Enum(values) if !values.iter().any(|v| i64::from(v.0) == value) => {
                Err(ParamError::Invalid)
            }
            ParamType::Src { .. } if value != 0 => match def(value as u16) {
                Some(src) if !matches!(src.ty, ParamType::Src { .. }) => Ok(()),
                _ => Err(ParamError::Invalid),
            },
            _ => Ok(()),
        }
    }

    /// Writes `par` as a user would (see [`ParamDb::check`]).
    pub fn set(&mut self, par: u16, value: i64) -> Result<(), ParamError> {
        self.check(par, value)?;
        self.generation = self.generation.wrapping_add(1);
        self.force(par, value)
    }

    /// Counts a change of settings made with [`ParamDb::force`] (the PDC wiring of a drive
    /// reset).
    pub fn touch(&mut self) {
        self.generation = self.generation.wrapping_add(1);
    }

    /// The number of settings writes so far (see [`ParamDb::touch`]).
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// Sets `par` as the drive itself does (monitors), without access or limit checks; the
    /// value is clamped to the type's range.
    #[inline]
    pub fn force(&mut self, par: u16, value: i64) -> Result<(), ParamError> {
        let i = self.slot(par)?;
        let (lo, hi) = self.catalog.ranges.get(i).copied().unwrap_or((0, 0));
        if let Some(v) = self.values.get_mut(i) {
            *v = value.clamp(lo, hi);
        }
        Ok(())
    }

    /// Decodes an SDO download of 1–4 bytes for `par` (§1.4: the manual's own example writes
    /// four bytes to a 16-bit parameter): little-endian, sign-extended from its length for a
    /// signed parameter.
    pub fn decode(par: u16, data: &[u8]) -> Result<i64, ParamError> {
        let d = def(par).ok_or(ParamError::Missing)?;
        if data.is_empty() || data.len() > 4 {
            return Err(ParamError::Length);
        }
        let mut b = [0u8; 8];
        b[..data.len()].copy_from_slice(data);
        let raw = u64::from_le_bytes(b);
        let bits = 8 * data.len() as u32;
        Ok(if d.ty.signed() {
            let shift = 64 - bits;
            ((raw << shift) as i64) >> shift
        } else {
            raw as i64
        })
    }

    /// The bytes an SDO upload of `par` returns: the parameter's size, little-endian.
    pub fn encode(&self, par: u16) -> Result<([u8; 4], usize), ParamError> {
        let d = def(par).ok_or(ParamError::Missing)?;
        let v = self.get(par)?;
        Ok(((v as u32).to_le_bytes(), d.ty.size()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn catalog_is_sorted_and_unique() {
        let c = catalog();
        assert!(c.windows(2).all(|w| w[0].par < w[1].par));
        assert!(c.iter().all(|d| d.min <= d.default && d.default <= d.max));
        assert!(c.iter().all(|d| d.par < PAR_LIMIT));
        assert!(c.iter().all(|d| def(d.par) == Some(d)));
        assert_eq!(def(1), None);
        assert_eq!(def(u16::MAX), None);
    }

    #[test]
    fn manual_1_3_3_dig_fieldbus_s2m_numbers() {
        for n in 1..=16u16 {
            assert_eq!(par::s2m_dig(n), 4184 + (n - 1) * 10);
            assert_eq!(
                def(par::s2m_dig(n)).unwrap().name,
                format!("Dig Fieldbus S->M{n}")
            );
        }
    }

    #[test]
    fn manual_1_4_decode_four_bytes_into_a_16_bit_parameter() {
        assert_eq!(ParamDb::decode(600, &[0xE8, 0x03, 0, 0]), Ok(1000));
        assert_eq!(ParamDb::decode(600, &[0xFF, 0xFF]), Ok(-1));
        assert_eq!(ParamDb::decode(600, &[0x18, 0xFC, 0xFF, 0xFF]), Ok(-1000));
        assert_eq!(ParamDb::decode(4006, &[0xFF]), Ok(255));
        assert_eq!(ParamDb::decode(600, &[]), Err(ParamError::Length));
        assert_eq!(ParamDb::decode(1, &[1]), Err(ParamError::Missing));
    }

    #[test]
    fn writes_are_checked_against_limits_access_and_enumerations() {
        let mut db = ParamDb::new();
        assert_eq!(db.set(600, 9000), Err(ParamError::AboveMax));
        assert_eq!(db.set(600, -9000), Err(ParamError::BelowMin));
        assert_eq!(db.set(260, 0), Err(ParamError::ReadOnly));
        assert_eq!(db.set(4004, 7), Err(ParamError::Invalid));
        assert_eq!(db.set(534, 0), Err(ParamError::ReadOnly));
        assert_eq!(db.set(610, 3), Err(ParamError::Invalid));
        assert_eq!(
            db.set(610, 4452),
            Err(ParamError::Invalid),
            "a src cannot feed a src"
        );
        assert_eq!(db.set(610, i64::from(par::m2s_mon(1))), Ok(()));
        assert_eq!(db.get(4010), Ok(1));
        assert_eq!(db.encode(600), Ok(([0, 0, 0, 0], 2)));
    }
}
