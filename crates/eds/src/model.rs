//! The typed model of an EDS or DCF file (CiA 306).

use crate::error::ParseError;
use crate::ini::RawSection;
use crate::value::{EdsValue, parse_integer};
use cantwin_canopen::od::Access;
use std::collections::BTreeMap;

/// A value type of a fixed key of `[FileInfo]`, `[DeviceInfo]` or `[DeviceComissioning]`.
pub(crate) trait Field: Sized {
    const EXPECTED: &'static str;
    fn parse(text: &str) -> Option<Self>;
    fn write(&self) -> String;
}

impl Field for String {
    const EXPECTED: &'static str = "text";
    fn parse(text: &str) -> Option<Self> {
        Some(text.to_owned())
    }
    fn write(&self) -> String {
        self.clone()
    }
}

impl Field for bool {
    const EXPECTED: &'static str = "0 or 1";
    fn parse(text: &str) -> Option<Self> {
        match parse_integer(text)? {
            0 => Some(false),
            1 => Some(true),
            _ => None,
        }
    }
    fn write(&self) -> String {
        u8::from(*self).to_string()
    }
}

macro_rules! int_field {
    ($t:ty, $expected:literal, $fmt:literal) => {
        impl Field for $t {
            const EXPECTED: &'static str = $expected;
            fn parse(text: &str) -> Option<Self> {
                parse_integer(text).and_then(|v| <$t>::try_from(v).ok())
            }
            fn write(&self) -> String {
                format!($fmt, self)
            }
        }
    };
}

int_field!(u8, "an integer 0..=255", "{}");
int_field!(u16, "an integer 0..=65535", "{}");
int_field!(u32, "an integer 0..=0xFFFFFFFF", "0x{:08X}");

