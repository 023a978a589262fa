//! UCMM (DeviceNet Vol. 1, Unconnected Message Manager) explicit connections on group 3,
//! and the card's parameter access over them (EXP-CAN/DN-ADV manual §3.4): the Parameter
//! object 0x0F with instance = PAR, and Drive Parameter Access 0x66 with services
//! 0x32–0x35, the data types of table 3.4.2 and the error codes of table 3.4.1.
//!
//! Slave MAC 9; clients MAC 10 (UCMM request 0x78A) and MAC 11 (0x78B); the slave's UCMM
//! response identifier is 0x749.
#![allow(clippy::unwrap_used)]

mod common;

use cantwin_devicenet::Slave;
use common::*;

/// Open a UCMM connection from client 10 with source message ID 0 and the given body
/// format; the first connection gets server message ID 0 (0x609) and instance 6.
fn opened(format: u8) -> (Slave<Drive>, cantwin_can::Instant) {
    let mut s = slave(9);
    let t = online(&mut s);
    let req = format!("78A#094B{format:02X}30");
    let actual = if format == 0 { 0 } else { 1 };
    assert_eq!(
        deliver(&mut s, &req, t),
        [format!("749#0ACB{actual:02X}000600")]
    );
    (s, t)
}

#[test]
fn ucmm_open_8_8_get_identity_close() {
    let (mut s, t) = opened(0);
    let c = &s.ucmm_connections()[0];
    assert_eq!((c.instance, c.peer), (6, mac(10)));
    // Requests on 0x600 | 0 << 6 | 10 with our MAC in the header; answers on 0x609.
    assert_eq!(deliver(&mut s, "60A#090E010101", t), ["609#0A8E2301"]);
    // Its Connection instance: initial comm characteristics 0x33, IDs 0x609/0x60A.
    assert_eq!(deliver(&mut s, "60A#090E050606", t), ["609#0A8E33"]);
    assert_eq!(deliver(&mut s, "60A#090E050604", t), ["609#0A8E0906"]);
    assert_eq!(deliver(&mut s, "60A#090E050605", t), ["609#0A8E0A06"]);
    // Close.
    assert_eq!(deliver(&mut s, "78A#094C0600", t), ["749#0ACC"]);
    assert!(s.ucmm_connections().is_empty());
    assert!(deliver(&mut s, "60A#090E010101", t).is_empty());
}

#[test]
fn ucmm_16_16_request_gets_8_16() {
    let (s, _) = opened(2);
    assert_eq!(
        s.ucmm_connections()[0].format,
        cantwin_devicenet::wire::BodyFormat::F8_16
    );
}

#[test]
fn several_concurrent_explicit_connections() {
    let mut s = slave(9);
    let t = online(&mut s);
    deliver(&mut s, "44E#0A4B0301010A", t);
    assert_eq!(deliver(&mut s, "78A#094B0130", t), ["749#0ACB01000600"]);
    // A second client gets the next server message ID and instance.
    assert_eq!(deliver(&mut s, "78B#094B0130", t), ["749#0BCB01010700"]);
    // The third UCMM connection exceeds the card's 3 explicit connections.
    assert_eq!(deliver(&mut s, "78A#094B0131", t), ["749#0A9402FF"]);
    // All three explicit connections answer independently.
    assert_eq!(deliver(&mut s, "44C#0A0E010101", t), ["44B#0A8E2301"]);
    assert_eq!(deliver(&mut s, "60A#090E01010001", t), ["609#0A8E2301"]);
    assert_eq!(deliver(&mut s, "60B#090E01010001", t), ["649#0B8E2301"]);
    // Closing someone else's connection: object does not exist.
    assert_eq!(deliver(&mut s, "78A#094C0700", t), ["749#0A9416FF"]);
    assert_eq!(deliver(&mut s, "78B#094C0700", t), ["749#0BCC"]);
}

#[test]
fn ucmm_errors() {
    let mut s = slave(9);
    let t = online(&mut s);
    // Group 1 or 2 connections are not offered; message IDs 5–7 are not connection IDs.
    assert_eq!(deliver(&mut s, "78A#094B0010", t), ["749#0A9420FF"]);
    assert_eq!(deliver(&mut s, "78A#094B0035", t), ["749#0A9420FF"]);
    // Truncated open and close, unknown service.
    assert_eq!(deliver(&mut s, "78A#094B00", t), ["749#0A9413FF"]);
    assert_eq!(deliver(&mut s, "78A#094C06", t), ["749#0A9413FF"]);
    assert_eq!(deliver(&mut s, "78A#090E", t), ["749#0A9408FF"]);
    // The same client message ID twice: conflict.
    deliver(&mut s, "78A#094B0030", t);
    assert_eq!(deliver(&mut s, "78A#094B0030", t), ["749#0A940CFF"]);
    // A request addressed to another server (header MAC 8) is not ours.
    assert!(deliver(&mut s, "78A#084B0031", t).is_empty());
}

