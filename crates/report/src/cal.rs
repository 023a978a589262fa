//! One line for a CAL CMS frame (DS 202-2): which COB is which is the application's choice,
//! so the line names the COB and splits byte 0, the CMS control byte.

use cantwin_can::Frame;

use crate::hex::hex_bytes;

/// One line for `frame` on a CAL network.
pub fn describe(frame: &Frame) -> String {
    let cob = frame.id().as_raw();
    match frame.data_bytes().split_first() {
        _ if frame.is_remote() => format!("COB 0x{cob:X} remote read request"),
        Some((c, rest)) => format!(
            "COB 0x{cob:X} control 0x{c:02X} (bit 7 {}, multiplexor {}) data {}",
            c >> 7,
            c & 0x7F,
            hex_bytes(rest)
        ),
        None => format!("COB 0x{cob:X} (no data)"),
    }
}
