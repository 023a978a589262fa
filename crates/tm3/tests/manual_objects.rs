//! The communication objects of the manual ("Oggetti nella zona profilo di
//! comunicazione"), read and written over SDO: defaults, access and ranges.
#![allow(clippy::unwrap_used)]

mod harness;

use harness::*;

const READ_ONLY: u32 = 0x0601_0002;
const NO_OBJECT: u32 = 0x0602_0000;
const NO_SUB: u32 = 0x0609_0011;
const INVALID: u32 = 0x0609_0030;

const FULL: &[&str] = &["TM3DI16", "TM3DQ16T", "TM3AI4", "TM3AQ2"];

#[test]
fn manual_1000_device_type_bits_follow_the_modules() {
    let t = ms(1);
    assert_eq!(read_u32(&mut coupler(&[]), t, 0x1000, 0), Ok(0x0080_0191));
    assert_eq!(
        read_u32(&mut coupler(&["TM3DI8"]), t, 0x1000, 0),
        Ok(0x0081_0191)
    );
    assert_eq!(
        read_u32(&mut coupler(&["TM3DQ8R"]), t, 0x1000, 0),
        Ok(0x0082_0191)
    );
    assert_eq!(
        read_u32(&mut coupler(&["TM3AI2H"]), t, 0x1000, 0),
        Ok(0x0084_0191)
    );
    assert_eq!(
        read_u32(&mut coupler(&["TM2AMO1HT"]), t, 0x1000, 0),
        Ok(0x0088_0191)
    );
    let mut c = coupler(FULL);
    assert_eq!(read_u32(&mut c, t, 0x1000, 0), Ok(0x008F_0191));
    assert_eq!(write(&mut c, t, 0x1000, 0, &[0; 4]), Err(READ_ONLY));
}

#[test]
fn manual_1001_1002_1003_start_empty() {
    let mut c = coupler(FULL);
    let t = ms(1);
    assert_eq!(read(&mut c, t, 0x1001, 0), Ok(vec![0]));
    assert_eq!(read_u32(&mut c, t, 0x1002, 0), Ok(0));
    assert_eq!(write(&mut c, t, 0x1002, 0, &[0; 4]), Err(READ_ONLY));
    assert_eq!(read(&mut c, t, 0x1003, 0), Ok(vec![0]));
    // No error recorded: each entry is "no data available" (CiA 301 §7.5.2.4).
    for sub in 1..=10 {
        assert_eq!(read_u32(&mut c, t, 0x1003, sub), Err(0x0800_0024));
    }
    assert_eq!(read_u32(&mut c, t, 0x1003, 11), Err(NO_SUB));
    assert_eq!(write(&mut c, t, 0x1003, 1, &[0; 4]), Err(READ_ONLY));
    // Sub 0 is rw, range 0..=10; only 0 (clear) is accepted (CiA 301 §7.5.2.4).
    assert_eq!(write(&mut c, t, 0x1003, 0, &[0]), Ok(()));
    assert_eq!(write(&mut c, t, 0x1003, 0, &[1]), Err(INVALID));
    assert_eq!(write(&mut c, t, 0x1003, 0, &[11]), Err(0x0609_0031));
}

#[test]
fn manual_1005_cob_id_sync_no_producer_no_29_bit() {
    let mut c = coupler(FULL);
    let t = ms(1);
    assert_eq!(read_u32(&mut c, t, 0x1005, 0), Ok(0x80));
    assert_eq!(
        write(&mut c, t, 0x1005, 0, &0x4000_0080u32.to_le_bytes()),
        Err(INVALID)
    );
    assert_eq!(
        write(&mut c, t, 0x1005, 0, &0x2000_0080u32.to_le_bytes()),
        Err(INVALID)
    );
    assert_eq!(write(&mut c, t, 0x1005, 0, &0x81u32.to_le_bytes()), Ok(()));
    assert_eq!(read_u32(&mut c, t, 0x1005, 0), Ok(0x81));
}

