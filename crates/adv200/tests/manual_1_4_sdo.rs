//! §1.1 items 10–11 and §1.4: SDO access to the card, exact request/response frames.
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_adv200::Adv200Config;
use cantwin_adv200::params::par;
use common::*;

#[test]
fn manual_1_4_write_1000_to_par_600_with_four_bytes() {
    let mut h = H::canopen(|_| {});
    assert_eq!(h.send("60C#23582201E8030000"), ["58C#6058220100000000"]);
    assert_eq!(h.d.param(par::DIG_RAMP_REF_1), Ok(1000));
    // Upload returns the parameter's size: 2 bytes (e = 1, s = 1, n = 2).
    assert_eq!(h.send("60C#4058220100000000"), ["58C#4B582201E8030000"]);
}

#[test]
fn manual_1_4_downloads_of_one_to_four_bytes_are_accepted_for_any_parameter() {
    let mut h = H::canopen(|_| {});
    // One byte, two bytes (sign-extended for a signed parameter), four bytes.
    assert_eq!(h.send("60C#2F58220105000000"), ["58C#6058220100000000"]);
    assert_eq!(h.d.param(600), Ok(5));
    assert_eq!(h.send("60C#2B582201F6FF0000"), ["58C#6058220100000000"]);
    assert_eq!(h.d.param(600), Ok(-10));
    assert_eq!(h.send("60C#23582201F6FFFFFF"), ["58C#6058220100000000"]);
    assert_eq!(h.d.param(600), Ok(-10));
    // A 32-bit parameter (Dig Fieldbus S->M1, 4184 = 0x1058 → 0x3058) uploads 4 bytes.
    assert_eq!(h.send("60C#2F58300107000000"), ["58C#6058300100000000"]);
    assert_eq!(h.send("60C#4058300100000000"), ["58C#4358300107000000"]);
    // Expedited without size indication: 4 bytes.
    assert_eq!(h.send("60C#2258220164000000"), ["58C#6058220100000000"]);
    assert_eq!(h.d.param(600), Ok(100));
    // Sub-index 0 tells the highest sub-index, 1.
    assert_eq!(h.send("60C#4058220000000000"), ["58C#4F58220001000000"]);
}

#[test]
fn manual_1_4_abort_codes() {
    let mut h = H::canopen(|_| {});
    // Parameter missing (PAR 1 = 0x2001): 0x06020000.
    assert_eq!(h.send("60C#4001200100000000"), ["58C#8001200100000206"]);
    // Read-only: Motor speed 260 = 0x2104: 0x06010002.
    assert_eq!(h.send("60C#2B04210101000000"), ["58C#8004210102000106"]);
    // Above / below limits of Dig ramp ref 1 (±8000): 0x06090031 / 0x06090032.
    assert_eq!(h.send("60C#2B58220141230000"), ["58C#8058220131000906"]);
    assert_eq!(h.send("60C#2B582201BFDC0000"), ["58C#8058220132000906"]);
    // Invalid value: Ramp ref 1 src (610 = 0x2262) pointing at no parameter: 0x06090030.
    assert_eq!(h.send("60C#2B62220103000000"), ["58C#8062220130000906"]);
    // Sub-index other than 0/1: 0x06090011; sub-index 0 is read-only.
    assert_eq!(h.send("60C#4058220200000000"), ["58C#8058220211000906"]);
    assert_eq!(h.send("60C#2F58220001000000"), ["58C#8058220002000106"]);
    // Wrong device state: Full scale speed (680 = 0x22A8) while the drive is enabled.
    assert_eq!(h.send("000#010C"), Vec::<String>::new());
    h.d.set_digital_input(1, true);
    h.run_to(h.now + MS);
    assert_eq!(h.send("60C#2BA82201DC050000"), ["58C#80A8220122000008"]);
}

#[test]
fn manual_1_1_item_10_sub_index_ff_is_refused() {
    let mut h = H::canopen(|_| {});
    assert_eq!(h.send("60C#401810FF00000000"), ["58C#801810FF11000906"]);
    assert_eq!(h.send("60C#235822FF00000000"), ["58C#805822FF11000906"]);
}

