//! SDO server conformance (CiA 301 §7.2.4.3): exact frames on the wire, exact times.
#![allow(clippy::unwrap_used)]

mod sdo_harness;

use cantwin_can::{Duration, Id, Instant, Outbox};
use cantwin_canopen::od::{
    Access, DataType, Hooked, ObjectDictionary, OdBuilder, OdHooks, ReadInfo, SubObject, Value,
};
use cantwin_canopen::sdo::crc::Crc16;
use cantwin_canopen::sdo::{SdoCapabilities, SdoServer};
use cantwin_canopen::{AbortCode, ObjectAccess};
use sdo_harness::*;
use std::sync::Arc;

fn resp(b0: u8, rest: [u8; 7]) -> [u8; 8] {
    let mut b = [b0, 0, 0, 0, 0, 0, 0, 0];
    b[1..].copy_from_slice(&rest);
    b
}

// ---- §7.2.4.3.3 initiate SDO download (expedited) ----

#[test]
fn cia301_7_2_4_3_3_expedited_download() {
    let mut h = Harness::new();
    assert_eq!(
        h.req([0x2B, 0x17, 0x10, 0x00, 0xE8, 0x03, 0, 0]),
        [[0x60, 0x17, 0x10, 0x00, 0, 0, 0, 0]]
    );
    assert_eq!(h.access.get(0x1017, 0), Ok(Value::Unsigned16(1000)));
    assert!(h.server.is_idle());
    assert_eq!(h.server.next_deadline(), None);
}

#[test]
fn cia301_7_2_4_3_3_expedited_download_of_four_bytes_and_one_byte() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0x23, 0x02, 0x20, 0x00, 1, 2, 3, 4]),
        [0x60, 0x02, 0x20, 0, 0, 0, 0, 0]
    );
    assert_eq!(
        h.one([0x2F, 0x00, 0x20, 0x00, 42, 0, 0, 0]),
        [0x60, 0x00, 0x20, 0, 0, 0, 0, 0]
    );
    assert_eq!(h.access.get(0x2000, 0), Ok(Value::Unsigned8(42)));
}

#[test]
fn cia301_7_2_4_3_3_expedited_download_without_size_takes_the_type_size() {
    let mut h = Harness::new();
    // e = 1, s = 0: the client does not say how many of the 4 bytes are data.
    assert_eq!(
        h.one([0x22, 0x17, 0x10, 0x00, 0xD0, 0x07, 0xFF, 0xFF]),
        [0x60, 0x17, 0x10, 0, 0, 0, 0, 0]
    );
    assert_eq!(h.access.get(0x1017, 0), Ok(Value::Unsigned16(2000)));
    assert_eq!(
        h.one([0x22, 0x00, 0x20, 0x00, 20, 0xAA, 0xBB, 0xCC]),
        [0x60, 0x00, 0x20, 0, 0, 0, 0, 0]
    );
    assert_eq!(h.access.get(0x2000, 0), Ok(Value::Unsigned8(20)));
}

// ---- §7.2.4.3.6 initiate SDO upload (expedited) ----

#[test]
fn cia301_7_2_4_3_6_expedited_upload() {
    let mut h = Harness::new();
    assert_eq!(
        h.req([0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]),
        [[0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00]]
    );
    assert_eq!(
        h.req([0x40, 0x17, 0x10, 0x00, 0, 0, 0, 0]),
        [[0x4B, 0x17, 0x10, 0x00, 0, 0, 0, 0]]
    );
    assert_eq!(
        h.req([0x40, 0x00, 0x20, 0x00, 0, 0, 0, 0]),
        [[0x4F, 0x00, 0x20, 0x00, 50, 0, 0, 0]]
    );
    assert_eq!(
        h.req([0x40, 0x18, 0x10, 0x00, 0, 0, 0, 0]),
        [[0x4F, 0x18, 0x10, 0x00, 2, 0, 0, 0]]
    );
    assert!(h.server.is_idle());
}

#[test]
fn cia301_7_2_4_3_6_request_bytes_4_to_7_are_ignored() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0x40, 0x00, 0x10, 0x00, 9, 9, 9, 9]),
        [0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00]
    );
}

// ---- §7.2.4.3.4/5 segmented download ----

