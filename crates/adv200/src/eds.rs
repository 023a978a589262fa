//! The card's EDS files (CiA 306), generated from its object dictionary: one per CANopen
//! personality. The files shipped in `crates/adv200/eds/` are this module's output for the
//! factory PDC (no channel assigned: no PDO mapped in the CANopen personality) and are
//! checked against it by the test suite.
//!
//! CiA 306 has no key for a unit; the files carry each unit in the vendor key `Unit` of the
//! entry that holds the value (the parameters' units of the drive's parameter database at
//! 0x2000 + PAR sub 1; rpm for 0x6042–0x6044, chapter 2 note 1; rpm for the 0x6046 limits,
//! rpm and s for the 0x6048/0x6049 delta speed and delta time). Tools that do not know the
//! key keep or ignore it, as CiA 306 says of keys it does not define.

use cantwin_canopen::od::OdBuildError;
use cantwin_cia402::objects as cia402;
use cantwin_eds::{DeviceInfo, Eds, FileInfo};

use crate::od::{CardInfo, Personality, build};
use crate::params::catalog;
use crate::pdc::Pdc;

/// The manufacturer, CiA 306 `VendorName`.
pub const VENDOR_NAME: &str = "Gefran";
/// The product as the manual names it (drive and fieldbus card), CiA 306 `ProductName`
/// without the personality.
pub const PRODUCT_NAME: &str = "ADV200 EXP-CAN/DN-ADV";

/// The EDS model of `personality` with the PDO mappings of `pdc` (CANopen).
pub fn eds_for(personality: Personality, pdc: &Pdc) -> Result<Eds, OdBuildError> {
    // The card as shipped: expedited transfers only (0x1008 as it answers them).
    let desc = build(personality, pdc, CardInfo::default())?;
    let (file, product) = match personality {
        Personality::CanOpen => ("adv200-canopen.eds", format!("{PRODUCT_NAME} CANopen")),
        Personality::Ds402 => ("adv200-ds402.eds", format!("{PRODUCT_NAME} DS402")),
    };
    let mut info = DeviceInfo {
        vendor_name: Some(VENDOR_NAME.to_owned()),
        product_name: Some(product.clone()),
        simple_boot_up_slave: Some(true),
        simple_boot_up_master: Some(false),
        // §1.1 item 3: PDOs can be mapped dynamically.
        granularity: Some(8),
        group_messaging: Some(false),
        nr_of_rx_pdo: Some(4),
        nr_of_tx_pdo: Some(4),
        lss_supported: Some(false),
        ..DeviceInfo::default()
    };
    // §1.2: 125k, 250k, 500k, 1M.
    info.set_baud_rates(&[125, 250, 500, 1000]);
    let mut file_info = FileInfo::new(file);
    file_info.description = Some(format!(
        "{product} (generated from the twin's object dictionary)"
    ));
    let mut eds = cantwin_eds::from_od(&desc, info, file_info);
    let mut units: Vec<(u16, u8, &str)> = catalog()
        .iter()
        .filter(|d| !d.unit.is_empty())
        .map(|d| (d.sdo_index(), 1, d.unit))
        .collect();
    if personality == Personality::Ds402 {
        units.extend([
            (cia402::VL_TARGET_VELOCITY, 0, "rpm"),
            (cia402::VL_VELOCITY_DEMAND, 0, "rpm"),
            (cia402::VL_VELOCITY_ACTUAL_VALUE, 0, "rpm"),
            (cia402::VL_VELOCITY_MIN_MAX_AMOUNT, 1, "rpm"),
            (cia402::VL_VELOCITY_MIN_MAX_AMOUNT, 2, "rpm"),
            (cia402::VL_VELOCITY_ACCELERATION, 1, "rpm"),
            (cia402::VL_VELOCITY_ACCELERATION, 2, "s"),
            (cia402::VL_VELOCITY_DECELERATION, 1, "rpm"),
            (cia402::VL_VELOCITY_DECELERATION, 2, "s"),
        ]);
    }
    for (index, sub, unit) in units {
        let Some(o) = eds.objects.get_mut(&index) else {
            continue;
        };
        let entry = if o.subs.is_empty() && sub == 0 {
            Some(&mut o.entry)
        } else {
            o.subs.get_mut(&sub)
        };
        if let Some(e) = entry {
            e.extra.push(("Unit".to_owned(), unit.to_owned()));
        }
    }
    Ok(eds)
}

/// The EDS text of `personality` with the factory PDC.
pub fn eds_text(personality: Personality) -> Result<String, OdBuildError> {
    Ok(cantwin_eds::write(&eds_for(personality, &Pdc::default())?))
}