#[test]
fn ucmm_connection_inactivity_deletes_it() {
    let (mut s, t) = opened(0);
    use cantwin_can::Node;
    assert_eq!(
        s.next_deadline(),
        Some(t + cantwin_can::Duration::from_secs(10))
    );
    tick(&mut s, t + cantwin_can::Duration::from_secs(10));
    assert!(s.ucmm_connections().is_empty());
}

/// Manual §3.4.1: Get_Attribute_Single (0x0E; the manual's "0hex" is a conversion loss)
/// of class 0x0F, instance 600 (0x258), attribute 1: 4 bytes.
#[test]
fn parameter_object_get_par_600_returns_dword_3_4_1() {
    let (mut s, t) = opened(1);
    s.app_mut().pars.get_mut(&600).unwrap().value = -2;
    assert_eq!(deliver(&mut s, "60A#090E0F580201", t), ["609#0A8EFEFFFFFF"]);
    // Class attribute 1: revision.
    assert_eq!(deliver(&mut s, "60A#090E0F000001", t), ["609#0A8E0100"]);
    // A PAR that does not exist.
    assert_eq!(deliver(&mut s, "60A#090E0F010001", t), ["609#0A9416FF"]);
}

/// Manual §3.4.1: Set_Attribute_Single of PAR 600 := 1000 with a 2-byte value (INT); an
/// erroneous Set is not answered (the client times out).
#[test]
fn parameter_object_set_par_600_and_silent_error_3_4_1() {
    let (mut s, t) = opened(1);
    assert_eq!(deliver(&mut s, "60A#09100F580201E803", t), ["609#0A90"]);
    assert_eq!(s.app().pars[&600].value, 1000);
    // Above the maximum, read-only, wrong size, unknown PAR: silence.
    assert!(deliver(&mut s, "60A#09100F5802011127", t).is_empty());
    assert!(deliver(&mut s, "60A#09100F AE0F010200".replace(' ', "").as_str(), t).is_empty());
    assert!(deliver(&mut s, "60A#09100F580201E8", t).is_empty());
    assert!(deliver(&mut s, "60A#09100F01000101", t).is_empty());
    assert_eq!(s.app().pars[&600].value, 1000);
}

/// With the 8/8 format of the predefined connection only PARs up to 255 are reachable
/// (manual §3.4.2 note 1: "byte or word depending on the allocation").
#[test]
fn predefined_connection_uses_8_bit_instances() {
    let mut s = slave(9);
    let t = online(&mut s);
    deliver(&mut s, "44E#0A4B0301010A", t);
    assert_eq!(deliver(&mut s, "44C#0A0E0F5801", t), ["44B#0A9416FF"]);
}

/// Manual §3.4.2 A: Set_Drive_Value 0x33, reply 0xB3 with Result 0.
#[test]
fn drive_parameter_access_set_a() {
    let (mut s, t) = opened(1);
    assert_eq!(deliver(&mut s, "60A#0933665802E803", t), ["609#0AB30000"]);
    assert_eq!(s.app().pars[&600].value, 1000);
    // refused writes carry the drive error code of table 3.4.1.
    assert_eq!(deliver(&mut s, "60A#09336658021127", t), ["609#0AB30900"]);
    assert_eq!(deliver(&mut s, "60A#09336658020FD8", t), ["609#0AB30A00"]);
    assert_eq!(
        deliver(&mut s, "60A#0933 66AE0F0200".replace(' ', "").as_str(), t),
        ["609#0AB30C00"]
    );
    assert_eq!(
        deliver(&mut s, "60A#093366010001 00".replace(' ', "").as_str(), t),
        ["609#0AB30100"]
    );
    s.app_mut().enabled = true;
    assert_eq!(deliver(&mut s, "60A#093366A60F0500", t), ["609#0AB31000"]);
}

/// Manual §3.4.2 B: Get_Drive_Value 0x32, reply 0xB2 with Result 0 and the value in the
/// parameter's size.
#[test]
fn drive_parameter_access_get_b() {
    let (mut s, t) = opened(1);
    assert_eq!(deliver(&mut s, "60A#0932665802", t), ["609#0AB200000000"]);
    // A 32-bit parameter: 100000 = 0x000186A0.
    assert_eq!(
        deliver(&mut s, "60A#093266BC02", t),
        ["609#0AB20000A0860100"]
    );
    assert_eq!(deliver(&mut s, "60A#0932660100", t), ["609#0AB20100"]);
}

