//! Frame data as text, shared by every protocol's decoder.

/// Bytes as spaced hex, `01 02 0A`.
pub fn hex_bytes(data: &[u8]) -> String {
    data.iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}
