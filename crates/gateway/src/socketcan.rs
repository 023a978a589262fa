//! Real CAN interfaces on Linux (SocketCAN raw sockets) as a [`BusConnector`].
//!
//! A port is a `CAN_RAW` socket bound to the interface: the kernel's default loopback makes
//! other sockets on the host see its frames, and, with own-message reception off (the
//! default), it receives every frame on the interface except its own, as a bus port does.
//! Frames are stamped with the kernel's receive time (`SO_TIMESTAMPNS`). The receive buffer is
//! the socket's own: the kernel drops frames when it is full, and [`BusPort::overflows`]
//! reports 0 because the count is not read back.
//!
//! Error frames are not received (the socket's error mask is left empty).

use std::io::ErrorKind;
use std::time::Duration;

use cantwin_can::{Frame, Id};
use socketcan::{CanFrame, CanSocket, EmbeddedFrame, Socket, SocketOptions};

use crate::port::{BusConnector, BusPort, PortError, Received};

/// The CAN interfaces of this host (`can0`, `vcan0`, …), opened by name.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SocketCan;

/// A raw socket on one interface; dropping it closes the socket.
#[derive(Debug)]
struct SocketCanPort {
    socket: CanSocket,
}

fn io_error(e: std::io::Error) -> PortError {
    PortError::Transport(e.to_string())
}

impl BusConnector for SocketCan {
    fn open(&self, channel: &str, _rx_capacity: usize) -> Result<Box<dyn BusPort>, PortError> {
        let socket = CanSocket::open(channel).map_err(|e| match e.kind() {
            ErrorKind::NotFound => PortError::UnknownChannel(channel.to_owned()),
            _ => io_error(e),
        })?;
        socket.set_recv_timestamp(true).map_err(io_error)?;
        Ok(Box::new(SocketCanPort { socket }))
    }
}

fn to_socketcan(frame: &Frame) -> Option<CanFrame> {
    let id: socketcan::Id = match frame.id() {
        Id::Standard(id) => socketcan::StandardId::new(id.as_raw())?.into(),
        Id::Extended(id) => socketcan::ExtendedId::new(id.as_raw())?.into(),
    };
    if frame.is_remote() {
        CanFrame::new_remote(id, usize::from(frame.dlc()))
    } else {
        CanFrame::new(id, frame.data_bytes())
    }
}

fn from_socketcan(frame: &CanFrame) -> Option<Frame> {
    let id = match frame.id() {
        socketcan::Id::Standard(id) => Id::standard(id.as_raw()).ok()?,
        socketcan::Id::Extended(id) => Id::extended(id.as_raw()).ok()?,
    };
    match frame {
        CanFrame::Data(_) => Frame::data(id, frame.data()).ok(),
        CanFrame::Remote(_) => Frame::remote(id, u8::try_from(frame.dlc()).ok()?).ok(),
        CanFrame::Error(_) => None,
    }
}

impl BusPort for SocketCanPort {
    fn send(&self, frame: Frame) -> Result<(), PortError> {
        let raw = to_socketcan(&frame).ok_or(PortError::Transport(format!(
            "frame {frame} cannot be written to SocketCAN"
        )))?;
        /// Linux `ENOBUFS`: the interface's transmit queue is full.
        const ENOBUFS: i32 = 105;
        self.socket.write_frame(&raw).map_err(|e| {
            if e.raw_os_error() == Some(ENOBUFS) {
                PortError::TxQueueFull
            } else {
                io_error(e)
            }
        })
    }

    fn recv_timeout(&self, timeout: Duration) -> Result<Option<Received>, PortError> {
        // A zero timeout means "block forever" to SO_RCVTIMEO: never pass one.
        self.socket
            .set_read_timeout(timeout.max(Duration::from_micros(1)))
            .map_err(io_error)?;
        loop {
            match self.socket.read_frame_with_timestamp() {
                Ok((raw, timestamp)) => {
                    if let Some(frame) = from_socketcan(&raw) {
                        return Ok(Some(Received { frame, timestamp }));
                    }
                }
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                    return Ok(None);
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => return Err(io_error(e)),
            }
        }
    }

    fn overflows(&self) -> u64 {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_convert_both_ways() {
        let frames = [
            Frame::std(0x123, &[1, 2, 3]).unwrap(),
            Frame::data(Id::extended(0x1FFF_FFFF).unwrap(), &[0xFF; 8]).unwrap(),
            Frame::remote(Id::standard(0x705).unwrap(), 1).unwrap(),
            Frame::remote(Id::extended(0x100).unwrap(), 0).unwrap(),
        ];
        for f in frames {
            let raw = to_socketcan(&f).unwrap();
            assert_eq!(from_socketcan(&raw), Some(f));
        }
    }
}
