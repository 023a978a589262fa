//! §1.3: Process Data Channel placement rules and their Opt Bus Fault sub-codes (§1.5).
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_adv200::Adv200;
use cantwin_adv200::params::par;
use common::*;

/// Mapping entries of mapping object `index` and the COB-ID of its communication object.
fn pdo(h: &H, index: u16) -> (u32, Vec<u32>) {
    let od = h.d.device().unwrap().od();
    let n = od.get_unsigned(index, 0).unwrap();
    let map = (1..=n)
        .map(|k| od.get_unsigned(index, k as u8).unwrap() as u32)
        .collect();
    let comm = index - 0x200;
    (od.get_unsigned(comm, 1).unwrap() as u32, map)
}

fn m2s(d: &mut Adv200, n: u16, sys: &str, ipa: u16) {
    d.set_param_str(par::m2s_sys(n), sys).unwrap();
    d.set_param(par::m2s_ipa(n), i64::from(ipa)).unwrap();
}

fn s2m(d: &mut Adv200, n: u16, sys: &str, ipa: u16) {
    d.set_param_str(par::s2m_sys(n), sys).unwrap();
    d.set_param(par::s2m_ipa(n), i64::from(ipa)).unwrap();
}

/// The mapping entry of M2S (S2M) channel n's `mon` with `bits`.
fn m(n: u16, bits: u32) -> u32 {
    (u32::from(0x2000 + par::m2s_mon(n)) << 16) | 0x100 | bits
}
fn s(n: u16, bits: u32) -> u32 {
    (u32::from(0x2000 + par::s2m_mon(n)) << 16) | 0x100 | bits
}

fn faults(setup: impl FnOnce(&mut Adv200)) -> (Vec<u16>, Vec<String>) {
    let h = H::canopen(setup);
    (h.d.opt_bus_faults(), h.frames())
}

#[test]
fn manual_1_3_1_pdos_fill_from_rpdo1_four_words_each_up_to_four() {
    let h = H::canopen(|d| {
        for n in 1..=6 {
            m2s(d, n, "Count 16", 0);
            s2m(d, n, "Count 16", par::MOTOR_SPEED);
        }
        // Channel 1 must carry data for the placeholders after it to count.
        m2s(d, 1, "Count 16", par::WORD_DECOMP_SRC);
        for n in 2..=6 {
            m2s(d, n, "Mdplc 16", 0);
        }
    });
    assert!(h.d.opt_bus_faults().is_empty());
    assert_eq!(
        pdo(&h, 0x1600),
        (0x20C, vec![m(1, 16), m(2, 16), m(3, 16), m(4, 16)])
    );
    assert_eq!(pdo(&h, 0x1601), (0x30C, vec![m(5, 16), m(6, 16)]));
    assert_eq!(pdo(&h, 0x1602), (0x8000_040C, vec![]));
    assert_eq!(
        pdo(&h, 0x1A00),
        (0x4000_018C, vec![s(1, 16), s(2, 16), s(3, 16), s(4, 16)])
    );
    assert_eq!(pdo(&h, 0x1A01), (0x4000_028C, vec![s(5, 16), s(6, 16)]));
    assert_eq!(pdo(&h, 0x1A03), (0xC000_048C, vec![]));
}

