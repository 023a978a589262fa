//! CiA 301 §7.2.2 (PDO services and protocols) and §7.5.2.35–38 (PDO communication and
//! mapping objects), driven on the PDO engine with an object dictionary.
#![allow(clippy::unwrap_used)]

mod pdo_harness;

use cantwin_can::{Frame, Id, Instant};
use cantwin_canopen::AbortCode;
use cantwin_canopen::device::NoHooks;
use cantwin_canopen::od::Value;
use cantwin_canopen::pdo::{PdoEvent, PdoObjects};
use pdo_harness::{Harness, ms, us};

const IN16: u32 = 0x6000_0010;
const IN8: u32 = 0x6001_0008;
const IN32: u32 = 0x6002_0020;
const OUT16: u32 = 0x6200_0010;
const OUT8: u32 = 0x6201_0008;

fn tpdo1(ttype: u8, mapping: &[u32]) -> Harness {
    let mut h = Harness::new(PdoObjects::new(0, 4).tpdo(0, ttype, mapping));
    h.od.set(0x6000, 0, &Value::Unsigned16(0x1234)).unwrap();
    h.operational(Instant::ZERO)
}

fn rpdo1(ttype: u8, mapping: &[u32]) -> Harness {
    Harness::new(PdoObjects::new(4, 0).rpdo(0, ttype, mapping)).operational(Instant::ZERO)
}

#[test]
fn cia301_7_2_2_4_tpdo_transmission_type_1_sends_every_sync() {
    let mut h = tpdo1(1, &[IN16]);
    assert_eq!(h.sync(None, ms(1)), ["185#3412"]);
    h.od.set(0x6000, 0, &Value::Unsigned16(0xBEEF)).unwrap();
    assert_eq!(h.sync(None, ms(2)), ["185#EFBE"]);
    assert_eq!(h.sync(None, ms(3)), ["185#EFBE"]);
    // Synchronous TPDOs have no timers.
    assert_eq!(h.pdo.next_deadline(), None);
}

#[test]
fn cia301_7_2_2_4_tpdo_transmission_type_3_sends_every_third_sync() {
    let mut h = tpdo1(3, &[IN16]);
    let sent: Vec<u64> = (1..=10)
        .filter(|k| !h.sync(None, ms(*k)).is_empty())
        .collect();
    assert_eq!(sent, [3, 6, 9]);
}

#[test]
fn cia301_7_2_2_4_tpdo_transmission_type_240_sends_every_240th_sync() {
    let mut h = tpdo1(240, &[IN16]);
    let sent: Vec<u64> = (1..=500)
        .filter(|k| !h.sync(None, us(*k)).is_empty())
        .collect();
    assert_eq!(sent, [240, 480]);
}

#[test]
fn cia301_7_2_2_4_tpdo_transmission_type_0_sends_at_the_sync_after_an_event() {
    let mut h = tpdo1(0, &[IN16]);
    assert!(h.sync(None, ms(1)).is_empty());
    h.od.set(0x6000, 0, &Value::Unsigned16(0x0A0B)).unwrap();
    h.pdo.mark_changed(0x6000, 0);
    // Acyclic synchronous: nothing until the SYNC, then once.
    assert!(h.tick(ms(1)).is_empty());
    assert_eq!(h.sync(None, ms(2)), ["185#0B0A"]);
    assert!(h.sync(None, ms(3)).is_empty());
    // A change of an object the PDO does not map is no event for it.
    h.pdo.mark_changed(0x6001, 0);
    assert!(h.sync(None, ms(4)).is_empty());
}

#[test]
fn cia301_7_5_2_35_sync_start_value_delays_the_first_transmission() {
    let mut h = tpdo1(2, &[IN16]);
    // Sub 6 can change only while the PDO is invalid.
    assert_eq!(
        h.write_u8(0x1800, 6, 3, Instant::ZERO),
        Err(AbortCode::INVALID_VALUE)
    );
    h.write_u32(0x1800, 1, 0x8000_0185, Instant::ZERO).unwrap();
    assert_eq!(
        h.write_u8(0x1800, 6, 241, Instant::ZERO),
        Err(AbortCode::INVALID_VALUE)
    );
    h.write_u8(0x1800, 6, 3, Instant::ZERO).unwrap();
    h.write_u32(0x1800, 1, 0x0000_0185, Instant::ZERO).unwrap();
    let sent: Vec<u8> = [1u8, 2, 3, 4, 5, 6, 7, 1, 2]
        .into_iter()
        .enumerate()
        .filter(|(k, c)| !h.sync(Some(*c), ms(*k as u64 + 1)).is_empty())
        .map(|(_, c)| c)
        .collect();
    // First on the SYNC with counter 3, then every second SYNC.
    assert_eq!(sent, [3, 5, 7, 2]);
}

