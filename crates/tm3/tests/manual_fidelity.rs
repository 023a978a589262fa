//! Where the twin followed CiA 301 or its own choice instead of the manual's tables: EMCY
//! only after boot-up, the 0x8210 length rule, the reserved ranges of 1014H/1029H/1201H/
//! 1400H, 1201H sub 3 = 0, bit 4 of 1001H on a SYNC timeout, write-back of a valid PDO's
//! entries (one test per row of the table in the module documentation of
//! `cantwin_tm3::coupler`) and the EDS's vendor name and 1016H sub 0.
#![allow(clippy::unwrap_used)]

mod harness;

use cantwin_can::{Frame, Node, Outbox};
use cantwin_tm3::coupler::{CouplerConfig, Fitted, Tm3Coupler};
use cantwin_tm3::island::Island;
use harness::*;

const BOOT_UP: &str = "703#00";

fn strings(out: &mut Outbox) -> Vec<String> {
    out.drain().map(|f| f.to_string()).collect()
}

fn boot_up() -> Frame {
    Frame::std(0x703, &[0]).unwrap()
}

/// A started coupler with a digital input and a relay output module.
fn running() -> Tm3Coupler {
    let mut c = coupler(&["TM3DI8", "TM3DQ8R"]);
    start(&mut c, ms(1));
    c
}

#[test]
fn manual_emcy_7002_follows_the_boot_up_at_power_on() {
    let mut c = Tm3Coupler::new(CouplerConfig::new(
        NODE,
        Island::from_references(&["TM3DI8", "TM3DQ8R"]).unwrap(),
    ))
    .unwrap();
    c.fit(2, Fitted::Empty, ms(0), &mut Outbox::new()).unwrap();
    let mut out = Outbox::new();
    c.on_power_up(ms(0), &mut out);
    // Queued together, the EMCY (0x083) would win arbitration over the boot-up (0x703).
    assert_eq!(strings(&mut out), [BOOT_UP]);
    // Nothing before the boot-up is on the bus, whatever else happens meanwhile.
    c.on_tick(ms(0), &mut out);
    assert_eq!(strings(&mut out), Vec::<String>::new());
    c.on_sent(&boot_up(), us(112), &mut out);
    assert_eq!(strings(&mut out), ["083#0270810400004002"]);
}

#[test]
fn manual_emcy_7002_reaches_the_bus_after_the_boot_up_despite_its_priority() {
    use cantwin_bus::{BusConfig, PortConfig, Recorder, Simulation};
    use cantwin_can::{BitRate, ListenOnly};
    let mut c = Tm3Coupler::new(CouplerConfig::new(
        NODE,
        Island::from_references(&["TM3DI8", "TM3DQ8R"]).unwrap(),
    ))
    .unwrap();
    c.fit(2, Fitted::Empty, ms(0), &mut Outbox::new()).unwrap();
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R500K));
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    sim.attach(bus, c, PortConfig::default()).unwrap();
    let master = sim.attach(bus, ListenOnly, PortConfig::default()).unwrap();
    sim.run_until(ms(5));
    // NMT reset communication: the module error is raised again, after the boot-up.
    sim.transmit(master, Frame::std(0, &[0x82, NODE]).unwrap())
        .unwrap();
    sim.run_until(ms(10));
    let frames: Vec<String> = sim
        .bus(bus)
        .unwrap()
        .tap::<Recorder>(tap)
        .unwrap()
        .frames()
        .map(|f| f.frame.to_string())
        .collect();
    assert_eq!(
        frames,
        [
            BOOT_UP,
            "083#0270810400004002",
            "000#8203",
            BOOT_UP,
            "083#0270810400004002"
        ]
    );
}

#[test]
fn manual_emcy_7003_follows_the_boot_up_after_nmt_reset_communication() {
    let mut c = running();
    let mut out = Outbox::new();
    c.fit(2, Fitted::Empty, ms(2), &mut out).unwrap();
    assert_eq!(strings(&mut out), ["083#0370810800008002"]);
    c.on_frame(&Frame::std(0, &[0x82, NODE]).unwrap(), ms(3), &mut out);
    assert_eq!(strings(&mut out), [BOOT_UP]);
    c.on_sent(&boot_up(), ms(3), &mut out);
    assert_eq!(strings(&mut out), ["083#0370810800008002"]);
    // A node guarding answer on 0x703 is not a boot-up: it releases nothing.
    c.on_frame(&Frame::std(0, &[0x81, NODE]).unwrap(), ms(4), &mut out);
    assert_eq!(strings(&mut out), [BOOT_UP]);
    c.on_sent(&Frame::std(0x703, &[0x7F]).unwrap(), ms(4), &mut out);
    assert_eq!(strings(&mut out), Vec::<String>::new());
    c.on_sent(&boot_up(), ms(4), &mut out);
    assert_eq!(strings(&mut out), ["083#0370810800008002"]);
}

