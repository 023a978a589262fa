//! The device under test behind an slcan (Lawicel) adapter on TCP: cantwin's own slcan
//! gateway, or a serial adapter behind a TCP-to-serial bridge (`--slcan HOST:PORT`).
//!
//! The adapter answers each frame it is given with `z`/`Z`, or with BEL when it cannot
//! queue it. A refused frame is a stimulus the device never saw, and every verdict after it
//! would be about something else: the transport reports it as an error, which ends the run.

use std::net::{SocketAddr, ToSocketAddrs};
use std::sync::Arc;
use std::time::Duration as WallDuration;

use cantwin_can::{BitRate, Frame, Instant};
use cantwin_gateway::slcan::{Client, ClientError};
use cantwin_gateway::{BusPort, PortError, Received};

use crate::{PortTransport, Transport, TransportError};

/// The client, shared between the port the transport drives and the transport's own look
/// at the adapter's answers.
struct Shared(Arc<Client>);

impl BusPort for Shared {
    fn send(&self, frame: Frame) -> Result<(), PortError> {
        self.0.send(frame)
    }
    fn recv_timeout(&self, timeout: WallDuration) -> Result<Option<Received>, PortError> {
        self.0.recv_timeout(timeout)
    }
    fn overflows(&self) -> u64 {
        self.0.overflows()
    }
}

/// Why the slcan transport could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum SlcanError {
    /// The address is not `HOST:PORT`, or the host does not resolve.
    #[error("slcan address {spec:?}: {why}")]
    Address {
        /// The address as given.
        spec: String,
        /// What is wrong with it.
        why: String,
    },
    /// The adapter could not be reached or opened.
    #[error("slcan adapter at {addr}: {source}")]
    Connect {
        /// The address connected to.
        addr: SocketAddr,
        /// What failed.
        source: ClientError,
    },
}

/// Open the adapter at `spec` (`HOST:PORT`, as a command line gives it): the first address
/// the host resolves to, then [`SlcanTransport::connect`].
pub fn open(
    spec: &str,
    bit_rate: Option<BitRate>,
    timeout: WallDuration,
) -> Result<SlcanTransport, SlcanError> {
    let address = |why: String| SlcanError::Address {
        spec: spec.to_owned(),
        why,
    };
    let addr = spec
        .to_socket_addrs()
        .map_err(|e| address(format!("expected HOST:PORT ({e})")))?
        .next()
        .ok_or_else(|| address("resolves to no address".into()))?;
    SlcanTransport::connect(addr, bit_rate, timeout)
        .map_err(|source| SlcanError::Connect { addr, source })
}

/// An slcan adapter as the runner's [`Transport`], on the wall clock.
pub struct SlcanTransport {
    inner: PortTransport<Shared>,
    client: Arc<Client>,
}

impl SlcanTransport {
    /// Connect to the adapter at `addr` and open its channel, setting `bit_rate` first if
    /// given (a real adapter needs it; cantwin's gateway keeps its bus's rate); each step is
    /// answered within `timeout`.
    pub fn connect(
        addr: SocketAddr,
        bit_rate: Option<BitRate>,
        timeout: WallDuration,
    ) -> Result<SlcanTransport, ClientError> {
        let client = Arc::new(Client::connect(addr, bit_rate, timeout)?);
        Ok(SlcanTransport {
            inner: PortTransport::new(Shared(Arc::clone(&client)), format!("slcan {addr}")),
            client,
        })
    }

    /// How many frames the adapter has acknowledged so far.
    pub fn acknowledged(&self) -> u64 {
        self.client.tx_acknowledged()
    }

    fn check_refused(&self) -> Result<(), TransportError> {
        match self.client.tx_refused() {
            0 => Ok(()),
            n => Err(TransportError::Send(format!(
                "the slcan adapter refused {n} frame(s) (BEL): its transmit buffer was full \
                 or it is open listen-only"
            ))),
        }
    }
}

impl Transport for SlcanTransport {
    fn send(&mut self, frame: Frame) -> Result<(), TransportError> {
        self.check_refused()?;
        self.inner.send(frame)
    }

    fn recv(&mut self, deadline: Instant) -> Result<Option<(Instant, Frame)>, TransportError> {
        let r = self.inner.recv(deadline);
        // The answers are read with the frames: a refusal shows after a receive.
        self.check_refused()?;
        r
    }

    fn now(&self) -> Instant {
        self.inner.now()
    }