#[test]
fn cia301_7_5_2_35_sync_start_value_is_ignored_without_a_sync_counter() {
    let mut h = tpdo1(1, &[IN16]);
    h.write_u32(0x1800, 1, 0x8000_0185, Instant::ZERO).unwrap();
    h.write_u8(0x1800, 6, 3, Instant::ZERO).unwrap();
    h.write_u32(0x1800, 1, 0x0000_0185, Instant::ZERO).unwrap();
    assert_eq!(h.sync(None, ms(1)), ["185#3412"]);
}

#[test]
fn cia301_7_2_2_4_tpdo_transmission_type_252_samples_at_sync_and_sends_on_rtr() {
    let mut h = tpdo1(252, &[IN16]);
    let rtr = Frame::remote(Id::standard(0x185).unwrap(), 2).unwrap();
    // Nothing sampled yet: no answer.
    assert!(h.frame(rtr, ms(1)).is_empty());
    assert!(h.sync(None, ms(2)).is_empty());
    h.od.set(0x6000, 0, &Value::Unsigned16(0x5678)).unwrap();
    // The answer carries the value of the SYNC instant, not the current one.
    assert_eq!(h.frame(rtr, ms(3)), ["185#3412"]);
    assert!(h.sync(None, ms(4)).is_empty());
    assert_eq!(h.frame(rtr, ms(5)), ["185#7856"]);
}

#[test]
fn cia301_7_2_2_4_tpdo_transmission_type_253_sends_on_rtr_only() {
    let mut h = tpdo1(253, &[IN16]);
    assert!(h.sync(None, ms(1)).is_empty());
    h.pdo.mark_changed(0x6000, 0);
    assert!(h.tick(ms(1)).is_empty());
    assert_eq!(h.pdo.next_deadline(), None);
    let rtr = Frame::remote(Id::standard(0x185).unwrap(), 2).unwrap();
    h.od.set(0x6000, 0, &Value::Unsigned16(0x5678)).unwrap();
    assert_eq!(h.frame(rtr, ms(2)), ["185#7856"]);
}

#[test]
fn cia301_7_5_2_35_rtr_is_refused_when_cob_id_bit_30_is_set() {
    let mut h = tpdo1(253, &[IN16]);
    h.write_u32(0x1800, 1, 0x8000_0185, Instant::ZERO).unwrap();
    h.write_u32(0x1800, 1, 0x4000_0185, Instant::ZERO).unwrap();
    let rtr = Frame::remote(Id::standard(0x185).unwrap(), 2).unwrap();
    assert!(h.frame(rtr, ms(1)).is_empty());
}

#[test]
fn cia301_7_2_2_4_tpdo_transmission_type_255_sends_on_application_event() {
    for ttype in [254, 255] {
        let mut h = tpdo1(ttype, &[IN16]);
        assert!(h.sync(None, ms(1)).is_empty());
        h.od.set(0x6000, 0, &Value::Unsigned16(0x0102)).unwrap();
        h.pdo.mark_changed(0x6000, 0);
        assert_eq!(h.pdo.next_deadline(), Some(Instant::ZERO));
        assert_eq!(h.tick(ms(2)), ["185#0201"]);
        assert_eq!(h.pdo.next_deadline(), None);
        h.pdo.trigger_tpdo(0);
        assert_eq!(h.tick(ms(3)), ["185#0201"]);
    }
}

#[test]
fn cia301_7_2_2_4_event_driven_tpdos_are_sent_once_on_entering_operational() {
    let mut h = Harness::new(
        PdoObjects::new(0, 2)
            .tpdo(0, 255, &[IN8])
            .tpdo(1, 1, &[IN8]),
    );
    h.pdo.set_operational(true, ms(7));
    assert_eq!(h.pdo.next_deadline(), Some(Instant::ZERO));
    assert_eq!(h.tick(ms(7)), ["185#00"]);
    assert!(h.tick(ms(8)).is_empty());
}