#[test]
fn manual_1_1_item_11_only_expedited_transfers() {
    let mut h = H::canopen(|_| {});
    // Segmented download initiate, block download, block upload: command specifier not
    // valid, 0x05040001.
    assert_eq!(h.send("60C#2158220106000000"), ["58C#8058220101000405"]);
    assert_eq!(h.send("60C#C658220106000000"), ["58C#8058220101000405"]);
    assert_eq!(h.send("60C#A008100000000000"), ["58C#8008100001000405"]);
    // A stray segment request.
    assert_eq!(h.send("60C#6000000000000000"), ["58C#8000000001000405"]);
    // Four bytes or less go through the CiA 301 stack.
    assert_eq!(h.send("60C#4009100000000000"), ["58C#47091000312E3000"]);
}

#[test]
fn manual_1_1_item_11_limit_lifted_by_configuration() {
    let mut h = H::new(
        Adv200Config {
            expedited_only: false,
            ..Adv200Config::default()
        },
        |d| {
            d.set_param_str(par::FIELDBUS_TYPE, "CANopen").unwrap();
            d.set_param_str(par::FIELDBUS_BAUDRATE, "500k").unwrap();
            d.set_param(par::FIELDBUS_ADDRESS, 12).unwrap();
        },
    );
    assert_eq!(h.send("60C#4008100000000000"), ["58C#4108100006000000"]);
    assert_eq!(h.send("60C#6000000000000000"), ["58C#0341445632303000"]);
}

#[test]
fn manual_1_1_5_objects_and_defaults() {
    let mut h = H::canopen(|_| {});
    // Guard time 60 ms, life time factor 3 (§1.1.3).
    assert_eq!(h.send("60C#400C100000000000"), ["58C#4B0C10003C000000"]);
    assert_eq!(h.send("60C#400D100000000000"), ["58C#4F0D100003000000"]);
    // RPDO communication sub 0 = 2, TPDO communication sub 0 = 3 (§1.1.6, §1.1.7).
    assert_eq!(h.send("60C#4000140000000000"), ["58C#4F00140002000000"]);
    assert_eq!(h.send("60C#4000180000000000"), ["58C#4F00180003000000"]);
    // No event timer (sub 5), no TIME object (0x1012), no error history (0x1003).
    assert_eq!(h.send("60C#4000180500000000"), ["58C#8000180511000906"]);
    assert_eq!(h.send("60C#4012100000000000"), ["58C#8012100000000206"]);
    assert_eq!(h.send("60C#4003100000000000"), ["58C#8003100000000206"]);
    // COB-ID SYNC with bit 31 as §1.1.9 prints it; EMCY 0x80 + node (§1.1.10).
    assert_eq!(h.send("60C#4005100000000000"), ["58C#4305100080000080"]);
    assert_eq!(h.send("60C#4014100000000000"), ["58C#431410008C000000"]);
    // Device type 0 in the CANopen personality.
    assert_eq!(h.send("60C#4000100000000000"), ["58C#4300100000000000"]);
}

#[test]
fn manual_1_1_7_tpdos_do_not_answer_remote_requests() {
    let mut h = H::canopen(|d| {
        d.set_param_str(par::s2m_sys(1), "Count 16").unwrap();
        d.set_param(par::s2m_ipa(1), i64::from(par::MOTOR_SPEED))
            .unwrap();
    });
    h.send("000#010C");
    // COB-ID with bit 30 set: no RTR.
    assert_eq!(h.send("60C#4000180100000000"), ["58C#430018018C010040"]);
    assert_eq!(h.send("18C#R"), Vec::<String>::new());
    assert_eq!(h.send("080#"), ["18C#0000"]);
}

#[test]
fn manual_1_1_2_nmt_reset_node_keeps_the_drive_parameters() {
    let mut h = H::canopen(|d| {
        d.set_param_str(par::s2m_sys(1), "Count 16").unwrap();
        d.set_param(par::s2m_ipa(1), i64::from(par::DIG_RAMP_REF_1))
            .unwrap();
    });
    assert_eq!(h.send("60C#2B58220164000000"), ["58C#6058220100000000"]);
    // Reset node: boot-up again; the drive's parameters stay, the PDC mapping comes back.
    assert_eq!(h.send("000#810C"), ["70C#00"]);
    assert_eq!(h.d.param(par::DIG_RAMP_REF_1), Ok(100));
    assert_eq!(h.d.param(par::FIELDBUS_ADDRESS), Ok(12));
    assert_eq!(h.send("60C#4058220100000000"), ["58C#4B58220164000000"]);
    h.send("000#010C");
    assert_eq!(h.send("080#"), ["18C#6400"]);
    // Reset communication likewise.
    assert_eq!(h.send("000#820C"), ["70C#00"]);
    assert_eq!(h.d.param(par::DIG_RAMP_REF_1), Ok(100));
}