#[test]
fn manual_1006_cycle_period_10ms_to_10s_in_1ms_steps() {
    let mut c = coupler(FULL);
    let t = ms(1);
    assert_eq!(read_u32(&mut c, t, 0x1006, 0), Ok(0));
    for ok in [
        10_000u32, 25_000, 250_000, 1_000_000, 5_000_000, 10_000_000, 0,
    ] {
        assert_eq!(
            write(&mut c, t, 0x1006, 0, &ok.to_le_bytes()),
            Ok(()),
            "{ok}"
        );
        assert_eq!(read_u32(&mut c, t, 0x1006, 0), Ok(ok));
    }
    for bad in [1u32, 9_999, 10_500, 10_001_000, u32::MAX] {
        assert_eq!(
            write(&mut c, t, 0x1006, 0, &bad.to_le_bytes()),
            Err(INVALID),
            "{bad}"
        );
    }
    assert_eq!(read_u32(&mut c, t, 0x1006, 0), Ok(0));
}

#[test]
fn manual_1008_100a_names_are_const() {
    let mut c = coupler(FULL);
    let t = ms(1);
    assert_eq!(read(&mut c, t, 0x1008, 0), Ok(b"TM3BCCO".to_vec()));
    assert_eq!(read(&mut c, t, 0x100A, 0), Ok(b"01.00.15".to_vec()));
    assert_eq!(write(&mut c, t, 0x1008, 0, b"X"), Err(READ_ONLY));
    assert_eq!(write(&mut c, t, 0x100A, 0, b"X"), Err(READ_ONLY));
    assert_eq!(
        read_u32(&mut c, t, 0x1009, 0),
        Err(NO_OBJECT),
        "not in the manual"
    );
}

#[test]
fn manual_100c_100d_guarding_parameters() {
    let mut c = coupler(FULL);
    let t = ms(1);
    assert_eq!(read(&mut c, t, 0x100C, 0), Ok(vec![0, 0]));
    assert_eq!(read(&mut c, t, 0x100D, 0), Ok(vec![0]));
    assert_eq!(c.life_time_warning(), None);
    assert_eq!(write(&mut c, t, 0x100C, 0, &100u16.to_le_bytes()), Ok(()));
    assert_eq!(write(&mut c, t, 0x100D, 0, &[1]), Ok(()));
    assert_eq!(
        c.life_time_warning(),
        Some(cantwin_tm3::diag::LifeTimeWarning::FactorOne { guard_time_ms: 100 })
    );
    assert_eq!(write(&mut c, t, 0x100D, 0, &[2]), Ok(()));
    assert_eq!(c.life_time_warning(), None);
}

#[test]
fn manual_1014_cob_id_emcy() {
    let mut c = coupler(FULL);
    let t = ms(1);
    assert_eq!(read_u32(&mut c, t, 0x1014, 0), Ok(0x83));
    assert_eq!(
        write(&mut c, t, 0x1014, 0, &0x2000_0083u32.to_le_bytes()),
        Err(INVALID)
    );
}

#[test]
fn manual_1016_1017_heartbeat() {
    let mut c = coupler(FULL);
    let t = ms(1);
    assert_eq!(read(&mut c, t, 0x1016, 0), Ok(vec![1]));
    assert_eq!(write(&mut c, t, 0x1016, 0, &[2]), Err(READ_ONLY));
    assert_eq!(read_u32(&mut c, t, 0x1016, 1), Ok(0));
    assert_eq!(read_u32(&mut c, t, 0x1016, 2), Err(NO_SUB));
    assert_eq!(
        write(&mut c, t, 0x1016, 1, &0x0001_0064u32.to_le_bytes()),
        Ok(())
    );
    assert_eq!(
        write(&mut c, t, 0x1016, 1, &0x0101_0064u32.to_le_bytes()),
        Err(INVALID),
        "bits 31-24 are 0"
    );
    assert_eq!(read(&mut c, t, 0x1017, 0), Ok(vec![0, 0]));
    assert_eq!(write(&mut c, t, 0x1017, 0, &500u16.to_le_bytes()), Ok(()));
}