#[test]
fn cia301_7_5_2_35_tpdo_event_timer_sends_every_period_exactly() {
    let mut h = tpdo1(255, &[IN16]);
    h.write_u16(0x1800, 5, 100, Instant::ZERO).unwrap();
    // The period counts from the write.
    let trace = h.run_until(ms(350));
    assert_eq!(
        trace,
        [
            "100000000 185#3412",
            "200000000 185#3412",
            "300000000 185#3412"
        ]
    );
    // An event restarts the period.
    h.pdo.trigger_tpdo(0);
    assert_eq!(h.tick(ms(330)), ["185#3412"]);
    assert_eq!(h.pdo.next_deadline(), Some(ms(430)));
}

#[test]
fn cia301_7_2_2_5_inhibit_time_holds_a_second_event_until_it_ends() {
    let mut h = tpdo1(254, &[IN16]);
    h.write_u32(0x1800, 1, 0x8000_0185, Instant::ZERO).unwrap();
    // 100 × 100 µs = 10 ms.
    h.write_u16(0x1800, 3, 100, Instant::ZERO).unwrap();
    h.write_u32(0x1800, 1, 0x0000_0185, Instant::ZERO).unwrap();
    assert_eq!(h.tick(ms(1)), ["185#3412"]);
    h.pdo.trigger_tpdo(0);
    assert!(h.tick(ms(2)).is_empty());
    // Counted from queueing while no transmission confirmation arrived.
    assert_eq!(h.pdo.next_deadline(), Some(ms(11)));
    assert!(h.tick(Instant::from_nanos(10_999_999)).is_empty());
    assert_eq!(h.tick(ms(11)), ["185#3412"]);
}

#[test]
fn cia301_7_2_2_5_inhibit_time_counts_from_the_end_of_the_transmission() {
    let mut h = tpdo1(254, &[IN16]);
    h.write_u32(0x1800, 1, 0x8000_0185, Instant::ZERO).unwrap();
    h.write_u16(0x1800, 3, 100, Instant::ZERO).unwrap();
    h.write_u32(0x1800, 1, 0x0000_0185, Instant::ZERO).unwrap();
    assert_eq!(h.tick(ms(1)), ["185#3412"]);
    // The frame left the bus 250 µs after it was queued.
    h.pdo
        .on_sent(&Frame::std(0x185, &[0x12, 0x34]).unwrap(), us(1_250));
    h.pdo.trigger_tpdo(0);
    assert_eq!(h.pdo.next_deadline(), Some(us(11_250)));
    assert!(h.tick(ms(11)).is_empty());
    assert_eq!(h.tick(us(11_250)), ["185#3412"]);
}

#[test]
fn cia301_7_5_2_35_inhibit_time_is_writable_only_while_the_pdo_is_invalid() {
    let mut h = tpdo1(254, &[IN16]);
    assert_eq!(
        h.write_u16(0x1800, 3, 100, Instant::ZERO),
        Err(AbortCode::INVALID_VALUE)
    );
    assert_eq!(h.od.get_unsigned(0x1800, 3), Some(0));
}

#[test]
fn cia301_7_5_2_35_cob_id_of_a_valid_pdo_cannot_change() {
    let mut h = tpdo1(1, &[IN16]);
    assert_eq!(
        h.write_u32(0x1800, 1, 0x0000_0190, Instant::ZERO),
        Err(AbortCode::INVALID_VALUE)
    );
    // Rewriting the same identifier is fine; invalidating first allows the change.
    h.write_u32(0x1800, 1, 0x0000_0185, Instant::ZERO).unwrap();
    h.write_u32(0x1800, 1, 0x8000_0185, Instant::ZERO).unwrap();
    assert!(h.sync(None, ms(1)).is_empty());
    h.write_u32(0x1800, 1, 0x0000_0190, Instant::ZERO).unwrap();
    assert_eq!(h.sync(None, ms(2)), ["190#3412"]);
}

#[test]
fn cia301_7_3_5_restricted_and_malformed_cob_ids_are_refused() {
    let mut h = tpdo1(1, &[IN16]);
    h.write_u32(0x1800, 1, 0x8000_0185, Instant::ZERO).unwrap();
    for id in [0x000, 0x05, 0x581, 0x605, 0x705, 0x7E5, 0x800] {
        assert_eq!(
            h.write_u32(0x1800, 1, id, Instant::ZERO),
            Err(AbortCode::INVALID_VALUE),
            "{id:#X}"
        );
    }
    // Any identifier is accepted while the PDO stays invalid.
    h.write_u32(0x1800, 1, 0x8000_0705, Instant::ZERO).unwrap();
}