    fn describe(&self) -> String {
        self.inner.describe()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_gateway::memory::MemoryBus;
    use cantwin_gateway::{BusConnector, Limits};

    const GUARD: WallDuration = WallDuration::from_secs(10);

    fn deadline(t: &SlcanTransport, ms: u64) -> Instant {
        t.now() + cantwin_can::Duration::from_millis(ms)
    }

    #[test]
    fn frames_both_ways_through_the_slcan_gateway() {
        let bus = MemoryBus::new(["can0"]);
        let server = cantwin_gateway::slcan::Server::bind(
            "127.0.0.1:0".parse().unwrap(),
            Arc::new(bus.clone()),
            "can0",
            Limits::default(),
        )
        .unwrap();
        let device = bus.open("can0", 16).unwrap();
        let mut t =
            SlcanTransport::connect(server.local_addr(), Some(BitRate::R500K), GUARD).unwrap();
        assert_eq!(t.describe(), format!("slcan {}", server.local_addr()));
        while bus.attached("can0") < 2 {
            std::thread::sleep(WallDuration::from_millis(1));
        }
        let request = Frame::std(0x605, &[0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]).unwrap();
        t.send(request).unwrap();
        assert_eq!(device.recv_timeout(GUARD).unwrap().unwrap().frame, request);
        let answer = Frame::std(0x585, &[0x43, 0x00, 0x10, 0x00, 0x91, 0x01, 0, 0]).unwrap();
        device.send(answer).unwrap();
        let before = t.now();
        let (at, frame) = t.recv(deadline(&t, 10_000)).unwrap().unwrap();
        assert_eq!(frame, answer);
        assert!(before <= at && at <= t.now());
        assert_eq!(t.recv(deadline(&t, 20)).unwrap(), None);
        assert_eq!(t.acknowledged(), 1);
    }

    #[test]
    fn addresses_are_host_and_port_and_a_closed_port_is_named() {
        for bad in ["127.0.0.1", "127.0.0.1:port", "127.0.0.1:99999", ":29537"] {
            assert!(
                matches!(open(bad, None, GUARD), Err(SlcanError::Address { .. })),
                "{bad:?}"
            );
        }
        // A port nobody listens on: taken and released again.
        let free = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap();
        match open(&free.to_string(), None, GUARD) {
            Err(e @ SlcanError::Connect { .. }) => {
                assert!(e.to_string().contains(&free.to_string()), "{e}")
            }
            other => panic!("{:?}", other.map(|_| ())),
        }
    }

    #[test]
    fn a_refused_frame_ends_the_run_with_an_error() {
        // An adapter that opens, then refuses the first frame it is given.
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = listener.local_addr().unwrap();
        let adapter = std::thread::spawn(move || {
            use std::io::{Read, Write};
            let (mut s, _) = listener.accept().unwrap();
            let mut buf = [0u8; 64];
            let mut seen = Vec::new();
            for reply in [&b"\r"[..], b"\r", b"\x07"] {
                let start = seen.len();
                while !seen[start..].contains(&b'\r') {
                    let n = s.read(&mut buf).unwrap();
                    seen.extend_from_slice(&buf[..n]);
                }
                s.write_all(reply).unwrap();
            }
            let _ = s.read_to_end(&mut seen);
        });
        let mut t = SlcanTransport::connect(addr, None, GUARD).unwrap();
        t.send(Frame::std(0x000, &[0x80, 0x05]).unwrap()).unwrap();
        match t.recv(deadline(&t, 200)) {
            Err(TransportError::Send(why)) => assert!(why.contains("refused 1 frame"), "{why}"),
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            t.send(Frame::std(0x000, &[0x01, 0x05]).unwrap()),
            Err(TransportError::Send(_))
        ));
        drop(t);
        adapter.join().unwrap();
    }

    /// The whole path: the SDO area of the runner against the CiA 301 twin of the shipped
    /// scenario, on the wall clock behind cantwin's slcan gateway (segmented and block
    /// transfers included, a block of 127 segments back to back through the adapter).
    #[test]
    fn the_sdo_area_passes_against_the_cia301_twin_through_slcan() {
        use cantwin_bus::{PacedConfig, PacedSimulation};
        use cantwin_gateway::paced::PacedBus;
        let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../scenarios/cia301-device.toml");
        let scenario = cantwin_scenario::Scenario::load(&file).unwrap();
        let built = scenario
            .build(
                &cantwin_scenario::Registry::builtin(),
                &cantwin_scenario::BuildEnv::default(),
            )
            .unwrap();
        let dev = built.device("node5").unwrap().clone();
        let desc = built
            .sim
            .twin(dev.port)
            .unwrap()
            .dictionary()
            .unwrap()
            .description()
            .clone();
        let eds = cantwin_eds::from_od(
            &desc,
            cantwin_eds::DeviceInfo::default(),
            cantwin_eds::FileInfo::new("node5.eds"),
        );
        let paced = PacedSimulation::start(built.sim, PacedConfig::default());
        let server = cantwin_gateway::slcan::Server::bind(
            "127.0.0.1:0".parse().unwrap(),
            Arc::new(PacedBus::new(paced.handle())),
            "can0",
            Limits::default(),
        )
        .unwrap();
        let mut t = SlcanTransport::connect(server.local_addr(), None, GUARD).unwrap();
        let options = crate::Options {
            only: vec![crate::Area::Sdo],
            // Waits the twin's whole SDO timeout: its own test runs in virtual time.
            skip: vec!["sdo.abort-timeout".into()],
            ..crate::Options::default()
        };
        let profile = crate::Profile::from_eds(&eds);
        let report = crate::run(&mut t, 5, &eds, &profile, &options, &mut |_| {});
        assert!(report.passed(), "{}", crate::output::summary(&report));
        assert!(
            report.case("sdo.block-upload").map(|c| c.verdict) == Some(crate::Verdict::Pass),
            "{}",
            crate::output::summary(&report)
        );
        drop(t);
        server.shutdown();
        paced.stop();
    }
}
