//! The CiA 402 objects a drive has, chosen by an [`Objects`] description, with the
//! profile's types, access and defaults (CiA 402-2, the device control objects and those of vl mode).
//!
//! | index | object | type, access | default |
//! |---|---|---|---|
//! | 0x603F | error code | UNSIGNED16 `ro`, mappable | 0 |
//! | 0x6040 | controlword | UNSIGNED16 `rw`, mappable | 0 |
//! | 0x6041 | statusword | UNSIGNED16 `ro`, mappable | [`Objects::statusword`] |
//! | 0x6042 | vl target velocity | INTEGER16 `rw`, mappable | 0 |
//! | 0x6043 | vl velocity demand | INTEGER16 `ro`, mappable | 0 |
//! | 0x6044 | vl velocity actual value (DSP 402 V2.0: vl control effort) | INTEGER16 `ro`, mappable | 0 |
//! | 0x6046 | vl velocity min max amount: 1 min, 2 max | UNSIGNED32 `rw`, mappable | [`VlObjects::min_max_amount`] |
//! | 0x6047 | vl velocity min max: 1 min pos, 2 max pos, 3 min neg, 4 max neg | UNSIGNED32 `rw`, mappable | [`VlObjects::min_max`] |
//! | 0x6048 | vl velocity acceleration: 1 delta speed, 2 delta time (s) | UNSIGNED32, UNSIGNED16 ≥ 1 `rw`, mappable | [`VlObjects::acceleration`] |
//! | 0x6049 | vl velocity deceleration | as 0x6048 | [`VlObjects::deceleration`] |
//! | 0x604A | vl velocity quick stop | as 0x6048 | [`VlObjects::quick_stop`] |
//! | 0x605A | quick stop option code | INTEGER16 `rw`, 0–8 | [`OptionCodeObjects::quick_stop`] |
//! | 0x605B | shutdown option code | INTEGER16 `rw`, 0–1 | [`OptionCodeObjects::shutdown`] |
//! | 0x605C | disable operation option code | INTEGER16 `rw`, 0–1 | [`OptionCodeObjects::disable_operation`] |
//! | 0x605D | halt option code | INTEGER16 `rw`, 1–4 | [`OptionCodeObjects::halt`] |
//! | 0x605E | fault reaction option code | INTEGER16 `rw`, 0–4 | [`OptionCodeObjects::fault_reaction`] |
//! | 0x6060 | modes of operation | INTEGER8 `rw`, limited to the supported codes' range | [`Objects::mode`] |
//! | 0x6061 | modes of operation display | INTEGER8 `ro`, mappable | [`Objects::mode`] |
//! | 0x6502 | supported drive modes | UNSIGNED32 `ro` | [`Objects::modes`] |
//!
//! Every object but the controlword, the statusword and the modes of operation is
//! optional, and so is a `None` in the description. [`objects`] lists the objects so that a
//! device can adjust one before [`add`] puts them into its dictionary.

use cantwin_canopen::od::{Access, DataType, ObjectCode, OdBuilder, SubObject, Value};

use crate::modes::{Mode, SupportedModes};
use crate::options::{
    DisableOption, FaultReactionOption, HaltOption, OptionCodes, QuickStopOption,
};
use crate::state::State;
use crate::statusword::{REMOTE, Statusword};
use crate::vl::{MinMax, MinMaxAmount, Ramp};

pub use crate::index::*;

/// Which edition's object names a dictionary uses. They differ only in 0x6044.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub enum Naming {
    /// CiA 402-2 (IEC 61800-7-201): 0x6044 is "vl velocity actual value".
    #[default]
    Cia402,
    /// CiA DSP 402 V2.0, which older drive manuals follow: 0x6044 is "vl control effort".
    Dsp402V2,
}

/// Which option code objects a drive has, each with its default; `None` leaves it out.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct OptionCodeObjects {
    /// 0x605A.
    pub quick_stop: Option<QuickStopOption>,
    /// 0x605B.
    pub shutdown: Option<DisableOption>,
    /// 0x605C.
    pub disable_operation: Option<DisableOption>,
    /// 0x605D.
    pub halt: Option<HaltOption>,
    /// 0x605E.
    pub fault_reaction: Option<FaultReactionOption>,
}

impl OptionCodeObjects {
    /// None of them.
    pub const NONE: OptionCodeObjects = OptionCodeObjects {
        quick_stop: None,
        shutdown: None,
        disable_operation: None,
        halt: None,
        fault_reaction: None,
    };