#[test]
fn manual_1018_identity() {
    let mut c = coupler(FULL);
    let t = ms(1);
    assert_eq!(read(&mut c, t, 0x1018, 0), Ok(vec![4]));
    assert_eq!(read_u32(&mut c, t, 0x1018, 1), Ok(0x0500_005A));
    assert_eq!(read_u32(&mut c, t, 0x1018, 2), Ok(811_044));
    // 0x010015 reads as firmware v1.0.15 (manual: 1018H).
    assert_eq!(read_u32(&mut c, t, 0x1018, 3), Ok(0x0001_0015));
    assert_eq!(write(&mut c, t, 0x1018, 1, &[0; 4]), Err(READ_ONLY));
}

#[test]
fn manual_1027_module_list() {
    let t = ms(1);
    let mut c = coupler(FULL);
    assert_eq!(read(&mut c, t, 0x1027, 0), Ok(vec![4]));
    let codes: Vec<u32> = (1..=4)
        .map(|s| read_u32(&mut c, t, 0x1027, s).unwrap())
        .collect();
    assert_eq!(codes, [0x0102, 0x0112, 0x0132, 0x0141]);
    assert_eq!(read_u32(&mut c, t, 0x1027, 5), Err(NO_SUB));
    assert_eq!(write(&mut c, t, 0x1027, 1, &[0, 0]), Err(READ_ONLY));
    // Without modules: 14 sub-indices of 0.
    let mut c = coupler(&[]);
    assert_eq!(read(&mut c, t, 0x1027, 0), Ok(vec![14]));
    assert_eq!(read_u32(&mut c, t, 0x1027, 14), Ok(0));
}

#[test]
fn manual_1029_error_behaviour() {
    let mut c = coupler(FULL);
    let t = ms(1);
    assert_eq!(read(&mut c, t, 0x1029, 0), Ok(vec![1]));
    assert_eq!(read(&mut c, t, 0x1029, 1), Ok(vec![0]));
    for v in [1u8, 2, 0] {
        assert_eq!(write(&mut c, t, 0x1029, 1, &[v]), Ok(()));
    }
    assert_eq!(write(&mut c, t, 0x1029, 1, &[3]), Err(INVALID));
}

#[test]
fn manual_1200_1201_sdo_servers() {
    let mut c = coupler(FULL);
    let t = ms(1);
    assert_eq!(read(&mut c, t, 0x1200, 0), Ok(vec![2]));
    assert_eq!(read_u32(&mut c, t, 0x1200, 1), Ok(0x603));
    assert_eq!(read_u32(&mut c, t, 0x1200, 2), Ok(0x583));
    assert_eq!(
        write(&mut c, t, 0x1200, 1, &0x604u32.to_le_bytes()),
        Err(READ_ONLY)
    );
    assert_eq!(read(&mut c, t, 0x1201, 0), Ok(vec![3]));
    assert_eq!(read_u32(&mut c, t, 0x1201, 1), Ok(0x8000_0000));
    assert_eq!(read_u32(&mut c, t, 0x1201, 2), Ok(0x8000_0000));
    assert_eq!(read(&mut c, t, 0x1201, 3), Ok(vec![0]));
    // Nothing answers on the second server until it is configured.
    assert_eq!(
        send(&mut c, t, 0x6C3, &[0x40, 0x18, 0x10, 2, 0, 0, 0, 0]),
        Vec::<String>::new()
    );
    // Its identifiers cannot be restricted CAN-IDs (CiA 301 §7.3.5), such as the default
    // SDO ranges 0x601..=0x67F and 0x581..=0x5FF.
    assert_eq!(
        write(&mut c, t, 0x1201, 1, &0x643u32.to_le_bytes()),
        Err(INVALID)
    );
    assert_eq!(write(&mut c, t, 0x1201, 1, &0x6C3u32.to_le_bytes()), Ok(()));
    assert_eq!(write(&mut c, t, 0x1201, 2, &0x6A3u32.to_le_bytes()), Ok(()));
    assert_eq!(
        send(&mut c, t, 0x6C3, &[0x40, 0x18, 0x10, 2, 0, 0, 0, 0]),
        ["6A3#4318100224600C00"]
    );
}