#[test]
fn manual_1_3_pdc_32_bit_items_never_straddle_pdos() {
    // Three words, then a 32-bit item that would straddle RPDO1 and RPDO2: FF34 + (4 − 1).
    let (f, frames) = faults(|d| {
        m2s(d, 1, "Fill 16", 0);
        m2s(d, 2, "Count 16", par::WORD_DECOMP_SRC);
        m2s(d, 3, "Eu", par::RAMP_REF_1_SRC);
        m2s(d, 4, "Count 32", par::COMPARE_INPUT_1_SRC);
    });
    assert_eq!(f, [0xFF37]);
    // Boot-up, then EMCY 0xFF11 (Opt Bus fault) with the sub-code in the manufacturer bytes.
    assert_eq!(frames, ["70C#00", "08C#11FF8137FF000000"]);
    // On the TPDO side: FF54 + (n − 1).
    let (f, _) = faults(|d| {
        s2m(d, 1, "Count 16", par::MOTOR_SPEED);
        s2m(d, 2, "Count 16", par::MOTOR_SPEED);
        s2m(d, 3, "Count 16", par::MOTOR_SPEED);
        s2m(d, 4, "Count 32", par::s2m_dig(4));
    });
    assert_eq!(f, [0xFF57]);
    // Aligned, the same 32-bit item fits: two words, then 32 bits at the start of RPDO1's
    // second half.
    let h = H::canopen(|d| {
        m2s(d, 1, "Count 16", par::WORD_DECOMP_SRC);
        m2s(d, 2, "Eu", par::RAMP_REF_1_SRC);
        m2s(d, 3, "Count 32", par::COMPARE_INPUT_1_SRC);
    });
    assert_eq!(pdo(&h, 0x1600).1, vec![m(1, 16), m(2, 16), m(3, 32)]);
}

#[test]
fn manual_1_3_1_ipa_zero_placeholder_closes_the_pdo() {
    // The §1.3.1 example with a value-format placeholder: RPDO1 of 2 words, RPDO2 of 2 words.
    let h = H::canopen(|d| {
        m2s(d, 1, "Eu", par::RAMP_REF_1_SRC);
        m2s(d, 2, "Count 16", par::WORD_DECOMP_SRC);
        m2s(d, 3, "Count 16", 0);
        m2s(d, 4, "Count 32", par::COMPARE_INPUT_1_SRC);
    });
    assert!(h.d.opt_bus_faults().is_empty());
    assert_eq!(pdo(&h, 0x1600), (0x20C, vec![m(1, 16), m(2, 16)]));
    assert_eq!(pdo(&h, 0x1601), (0x30C, vec![m(4, 32)]));
    // The export wiring: each src now takes the channel's mon, shown in dest.
    assert_eq!(
        h.d.param(par::RAMP_REF_1_SRC),
        Ok(i64::from(par::m2s_mon(1)))
    );
    assert_eq!(
        h.d.param(par::COMPARE_INPUT_1_SRC),
        Ok(i64::from(par::m2s_mon(4)))
    );
    assert_eq!(
        h.d.param(par::m2s_dest(2)),
        Ok(i64::from(par::WORD_DECOMP_SRC))
    );
}

#[test]
fn manual_1_3_1_fill_is_inserted_and_not_assigned_ends_the_pdc() {
    // A Fill that does not follow an assigned datum is padding: a dummy entry of its size
    // (0x0007 UNSIGNED32, 0x0006 UNSIGNED16) in the RPDO.
    let h = H::canopen(|d| {
        m2s(d, 1, "Fill 32", 0);
        m2s(d, 2, "Eu", par::RAMP_REF_1_SRC);
        m2s(d, 3, "Fill 16", 4);
        m2s(d, 4, "Count 16", par::WORD_DECOMP_SRC);
        // Channel 5 Not assigned: channel 6 is never placed.
        m2s(d, 6, "Count 16", par::WORD_DECOMP_SRC);
    });
    assert!(h.d.opt_bus_faults().is_empty());
    assert_eq!(pdo(&h, 0x1600).1, vec![0x0007_0020, m(2, 16), 0x0006_0010]);
    assert_eq!(pdo(&h, 0x1601).1, vec![m(4, 16)]);
    assert_eq!(pdo(&h, 0x1602).1, Vec::<u32>::new());
}