#[test]
fn cia301_7_5_2_35_extended_cob_id_sends_29_bit_frames() {
    let mut h = tpdo1(1, &[IN16]);
    h.write_u32(0x1800, 1, 0x8000_0185, Instant::ZERO).unwrap();
    h.write_u32(0x1800, 1, 0x2012_3456, Instant::ZERO).unwrap();
    assert_eq!(h.sync(None, ms(1)), ["00123456#3412"]);
}

#[test]
fn cia301_7_5_2_35_reserved_transmission_types_are_refused() {
    let mut h = Harness::new(PdoObjects::new(1, 1)).operational(Instant::ZERO);
    for t in [241u8, 251] {
        assert_eq!(
            h.write_u8(0x1800, 2, t, Instant::ZERO),
            Err(AbortCode::INVALID_VALUE)
        );
    }
    for t in [241u8, 252, 253] {
        assert_eq!(
            h.write_u8(0x1400, 2, t, Instant::ZERO),
            Err(AbortCode::INVALID_VALUE)
        );
    }
    for t in [0u8, 240, 252, 253, 254, 255] {
        h.write_u8(0x1800, 2, t, Instant::ZERO).unwrap();
    }
    for t in [0u8, 240, 254, 255] {
        h.write_u8(0x1400, 2, t, Instant::ZERO).unwrap();
    }
}

#[test]
fn cia301_7_5_2_36_dynamic_mapping_sequence() {
    let mut h = tpdo1(1, &[IN16]);
    h.od.set(0x6002, 0, &Value::Unsigned32(0xA1B2_C3D4))
        .unwrap();
    h.od.set(0x6001, 0, &Value::Unsigned8(0x77)).unwrap();
    let t = Instant::ZERO;
    // While the PDO is valid, its mapping cannot be touched.
    assert_eq!(
        h.write_u8(0x1A00, 0, 0, t),
        Err(AbortCode::UNSUPPORTED_ACCESS)
    );
    // (1) invalidate the PDO.
    h.write_u32(0x1800, 1, 0x8000_0185, t).unwrap();
    // Entries are locked while sub-index 0 is not 0.
    assert_eq!(
        h.write_u32(0x1A00, 1, IN32, t),
        Err(AbortCode::UNSUPPORTED_ACCESS)
    );
    // (2) disable the mapping.
    h.write_u8(0x1A00, 0, 0, t).unwrap();
    // (3) write the entries; each is checked.
    assert_eq!(
        h.write_u32(0x1A00, 1, 0x7000_0008, t),
        Err(AbortCode::NO_OBJECT)
    );
    assert_eq!(
        h.write_u32(0x1A00, 1, 0x6203_0008, t),
        Err(AbortCode::NOT_MAPPABLE)
    );
    assert_eq!(
        h.write_u32(0x1A00, 1, 0x6204_0008, t),
        Err(AbortCode::NOT_MAPPABLE)
    );
    assert_eq!(
        h.write_u32(0x1A00, 1, 0x6001_0010, t),
        Err(AbortCode::NOT_MAPPABLE)
    );
    h.write_u32(0x1A00, 1, IN32, t).unwrap();
    h.write_u32(0x1A00, 2, IN32, t).unwrap();
    h.write_u32(0x1A00, 3, IN8, t).unwrap();
    // (4) enable: 72 bits do not fit, 64 do.
    assert_eq!(
        h.write_u8(0x1A00, 0, 3, t),
        Err(AbortCode::PDO_LENGTH_EXCEEDED)
    );
    assert_eq!(
        h.write_u8(0x1A00, 0, 65, t),
        Err(AbortCode::PDO_LENGTH_EXCEEDED)
    );
    assert_eq!(h.od.get_unsigned(0x1A00, 0), Some(0));
    h.write_u8(0x1A00, 0, 2, t).unwrap();
    assert!(h.sync(None, ms(1)).is_empty());
    // (5) validate the PDO.
    h.write_u32(0x1800, 1, 0x0000_0185, t).unwrap();
    assert_eq!(h.sync(None, ms(2)), ["185#D4C3B2A1D4C3B2A1"]);
}