#[test]
fn manual_1_1_7_tpdo_cob_id_bit_30_stays_set_and_rtr_types_are_refused() {
    let mut h = H::canopen(|d| {
        d.set_param_str(par::s2m_sys(1), "Count 16").unwrap();
        d.set_param(par::s2m_ipa(1), i64::from(par::MOTOR_SPEED))
            .unwrap();
    });
    let invalid = |i: &str, s: &str| format!("58C#80{i}{s}30000906");
    // PDO invalid (bit 31) with bit 30 cleared: 0x06090030; with bit 30 set: accepted.
    assert_eq!(h.send("60C#230018018C010080"), [invalid("0018", "01")]);
    assert_eq!(h.send("60C#230018018C0100C0"), ["58C#6000180100000000"]);
    // Transmission types 252 and 253 need RTR: refused; 1, 254, 255 accepted.
    assert_eq!(h.send("60C#2F001802FC000000"), [invalid("0018", "02")]);
    assert_eq!(h.send("60C#2F001802FD000000"), [invalid("0018", "02")]);
    for ty in ["01", "FE", "FF"] {
        assert_eq!(
            h.send(&format!("60C#2F001802{ty}000000")),
            ["58C#6000180200000000"]
        );
    }
    // A remote request is not answered.
    h.send("60C#230018010C018040");
    h.send("000#010C");
    assert_eq!(h.send("18C#R"), Vec::<String>::new());
}

#[test]
fn manual_1_1_6_transmission_types_are_1_254_and_255() {
    let mut h = H::canopen(|_| {});
    let invalid = |i: &str| format!("58C#80{i}0230000906");
    for (index, ok) in [
        ("0014", "58C#6000140200000000"),
        ("0018", "58C#6000180200000000"),
    ] {
        for ty in ["00", "05", "F0", "FC", "FD"] {
            assert_eq!(
                h.send(&format!("60C#2F{index}02{ty}000000")),
                [invalid(index)],
                "{index} type {ty}"
            );
        }
        for ty in ["01", "FE", "FF"] {
            assert_eq!(
                h.send(&format!("60C#2F{index}02{ty}000000")),
                [ok],
                "{index} {ty}"
            );
        }
    }
}

#[test]
fn manual_1_2_fieldbus_enumerations_refuse_other_values_as_invalid() {
    let mut h = H::canopen(|_| {});
    // PAR 4000 (0x2FA0) = 9, PAR 4004 (0x2FA4) = 7: 0x06090030 "invalid value" (§1.4).
    assert_eq!(h.send("60C#2BA02F0109000000"), ["58C#80A02F0130000906"]);
    assert_eq!(h.send("60C#2BA42F0107000000"), ["58C#80A42F0130000906"]);
    // PAR 4006 (0x2FA6): 1–127 (§1.2), 200 is too high.
    assert_eq!(h.send("60C#2BA62F01C8000000"), ["58C#80A62F0131000906"]);
    assert_eq!(h.send("60C#2BA62F017F000000"), ["58C#60A62F0100000000"]);
}

#[test]
fn manual_1_1_5_device_name_0x1008_is_read_with_one_expedited_upload() {
    // Table 1.1.5 lists 0x1008; the card answers expedited transfers only (§1.1 item 11),
    // so its name is at most 4 bytes: "ADV2", as the EDS states.
    let mut h = H::canopen(|_| {});
    assert_eq!(h.send("60C#4008100000000000"), ["58C#4308100041445632"]);
    let eds = cantwin_adv200::eds::eds_text(cantwin_adv200::od::Personality::CanOpen).unwrap();
    let eds = cantwin_eds::parse(&eds).unwrap();
    let name = eds.entry(0x1008, 0).unwrap();
    assert_eq!(
        name.default_value.as_ref().map(|v| v.to_string()),
        Some("ADV2".to_owned())
    );
}