    /// All five, with `defaults`.
    pub const fn all(defaults: OptionCodes) -> OptionCodeObjects {
        OptionCodeObjects {
            quick_stop: Some(defaults.quick_stop),
            shutdown: Some(defaults.shutdown),
            disable_operation: Some(defaults.disable_operation),
            halt: Some(defaults.halt),
            fault_reaction: Some(defaults.fault_reaction),
        }
    }
}

/// Which vl objects a drive has (CiA 402-2, velocity mode), with their defaults; `None`
/// leaves an object out. 0x6042–0x6044 are always there.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct VlObjects {
    /// 0x6046.
    pub min_max_amount: Option<MinMaxAmount>,
    /// 0x6047.
    pub min_max: Option<MinMax>,
    /// 0x6048.
    pub acceleration: Option<Ramp>,
    /// 0x6049.
    pub deceleration: Option<Ramp>,
    /// 0x604A.
    pub quick_stop: Option<Ramp>,
}

impl VlObjects {
    /// Only 0x6042–0x6044, which every vl drive has.
    pub const MINIMAL: VlObjects = VlObjects {
        min_max_amount: None,
        min_max: None,
        acceleration: None,
        deceleration: None,
        quick_stop: None,
    };
}

impl Default for VlObjects {
    /// All of them, with the defaults of [`MinMaxAmount::default`], [`MinMax::default`] and
    /// [`Ramp::default`].
    fn default() -> Self {
        VlObjects {
            min_max_amount: Some(MinMaxAmount::default()),
            min_max: Some(MinMax::default()),
            acceleration: Some(Ramp::default()),
            deceleration: Some(Ramp::default()),
            quick_stop: Some(Ramp::default()),
        }
    }
}

/// Which CiA 402 objects a drive has and their defaults.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Objects {
    /// The names of which edition.
    pub naming: Naming,
    /// 0x603F error code.
    pub error_code: bool,
    /// 0x6041's default (the statusword before the drive first evaluates its state).
    pub statusword: u16,
    /// The supported modes: 0x6502 and the limits of 0x6060.
    pub modes: SupportedModes,
    /// 0x6502 is in the dictionary.
    pub supported_drive_modes: bool,
    /// 0x6060's and 0x6061's default.
    pub mode: Option<Mode>,
    /// Whether 0x6060 may be mapped into a PDO.
    pub mode_mappable: bool,
    /// 0x605A–0x605E.
    pub option_codes: OptionCodeObjects,
    /// The vl objects, for a drive that supports velocity mode.
    pub vl: Option<VlObjects>,
}

impl Objects {
    /// Only the objects every drive has: controlword, statusword (default 0x0240), modes of
    /// operation and its display (default 0, no mode), no mode supported. A device states
    /// what it has on top of this, `Objects { vl: Some(..), ..Objects::minimal() }`, and so
    /// keeps exactly its dictionary when the profile grows optional objects.
    pub fn minimal() -> Objects {
        Objects {
            naming: Naming::Cia402,
            error_code: false,
            statusword: Statusword::encode(State::SwitchOnDisabled, Default::default()).0 | REMOTE,
            modes: SupportedModes::NONE,
            supported_drive_modes: false,
            mode: None,
            mode_mappable: true,
            option_codes: OptionCodeObjects::NONE,
            vl: None,
        }
    }

    /// A velocity-mode drive with every object of the table and the profile's defaults:
    /// statusword SWITCH ON DISABLED with remote set (0x0240), modes of operation vl.
    pub fn velocity_drive() -> Objects {
        Objects {
            naming: Naming::Cia402,
            error_code: true,
            statusword: Statusword::encode(State::SwitchOnDisabled, Default::default()).0 | REMOTE,
            modes: SupportedModes::VELOCITY,
            supported_drive_modes: true,
            mode: Some(Mode::Velocity),
            mode_mappable: true,
            option_codes: OptionCodeObjects::all(OptionCodes::STANDARD),
            vl: Some(VlObjects::default()),
        }
    }
}

/// One object before it goes into a dictionary: [`objects`] lists them so that a device can
/// change a name, a default or a flag first.
#[derive(Debug, Clone, PartialEq)]
pub struct Object {
    /// Its index.
    pub index: u16,
    /// Its name (a VAR's is its sub-object's).
    pub name: String,
    /// VAR, ARRAY or RECORD.
    pub code: ObjectCode,
    /// Its sub-objects; an ARRAY or RECORD gets its sub-index 0 from [`OdBuilder`].
    pub subs: Vec<(u8, SubObject)>,
}