#[test]
fn cia301_7_2_4_3_4_segmented_download() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0x21, 0x06, 0x20, 0x00, 12, 0, 0, 0]),
        [0x60, 0x06, 0x20, 0x00, 0, 0, 0, 0]
    );
    assert_eq!(h.one(resp(0x00, *b"hello w")), resp(0x20, [0; 7]));
    // toggle 1, n = 2 unused bytes, c = 1.
    assert_eq!(
        h.one(resp(0x15, [b'o', b'r', b'l', b'd', b'!', 0, 0])),
        resp(0x30, [0; 7])
    );
    assert_eq!(
        h.access.get(0x2006, 0),
        Ok(Value::VisibleString("hello world!".into()))
    );
    assert!(h.server.is_idle());
}

#[test]
fn cia301_7_2_4_3_4_segmented_download_without_size() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0x20, 0x06, 0x20, 0x00, 0, 0, 0, 0]),
        [0x60, 0x06, 0x20, 0x00, 0, 0, 0, 0]
    );
    assert_eq!(
        h.one(resp(0x0B, [b'a', b'b', 0, 0, 0, 0, 0])),
        resp(0x20, [0; 7])
    );
    assert_eq!(
        h.access.get(0x2006, 0),
        Ok(Value::VisibleString("ab".into()))
    );
}

#[test]
fn cia301_7_2_4_3_5_toggle_bit_not_alternated_in_download() {
    let mut h = Harness::new();
    h.one([0x21, 0x06, 0x20, 0x00, 12, 0, 0, 0]);
    assert_eq!(
        h.one(resp(0x10, *b"hello w")),
        abort(0x2006, 0, AbortCode::TOGGLE_BIT_NOT_ALTERNATED)
    );
    assert!(h.server.is_idle());
    assert_eq!(
        h.access.get(0x2006, 0),
        Ok(Value::VisibleString(String::new()))
    );
}

#[test]
fn cia301_7_2_4_3_4_more_data_than_indicated_is_length_too_high() {
    let mut h = Harness::new();
    h.one([0x21, 0x06, 0x20, 0x00, 10, 0, 0, 0]);
    h.one(resp(0x00, *b"0123456"));
    assert_eq!(
        h.one(resp(0x10, *b"789abcd")),
        abort(0x2006, 0, AbortCode::LENGTH_TOO_HIGH)
    );
}

#[test]
fn cia301_7_2_4_3_4_less_data_than_indicated_is_length_too_low() {
    let mut h = Harness::new();
    h.one([0x21, 0x06, 0x20, 0x00, 10, 0, 0, 0]);
    assert_eq!(
        h.one(resp(0x01, *b"0123456")),
        abort(0x2006, 0, AbortCode::LENGTH_TOO_LOW)
    );
}

// ---- §7.2.4.3.7/8 segmented upload ----

#[test]
fn cia301_7_2_4_3_7_segmented_upload() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0]),
        [0x41, 0x08, 0x10, 0x00, 7, 0, 0, 0]
    );
    assert_eq!(h.one([0x60, 0, 0, 0, 0, 0, 0, 0]), resp(0x01, *b"cantwin"));
    assert!(h.server.is_idle());
}

#[test]
fn cia301_7_2_4_3_7_segmented_upload_of_twelve_bytes_toggles() {
    let mut h = Harness::new();
    h.download(0x2006, 0, b"hello world!").unwrap();
    assert_eq!(
        h.one([0x40, 0x06, 0x20, 0x00, 0, 0, 0, 0]),
        [0x41, 0x06, 0x20, 0x00, 12, 0, 0, 0]
    );
    assert_eq!(h.one([0x60, 0, 0, 0, 0, 0, 0, 0]), resp(0x00, *b"hello w"));
    assert_eq!(
        h.one([0x70, 0, 0, 0, 0, 0, 0, 0]),
        resp(0x15, [b'o', b'r', b'l', b'd', b'!', 0, 0])
    );
}

#[test]
fn cia301_7_2_4_3_7_upload_of_an_empty_value() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0x40, 0x06, 0x20, 0x00, 0, 0, 0, 0]),
        [0x41, 0x06, 0x20, 0x00, 0, 0, 0, 0]
    );
    // n = 7, c = 1: a last segment without data.
    assert_eq!(h.one([0x60, 0, 0, 0, 0, 0, 0, 0]), resp(0x0F, [0; 7]));
}

#[test]
fn cia301_7_2_4_3_8_toggle_bit_not_alternated_in_upload() {
    let mut h = Harness::new();
    h.one([0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0]);
    assert_eq!(
        h.one([0x70, 0, 0, 0, 0, 0, 0, 0]),
        abort(0x1008, 0, AbortCode::TOGGLE_BIT_NOT_ALTERNATED)
    );
}

// ---- §7.2.4.3.17 abort transfer ----