#[test]
fn manual_emcy_table_8210_an_over_long_rpdo_is_not_processed() {
    let mut c = running();
    // RPDO1 maps one output byte; two bytes are a length mismatch: not processed, 0x8210
    // (the manual's table has no 0x8220). Register 0x11: generic + communication.
    assert_eq!(
        send(&mut c, ms(5), 0x203, &[0xFF, 0x00]),
        ["083#1082110000000000"]
    );
    assert_eq!(c.digital_output(2, 0), Ok(false));
    // The right length is processed and resets the error.
    assert_eq!(
        send(&mut c, ms(6), 0x203, &[0x01]),
        ["083#0000000000000000"]
    );
    assert_eq!(c.digital_output(2, 0), Ok(true));
    assert_eq!(read_u32(&mut c, ms(7), 0x1003, 1), Ok(0x0011_8210));
}

#[test]
fn manual_1029_values_03h_ffh_are_reserved() {
    let mut c = coupler(&["TM3DI8"]);
    for v in [0x03u8, 0x7F, 0x80, 0xFF] {
        assert_eq!(
            write(&mut c, ms(1), 0x1029, 1, &[v]),
            Err(0x0609_0030),
            "{v:#x}"
        );
    }
    for v in [0u8, 1, 2] {
        assert_eq!(write(&mut c, ms(1), 0x1029, 1, &[v]), Ok(()));
        assert_eq!(read(&mut c, ms(1), 0x1029, 1), Ok(vec![v]));
    }
}

#[test]
fn manual_1201_and_1400_29_bit_cob_ids_are_not_supported() {
    let mut c = coupler(&["TM3DI8", "TM3DQ8R"]);
    for sub in [1u8, 2] {
        let v = 0xA000_0000u32 | 0x0123_4567;
        assert_eq!(
            write(&mut c, ms(1), 0x1201, sub, &v.to_le_bytes()),
            Err(0x0609_0030)
        );
    }
    assert_eq!(
        write(&mut c, ms(1), 0x1201, 1, &0x0000_0690u32.to_le_bytes()),
        Ok(())
    );
    // RPDO1 taken out of use first, then a 29-bit identifier, valid or not.
    assert_eq!(
        write(&mut c, ms(1), 0x1400, 1, &0x8000_0203u32.to_le_bytes()),
        Ok(())
    );
    for v in [0xA000_0203u32, 0x2000_0203] {
        assert_eq!(
            write(&mut c, ms(1), 0x1400, 1, &v.to_le_bytes()),
            Err(0x0609_0030)
        );
    }
    assert_eq!(read_u32(&mut c, ms(1), 0x1400, 1), Ok(0x8000_0203));
}

#[test]
fn manual_1014_bits_31_and_30_are_reserved_0() {
    let mut c = coupler(&["TM3DI8"]);
    for v in [0x8000_0083u32, 0x4000_0083, 0x2000_0083] {
        assert_eq!(
            write(&mut c, ms(1), 0x1014, 0, &v.to_le_bytes()),
            Err(0x0609_0030)
        );
    }
    assert_eq!(read_u32(&mut c, ms(1), 0x1014, 0), Ok(0x83));
    assert_eq!(
        write(&mut c, ms(1), 0x1014, 0, &0x83u32.to_le_bytes()),
        Ok(())
    );
}

#[test]
fn manual_1201_sub_3_takes_0_its_default_so_a_dcf_of_the_defaults_downloads() {
    let mut c = coupler(&["TM3DI8"]);
    assert_eq!(read(&mut c, ms(1), 0x1201, 3), Ok(vec![0]));
    assert_eq!(write(&mut c, ms(1), 0x1201, 3, &[0]), Ok(()));
    assert_eq!(write(&mut c, ms(1), 0x1201, 3, &[5]), Ok(()));
    assert_eq!(write(&mut c, ms(1), 0x1201, 3, &[0]), Ok(()));
    assert_eq!(write(&mut c, ms(1), 0x1201, 3, &[128]), Err(0x0609_0030));
    assert_eq!(read(&mut c, ms(1), 0x1201, 3), Ok(vec![0]));
}