#[test]
fn manual_1400_141c_receive_pdo_parameters() {
    let mut c = coupler(FULL);
    // One request per millisecond: the receive queue is never loaded.
    for index in 0x1400..=0x141C {
        let t = ms(u64::from(index));
        assert_eq!(read(&mut c, t, index, 0), Ok(vec![5]), "{index:#x}");
        assert_eq!(read(&mut c, t, index, 2), Ok(vec![255]));
        assert_eq!(read(&mut c, t, index, 5), Ok(vec![0, 0]));
        assert_eq!(read(&mut c, t, index, 3), Err(NO_SUB));
        assert_eq!(read(&mut c, t, index + 0x200, 0).map(|v| v.len()), Ok(1));
    }
    let t = ms(0x2000);
    assert_eq!(read(&mut c, t, 0x141D, 0), Err(NO_OBJECT));
    assert_eq!(read(&mut c, t, 0x161D, 0), Err(NO_OBJECT));
    assert_eq!(read_u32(&mut c, t, 0x1400, 1), Ok(0x203));
    assert_eq!(
        read_u32(&mut c, t, 0x1403, 1),
        Ok(0x8000_0503),
        "no third AO pair"
    );
    assert_eq!(read_u32(&mut c, t, 0x1404, 1), Ok(0x8000_0000));
    assert_eq!(read_u32(&mut c, t, 0x141C, 1), Ok(0x8000_0000));
    // Transmission types 0..=240 and 255 (manual table); 241..=254 are refused.
    assert_eq!(write(&mut c, t, 0x1400, 2, &[0]), Ok(()));
    assert_eq!(write(&mut c, t, 0x1400, 2, &[240]), Ok(()));
    assert_eq!(write(&mut c, t, 0x1400, 2, &[241]), Err(INVALID));
    assert_eq!(write(&mut c, t, 0x1400, 2, &[254]), Err(INVALID));
    assert_eq!(write(&mut c, t, 0x1400, 2, &[255]), Ok(()));
}

#[test]
fn manual_1800_1837_transmit_pdo_parameters() {
    let mut c = coupler(FULL);
    for index in 0x1800..=0x1837 {
        let t = ms(u64::from(index));
        assert_eq!(read(&mut c, t, index, 0), Ok(vec![5]), "{index:#x}");
        assert_eq!(read(&mut c, t, index, 2), Ok(vec![255]));
        assert_eq!(read(&mut c, t, index, 3), Ok(vec![0, 0]));
        assert_eq!(read(&mut c, t, index, 4), Err(NO_SUB), "reserved");
        assert_eq!(read(&mut c, t, index, 5), Ok(vec![0, 0]));
        assert_eq!(read(&mut c, t, index + 0x200, 0).map(|v| v.len()), Ok(1));
    }
    let t = ms(0x2000);
    assert_eq!(read(&mut c, t, 0x1838, 0), Err(NO_OBJECT));
    assert_eq!(read(&mut c, t, 0x1A38, 0), Err(NO_OBJECT));
    assert_eq!(read_u32(&mut c, t, 0x1800, 1), Ok(0x183));
    assert_eq!(read_u32(&mut c, t, 0x1801, 1), Ok(0x283));
    assert_eq!(
        read_u32(&mut c, t, 0x1802, 1),
        Ok(0x8000_0383),
        "4 AI fill TPDO2 only"
    );
    assert_eq!(read_u32(&mut c, t, 0x1837, 1), Ok(0x8000_0000));
    for bad in [241u8, 252, 253, 254] {
        assert_eq!(write(&mut c, t, 0x1800, 2, &[bad]), Err(INVALID), "{bad}");
    }
    for ok in [0u8, 1, 240, 255] {
        assert_eq!(write(&mut c, t, 0x1800, 2, &[ok]), Ok(()), "{ok}");
    }
    // 29-bit identifiers and "no RTR" are not supported on TPDOs.
    assert_eq!(
        write(&mut c, t, 0x1804, 1, &0xA000_0190u32.to_le_bytes()),
        Err(INVALID)
    );
    assert_eq!(
        write(&mut c, t, 0x1804, 1, &0xC000_0190u32.to_le_bytes()),
        Err(INVALID)
    );
    assert_eq!(
        write(&mut c, t, 0x1804, 1, &0x8000_0190u32.to_le_bytes()),
        Ok(())
    );
}