macro_rules! keyed_section {
    (
        $(#[$m:meta])*
        $name:ident {
            $( $(#[$fm:meta])* $field:ident : $ty:ty = $key:literal, )*
        }
    ) => {
        $(#[$m])*
        #[derive(Debug, Clone, Default, PartialEq)]
        pub struct $name {
            $( $(#[$fm])* pub $field: Option<$ty>, )*
            /// Keys CiA 306 does not define for this section, and defined keys whose value
            /// could not be read, in file order. A key a typed field writes is not written
            /// twice.
            pub extra: Vec<(String, String)>,
        }

        impl $name {
            /// The CiA 306 names of the typed keys, in the order they are written.
            pub const KEYS: &'static [&'static str] = &[$($key),*];

            /// Reads the section; a key whose value cannot be read is kept among the extra
            /// keys (so that it is written back as found) and returned as an error.
            pub(crate) fn from_raw(sec: &RawSection) -> (Self, Vec<ParseError>) {
                let mut out = Self::default();
                let mut bad = Vec::new();
                for e in &sec.entries {
                    $(
                        if e.key.eq_ignore_ascii_case($key) {
                            match <$ty as Field>::parse(&e.value) {
                                Some(v) => out.$field = Some(v),
                                None => {
                                    bad.push(ParseError::invalid(
                                        e.line, &sec.name, &e.key, &e.value, <$ty as Field>::EXPECTED,
                                    ));
                                    out.extra.push((e.key.clone(), e.value.clone()));
                                }
                            }
                            continue;
                        }
                    )*
                    out.extra.push((e.key.clone(), e.value.clone()));
                }
                (out, bad)
            }

            pub(crate) fn to_entries(&self) -> Vec<(String, String)> {
                let mut v: Vec<(String, String)> = Vec::new();
                $(
                    if let Some(x) = &self.$field {
                        v.push(($key.to_owned(), Field::write(x)));
                    }
                )*
                // An extra key is written unless a typed field already wrote one of its name.
                for (k, val) in &self.extra {
                    if !v.iter().any(|(w, _)| w.eq_ignore_ascii_case(k)) {
                        v.push((k.clone(), val.clone()));
                    }
                }
                v
            }
        }
    };
}

keyed_section! {
    /// `[FileInfo]` (CiA 306 file information), with `LastEDS` of a DCF.
    FileInfo {
        /// `FileName`.
        file_name: String = "FileName",
        /// `FileVersion`.
        file_version: u8 = "FileVersion",
        /// `FileRevision`.
        file_revision: u8 = "FileRevision",
        /// `EDSVersion` (e.g. `4.0`).
        eds_version: String = "EDSVersion",
        /// `Description`.
        description: String = "Description",
        /// `CreationTime` (`hh:mm(AM|PM)`).
        creation_time: String = "CreationTime",
        /// `CreationDate` (`mm-dd-yyyy`).
        creation_date: String = "CreationDate",
        /// `CreatedBy`.
        created_by: String = "CreatedBy",
        /// `ModificationTime`.
        modification_time: String = "ModificationTime",
        /// `ModificationDate`.
        modification_date: String = "ModificationDate",
        /// `ModifiedBy`.
        modified_by: String = "ModifiedBy",
        /// `LastEDS` (DCF): the EDS this DCF was made from.
        last_eds: String = "LastEDS",
    }
}

keyed_section! {
    /// `[DeviceInfo]` (CiA 306 general device information): identity, supported bit rates and capabilities.
    DeviceInfo {
        /// `VendorName`.
        vendor_name: String = "VendorName",
        /// `VendorNumber` (object 0x1018 sub-index 1).
        vendor_number: u32 = "VendorNumber",
        /// `ProductName`.
        product_name: String = "ProductName",
        /// `ProductNumber` (0x1018 sub-index 2).
        product_number: u32 = "ProductNumber",
        /// `RevisionNumber` (0x1018 sub-index 3).
        revision_number: u32 = "RevisionNumber",
        /// `OrderCode`.
        order_code: String = "OrderCode",
        /// `BaudRate_10`: 10 kbit/s supported.
        baud_rate_10: bool = "BaudRate_10",
        /// `BaudRate_20`.
        baud_rate_20: bool = "BaudRate_20",
        /// `BaudRate_50`.
        baud_rate_50: bool = "BaudRate_50",
        /// `BaudRate_125`.
        baud_rate_125: bool = "BaudRate_125",
        /// `BaudRate_250`.
        baud_rate_250: bool = "BaudRate_250",
        /// `BaudRate_500`.
        baud_rate_500: bool = "BaudRate_500",
        /// `BaudRate_800`.
        baud_rate_800: bool = "BaudRate_800",
        /// `BaudRate_1000`.
        baud_rate_1000: bool = "BaudRate_1000",
        /// `SimpleBootUpMaster`.
        simple_boot_up_master: bool = "SimpleBootUpMaster",
        /// `SimpleBootUpSlave`.
        simple_boot_up_slave: bool = "SimpleBootUpSlave",
        /// `Granularity`: the PDO mapping granularity in bits (0: the mapping cannot be
        /// changed, 8: byte-wise).
        granularity: u8 = "Granularity",
        /// `DynamicChannelsSupported`.
        dynamic_channels_supported: u8 = "DynamicChannelsSupported",
        /// `CompactPDO`.
        compact_pdo: u8 = "CompactPDO",
        /// `GroupMessaging`.
        group_messaging: bool = "GroupMessaging",
        /// `NrOfRXPDO`.
        nr_of_rx_pdo: u16 = "NrOfRXPDO",
        /// `NrOfTXPDO`.
        nr_of_tx_pdo: u16 = "NrOfTXPDO",
        /// `LSS_Supported`.
        lss_supported: bool = "LSS_Supported",
    }
}

impl FileInfo {
    /// The `[FileInfo]` of a newly generated file: `FileName`, `FileVersion=1`,
    /// `FileRevision=0`, `EDSVersion=4.0`. Dates and authors are left to the caller (this crate
    /// reads no clock).
    pub fn new(file_name: impl Into<String>) -> Self {
        FileInfo {
            file_name: Some(file_name.into()),
            file_version: Some(1),
            file_revision: Some(0),
            eds_version: Some("4.0".to_owned()),
            ..FileInfo::default()
        }
    }
}

impl DeviceInfo {
    /// The bit rates (kbit/s) marked `BaudRate_x=1`, ascending.
    pub fn baud_rates(&self) -> Vec<u32> {
        [
            (10, self.baud_rate_10),
            (20, self.baud_rate_20),
            (50, self.baud_rate_50),
            (125, self.baud_rate_125),
            (250, self.baud_rate_250),
            (500, self.baud_rate_500),
            (800, self.baud_rate_800),
            (1000, self.baud_rate_1000),
        ]
        .into_iter()
        .filter(|(_, on)| *on == Some(true))
        .map(|(r, _)| r)
        .collect()
    }

    /// Sets every `BaudRate_x` key: 1 for the rates (kbit/s) in `rates`, 0 for the others.
    pub fn set_baud_rates(&mut self, rates: &[u32]) {
        let on = |r| Some(rates.contains(&r));
        self.baud_rate_10 = on(10);
        self.baud_rate_20 = on(20);
        self.baud_rate_50 = on(50);
        self.baud_rate_125 = on(125);
        self.baud_rate_250 = on(250);
        self.baud_rate_500 = on(500);
        self.baud_rate_800 = on(800);
        self.baud_rate_1000 = on(1000);
    }
}

keyed_section! {
    /// `[DeviceComissioning]` of a DCF (CiA 306 DCF; the standard spells the section name
    /// with one `m`, and that is how it is written; `DeviceCommissioning` is read too).
    DeviceCommissioning {
        /// `NodeID`.
        node_id: u8 = "NodeID",
        /// `NodeName`.
        node_name: String = "NodeName",
        /// `Baudrate` in kbit/s.
        baudrate: u16 = "Baudrate",
        /// `NetNumber`.
        net_number: u32 = "NetNumber",
        /// `NetworkName`.
        network_name: String = "NetworkName",
        /// `CANopenManager`: the device is the CANopen manager.
        canopen_manager: bool = "CANopenManager",
        /// `LSS_SerialNumber`.
        lss_serial_number: u32 = "LSS_SerialNumber",
    }
}

/// The keys of one object section (`[1000]`) or sub-object section (`[1018sub1]`)
/// (CiA 306 object descriptions), except `SubNumber` and `CompactSubObj` which belong to [`Object`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Entry {
    /// `ParameterName`.
    pub parameter_name: String,
    /// `ObjectType` (absent means VAR, 0x7).
    pub object_type: Option<u8>,
    /// `DataType`: the object dictionary index of the type (0x0007 is UNSIGNED32).
    pub data_type: Option<u16>,
    /// `AccessType`.
    pub access_type: Option<Access>,
    /// `DefaultValue`.
    pub default_value: Option<EdsValue>,
    /// `LowLimit`.
    pub low_limit: Option<EdsValue>,
    /// `HighLimit`.
    pub high_limit: Option<EdsValue>,
    /// `PDOMapping`.
    pub pdo_mapping: Option<bool>,
    /// `ObjFlags` (bit 0: refuse write on download, bit 1: refuse read on scan).
    pub obj_flags: Option<u32>,
    /// `ParameterValue` (DCF): the configured value.
    pub parameter_value: Option<EdsValue>,
    /// `Denotation` (DCF): the configured name.
    pub denotation: Option<String>,
    /// `UploadFile` (DOMAIN): file the value is uploaded into.
    pub upload_file: Option<String>,
    /// `DownloadFile` (DOMAIN): file whose contents are downloaded.
    pub download_file: Option<String>,
    /// Keys CiA 306 does not define (e.g. `StorageLocation`, `Unit`), in file order.
    pub extra: Vec<(String, String)>,
}

impl Entry {
    /// A VAR entry with a name, type and access.
    pub fn var(name: impl Into<String>, data_type: u16, access: Access) -> Self {
        Entry {
            parameter_name: name.into(),
            object_type: Some(crate::VAR),
            data_type: Some(data_type),
            access_type: Some(access),
            ..Entry::default()
        }
    }

    /// The text of a key kept among [`Entry::extra`] (case-insensitive): also where a key
    /// CiA 306 defines is kept when its value could not be read.
    pub fn extra_value(&self, key: &str) -> Option<&str> {
        self.extra
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(key))
            .map(|(_, v)| v.as_str())
    }

    /// The object code: `ObjectType`, or VAR when absent (CiA 306 object descriptions).
    pub fn object_code(&self) -> u8 {
        self.object_type.unwrap_or(crate::VAR)
    }
}

/// One object: its section, its sub-objects and how they are written.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Object {
    /// The object section's keys.
    pub entry: Entry,
    /// `SubNumber` as stated, and written back as stated ([`crate::from_od`] states it for
    /// every ARRAY and RECORD). [`crate::Eds::check`] compares it with the sub-objects.
    pub sub_number: Option<u8>,
    /// `CompactSubObj` as stated. The sub-objects it defines are expanded into
    /// [`Object::subs`]; the writer compacts them again when they still have the shape
    /// `CompactSubObj` describes.
    pub compact_sub_obj: Option<u8>,
    /// Sub-objects by sub-index.
    pub subs: BTreeMap<u8, Entry>,
}

impl Object {
    /// A VAR object.
    pub fn var(entry: Entry) -> Self {
        Object {
            entry,
            ..Object::default()
        }
    }

    /// The object code (`ObjectType`, VAR when absent).
    pub fn object_code(&self) -> u8 {
        self.entry.object_code()
    }

    /// The sub-objects as [`Object::subs`] says, or, for an object without sub-objects, its
    /// own entry as sub-index 0.
    pub fn values(&self) -> Vec<(u8, &Entry)> {
        if self.subs.is_empty() {
            vec![(0, &self.entry)]
        } else {
            self.subs.iter().map(|(s, e)| (*s, e)).collect()
        }
    }
}

/// A section the model has no type for, kept with its keys in file order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Section {
    /// The section name, without brackets.
    pub name: String,
    /// The keys and values.
    pub entries: Vec<(String, String)>,
}

/// An EDS or DCF file (CiA 306).
///
/// Parsing and writing are lossless at the level of this model:
/// `parse(&write(&parse(x)?))? == parse(x)?`. What is not kept: `;` comment lines (the
/// `[Comments]` section is CiA 306's place for comments), blank lines, letter case of
/// known keys and section names, number notation (`0x10` and `16` are the same number) and
/// the order of known keys within a section.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Eds {
    /// `[FileInfo]`.
    pub file_info: FileInfo,
    /// `[DeviceInfo]`.
    pub device_info: DeviceInfo,
    /// `[DummyUsage]`: `Dummy0001`..`Dummy0007` keyed by the data type index, `None` if the
    /// section is absent.
    pub dummy_usage: Option<BTreeMap<u16, bool>>,
    /// `[Comments]` lines, `None` if the section is absent.
    pub comments: Option<Vec<String>>,
    /// `[MandatoryObjects]`, in listed order.
    pub mandatory_objects: Vec<u16>,
    /// `[OptionalObjects]`, in listed order.
    pub optional_objects: Vec<u16>,
    /// `[ManufacturerObjects]`, in listed order.
    pub manufacturer_objects: Vec<u16>,
    /// Objects by index.
    pub objects: BTreeMap<u16, Object>,
    /// `[xxxxObjectLinks]`: objects linked to an object, in listed order.
    pub object_links: BTreeMap<u16, Vec<u16>>,
    /// `[DeviceComissioning]` (DCF).
    pub commissioning: Option<DeviceCommissioning>,
    /// Sections without a type here (e.g. `[SupportedModules]`, tool sections), in file order.
    pub other_sections: Vec<Section>,
}