#[test]
fn cia301_7_2_4_3_17_abort_from_the_client_ends_the_transfer_silently() {
    let mut h = Harness::new();
    h.one([0x21, 0x06, 0x20, 0x00, 12, 0, 0, 0]);
    h.one(resp(0x00, *b"hello w"));
    assert!(
        h.req([0x80, 0x06, 0x20, 0x00, 0x00, 0x00, 0x00, 0x08])
            .is_empty()
    );
    assert!(h.server.is_idle());
    assert_eq!(h.server.next_deadline(), None);
    assert_eq!(h.access.staged(), b"");
    // The next segment belongs to no transfer.
    assert_eq!(
        h.one(resp(0x10, *b"orld!\0\0")),
        abort(0, 0, AbortCode::INVALID_COMMAND)
    );
}

#[test]
fn cia301_7_2_4_3_17_abort_from_the_client_while_idle_is_ignored() {
    let mut h = Harness::new();
    assert!(
        h.req([0x80, 0x00, 0x10, 0x00, 0x00, 0x00, 0x00, 0x08])
            .is_empty()
    );
}

#[test]
fn cia301_7_2_4_3_17_unknown_command_specifier() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0xE0, 0x00, 0x10, 0x00, 0, 0, 0, 0]),
        abort(0, 0, AbortCode::INVALID_COMMAND)
    );
    assert_eq!(
        h.one([0x60, 0, 0, 0, 0, 0, 0, 0]),
        abort(0, 0, AbortCode::INVALID_COMMAND)
    );
    assert_eq!(
        h.one([0xA2, 1, 127, 0, 0, 0, 0, 0]),
        abort(0, 0, AbortCode::INVALID_COMMAND)
    );
}

#[test]
fn cia301_7_2_4_3_17_new_initiate_during_a_transfer_aborts_it() {
    let mut h = Harness::new();
    h.one([0x21, 0x06, 0x20, 0x00, 12, 0, 0, 0]);
    h.one(resp(0x00, *b"hello w"));
    // An upload request where the next download segment was due.
    assert_eq!(
        h.one([0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]),
        abort(0x2006, 0, AbortCode::INVALID_COMMAND)
    );
    assert!(h.server.is_idle());
    assert_eq!(
        h.access.get(0x2006, 0),
        Ok(Value::VisibleString(String::new()))
    );
    // The client starts again and is served.
    assert_eq!(
        h.one([0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]),
        [0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00]
    );
}

#[test]
fn cia301_7_2_4_3_17_object_does_not_exist() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0x40, 0x00, 0x50, 0x00, 0, 0, 0, 0]),
        [0x80, 0x00, 0x50, 0x00, 0x00, 0x00, 0x02, 0x06]
    );
    assert_eq!(
        h.one([0x2F, 0x00, 0x50, 0x00, 1, 0, 0, 0]),
        abort(0x5000, 0, AbortCode::NO_OBJECT)
    );
}

#[test]
fn cia301_7_2_4_3_17_sub_index_does_not_exist() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0x40, 0x18, 0x10, 0x09, 0, 0, 0, 0]),
        [0x80, 0x18, 0x10, 0x09, 0x11, 0x00, 0x09, 0x06]
    );
    assert_eq!(
        h.one([0x40, 0x17, 0x10, 0x01, 0, 0, 0, 0]),
        abort(0x1017, 1, AbortCode::NO_SUB_INDEX)
    );
}

#[test]
fn cia301_7_2_4_3_17_read_of_a_write_only_object() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0x40, 0x02, 0x20, 0x00, 0, 0, 0, 0]),
        [0x80, 0x02, 0x20, 0x00, 0x01, 0x00, 0x01, 0x06]
    );
    // Writing it works.
    assert_eq!(
        h.one([0x23, 0x02, 0x20, 0x00, 1, 2, 3, 4]),
        [0x60, 0x02, 0x20, 0, 0, 0, 0, 0]
    );
}

#[test]
fn cia301_7_2_4_3_17_write_of_a_read_only_or_const_object() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0x23, 0x00, 0x10, 0x00, 1, 2, 3, 4]),
        [0x80, 0x00, 0x10, 0x00, 0x02, 0x00, 0x01, 0x06]
    );
    assert_eq!(
        h.one([0x2F, 0x08, 0x20, 0x00, 1, 0, 0, 0]),
        abort(0x2008, 0, AbortCode::READ_ONLY)
    );
    assert_eq!(
        h.one([0x21, 0x08, 0x10, 0x00, 3, 0, 0, 0]),
        abort(0x1008, 0, AbortCode::READ_ONLY)
    );
    assert_eq!(
        h.one([0xC6, 0x08, 0x10, 0x00, 3, 0, 0, 0]),
        abort(0x1008, 0, AbortCode::READ_ONLY)
    );
}