#[test]
fn manual_1001_bit_4_communication_error_while_the_sync_timed_out() {
    let mut c = coupler(&["TM3DI8", "TM3AI4"]);
    assert_eq!(
        write(&mut c, ms(1), 0x1006, 0, &10_000u32.to_le_bytes()),
        Ok(())
    );
    send(&mut c, ms(20), 0x080, &[]);
    // 0x31: generic, communication (bit 4) and device profile (bit 5, 0x0080 is not
    // active before OPERATIONAL, so here only bits 0 and 4).
    assert_eq!(tick(&mut c, ms(35)), ["083#01F0110000000000"]);
    assert_eq!(read(&mut c, ms(36), 0x1001, 0), Ok(vec![0x11]));
    assert_eq!(send(&mut c, ms(40), 0x080, &[]), ["083#0000000000000000"]);
    assert_eq!(read(&mut c, ms(41), 0x1001, 0), Ok(vec![0x00]));
}

/// Writes back what `index`/`sub` holds (accepted), then `other` (refused with `abort`);
/// the entry keeps its value.
fn write_back_and_change(index: u16, sub: u8, other: &[u8], abort: u32) {
    let mut c = running();
    let held = read(&mut c, ms(2), index, sub).unwrap();
    assert_eq!(
        write(&mut c, ms(2), index, sub, &held),
        Ok(()),
        "write-back"
    );
    assert_eq!(
        write(&mut c, ms(2), index, sub, other),
        Err(abort),
        "change"
    );
    assert_eq!(read(&mut c, ms(2), index, sub), Ok(held));
}

#[test]
fn cia301_7_5_2_35_valid_rpdo_cob_id_write_back_and_change() {
    write_back_and_change(0x1400, 1, &0x0000_0204u32.to_le_bytes(), 0x0609_0030);
}

#[test]
fn cia301_7_5_2_37_valid_tpdo_cob_id_write_back_and_change() {
    write_back_and_change(0x1800, 1, &0x0000_0184u32.to_le_bytes(), 0x0609_0030);
}

#[test]
fn cia301_7_5_2_37_valid_tpdo_inhibit_time_write_back_and_change() {
    write_back_and_change(0x1800, 3, &10u16.to_le_bytes(), 0x0609_0030);
}

#[test]
fn cia301_7_5_2_36_valid_rpdo_mapping_count_write_back_and_change() {
    write_back_and_change(0x1600, 0, &[0], 0x0601_0000);
}

#[test]
fn cia301_7_5_2_36_valid_rpdo_mapping_entry_write_back_and_change() {
    write_back_and_change(0x1600, 1, &0x6200_0208u32.to_le_bytes(), 0x0601_0000);
}

#[test]
fn cia301_7_5_2_38_valid_tpdo_mapping_count_write_back_and_change() {
    write_back_and_change(0x1A00, 0, &[0], 0x0601_0000);
}

#[test]
fn cia301_7_5_2_38_valid_tpdo_mapping_entry_write_back_and_change() {
    write_back_and_change(0x1A00, 1, &0x6000_0208u32.to_le_bytes(), 0x0601_0000);
}

#[test]
fn cia301_7_5_2_35_37_valid_pdo_transmission_type_and_event_timer_may_change() {
    let mut c = running();
    for (index, sub, v) in [
        (0x1400u16, 2u8, vec![1u8]),
        (0x1400, 5, 100u16.to_le_bytes().to_vec()),
        (0x1800, 2, vec![1]),
        (0x1800, 5, 100u16.to_le_bytes().to_vec()),
    ] {
        assert_eq!(
            write(&mut c, ms(2), index, sub, &v),
            Ok(()),
            "{index:04X}:{sub}"
        );
        assert_eq!(read(&mut c, ms(2), index, sub), Ok(v));
    }
}

#[test]
fn manual_eds_vendor_name_and_1016_sub_0_read_only() {
    let island = Island::from_references(&["TM3DI8"]).unwrap();
    let text = cantwin_tm3::eds::eds_text(&island).unwrap();
    assert!(text.contains("VendorName=Schneider Electric\n"), "{text}");
    let start = text.find("[1016sub0]\n").unwrap();
    let section = &text[start
        ..text[start + 1..]
            .find("\n[")
            .map_or(text.len(), |e| start + 1 + e)];
    assert!(section.contains("AccessType=ro\n"), "{section}");
    // And the dictionary refuses a write to it (CiA 301: 0x06010002 read only).
    let mut c = coupler(&["TM3DI8"]);
    assert_eq!(write(&mut c, ms(1), 0x1016, 0, &[1]), Err(0x0601_0002));
}
