//! The card's EDS files (CiA 306), generated from its object dictionary: one per CANopen
//! personality. The files shipped in `crates/adv200/eds/` are this module's output for the
//! factory PDC (no channel assigned: no PDO mapped in the CANopen personality) and are
//! checked against it by the test suite.

use cantwin_canopen::od::OdBuildError;
use cantwin_eds::{DeviceInfo, Eds, FileInfo};

use crate::od::{Personality, build};
use crate::pdc::Pdc;

/// The EDS model of `personality` with the PDO mappings of `pdc` (CANopen).
pub fn eds_for(personality: Personality, pdc: &Pdc) -> Result<Eds, OdBuildError> {
    let desc = build(personality, pdc, 0)?;
    let (file, product) = match personality {
        Personality::CanOpen => ("adv200-canopen.eds", "ADV200 EXP-CAN/DN-ADV CANopen"),
        Personality::Ds402 => ("adv200-ds402.eds", "ADV200 EXP-CAN/DN-ADV DS402"),
    };
    let mut info = DeviceInfo {
        vendor_name: Some("Gefran".to_owned()),
        product_name: Some(product.to_owned()),
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
    Ok(cantwin_eds::from_od(&desc, info, file_info))
}

/// The EDS text of `personality` with the factory PDC.
pub fn eds_text(personality: Personality) -> Result<String, OdBuildError> {
    Ok(cantwin_eds::write(&eds_for(personality, &Pdc::default())?))
}