#[test]
fn cia301_7_2_4_3_17_length_too_high() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0x2B, 0x00, 0x20, 0x00, 1, 2, 0, 0]),
        [0x80, 0x00, 0x20, 0x00, 0x12, 0x00, 0x07, 0x06]
    );
    // A string longer than its declared maximum (20), refused at the initiate.
    assert_eq!(
        h.one([0x21, 0x06, 0x20, 0x00, 21, 0, 0, 0]),
        abort(0x2006, 0, AbortCode::LENGTH_TOO_HIGH)
    );
    // ... and without size indication, at the segment that crosses it.
    h.one([0x20, 0x06, 0x20, 0x00, 0, 0, 0, 0]);
    h.one(resp(0x00, *b"0123456"));
    h.one(resp(0x10, *b"0123456"));
    assert_eq!(
        h.one(resp(0x00, *b"0123456")),
        abort(0x2006, 0, AbortCode::LENGTH_TOO_HIGH)
    );
}

#[test]
fn cia301_7_2_4_3_17_length_too_low() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0x23, 0x05, 0x20, 0x00, 1, 2, 3, 4]),
        [0x80, 0x05, 0x20, 0x00, 0x13, 0x00, 0x07, 0x06]
    );
    assert_eq!(
        h.one([0x2F, 0x17, 0x10, 0x00, 1, 0, 0, 0]),
        abort(0x1017, 0, AbortCode::LENGTH_TOO_LOW)
    );
}

#[test]
fn cia301_7_2_4_3_17_length_does_not_match() {
    let mut h = Harness::new();
    // UNICODE_STRING of 3 bytes.
    assert_eq!(
        h.one([0x27, 0x09, 0x20, 0x00, 0x41, 0, 0x42, 0]),
        [0x80, 0x09, 0x20, 0x00, 0x10, 0x00, 0x07, 0x06]
    );
    assert_eq!(
        h.one([0x2B, 0x09, 0x20, 0x00, 0x41, 0, 0, 0]),
        [0x60, 0x09, 0x20, 0x00, 0, 0, 0, 0]
    );
}

#[test]
fn cia301_7_2_4_3_17_invalid_value() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0x2F, 0x04, 0x20, 0x00, 2, 0, 0, 0]),
        [0x80, 0x04, 0x20, 0x00, 0x30, 0x00, 0x09, 0x06]
    );
    assert_eq!(
        h.one([0x2F, 0x04, 0x20, 0x00, 1, 0, 0, 0]),
        [0x60, 0x04, 0x20, 0x00, 0, 0, 0, 0]
    );
}

#[test]
fn cia301_7_2_4_3_17_value_too_high() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0x2F, 0x00, 0x20, 0x00, 101, 0, 0, 0]),
        [0x80, 0x00, 0x20, 0x00, 0x31, 0x00, 0x09, 0x06]
    );
    assert_eq!(
        h.one([0x2B, 0x01, 0x20, 0x00, 101, 0, 0, 0]),
        abort(0x2001, 0, AbortCode::VALUE_TOO_HIGH)
    );
    assert_eq!(
        h.one([0x2F, 0x00, 0x20, 0x00, 100, 0, 0, 0]),
        [0x60, 0x00, 0x20, 0x00, 0, 0, 0, 0]
    );
    assert_eq!(h.access.get(0x2000, 0), Ok(Value::Unsigned8(100)));
}

#[test]
fn cia301_7_2_4_3_17_value_too_low() {
    let mut h = Harness::new();
    assert_eq!(
        h.one([0x2F, 0x00, 0x20, 0x00, 9, 0, 0, 0]),
        [0x80, 0x00, 0x20, 0x00, 0x32, 0x00, 0x09, 0x06]
    );
    let minus_101 = (-101i16).to_le_bytes();
    assert_eq!(
        h.one([0x2B, 0x01, 0x20, 0x00, minus_101[0], minus_101[1], 0, 0]),
        abort(0x2001, 0, AbortCode::VALUE_TOO_LOW)
    );
    assert_eq!(h.access.get(0x2000, 0), Ok(Value::Unsigned8(50)));
}