/// Manual §3.4.2 C and D: typed access. The service table lists 0x34 Get_Typed_Drive_Value
/// and 0x35 Set_Typed_Drive_Value; example D-1 prints 0x36 for the typed read. The table
/// wins: services pair up Get/Set (0x32/0x33, 0x34/0x35), 0x36 appears nowhere else, and
/// the example's reply tables (D-2, D-3 showing 0x32) are copies of B-2/B-3. Replies carry
/// the request's service | 0x80 as every CIP reply does (0xB4, 0xB5), not the 0x32/0x33
/// the copied tables show. 0x36 is answered "service not supported".
#[test]
fn drive_parameter_access_typed_c_d() {
    let (mut s, t) = opened(1);
    // Set typed: PAR 700 := 5000 sent as DB_T_INT (3).
    assert_eq!(deliver(&mut s, "60A#093566BC02038813", t), ["609#0AB50000"]);
    assert_eq!(s.app().pars[&700].value, 5000);
    // Get typed as DB_T_INT: 2 bytes; as DB_T_DWORD (7): 4 bytes; DB_T_VOID: native.
    assert_eq!(deliver(&mut s, "60A#093466BC0203", t), ["609#0AB400008813"]);
    assert_eq!(
        deliver(&mut s, "60A#093466BC0207", t),
        ["609#0AB4000088130000"]
    );
    assert_eq!(
        deliver(&mut s, "60A#093466BC0200", t),
        ["609#0AB4000088130000"]
    );
    // Unknown type code.
    assert_eq!(deliver(&mut s, "60A#093466BC0209", t), ["609#0AB40B00"]);
    // The example's 0x36.
    assert_eq!(deliver(&mut s, "60A#093666BC0203", t), ["609#0A9408FF"]);
}

/// A typed write of a 4-byte value on 8/16 is 9 bytes of body: acknowledged fragments.
#[test]
fn fragmented_request_to_drive_parameter_access() {
    let (mut s, t) = opened(1);
    // body: 35 66 BC 02 07 | 40 0D 03 00 (DB_T_DWORD 200000)
    assert_eq!(deliver(&mut s, "60A#89003566BC020740", t), ["609#8AC000"]);
    assert_eq!(
        deliver(&mut s, "60A#89810D0300", t),
        ["609#8AC100", "609#0AB50000"]
    );
    assert_eq!(s.app().pars[&700].value, 200_000);
}

/// More than 32 bytes of request body: the fragment that overflows is acknowledged with
/// "too much data" and the message is dropped.
#[test]
fn fragmented_request_over_32_bytes_is_refused() {
    let (mut s, t) = opened(1);
    let mut replies = Vec::new();
    for (i, kind) in [0x00u8, 0x41, 0x42, 0x43, 0x44, 0x85].iter().enumerate() {
        let _ = i;
        replies.extend(deliver(&mut s, &format!("60A#89{kind:02X}350000000000"), t));
    }
    assert_eq!(
        replies,
        [
            "609#8AC000",
            "609#8AC100",
            "609#8AC200",
            "609#8AC300",
            "609#8AC400",
            "609#8AC501"
        ]
    );
}

/// A lost fragment (a gap in the count) drops the message without acknowledge.
#[test]
fn fragment_gap_is_not_acknowledged() {
    let (mut s, t) = opened(1);
    assert_eq!(deliver(&mut s, "60A#89003566BC020740", t), ["609#8AC000"]);
    assert!(deliver(&mut s, "60A#89820D0300", t).is_empty());
    assert_eq!(s.app().pars[&700].value, 100_000);
}

/// A fragmented response whose acknowledge never comes is sent once more after the
/// acknowledge timeout (1 s), then abandoned.
#[test]
fn lost_acknowledge_retry_and_abort() {
    let (mut s, t) = opened(1);
    // Identity Get_Attributes_All: 15 + 9 bytes of reply → 25-byte body, 5 fragments.
    let first = deliver(&mut s, "60A#0901010100", t);
    assert_eq!(first, ["609#8A00812301020000"]);
    let t1 = t + cantwin_can::Duration::from_secs(1);
    assert_eq!(tick(&mut s, t1), ["609#8A00812301020000"]);
    assert!(tick(&mut s, t1 + cantwin_can::Duration::from_secs(1)).is_empty());
    assert!(s.ucmm_connections()[0].tx.is_none());
}

/// A device configured to answer Allocate with 8/16 reaches every PAR on the predefined
/// connection too.
#[test]
fn predefined_connection_with_8_16_allocation() {
    let mut cfg =
        cantwin_devicenet::SlaveConfig::new(mac(9), cantwin_can::BitRate::R500K, identity());
    cfg.allocate_format = cantwin_devicenet::wire::BodyFormat::F8_16;
    let mut s = Slave::new(cfg, Drive::new(1, 1)).unwrap();
    let t = online(&mut s);
    assert_eq!(deliver(&mut s, "44E#0A4B0301010A", t), ["44B#0ACB01"]);
    assert_eq!(deliver(&mut s, "44C#0A32665802", t), ["44B#0AB200000000"]);
}