#[test]
fn manual_1_3_1_example_fill_32_after_a_datum_closes_rpdo1() {
    // The example as printed: RPDO1 of 2 words (M->S1 + M->S2), RPDO2 of 2 words (M->S4).
    let mut h = H::canopen(|d| {
        m2s(d, 1, "Eu", par::RAMP_REF_1_SRC);
        m2s(d, 2, "Count 16", par::WORD_DECOMP_SRC);
        m2s(d, 3, "Fill 32", 0);
        m2s(d, 4, "Count 32", par::COMPARE_INPUT_1_SRC);
    });
    assert!(h.d.opt_bus_faults().is_empty());
    assert_eq!(pdo(&h, 0x1600), (0x20C, vec![m(1, 16), m(2, 16)]));
    assert_eq!(pdo(&h, 0x1601), (0x30C, vec![m(4, 32)]));
    assert_eq!(
        h.d.param(par::COMPARE_INPUT_1_SRC),
        Ok(i64::from(par::m2s_mon(4)))
    );
    // 4 bytes each on the wire: RPDO2 with 100000 reaches M->S4 mon, no length EMCY.
    h.send("000#010C");
    assert_eq!(h.send("30C#A0860100"), Vec::<String>::new());
    h.send("080#");
    assert_eq!(h.d.param(par::m2s_mon(4)), Ok(100_000));
}

#[test]
fn manual_1_3_3_mdplc_variables() {
    let mut h = H::canopen(|d| {
        m2s(d, 1, "Mdplc 32", 0);
        d.set_param_str(par::s2m_sys(1), "Count 16").unwrap();
    });
    // Naming Dig Fieldbus S->M1 (4184) as S2M ipa sets its format to Mdplc.
    // 0x2000 + 4182 = 0x3056.
    assert_eq!(h.send("60C#2B56300158100000"), ["58C#6056300100000000"]);
    assert_eq!(h.d.param(par::s2m_sys(1)), Ok(6));
    h.d.reset_drive(
        cantwin_can::Instant::from_nanos(h.now),
        &mut cantwin_can::Outbox::new(),
    );
    h.run_to(h.now);
    assert_eq!(pdo(&h, 0x1A00).1, vec![s(1, 16)]);
    assert_eq!(pdo(&h, 0x1600).1, vec![m(1, 32)]);
    h.send("000#010C");
    // The application writes Dig Fieldbus S->M1 (0x3058); the master reads it in TPDO1.
    h.send("60C#2B58300134120000");
    h.send("20C#78563412");
    assert_eq!(h.send("080#"), ["18C#3412"]);
    // The M2S data lands in Fieldbus M->S1 mon.
    assert_eq!(h.d.param(par::m2s_mon(1)), Ok(0x1234_5678));
}

#[test]
fn manual_1_5_opt_bus_fault_configuration_sub_codes() {
    // FF14: M2S ipa is not a src parameter (Dig ramp ref 1 is a value).
    let (f, _) = faults(|d| {
        m2s(d, 1, "Count 16", par::WORD_DECOMP_SRC);
        m2s(d, 2, "Eu", par::DIG_RAMP_REF_1);
    });
    assert_eq!(f, [0xFF15]);
    // FF24: two srcs take M2S channel 1.
    let (f, _) = faults(|d| {
        m2s(d, 1, "Count 16", par::WORD_DECOMP_SRC);
        d.set_param(par::RAMP_REF_1_SRC, i64::from(par::m2s_mon(1)))
            .unwrap();
    });
    assert_eq!(f, [0xFF24]);
    // FF34: a 16-bit channel on a 32-bit src.
    assert_eq!(
        faults(|d| m2s(d, 1, "Count 16", par::COMPARE_INPUT_1_SRC)).0,
        [0xFF34]
    );
    // FF44: S2M ipa names no parameter.
    let (f, _) = faults(|d| {
        s2m(d, 1, "Fill 16", 0);
        s2m(d, 2, "Fill 16", 0);
        s2m(d, 3, "Count 16", 1);
    });
    assert_eq!(f, [0xFF46]);
    // FF54: a 16-bit channel on a 32-bit parameter.
    assert_eq!(
        faults(|d| s2m(d, 1, "Count 16", par::m2s_mon(1))).0,
        [0xFF54]
    );
    // FF64: a src selector is not a value to send.
    let (f, _) = faults(|d| {
        for n in 1..=15 {
            s2m(d, n, "Fill 16", 0);
        }
        s2m(d, 16, "Count 16", par::RAMP_REF_1_SRC);
    });
    assert_eq!(f, [0xFF73]);
    // FF74 / FF84: channel 9 makes the PDC longer than 16 words.
    let (f, _) = faults(|d| {
        for n in 1..=8 {
            m2s(d, n, "Fill 32", 0);
        }
        m2s(d, 9, "Fill 16", 0);
    });
    assert_eq!(f, [0xFF7C]);
    let (f, _) = faults(|d| {
        for n in 1..=8 {
            s2m(d, n, "Fill 32", 0);
        }
        s2m(d, 9, "Count 16", par::MOTOR_SPEED);
    });
    assert_eq!(f, [0xFF8C]);
}