#[test]
fn cia301_7_2_4_3_17_out_of_memory() {
    let mut od = ObjectDictionary::new(Arc::new(description()), NODE);
    od.set_staging_limit(1000);
    let mut h = Harness::with(od);
    assert_eq!(
        h.one([0x21, 0x07, 0x20, 0x00, 0xD0, 0x07, 0, 0]),
        [0x80, 0x07, 0x20, 0x00, 0x05, 0x00, 0x04, 0x05]
    );
    assert_eq!(
        h.block_download(0x2007, 0, &pattern(2000), true),
        Err(AbortCode::OUT_OF_MEMORY)
    );
    assert_eq!(
        h.block_download(0x2007, 0, &pattern(1000), true)
            .map(|_| ()),
        Ok(())
    );
}

/// A device that refuses everything with a chosen code: the server puts the device's own
/// abort codes (PDO mapping, state, hardware, resources ...) on the wire unchanged.
struct Refuses(AbortCode);

impl ObjectAccess for Refuses {
    fn read(&mut self, _: u16, _: u8, _: usize, _: &mut [u8]) -> Result<ReadInfo, AbortCode> {
        Err(self.0)
    }
    fn write(&mut self, _: u16, _: u8, _: &[u8]) -> Result<(), AbortCode> {
        Err(self.0)
    }
    fn write_begin(&mut self, _: u16, _: u8, _: Option<usize>) -> Result<(), AbortCode> {
        Ok(())
    }
    fn write_segment(&mut self, _: u16, _: u8, _: &[u8]) -> Result<(), AbortCode> {
        Ok(())
    }
    fn write_end(&mut self, _: u16, _: u8) -> Result<(), AbortCode> {
        Err(self.0)
    }
    fn write_cancel(&mut self, _: u16, _: u8) {}
}

#[test]
fn cia301_7_2_4_3_17_device_abort_codes_reach_the_wire() {
    for code in [
        AbortCode::UNSUPPORTED_ACCESS,
        AbortCode::NOT_MAPPABLE,
        AbortCode::PDO_LENGTH_EXCEEDED,
        AbortCode::PARAMETER_INCOMPATIBLE,
        AbortCode::INTERNAL_INCOMPATIBILITY,
        AbortCode::HARDWARE_ERROR,
        AbortCode::MAX_LESS_THAN_MIN,
        AbortCode::RESOURCE_NOT_AVAILABLE,
        AbortCode::GENERAL_ERROR,
        AbortCode::DATA_TRANSFER,
        AbortCode::LOCAL_CONTROL,
        AbortCode::DEVICE_STATE,
        AbortCode::NO_OBJECT_DICTIONARY,
        AbortCode::NO_DATA,
        AbortCode::from_u32(0x0DEA_DBEE),
    ] {
        let mut h = Harness::with(Refuses(code));
        assert_eq!(
            h.one([0x2F, 0x00, 0x16, 0x01, 1, 0, 0, 0]),
            abort(0x1600, 1, code)
        );
        assert_eq!(
            h.one([0x40, 0x00, 0x16, 0x01, 0, 0, 0, 0]),
            abort(0x1600, 1, code)
        );
        assert_eq!(
            h.one([0x21, 0x00, 0x16, 0x01, 1, 0, 0, 0]),
            [0x60, 0x00, 0x16, 0x01, 0, 0, 0, 0]
        );
        assert_eq!(
            h.one(resp(0x0D, [1, 0, 0, 0, 0, 0, 0])),
            abort(0x1600, 1, code)
        );
    }
}

/// A device whose parameters 0x2000..=0x20FF may only be written while it is stopped.
struct Drive {
    running: bool,
}

impl OdHooks for Drive {
    fn validate_begin(
        &mut self,
        _: &ObjectDictionary,
        _: u16,
        _: u8,
        _: Option<usize>,
    ) -> Result<(), AbortCode> {
        if self.running {
            Err(AbortCode::DEVICE_STATE)
        } else {
            Ok(())
        }
    }
    fn validate(&mut self, _: &ObjectDictionary, _: u16, _: u8, _: &[u8]) -> Result<(), AbortCode> {
        if self.running {
            Err(AbortCode::DEVICE_STATE)
        } else {
            Ok(())
        }
    }
}