#[test]
fn cia301_7_5_2_36_mapping_an_empty_entry_is_refused_when_enabled() {
    let mut h = tpdo1(1, &[IN16]);
    let t = Instant::ZERO;
    h.write_u32(0x1800, 1, 0x8000_0185, t).unwrap();
    h.write_u8(0x1A00, 0, 0, t).unwrap();
    h.write_u32(0x1A00, 1, 0, t).unwrap();
    assert_eq!(h.write_u8(0x1A00, 0, 1, t), Err(AbortCode::NOT_MAPPABLE));
    // A mapping object with 8 entries cannot enable 9.
    assert_eq!(
        h.write_u8(0x1A00, 0, 9, t),
        Err(AbortCode::PDO_LENGTH_EXCEEDED)
    );
}

#[test]
fn cia301_7_5_2_38_bit_granular_mapping_packs_little_endian() {
    let mut h = tpdo1(1, &[0x6003_0001, 0x6001_0004, IN16]);
    h.od.set(0x6003, 0, &Value::Boolean(true)).unwrap();
    h.od.set(0x6001, 0, &Value::Unsigned8(0xFA)).unwrap();
    h.od.set(0x6000, 0, &Value::Unsigned16(0xFFFF)).unwrap();
    // bit 0: 1; bits 1..=4: 0xA; bits 5..=20: 0xFFFF → 0x1FFFF5, 21 bits in 3 bytes.
    assert_eq!(h.sync(None, ms(1)), ["185#F5FF1F"]);
}

#[test]
fn cia301_7_2_2_4_rpdo_event_driven_writes_at_once() {
    let mut h = rpdo1(255, &[OUT16, OUT8]);
    assert!(
        h.frame(Frame::std(0x205, &[0x34, 0x12, 0x56]).unwrap(), ms(1))
            .is_empty()
    );
    assert_eq!(h.od.get(0x6200, 0).unwrap(), Value::Unsigned16(0x1234));
    assert_eq!(h.od.get(0x6201, 0).unwrap(), Value::Unsigned8(0x56));
    assert_eq!(h.events(), [PdoEvent::Received { rpdo: 0 }]);
}

#[test]
fn cia301_7_2_2_4_rpdo_synchronous_takes_effect_at_the_next_sync() {
    let mut h = rpdo1(1, &[OUT16]);
    h.frame(Frame::std(0x205, &[0x01, 0x00]).unwrap(), ms(1));
    // A newer PDO before the SYNC replaces the older one.
    h.frame(Frame::std(0x205, &[0x02, 0x00]).unwrap(), ms(2));
    assert_eq!(h.od.get(0x6200, 0).unwrap(), Value::Unsigned16(0));
    assert!(h.events().is_empty());
    h.sync(None, ms(3));
    assert_eq!(h.od.get(0x6200, 0).unwrap(), Value::Unsigned16(2));
    assert_eq!(h.events(), [PdoEvent::Received { rpdo: 0 }]);
    h.sync(None, ms(4));
    assert!(h.events().is_empty());
}

#[test]
fn cia301_7_2_2_2_rpdo_too_short_is_not_processed_emcy_8210() {
    let mut h = rpdo1(255, &[OUT16, OUT8]);
    h.frame(Frame::std(0x205, &[0x34, 0x12]).unwrap(), ms(1));
    assert_eq!(h.od.get(0x6200, 0).unwrap(), Value::Unsigned16(0));
    let ev = h.events();
    assert_eq!(
        ev,
        [PdoEvent::LengthError {
            rpdo: 0,
            emcy: 0x8210,
            len: 2
        }]
    );
    assert_eq!(ev[0].emcy_code(), Some(0x8210));
}

#[test]
fn cia301_7_2_2_2_rpdo_too_long_is_processed_emcy_8220() {
    let mut h = rpdo1(255, &[OUT16]);
    h.frame(Frame::std(0x205, &[0x34, 0x12, 0xFF]).unwrap(), ms(1));
    assert_eq!(h.od.get(0x6200, 0).unwrap(), Value::Unsigned16(0x1234));
    assert_eq!(
        h.events(),
        [
            PdoEvent::LengthError {
                rpdo: 0,
                emcy: 0x8220,
                len: 3
            },
            PdoEvent::Received { rpdo: 0 }
        ]
    );
}

