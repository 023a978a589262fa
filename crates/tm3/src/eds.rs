//! The EDS of a configured island, generated from its dictionary (CiA 306).

use crate::island::Island;
use crate::od;
use cantwin_canopen::od::OdBuildError;
use cantwin_eds::{DeviceInfo, Eds, FileInfo};

/// The island's EDS: every object of its dictionary, TM3BCCO's identity, 29 RPDOs and
/// 56 TPDOs, byte-wise mapping granularity.
pub fn eds(island: &Island) -> Result<Eds, OdBuildError> {
    let desc = od::description(island)?;
    let info = DeviceInfo {
        vendor_name: Some(od::VENDOR_NAME.into()),
        product_name: Some(od::DEVICE_NAME.into()),
        order_code: Some(od::DEVICE_NAME.into()),
        granularity: Some(8),
        nr_of_rx_pdo: Some(od::RPDOS),
        nr_of_tx_pdo: Some(od::TPDOS),
        simple_boot_up_slave: Some(true),
        simple_boot_up_master: Some(false),
        group_messaging: Some(false),
        lss_supported: Some(false),
        dynamic_channels_supported: Some(0),
        ..DeviceInfo::default()
    };
    Ok(cantwin_eds::from_od(
        &desc,
        info,
        FileInfo::new("TM3BCCO.eds"),
    ))
}

/// The island's EDS as text.
pub fn eds_text(island: &Island) -> Result<String, OdBuildError> {
    Ok(cantwin_eds::write(&eds(island)?))
}