#[test]
fn cia301_7_2_4_3_17_present_device_state_does_not_allow_it() {
    let desc = OdBuilder::new()
        .var(
            0x2000,
            SubObject::new("Speed", DataType::Unsigned16, Access::Rw),
        )
        .var(
            0x2001,
            SubObject::new("Name", DataType::VisibleString, Access::Rw),
        )
        .hook(0x2000..=0x20FF)
        .build()
        .unwrap();
    let mut od = ObjectDictionary::new(Arc::new(desc), NODE);
    let mut drive = Drive { running: true };
    let mut server = SdoServer::for_node(NODE);
    let mut out = Outbox::new();
    let mut send = |b: [u8; 8], drive: &mut Drive, out: &mut Outbox| {
        out.clear();
        let mut access = Hooked::new(&mut od, drive);
        server.on_frame(&frame(RX, b), Instant::ZERO, &mut access, out);
        out.frames()
            .iter()
            .map(|f| <[u8; 8]>::try_from(f.data_bytes()).unwrap())
            .collect::<Vec<_>>()
    };
    // Expedited: refused as the value arrives.
    assert_eq!(
        send([0x2B, 0x00, 0x20, 0x00, 1, 0, 0, 0], &mut drive, &mut out),
        [[0x80, 0x00, 0x20, 0x00, 0x22, 0x00, 0x00, 0x08]]
    );
    // Segmented: refused at the initiate, before any data.
    assert_eq!(
        send([0x21, 0x01, 0x20, 0x00, 10, 0, 0, 0], &mut drive, &mut out),
        [abort(0x2001, 0, AbortCode::DEVICE_STATE)]
    );
    drive.running = false;
    assert_eq!(
        send([0x2B, 0x00, 0x20, 0x00, 1, 0, 0, 0], &mut drive, &mut out),
        [[0x60, 0x00, 0x20, 0x00, 0, 0, 0, 0]]
    );
    assert_eq!(
        send([0x21, 0x01, 0x20, 0x00, 2, 0, 0, 0], &mut drive, &mut out),
        [[0x60, 0x01, 0x20, 0x00, 0, 0, 0, 0]]
    );
}

// ---- SDO timeout ----

#[test]
fn cia301_7_2_4_3_17_timeout_after_one_second() {
    let mut h = Harness::new();
    h.one([0x21, 0x06, 0x20, 0x00, 12, 0, 0, 0]);
    assert_eq!(
        h.server.next_deadline(),
        Some(Instant::from_nanos(1_000_000_000))
    );
    h.advance(Duration::from_millis(500));
    h.one(resp(0x00, *b"hello w"));
    // Each request restarts the timer.
    assert_eq!(
        h.server.next_deadline(),
        Some(Instant::from_nanos(1_500_000_000))
    );
    h.now = Instant::from_nanos(1_499_999_999);
    assert!(h.tick().is_empty());
    h.now = Instant::from_nanos(1_500_000_000);
    assert_eq!(h.tick(), [[0x80, 0x06, 0x20, 0x00, 0x00, 0x00, 0x04, 0x05]]);
    assert!(h.server.is_idle());
    assert_eq!(h.server.next_deadline(), None);
    assert_eq!(h.access.staged(), b"");
}

#[test]
fn cia301_7_2_4_3_17_timeout_is_configurable_per_server() {
    let mut h = Harness::new();
    h.server.set_timeout(Duration::from_millis(100));
    h.one([0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0]);
    assert_eq!(
        h.server.next_deadline(),
        Some(Instant::from_nanos(100_000_000))
    );
    h.now = Instant::from_nanos(100_000_000);
    assert_eq!(h.tick(), [abort(0x1008, 0, AbortCode::TIMEOUT)]);
}

#[test]
fn cia301_7_2_4_3_17_timeout_while_waiting_for_a_block_acknowledgement() {
    let mut h = Harness::new();
    h.download(0x2003, 0, &pattern(20)).unwrap();
    h.one([0xA4, 0x03, 0x20, 0x00, 127, 0, 0, 0]);
    assert_eq!(h.req([0xA3, 0, 0, 0, 0, 0, 0, 0]).len(), 3);
    h.now = Instant::from_nanos(1_000_000_000);
    assert_eq!(h.tick(), [abort(0x2003, 0, AbortCode::TIMEOUT)]);
}

// ---- several servers, COB-IDs ----

