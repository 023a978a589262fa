//! The LINKTYPE_CAN_SOCKETCAN (227) packet: Linux `struct can_frame` with the identifier in
//! network byte order (tcpdump.org, "LINKTYPE_CAN_SOCKETCAN"):
//!
//! ```text
//! 0..4  CAN ID and flags, big-endian: 0x80000000 EFF, 0x40000000 RTR, 0x20000000 ERR
//! 4     payload length
//! 5     FD flags (0x04 FDF marks a CAN FD frame; 0 for classic CAN)
//! 6, 7  reserved / padding
//! 8..   payload, then padding
//! ```

use crate::record::{ErrorFrame, Event};
use cantwin_can::{Frame, Id};

/// The link-layer header type number.
pub(crate) const LINKTYPE_CAN_SOCKETCAN: u32 = 227;
/// Extended frame format flag.
pub(crate) const EFF_FLAG: u32 = 0x8000_0000;
/// Remote transmission request flag.
pub(crate) const RTR_FLAG: u32 = 0x4000_0000;
/// Error frame flag.
pub(crate) const ERR_FLAG: u32 = 0x2000_0000;
/// The identifier bits.
pub(crate) const ID_MASK: u32 = 0x1FFF_FFFF;
/// CANFD_FDF in the FD flags byte.
const FDF: u8 = 0x04;
/// Size of a classic `struct can_frame` (CAN_MTU): what cantwin writes, as Linux does.
pub(crate) const CAN_MTU: usize = 16;
/// Size of a `struct canfd_frame` (CANFD_MTU).
const CANFD_MTU: usize = 72;

/// A decoded packet.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum Decoded {
    /// A classic CAN frame or an error frame.
    Event(Event),
    /// A CAN FD or CAN XL frame, which [`Frame`] cannot represent.
    NotClassic,
}

/// Encodes an event as a full 16-byte `struct can_frame` (padding zeroed).
///
/// A remote frame's length byte holds the requested DLC, as Linux puts it in `can_dlc`.
pub(crate) fn encode(event: &Event) -> [u8; CAN_MTU] {
    let mut out = [0u8; CAN_MTU];
    match event {
        Event::Frame(frame) => {
            let mut id = frame.id().as_raw();
            if frame.is_extended() {
                id |= EFF_FLAG;
            }
            if frame.is_remote() {
                id |= RTR_FLAG;
            }
            out[..4].copy_from_slice(&id.to_be_bytes());
            out[4] = frame.dlc();
            let data = frame.data_bytes();
            out[8..8 + data.len()].copy_from_slice(data);
        }
        Event::Error(err) => {
            out[..4].copy_from_slice(&(ERR_FLAG | err.class()).to_be_bytes());
            out[4] = 8;
            out[8..].copy_from_slice(&err.data());
        }
    }
    out
}

/// Decodes one packet; the error says what is wrong with it.
pub(crate) fn decode(packet: &[u8]) -> Result<Decoded, String> {
    let Some((header, payload)) = packet.split_first_chunk::<8>() else {
        return Err(format!(
            "packet of {} bytes is shorter than the 8-byte SocketCAN header",
            packet.len()
        ));
    };
    let raw = u32::from_be_bytes([header[0], header[1], header[2], header[3]]);
    let len = header[4];
    // CAN FD: FDF set, or (older writers that left FDF clear) a payload length above 8 or a
    // packet of CANFD_MTU bytes. CAN XL sets 0x80 in byte 4, which also reads as len > 8.
    if header[5] & FDF != 0 || len > 8 || packet.len() == CANFD_MTU {
        return Ok(Decoded::NotClassic);
    }
    if raw & ERR_FLAG != 0 {
        // The payload of an error frame is always 8 bytes; be lenient with shorter captures.
        let mut data = [0u8; 8];
        let n = payload.len().min(usize::from(len));
        data[..n].copy_from_slice(&payload[..n]);
        let err = ErrorFrame::new(raw & ID_MASK, data).map_err(|e| e.to_string())?;
        return Ok(Decoded::Event(Event::Error(err)));
    }
    let id = if raw & EFF_FLAG != 0 {
        Id::extended(raw & ID_MASK)
    } else {
        Id::standard(u16::try_from(raw & ID_MASK).unwrap_or(u16::MAX))
    }
    .map_err(|_| format!("standard identifier {:#x} exceeds 11 bits", raw & ID_MASK))?;
    let frame = if raw & RTR_FLAG != 0 {
        Frame::remote(id, len)
    } else {
        let n = usize::from(len);
        if payload.len() < n {
            return Err(format!(
                "payload length {n} but only {} bytes captured",
                payload.len()
            ));
        }
        Frame::data(id, &payload[..n])
    }
    .map_err(|e| e.to_string())?;
    Ok(Decoded::Event(Event::Frame(frame)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extended_remote_frame_sets_eff_and_rtr_in_network_order() {
        let f = Frame::remote(Id::extended(0x1234_5678 & ID_MASK).unwrap(), 3).unwrap();
        let b = encode(&Event::Frame(f));
        assert_eq!(&b[..8], &[0xD2, 0x34, 0x56, 0x78, 3, 0, 0, 0]);
        assert_eq!(decode(&b), Ok(Decoded::Event(Event::Frame(f))));
    }

    #[test]
    fn fd_frames_are_not_classic() {
        let mut b = [0u8; 16];
        b[5] = FDF;
        assert_eq!(decode(&b), Ok(Decoded::NotClassic));
        let mut b = [0u8; 72];
        b[4] = 12;
        assert_eq!(decode(&b), Ok(Decoded::NotClassic));
        assert_eq!(decode(&[0u8; 72]), Ok(Decoded::NotClassic));
    }

    #[test]
    fn short_or_inconsistent_packets_are_errors() {
        assert!(decode(&[0u8; 7]).is_err());
        let mut b = [0u8; 10];
        b[4] = 4;
        assert!(decode(&b).is_err());
        let mut b = [0u8; 16];
        b[..4].copy_from_slice(&0x800u32.to_be_bytes());
        assert!(decode(&b).is_err());
    }

    #[test]
    fn short_error_frame_payload_is_zero_padded() {
        let mut b = [0u8; 10];
        b[..4].copy_from_slice(&(ERR_FLAG | 0x40).to_be_bytes());
        b[4] = 8;
        b[8] = 7;
        b[9] = 9;
        let want = ErrorFrame::new(0x40, [7, 9, 0, 0, 0, 0, 0, 0]).unwrap();
        assert_eq!(decode(&b), Ok(Decoded::Event(Event::Error(want))));
    }
}