#[test]
fn manual_1_5_factory_defaults_leave_the_card_off_the_bus() {
    // Baud rate None: FF02, nothing on the bus.
    let h = H::new(Default::default(), |d| {
        d.set_param_str(par::FIELDBUS_TYPE, "CANopen").unwrap();
    });
    assert_eq!(h.d.opt_bus_faults(), [0xFF02]);
    assert!(h.frames().is_empty());
    assert!(h.d.nmt_state().is_none());
    // Address 0: FF03.
    let h = H::new(Default::default(), |d| {
        d.set_param_str(par::FIELDBUS_TYPE, "DS402").unwrap();
        d.set_param_str(par::FIELDBUS_BAUDRATE, "1M").unwrap();
    });
    assert_eq!(h.d.opt_bus_faults(), [0xFF03]);
    // A fieldbus the card does not speak: FF01.
    let h = H::new(Default::default(), |d| {
        d.set_param_str(par::FIELDBUS_TYPE, "Profibus").unwrap();
    });
    assert_eq!(h.d.opt_bus_faults(), [0xFF01]);
    // Fieldbus type Off: no card, no fault.
    let h = H::new(Default::default(), |_| {});
    assert!(h.d.opt_bus_faults().is_empty());
    // Alarm reset does not clear a configuration fault.
    let mut h = H::new(Default::default(), |d| {
        d.set_param_str(par::FIELDBUS_TYPE, "CANopen").unwrap();
    });
    h.d.set_param(par::ALARM_RESET, 1).unwrap();
    h.run_to(MS);
    assert_eq!(h.d.opt_bus_faults(), [0xFF02]);
}

#[test]
fn manual_1_2_fieldbus_parameters_act_only_after_a_drive_reset() {
    let mut h = H::canopen(|_| {});
    // Fieldbus address 13 (4006 = 0x2FA6) by SDO: accepted, node 12 still answers.
    assert_eq!(h.send("60C#2BA62F010D000000"), ["58C#60A62F0100000000"]);
    assert_eq!(h.send("60C#40A62F0100000000"), ["58C#4BA62F010D000000"]);
    let mut out = cantwin_can::Outbox::new();
    h.d.reset_drive(cantwin_can::Instant::from_nanos(h.now), &mut out);
    assert_eq!(out.frames()[0].to_string(), "70D#00");
    assert_eq!(h.send("60C#40A62F0100000000"), Vec::<String>::new());
    assert_eq!(h.send("60D#40A62F0100000000"), ["58D#4BA62F010D000000"]);
}

#[test]
fn manual_1_1_7_asynchronous_tpdo_is_sent_when_its_value_changes() {
    let mut h = H::canopen(|d| s2m(d, 1, "Count 16", par::DIG_RAMP_REF_1));
    // TPDO1 transmission type 255 (§1.1.7: "254...255 se asincrono").
    assert_eq!(h.send("60C#2F001802FF000000"), ["58C#6000180200000000"]);
    h.send("000#010C");
    // PAR 600 = 100: the TPDO follows at once; writing the same value again sends nothing.
    assert_eq!(
        h.send("60C#2B58220164000000"),
        ["58C#6058220100000000", "18C#6400"]
    );
    assert_eq!(h.send("60C#2B58220164000000"), ["58C#6058220100000000"]);
    // Synchronous again (type 1): a change waits for the SYNC.
    assert_eq!(h.send("60C#2F00180201000000"), ["58C#6000180200000000"]);
    assert_eq!(h.send("60C#2B582201C8000000"), ["58C#6058220100000000"]);
    assert_eq!(h.send("080#"), ["18C#C800"]);
}