#[test]
fn cia301_7_5_2_33_several_servers_with_their_own_cob_ids() {
    let mut od = ObjectDictionary::new(Arc::new(description()), NODE);
    let mut first = SdoServer::for_node(NODE);
    let mut second = SdoServer::new(Id::standard(0x640).unwrap(), Id::standard(0x5C0).unwrap());
    let mut out = Outbox::new();
    let req = frame(0x640, [0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]);
    assert!(!first.on_frame(&req, Instant::ZERO, &mut od, &mut out));
    assert!(second.on_frame(&req, Instant::ZERO, &mut od, &mut out));
    assert_eq!(
        out.frames(),
        [frame(
            0x5C0,
            [0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00]
        )]
    );
    // Transfers on the two channels are independent.
    out.clear();
    first.on_frame(
        &frame(RX, [0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0]),
        Instant::ZERO,
        &mut od,
        &mut out,
    );
    second.on_frame(
        &frame(0x640, [0x40, 0x17, 0x10, 0x00, 0, 0, 0, 0]),
        Instant::ZERO,
        &mut od,
        &mut out,
    );
    first.on_frame(
        &frame(RX, [0x60, 0, 0, 0, 0, 0, 0, 0]),
        Instant::ZERO,
        &mut od,
        &mut out,
    );
    assert_eq!(
        out.frames(),
        [
            frame(TX, [0x41, 0x08, 0x10, 0x00, 7, 0, 0, 0]),
            frame(0x5C0, [0x4B, 0x17, 0x10, 0x00, 0, 0, 0, 0]),
            frame(TX, resp(0x01, *b"cantwin")),
        ]
    );
}

#[test]
fn cia301_7_5_2_33_cob_id_valid_bit_and_extended_frames() {
    let mut od = ObjectDictionary::new(Arc::new(description()), NODE);
    let mut s = SdoServer::for_node(NODE);
    let mut out = Outbox::new();
    s.set_cob_ids(0x8000_0605, 0x585);
    assert_eq!(s.rx_id(), None);
    assert!(!s.on_frame(
        &frame(RX, [0x40, 0x00, 0x10, 0, 0, 0, 0, 0]),
        Instant::ZERO,
        &mut od,
        &mut out
    ));
    assert!(out.is_empty());
    s.set_cob_ids(0x2000_1234, 0x2000_1235);
    let req = cantwin_can::Frame::data_array(
        Id::extended(0x1234).unwrap(),
        [0x40, 0x00, 0x10, 0, 0, 0, 0, 0],
    );
    assert!(s.on_frame(&req, Instant::ZERO, &mut od, &mut out));
    assert_eq!(out.frames()[0].id(), Id::extended(0x1235).unwrap());
    assert_eq!(SdoServer::for_node(0).rx_id(), None);
    assert_eq!(SdoServer::for_node(128).rx_id(), None);
}

#[test]
fn cia301_7_2_4_short_requests_are_zero_padded_and_remote_frames_ignored() {
    let mut h = Harness::new();
    let short = cantwin_can::Frame::std(RX, &[0x40, 0x00, 0x10]).unwrap();
    assert!(
        h.server
            .on_frame(&short, Instant::ZERO, &mut h.access, &mut h.out)
    );
    assert_eq!(
        h.drain(),
        [[0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00]]
    );
    let empty = cantwin_can::Frame::std(RX, &[]).unwrap();
    assert!(
        h.server
            .on_frame(&empty, Instant::ZERO, &mut h.access, &mut h.out)
    );
    assert_eq!(h.drain(), [abort(0, 0, AbortCode::INVALID_COMMAND)]);
    let remote = cantwin_can::Frame::remote(Id::standard(RX).unwrap(), 8).unwrap();
    assert!(
        !h.server
            .on_frame(&remote, Instant::ZERO, &mut h.access, &mut h.out)
    );
    assert!(h.out.is_empty());
}

#[test]
fn cia301_7_4_8_1_node_id_relative_defaults() {
    let h = Harness::new();
    assert_eq!(h.access.get(0x1200, 1), Ok(Value::Unsigned32(0x605)));
    assert_eq!(h.access.get(0x1200, 2), Ok(Value::Unsigned32(0x585)));
    assert_eq!(h.access.get(0x1200, 0), Ok(Value::Unsigned8(2)));
}

#[test]
fn cia301_7_2_4_3_16_crc_is_ccitt_with_initial_value_zero() {
    assert_eq!(Crc16::of(b"123456789"), 0x31C3);
}

// ---- §7.2.4.1 server capabilities: a minimum-capability device ----

fn expedited_only() -> Harness {
    let mut h = Harness::new();
    h.server.set_capabilities(SdoCapabilities::EXPEDITED_ONLY);
    h
}

#[test]
fn cia301_7_2_4_1_expedited_only_server_refuses_segments_with_index_zero() {
    let mut h = expedited_only();
    // Download segment (ccs 0) and upload segment (ccs 3) follow no initiate.
    assert_eq!(
        h.one([0x00, 0x17, 0x10, 0x00, 1, 2, 3, 4]),
        abort(0, 0, AbortCode::INVALID_COMMAND)
    );
    assert_eq!(
        h.one([0x60, 0x17, 0x10, 0x00, 0, 0, 0, 0]),
        abort(0, 0, AbortCode::INVALID_COMMAND)
    );
    assert!(h.server.is_idle());
}