impl Object {
    fn var(index: u16, sub: SubObject) -> Object {
        Object {
            index,
            name: sub.name.clone(),
            code: ObjectCode::Var,
            subs: vec![(0, sub)],
        }
    }

    /// The sub-object at `sub`, to adjust it.
    pub fn sub_mut(&mut self, sub: u8) -> Option<&mut SubObject> {
        self.subs
            .iter_mut()
            .find(|(s, _)| *s == sub)
            .map(|(_, o)| o)
    }
}

fn ramp(index: u16, name: &str, r: Ramp) -> Object {
    Object {
        index,
        name: name.into(),
        code: ObjectCode::Record,
        subs: vec![
            (
                1,
                SubObject::unsigned32("Delta speed", Access::Rw, r.delta_speed).mappable(),
            ),
            (
                2,
                // A delta time of 0 would be an infinite rate: the range starts at 1 s.
                SubObject::new("Delta time", DataType::Unsigned16, Access::Rw)
                    .default(Value::Unsigned16(r.delta_time))
                    .limits(Value::Unsigned16(1), Value::Unsigned16(u16::MAX))
                    .mappable(),
            ),
        ],
    }
}

fn option_code(index: u16, name: &str, default: i16, low: i16, high: i16) -> Object {
    Object::var(
        index,
        SubObject::new(name, DataType::Integer16, Access::Rw)
            .default(Value::Integer16(default))
            .limits(Value::Integer16(low), Value::Integer16(high)),
    )
}

/// The objects `spec` describes (see the [module documentation](self)), in index order.
pub fn objects(spec: &Objects) -> Vec<Object> {
    let u16_var = |name: &str, access, v: u16| {
        SubObject::new(name, DataType::Unsigned16, access)
            .default(Value::Unsigned16(v))
            .mappable()
    };
    let i16_var = |name: &str, access| {
        SubObject::new(name, DataType::Integer16, access)
            .default(Value::Integer16(0))
            .mappable()
    };
    let mut out = Vec::new();
    if spec.error_code {
        out.push(Object::var(
            ERROR_CODE,
            u16_var("Error code", Access::Ro, 0),
        ));
    }
    out.push(Object::var(
        CONTROLWORD,
        u16_var("Controlword", Access::Rw, 0),
    ));
    out.push(Object::var(
        STATUSWORD,
        u16_var("Statusword", Access::Ro, spec.statusword),
    ));
    if let Some(vl) = &spec.vl {
        out.push(Object::var(
            VL_TARGET_VELOCITY,
            i16_var("vl target velocity", Access::Rw),
        ));
        out.push(Object::var(
            VL_VELOCITY_DEMAND,
            i16_var("vl velocity demand", Access::Ro),
        ));
        let actual = match spec.naming {
            Naming::Cia402 => "vl velocity actual value",
            Naming::Dsp402V2 => "vl control effort",
        };
        out.push(Object::var(
            VL_VELOCITY_ACTUAL_VALUE,
            i16_var(actual, Access::Ro),
        ));
        let amount = |name: &str, v: u32| SubObject::unsigned32(name, Access::Rw, v).mappable();
        if let Some(m) = vl.min_max_amount {
            out.push(Object {
                index: VL_VELOCITY_MIN_MAX_AMOUNT,
                name: "vl velocity min max amount".into(),
                code: ObjectCode::Array,
                subs: vec![
                    (1, amount("vl velocity min amount", m.min)),
                    (2, amount("vl velocity max amount", m.max)),
                ],
            });
        }
        if let Some(m) = vl.min_max {
            out.push(Object {
                index: VL_VELOCITY_MIN_MAX,
                name: "vl velocity min max".into(),
                code: ObjectCode::Array,
                subs: vec![
                    (1, amount("vl velocity min pos", m.min_pos)),
                    (2, amount("vl velocity max pos", m.max_pos)),
                    (3, amount("vl velocity min neg", m.min_neg)),
                    (4, amount("vl velocity max neg", m.max_neg)),
                ],
            });
        }
        if let Some(r) = vl.acceleration {
            out.push(ramp(
                VL_VELOCITY_ACCELERATION,
                "vl velocity acceleration",
                r,
            ));
        }
        if let Some(r) = vl.deceleration {
            out.push(ramp(
                VL_VELOCITY_DECELERATION,
                "vl velocity deceleration",
                r,
            ));
        }
        if let Some(r) = vl.quick_stop {
            out.push(ramp(VL_VELOCITY_QUICK_STOP, "vl velocity quick stop", r));
        }
    }
    let oc = &spec.option_codes;
    if let Some(o) = oc.quick_stop {
        out.push(option_code(
            QUICK_STOP_OPTION_CODE,
            "Quick stop option code",
            o.code(),
            0,
            8,
        ));
    }
    if let Some(o) = oc.shutdown {
        out.push(option_code(
            SHUTDOWN_OPTION_CODE,
            "Shutdown option code",
            o.code(),
            0,
            1,
        ));
    }
    if let Some(o) = oc.disable_operation {
        out.push(option_code(
            DISABLE_OPERATION_OPTION_CODE,
            "Disable operation option code",
            o.code(),
            0,
            1,
        ));
    }
    if let Some(o) = oc.halt {
        out.push(option_code(
            HALT_OPTION_CODE,
            "Halt option code",
            o.code(),
            1,
            4,
        ));
    }
    if let Some(o) = oc.fault_reaction {
        out.push(option_code(
            FAULT_REACTION_OPTION_CODE,
            "Fault reaction option code",
            o.code(),
            0,
            4,
        ));
    }
    let mode = spec.mode.map_or(0, Mode::code);
    let mut modes = SubObject::new("Modes of operation", DataType::Integer8, Access::Rw)
        .default(Value::Integer8(mode));
    if let Some((low, high)) = spec.modes.code_range() {
        // The limits hold the default too: a drive that starts in no mode (0, CiA 402-2
        // object 6060h) reads 0 and takes 0 back, and its EDS's DefaultValue lies inside
        // its limits (CiA 306 §4.6.3). Which other codes are modes of the drive is its
        // write hook's to say (0x06090030).
        modes = modes.limits(
            Value::Integer8(low.min(mode)),
            Value::Integer8(high.max(mode)),
        );
    }
    if spec.mode_mappable {
        modes = modes.mappable();
    }
    out.push(Object::var(MODES_OF_OPERATION, modes));
    out.push(Object::var(
        MODES_OF_OPERATION_DISPLAY,
        SubObject::new("Modes of operation display", DataType::Integer8, Access::Ro)
            .default(Value::Integer8(mode))
            .mappable(),
    ));
    if spec.supported_drive_modes {
        out.push(Object::var(
            SUPPORTED_DRIVE_MODES,
            SubObject::unsigned32("Supported drive modes", Access::Ro, spec.modes.0),
        ));
    }
    out
}