impl Eds {
    /// Whether the file is a DCF: it has `[DeviceComissioning]` or a `ParameterValue`.
    pub fn is_dcf(&self) -> bool {
        self.commissioning.is_some()
            || self.objects.values().any(|o| {
                o.entry.parameter_value.is_some()
                    || o.subs.values().any(|s| s.parameter_value.is_some())
            })
    }

    /// The entry of `index`/`sub`: the object's own entry for sub-index 0 of an object without
    /// sub-objects.
    pub fn entry(&self, index: u16, sub: u8) -> Option<&Entry> {
        let o = self.objects.get(&index)?;
        if o.subs.is_empty() {
            (sub == 0).then_some(&o.entry)
        } else {
            o.subs.get(&sub)
        }
    }

    /// The list (mandatory, optional, manufacturer) CiA 306 object lists put `index` in.
    pub fn list_for(index: u16) -> ObjectList {
        match index {
            0x1000 | 0x1001 | 0x1018 => ObjectList::Mandatory,
            0x2000..=0x5FFF => ObjectList::Manufacturer,
            _ => ObjectList::Optional,
        }
    }

    /// Rebuilds the three object lists from [`Eds::objects`] (CiA 306 object lists), in index order.
    pub fn rebuild_lists(&mut self) {
        self.mandatory_objects.clear();
        self.optional_objects.clear();
        self.manufacturer_objects.clear();
        for &i in self.objects.keys() {
            match Eds::list_for(i) {
                ObjectList::Mandatory => self.mandatory_objects.push(i),
                ObjectList::Optional => self.optional_objects.push(i),
                ObjectList::Manufacturer => self.manufacturer_objects.push(i),
            }
        }
    }
}

/// The three object lists of CiA 306.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObjectList {
    /// `[MandatoryObjects]`: 0x1000, 0x1001, 0x1018.
    Mandatory,
    /// `[OptionalObjects]`: the other objects outside 0x2000..=0x5FFF.
    Optional,
    /// `[ManufacturerObjects]`: 0x2000..=0x5FFF.
    Manufacturer,
}