#[test]
fn cia301_7_5_2_35_rpdo_deadline_monitoring_emcy_8250() {
    let mut h = rpdo1(255, &[OUT16]);
    h.write_u16(0x1400, 5, 50, Instant::ZERO).unwrap();
    // Not armed before the first PDO, nor by one of the wrong length.
    assert_eq!(h.pdo.next_deadline(), None);
    h.frame(Frame::std(0x205, &[0]).unwrap(), ms(5));
    assert_eq!(h.pdo.next_deadline(), None);
    let pdo = Frame::std(0x205, &[0, 0]).unwrap();
    h.frame(pdo, ms(10));
    h.frame(pdo, ms(40));
    assert_eq!(h.pdo.next_deadline(), Some(ms(90)));
    h.events();
    h.tick(Instant::from_nanos(89_999_999));
    assert!(h.events().is_empty());
    h.tick(ms(90));
    let ev = h.events();
    assert_eq!(ev, [PdoEvent::Timeout { rpdo: 0 }]);
    assert_eq!(ev[0].emcy_code(), Some(0x8250));
    // Reported once; the next PDO re-arms it.
    assert_eq!(h.pdo.next_deadline(), None);
    h.frame(pdo, ms(200));
    assert_eq!(h.pdo.next_deadline(), Some(ms(250)));
}

#[test]
fn cia301_7_4_8_2_dummy_mapping_skips_received_bits() {
    let mut h = rpdo1(255, &[0x0005_0008, OUT16, 0x0001_0001]);
    h.frame(Frame::std(0x205, &[0xEE, 0x34, 0x12, 0x01]).unwrap(), ms(1));
    assert_eq!(h.od.get(0x6200, 0).unwrap(), Value::Unsigned16(0x1234));
    // A dummy entry is refused in a TPDO.
    let mut t = tpdo1(1, &[IN16]);
    t.write_u32(0x1800, 1, 0x8000_0185, Instant::ZERO).unwrap();
    t.write_u8(0x1A00, 0, 0, Instant::ZERO).unwrap();
    assert_eq!(
        t.write_u32(0x1A00, 1, 0x0005_0008, Instant::ZERO),
        Err(AbortCode::NOT_MAPPABLE)
    );
}

#[test]
fn cia301_7_5_2_36_rpdo_maps_only_writable_objects() {
    let mut h = rpdo1(255, &[OUT16]);
    let t = Instant::ZERO;
    h.write_u32(0x1400, 1, 0x8000_0205, t).unwrap();
    h.write_u8(0x1600, 0, 0, t).unwrap();
    assert_eq!(
        h.write_u32(0x1600, 1, IN16, t),
        Err(AbortCode::NOT_MAPPABLE)
    );
    h.write_u32(0x1600, 1, 0x6202_0020, t).unwrap();
}

#[test]
fn cia301_7_3_2_2_pdos_run_only_in_operational() {
    let mut h = Harness::new(
        PdoObjects::new(1, 1)
            .rpdo(0, 1, &[OUT16])
            .tpdo(0, 1, &[IN16]),
    );
    // Pre-operational: no TPDO at SYNC, RPDOs ignored.
    assert!(h.sync(None, ms(1)).is_empty());
    h.frame(Frame::std(0x205, &[1, 0]).unwrap(), ms(1));
    assert!(h.events().is_empty());
    h.pdo.set_operational(true, ms(2));
    h.frame(Frame::std(0x205, &[1, 0]).unwrap(), ms(3));
    // Leaving OPERATIONAL drops the buffered RPDO.
    h.pdo.set_operational(false, ms(4));
    h.pdo.set_operational(true, ms(5));
    assert_eq!(h.sync(None, ms(6)), ["185#0000"]);
    assert_eq!(h.od.get(0x6200, 0).unwrap(), Value::Unsigned16(0));
}

#[test]
fn cia301_7_3_2_2_leaving_operational_stops_event_timers_and_deadlines() {
    let mut h = Harness::new(
        PdoObjects::new(1, 1)
            .rpdo(0, 255, &[OUT16])
            .tpdo(0, 255, &[IN16]),
    )
    .operational(Instant::ZERO);
    h.write_u16(0x1800, 5, 10, Instant::ZERO).unwrap();
    h.write_u16(0x1400, 5, 10, Instant::ZERO).unwrap();
    h.frame(Frame::std(0x205, &[1, 0]).unwrap(), ms(1));
    assert_eq!(h.pdo.next_deadline(), Some(ms(10)));
    h.pdo.set_operational(false, ms(2));
    assert_eq!(h.pdo.next_deadline(), None);
    assert!(h.tick(ms(20)).is_empty());
    h.pdo.mark_changed(0x6000, 0);
    assert!(h.tick(ms(21)).is_empty());
    h.events();
    assert!(h.events().is_empty());
}