/// Adds `objects` to `b`.
pub fn add(mut b: OdBuilder, objects: impl IntoIterator<Item = Object>) -> OdBuilder {
    for o in objects {
        b = match o.code {
            ObjectCode::Array => b.array(o.index, o.name, o.subs),
            ObjectCode::Record => b.record(o.index, o.name, o.subs),
            _ => match o.subs.into_iter().next() {
                Some((_, sub)) => b.var(o.index, sub),
                None => b,
            },
        };
    }
    b
}

/// Adds the objects `spec` describes to `b`.
pub fn add_objects(b: OdBuilder, spec: &Objects) -> OdBuilder {
    add(b, objects(spec))
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_canopen::od::ObjectDictionary;
    use std::sync::Arc;

    #[test]
    fn cia402_objects_velocity_drive_defaults() {
        let desc = add_objects(OdBuilder::new(), &Objects::velocity_drive())
            .build()
            .unwrap();
        let od = ObjectDictionary::new(Arc::new(desc), 1);
        assert_eq!(od.get(STATUSWORD, 0), Ok(Value::Unsigned16(0x0240)));
        assert_eq!(od.get(MODES_OF_OPERATION, 0), Ok(Value::Integer8(2)));
        assert_eq!(od.get(QUICK_STOP_OPTION_CODE, 0), Ok(Value::Integer16(2)));
        assert_eq!(od.get(SHUTDOWN_OPTION_CODE, 0), Ok(Value::Integer16(0)));
        assert_eq!(
            od.get(DISABLE_OPERATION_OPTION_CODE, 0),
            Ok(Value::Integer16(1))
        );
        assert_eq!(od.get(HALT_OPTION_CODE, 0), Ok(Value::Integer16(1)));
        assert_eq!(
            od.get(FAULT_REACTION_OPTION_CODE, 0),
            Ok(Value::Integer16(2))
        );
        assert_eq!(od.get(SUPPORTED_DRIVE_MODES, 0), Ok(Value::Unsigned32(2)));
        assert_eq!(od.get_unsigned(VL_VELOCITY_MIN_MAX, 0), Some(4));
        assert_eq!(od.get_unsigned(VL_VELOCITY_QUICK_STOP, 2), Some(1));
        assert_eq!(
            od.description()
                .object(VL_VELOCITY_ACTUAL_VALUE)
                .unwrap()
                .name(),
            "vl velocity actual value"
        );
        assert_eq!(
            OptionCodes::from_od(&od, OptionCodes::STANDARD),
            OptionCodes::STANDARD
        );
    }

    /// A DSP 402 V2.0 velocity drive with only the objects of its manual (the ADV200's
    /// chapter 2), spelled out object by object, is what the description builds.
    #[test]
    fn cia402_objects_a_dsp402_v2_velocity_drive_is_built_exactly() {
        let spec = Objects {
            naming: Naming::Dsp402V2,
            modes: SupportedModes::VELOCITY,
            mode: Some(Mode::Velocity),
            mode_mappable: false,
            vl: Some(VlObjects {
                min_max_amount: Some(MinMaxAmount { min: 0, max: 8000 }),
                acceleration: Some(Ramp::new(1000, 1)),
                deceleration: Some(Ramp::new(1000, 1)),
                ..VlObjects::MINIMAL
            }),
            ..Objects::minimal()
        };
        let built = add_objects(OdBuilder::new(), &spec).build().unwrap();

        let var = |name: &str, ty: DataType, access: Access, v: Value| {
            SubObject::new(name, ty, access).default(v).mappable()
        };
        let ramp = |b: OdBuilder, index: u16, name: &str| {
            b.record(
                index,
                name,
                [
                    (
                        1,
                        SubObject::unsigned32("Delta speed", Access::Rw, 1000).mappable(),
                    ),
                    (
                        2,
                        SubObject::new("Delta time", DataType::Unsigned16, Access::Rw)
                            .default(Value::Unsigned16(1))
                            .limits(Value::Unsigned16(1), Value::Unsigned16(u16::MAX))
                            .mappable(),
                    ),
                ],
            )
        };
        let b = OdBuilder::new()
            .var(
                0x6040,
                var(
                    "Controlword",
                    DataType::Unsigned16,
                    Access::Rw,
                    Value::Unsigned16(0),
                ),
            )
            .var(
                0x6041,
                var(
                    "Statusword",
                    DataType::Unsigned16,
                    Access::Ro,
                    Value::Unsigned16(0x0240),
                ),
            )
            .var(
                0x6042,
                var(
                    "vl target velocity",
                    DataType::Integer16,
                    Access::Rw,
                    Value::Integer16(0),
                ),
            )
            .var(
                0x6043,
                var(
                    "vl velocity demand",
                    DataType::Integer16,
                    Access::Ro,
                    Value::Integer16(0),
                ),
            )
            .var(
                0x6044,
                var(
                    "vl control effort",
                    DataType::Integer16,
                    Access::Ro,
                    Value::Integer16(0),
                ),
            )
            .array(
                0x6046,
                "vl velocity min max amount",
                [
                    (
                        1,
                        SubObject::unsigned32("vl velocity min amount", Access::Rw, 0).mappable(),
                    ),
                    (
                        2,
                        SubObject::unsigned32("vl velocity max amount", Access::Rw, 8000)
                            .mappable(),
                    ),
                ],
            );
        let b = ramp(b, 0x6048, "vl velocity acceleration");
        let b = ramp(b, 0x6049, "vl velocity deceleration");
        let expected = b
            .var(
                0x6060,
                SubObject::new("Modes of operation", DataType::Integer8, Access::Rw)
                    .default(Value::Integer8(2))
                    .limits(Value::Integer8(2), Value::Integer8(2)),
            )
            .var(
                0x6061,
                SubObject::new("Modes of operation display", DataType::Integer8, Access::Ro)
                    .default(Value::Integer8(2))
                    .mappable(),
            )
            .build()
            .unwrap();

        let shape = |d: &cantwin_canopen::od::OdDescription| {
            d.objects()
                .map(|o| {
                    let subs: Vec<(u8, SubObject)> =
                        o.subs().map(|(s, sub)| (s, sub.clone())).collect();
                    (o.index(), o.name().to_string(), o.code(), o.flags(), subs)
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(shape(&built), shape(&expected));
    }

    #[test]
    fn cia402_objects_a_drive_without_vl_has_only_the_device_control_objects() {
        let list = objects(&Objects::minimal());
        let indices: Vec<u16> = list.iter().map(|o| o.index).collect();
        assert_eq!(indices, [0x6040, 0x6041, 0x6060, 0x6061]);
        assert_eq!(list[2].subs[0].1.low_limit, None);
        assert_eq!(list[2].subs[0].1.default, Some(Value::Integer8(0)));
    }
}