#[test]
fn cia301_7_2_4_1_expedited_only_server_refuses_block_requests_with_their_bytes() {
    let mut h = expedited_only();
    // Block upload initiate (ccs 5) and block download initiate (ccs 6).
    assert_eq!(
        h.one([0xA4, 0x08, 0x10, 0x00, 0x7F, 0, 0, 0]),
        abort(0x1008, 0, AbortCode::INVALID_COMMAND)
    );
    assert_eq!(
        h.one([0xC6, 0x03, 0x20, 0x00, 0x10, 0, 0, 0]),
        abort(0x2003, 0, AbortCode::INVALID_COMMAND)
    );
    // Any other block command echoes bytes 1–3 as index and sub-index.
    assert_eq!(
        h.one([0xA2, 0x05, 0x7F, 0x01, 0, 0, 0, 0]),
        abort(0x7F05, 1, AbortCode::INVALID_COMMAND)
    );
    assert!(h.server.is_idle());
    assert_eq!(h.server.next_deadline(), None);
}

#[test]
fn cia301_7_2_4_1_expedited_only_server_refuses_segmented_initiates() {
    let mut h = expedited_only();
    // Initiate download with e = 0 (segmented), size indicated.
    assert_eq!(
        h.one([0x21, 0x03, 0x20, 0x00, 0x10, 0, 0, 0]),
        abort(0x2003, 0, AbortCode::INVALID_COMMAND)
    );
    // An upload of a value longer than 4 bytes cannot be expedited.
    assert_eq!(
        h.one([0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0]),
        abort(0x1008, 0, AbortCode::LENGTH_TOO_HIGH)
    );
    // Expedited transfers work as before.
    assert_eq!(
        h.one([0x2F, 0x00, 0x20, 0x00, 42, 0, 0, 0]),
        [0x60, 0x00, 0x20, 0, 0, 0, 0, 0]
    );
    assert_eq!(
        h.one([0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]),
        [0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00]
    );
    assert!(h.server.is_idle());
}

#[test]
fn cia301_7_4_3_sub_index_ff_refused_before_any_other_check() {
    let mut h = expedited_only();
    h.server
        .set_capabilities(SdoCapabilities::EXPEDITED_ONLY.with_sub_index_ff_refused());
    // Initiate download and upload, even of an object that does not exist.
    assert_eq!(
        h.one([0x2F, 0x00, 0x20, 0xFF, 42, 0, 0, 0]),
        abort(0x2000, 0xFF, AbortCode::NO_SUB_INDEX)
    );
    assert_eq!(
        h.one([0x40, 0x34, 0x12, 0xFF, 0, 0, 0, 0]),
        abort(0x1234, 0xFF, AbortCode::NO_SUB_INDEX)
    );
    // Before the capability check: a block request for sub-index 0xFF.
    assert_eq!(
        h.one([0xA4, 0x08, 0x10, 0xFF, 0x7F, 0, 0, 0]),
        abort(0x1008, 0xFF, AbortCode::NO_SUB_INDEX)
    );
    assert_eq!(
        h.one([0xC2, 0x03, 0x20, 0xFF, 0x10, 0, 0, 0]),
        abort(0x2003, 0xFF, AbortCode::NO_SUB_INDEX)
    );
    // Segments carry no multiplexer: the segment rule applies.
    assert_eq!(
        h.one([0x00, 0x17, 0x10, 0xFF, 1, 2, 3, 4]),
        abort(0, 0, AbortCode::INVALID_COMMAND)
    );
    // Without the rule, a missing object is looked up as usual.
    h.server.set_capabilities(SdoCapabilities::FULL);
    assert_eq!(
        h.one([0x40, 0x34, 0x12, 0xFF, 0, 0, 0, 0]),
        abort(0x1234, 0xFF, AbortCode::NO_OBJECT)
    );
}

#[test]
fn cia301_7_4_3_sub_index_ff_rule_in_a_full_server_leaves_block_segments_alone() {
    let mut h = Harness::new();
    h.server
        .set_capabilities(SdoCapabilities::FULL.with_sub_index_ff_refused());
    // The last of 43 segments starts 0xAB (c = 1, seqno 43: it reads as ccs 5) and
    // carries 0xFF where a request has its sub-index.
    let mut data = pattern(300);
    data[296] = 0xFF;
    assert!(h.block_download(0x2003, 0, &data, true).is_ok());
    assert_eq!(h.access.get(0x2003, 0), Ok(Value::Domain(data)));
}