#[test]
fn cia301_7_3_5_predefined_connection_set_cob_ids() {
    let mut h = Harness::new(
        PdoObjects::new(4, 4)
            .tpdo(0, 1, &[IN8])
            .tpdo(1, 1, &[IN8])
            .tpdo(2, 1, &[IN8])
            .tpdo(3, 1, &[IN8]),
    )
    .operational(Instant::ZERO);
    assert_eq!(
        h.sync(None, ms(1)),
        ["185#00", "285#00", "385#00", "485#00"]
    );
}

#[test]
fn cia301_7_5_2_36_an_invalid_stored_mapping_leaves_only_that_pdo_off() {
    use cantwin_canopen::od::{ObjectDictionary, OdBuilder};
    use cantwin_canopen::pdo::{PdoEngine, PdoError};
    use std::sync::Arc;
    // TPDO1 maps an object that does not exist; TPDO2 is fine.
    let b = PdoObjects::new(0, 2)
        .tpdo(0, 1, &[0x7000_0008])
        .tpdo(1, 1, &[IN8])
        .add_to(pdo_harness::app(OdBuilder::new()));
    let mut od = ObjectDictionary::new(Arc::new(b.build().unwrap()), pdo_harness::NODE);
    let err = PdoError::Mapping {
        index: 0x1A00,
        code: AbortCode::NO_OBJECT,
    };
    assert_eq!(PdoEngine::new(&od).err(), Some(err));
    let (mut pdo, result) = PdoEngine::load(&od);
    assert_eq!(result, Err(err));
    assert!(!pdo.tpdo_active(0));
    assert!(pdo.tpdo_active(1));
    pdo.set_operational(true, Instant::ZERO);
    let mut out = cantwin_can::Outbox::new();
    pdo.on_sync(None, ms(1), &mut od, &mut NoHooks, &mut out);
    assert_eq!(out.frames(), [Frame::std(0x285, &[0]).unwrap()]);
    // It cannot be validated again until the mapping is repaired.
    let mut h = Harness {
        od,
        pdo,
        out: cantwin_can::Outbox::new(),
    };
    let t = Instant::ZERO;
    h.write_u32(0x1800, 1, 0x8000_0185, t).unwrap();
    assert_eq!(
        h.write_u32(0x1800, 1, 0x185, t),
        Err(AbortCode::PARAMETER_INCOMPATIBLE)
    );
    h.write_u8(0x1A00, 0, 0, t).unwrap();
    h.write_u32(0x1A00, 1, IN8, t).unwrap();
    h.write_u8(0x1A00, 0, 1, t).unwrap();
    h.write_u32(0x1800, 1, 0x185, t).unwrap();
    assert_eq!(h.sync(None, ms(2)), ["185#00", "285#00"]);
}

#[test]
fn cia301_7_4_8_engine_runs_512_rpdos_and_512_tpdos() {
    let mut objects = PdoObjects::new(512, 512).max_entries(2);
    for n in 0..512 {
        objects = objects.tpdo(n, 1, &[IN8]).rpdo(n, 255, &[OUT8]);
    }
    let mut h = Harness::new(objects).operational(Instant::ZERO);
    // Beyond the pre-defined connection set, give every PDO a 29-bit identifier.
    for n in 4..512u16 {
        let t = Instant::ZERO;
        h.write_u32(0x1800 + n, 1, 0xA000_0000 | u32::from(n), t)
            .unwrap();
        h.write_u32(0x1800 + n, 1, 0x2000_0000 | u32::from(n), t)
            .unwrap();
        h.write_u32(0x1400 + n, 1, 0xA001_0000 | u32::from(n), t)
            .unwrap();
        h.write_u32(0x1400 + n, 1, 0x2001_0000 | u32::from(n), t)
            .unwrap();
    }
    assert_eq!((h.pdo.rpdo_slots(), h.pdo.tpdo_slots()), (512, 512));
    assert!((0..512).all(|n| h.pdo.rpdo_active(n) && h.pdo.tpdo_active(n)));
    let sent = h.sync(None, ms(1));
    assert_eq!(sent.len(), 512);
    assert_eq!(sent[511], "000001FF#00");
    let id = cantwin_can::Id::extended(0x0001_01FF).unwrap();
    h.frame(Frame::data(id, &[0x42]).unwrap(), ms(2));
    assert_eq!(h.events(), [PdoEvent::Received { rpdo: 511 }]);
    assert_eq!(h.od.get(0x6201, 0).unwrap(), Value::Unsigned8(0x42));
}

