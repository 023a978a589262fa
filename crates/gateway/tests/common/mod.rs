//! A raw TCP peer for byte-exact protocol tests.
#![allow(dead_code, clippy::unwrap_used)]

use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use cantwin_gateway::Limits;
use cantwin_gateway::memory::MemoryBus;
use cantwin_gateway::socketcand::Server;

/// Upper bound on any wait in these tests: reached only when a test fails.
pub const GUARD: Duration = Duration::from_secs(10);

/// A fixed wall-clock timestamp: 2023-11-14T22:13:20.000250Z.
pub fn ts() -> SystemTime {
    UNIX_EPOCH + Duration::new(1_700_000_000, 250_000)
}

/// A socketcand server on 127.0.0.1 (a free port) in front of `bus`.
pub fn socketcand_server(bus: &MemoryBus, limits: Limits) -> Server {
    Server::bind(
        "127.0.0.1:0".parse().unwrap(),
        Arc::new(bus.clone()),
        limits,
    )
    .unwrap()
}

pub struct Peer {
    pub s: TcpStream,
}

impl Peer {
    pub fn connect(addr: SocketAddr) -> Peer {
        let s = TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(GUARD)).unwrap();
        s.set_nodelay(true).unwrap();
        Peer { s }
    }

    pub fn write(&mut self, bytes: &[u8]) {
        self.s.write_all(bytes).unwrap();
    }

    /// One `read` call, as python-can's `recv(256)` does.
    pub fn read_once(&mut self) -> Vec<u8> {
        let mut buf = [0u8; 256];
        let n = self.s.read(&mut buf).unwrap();
        buf[..n].to_vec()
    }

    /// Exactly `expected.len()` bytes, compared with `expected`.
    pub fn expect(&mut self, expected: &[u8]) {
        let mut buf = vec![0u8; expected.len()];
        self.s.read_exact(&mut buf).unwrap();
        assert_eq!(
            String::from_utf8_lossy(&buf),
            String::from_utf8_lossy(expected)
        );
    }

    /// One `< … >` element, read byte by byte.
    pub fn read_element(&mut self) -> String {
        let mut out = Vec::new();
        let mut b = [0u8; 1];
        loop {
            self.s.read_exact(&mut b).unwrap();
            out.push(b[0]);
            if b[0] == b'>' {
                return String::from_utf8(out).unwrap();
            }
        }
    }

    /// Everything until the server closes the connection.
    pub fn read_to_close(&mut self) -> Vec<u8> {
        let mut out = Vec::new();
        let mut buf = [0u8; 4096];
        loop {
            match self.s.read(&mut buf) {
                Ok(0) => return out,
                Ok(n) => out.extend_from_slice(&buf[..n]),
                Err(e) if e.kind() == ErrorKind::ConnectionReset => return out,
                Err(e) => panic!("no close within the guard time: {e}"),
            }
        }
    }

    /// The socketcand handshake python-can performs, with its exact checks.
    pub fn socketcand_handshake(&mut self, channel: &str) {
        assert_eq!(self.read_once(), b"< hi >");
        self.write(format!("< open {channel} >").as_bytes());
        assert_eq!(self.read_once(), b"< ok >");
        self.write(b"< rawmode >");
        assert_eq!(self.read_once(), b"< ok >");
    }
}