#[test]
fn cia301_7_2_2_4_synchronous_cyclic_and_acyclic_tpdos_ignore_rtr() {
    for ttype in [0, 1] {
        let mut h = tpdo1(ttype, &[IN16]);
        let rtr = Frame::remote(Id::standard(0x185).unwrap(), 2).unwrap();
        assert!(h.frame(rtr, ms(1)).is_empty());
        assert!(
            h.pdo
                .on_frame(&rtr, ms(1), &mut h.od, &mut NoHooks, &mut h.out)
        );
    }
}

#[test]
fn cia301_7_2_2_4_rpdo_on_a_29_bit_cob_id_and_foreign_frames() {
    let mut h = rpdo1(255, &[OUT8]);
    let t = Instant::ZERO;
    h.write_u32(0x1400, 1, 0x8000_0205, t).unwrap();
    h.write_u32(0x1400, 1, 0x2000_0205, t).unwrap();
    // The 11-bit frame with the same number is not this PDO any more.
    let mut out = cantwin_can::Outbox::new();
    let std = Frame::std(0x205, &[9]).unwrap();
    assert!(
        !h.pdo
            .on_frame(&std, ms(1), &mut h.od, &mut NoHooks, &mut out)
    );
    let ext = Frame::data(Id::extended(0x205).unwrap(), &[9]).unwrap();
    // A remote frame on an RPDO's identifier is no PDO data.
    let rtr = Frame::remote(Id::extended(0x205).unwrap(), 1).unwrap();
    assert!(
        !h.pdo
            .on_frame(&rtr, ms(1), &mut h.od, &mut NoHooks, &mut out)
    );
    assert!(
        h.pdo
            .on_frame(&ext, ms(2), &mut h.od, &mut NoHooks, &mut out)
    );
    assert!(out.is_empty());
    assert_eq!(h.od.get(0x6201, 0).unwrap(), Value::Unsigned8(9));
    assert_eq!(h.events(), [PdoEvent::Received { rpdo: 0 }]);
}

#[test]
fn cia301_7_5_2_36_a_count_above_the_entries_the_object_holds_is_0x06040042_in_any_state() {
    let t = Instant::ZERO;
    let mut h = Harness::new(
        PdoObjects::new(4, 4)
            .rpdo(2, 255, &[OUT16])
            .tpdo(0, 1, &[IN16]),
    );
    for (comm, map, id) in [(0x1402u16, 0x1602u16, 0x405u32), (0x1800, 0x1A00, 0x185)] {
        // Valid PDO: the count is out of range before the state matters.
        for n in [9u8, 31, 64, 65, 255] {
            assert_eq!(
                h.write_u8(map, 0, n, t),
                Err(AbortCode::PDO_LENGTH_EXCEEDED),
                "{map:04X} = {n}"
            );
        }
        // A count in range that changes the mapping is refused while the PDO is valid
        // (0x06010000), as is an entry.
        assert_eq!(h.write_u8(map, 0, 0, t), Err(AbortCode::UNSUPPORTED_ACCESS));
        assert_eq!(
            h.write_u32(map, 1, IN8, t),
            Err(AbortCode::UNSUPPORTED_ACCESS)
        );
        // Writing back what the mapping holds changes nothing and is accepted.
        assert_eq!(h.write_u8(map, 0, 1, t), Ok(()));
        h.write_u32(comm, 1, 0x8000_0000 | id, t).unwrap();
        for n in [9u8, 31, 65] {
            assert_eq!(
                h.write_u8(map, 0, n, t),
                Err(AbortCode::PDO_LENGTH_EXCEEDED),
                "{map:04X} = {n}"
            );
        }
        assert_eq!(h.od.get_unsigned(map, 0), Some(1));
        h.write_u8(map, 0, 0, t).unwrap();
        assert_eq!(
            h.write_u8(map, 0, 31, t),
            Err(AbortCode::PDO_LENGTH_EXCEEDED)
        );
        h.write_u8(map, 0, 1, t).unwrap();
        h.write_u32(comm, 1, id, t).unwrap();
    }
}
