//! DS 202-2 CMS services between a client and a server on the virtual bus: exact frames
//! and times.
#![allow(clippy::unwrap_used)]

use cantwin_bus::{BusConfig, PortConfig, PortId, Recorder, Simulation, TapId};
use cantwin_cal::{
    Application, ClientEvent, ClientObject, CmsClient, CmsServer, CobPair, Mux, ObjectIndex,
    ObjectKind, Payload, Request, ServerObject,
};
use cantwin_can::{BitRate, Duration, Frame, Id, Instant, Node, Outbox};

const BASIC: ObjectIndex = ObjectIndex(0);
const EVENT: ObjectIndex = ObjectIndex(1);
const MUX: ObjectIndex = ObjectIndex(2);

#[derive(Default)]
struct Values {
    basic: [u8; 3],
    table: [u16; 4],
}

impl Application for Values {
    fn read_basic(&mut self, _: ObjectIndex, _: Instant) -> Result<Payload, Payload> {
        Ok(Payload::new(&self.basic).unwrap())
    }
    fn write_basic(&mut self, _: ObjectIndex, d: &[u8], _: Instant) -> Result<Payload, Payload> {
        let v: [u8; 3] = d.try_into().map_err(|_| Payload::u16(0))?;
        self.basic = v;
        Ok(Payload::new(&v).unwrap())
    }
    fn read_mux(&mut self, _: ObjectIndex, mux: Mux, _: Instant) -> Result<Payload, Payload> {
        self.table
            .get(usize::from(mux.raw()))
            .map(|v| Payload::u16(*v))
            .ok_or(Payload::u16(1))
    }
    fn write_mux(
        &mut self,
        _: ObjectIndex,
        mux: Mux,
        d: &[u8],
        _: Instant,
    ) -> Result<Payload, Payload> {
        let slot = self
            .table
            .get_mut(usize::from(mux.raw()))
            .ok_or(Payload::u16(1))?;
        let v: [u8; 2] = d.try_into().map_err(|_| Payload::u16(2))?;
        *slot = u16::from_le_bytes(v);
        Ok(Payload::u16(*slot))
    }
    fn malformed(&mut self, _: ObjectIndex) -> Payload {
        Payload::u16(0)
    }
}

struct Server {
    cms: CmsServer,
    app: Values,
}

impl Server {
    fn raise(&mut self, data: &[u8], out: &mut Outbox) -> bool {
        self.cms.notify(EVENT, data, out)
    }
}

impl Node for Server {
    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.cms.handle(frame, &mut self.app, now, out);
    }
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
    fn accepts(&self, id: Id) -> bool {
        self.cms.accepts(id)
    }
}

fn objects() -> Vec<(ObjectKind, CobPair)> {
    vec![
        (ObjectKind::BasicVariable, CobPair::new(440, 439).unwrap()),
        (ObjectKind::ControlledEvent, CobPair::new(430, 429).unwrap()),
        (
            ObjectKind::MultiplexedVariable,
            CobPair::new(1100, 1099).unwrap(),
        ),
    ]
}

struct Rig {
    sim: Simulation,
    bus: cantwin_bus::BusId,
    client: PortId,
    server: PortId,
    tap: TapId,
}

fn rig() -> Rig {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("cal", BitRate::R500K));
    let server = Server {
        cms: CmsServer::new(
            objects()
                .into_iter()
                .map(|(kind, cobs)| ServerObject { kind, cobs })
                .collect(),
        )
        .unwrap(),
        app: Values::default(),
    };
    let mut objs: Vec<ClientObject> = objects()
        .into_iter()
        .map(|(k, c)| ClientObject::new(k, c))
        .collect();
    objs[0].remote_dlc = 4;
    let client = CmsClient::new(objs);
    let server = sim.attach(bus, server, PortConfig::default()).unwrap();
    let client = sim.attach(bus, client, PortConfig::default()).unwrap();
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    Rig {
        sim,
        bus,
        client,
        server,
        tap,
    }
}

impl Rig {
    fn request(&mut self, object: ObjectIndex, r: Request) {
        self.sim
            .bus_mut(self.bus)
            .unwrap()
            .with_node::<CmsClient, _>(self.client, |c, now, out| c.request(object, r, now, out))
            .unwrap()
            .unwrap();
    }
    fn trace(&self) -> Vec<(String, u64)> {
        self.sim
            .bus(self.bus)
            .unwrap()
            .tap::<Recorder>(self.tap)
            .unwrap()
            .frames()
            .map(|f| (f.frame.to_string(), f.end.as_nanos()))
            .collect()
    }
    fn events(&mut self) -> Vec<ClientEvent> {
        let c = self.sim.node_mut::<CmsClient>(self.client).unwrap();
        std::iter::from_fn(|| c.poll_event()).collect()
    }
}

fn end_of(frames: &[Frame]) -> Vec<u64> {
    // Back to back at 500 kbit/s (2 µs a bit), starting at 0, delivered at the end of EOF.
    let mut t = 0;
    frames
        .iter()
        .map(|f| {
            let end = t + u64::from(f.bit_length() - 3) * 2_000;
            t += u64::from(f.bit_length()) * 2_000;
            end
        })
        .collect()
}

#[test]
fn read_write_basic_variable_is_confirmed_on_the_response_cob() {
    let mut r = rig();
    r.request(
        BASIC,
        Request::WriteBasic(Payload::new(&[0xAA, 0x88, 0x13]).unwrap()),
    );
    r.sim.run_for(Duration::from_millis(1));
    let frames = [
        Frame::std(440, &[0x00, 0xAA, 0x88, 0x13]).unwrap(),
        Frame::std(439, &[0x00, 0xAA, 0x88, 0x13]).unwrap(),
    ];
    let ends = end_of(&frames);
    assert_eq!(
        r.trace(),
        vec![
            ("1B8#00AA8813".to_string(), ends[0]),
            ("1B7#00AA8813".to_string(), ends[1])
        ]
    );
    assert_eq!(
        r.events(),
        [ClientEvent::Confirmed {
            object: BASIC,
            request: Request::WriteBasic(Payload::new(&[0xAA, 0x88, 0x13]).unwrap()),
            data: Payload::new(&[0xAA, 0x88, 0x13]).unwrap(),
            at: Instant::from_nanos(ends[1]),
        }]
    );
}

#[test]
fn read_basic_variable_by_data_frame_and_by_remote_frame() {
    let mut r = rig();
    r.sim.node_mut::<Server>(r.server).unwrap().app.basic = [1, 2, 3];
    r.request(BASIC, Request::ReadBasic);
    r.sim.run_for(Duration::from_millis(1));
    r.request(BASIC, Request::ReadBasicRemote);
    r.sim.run_for(Duration::from_millis(1));
    let t: Vec<String> = r.trace().into_iter().map(|(f, _)| f).collect();
    assert_eq!(t, ["1B8#80", "1B7#00010203", "1B7#R4", "1B7#00010203"]);
    let ev = r.events();
    assert_eq!(ev.len(), 2);
    for e in ev {
        assert!(
            matches!(e, ClientEvent::Confirmed { data, .. } if data.as_slice() == [1, 2, 3]),
            "{e:?}"
        );
    }
}

#[test]
fn error_response_sets_r_and_carries_error_data() {
    let mut r = rig();
    r.request(BASIC, Request::WriteBasic(Payload::new(&[1]).unwrap()));
    r.request(MUX, Request::ReadMux(Mux::new(0x34).unwrap()));
    r.sim.run_for(Duration::from_millis(2));
    let t: Vec<String> = r.trace().into_iter().map(|(f, _)| f).collect();
    assert_eq!(t, ["1B8#0001", "1B7#800000", "44C#B4", "44B#B40100"]);
    let ev = r.events();
    assert!(
        matches!(ev[0], ClientEvent::Failed { object: BASIC, error, .. } if error.as_u16() == Some(0))
    );
    assert!(
        matches!(ev[1], ClientEvent::Failed { object: MUX, error, .. } if error.as_u16() == Some(1))
    );
}

#[test]
fn multiplexed_variable_write_then_read() {
    let mut r = rig();
    let m = Mux::new(3).unwrap();
    r.request(MUX, Request::WriteMux(m, Payload::u16(0x1388)));
    r.sim.run_for(Duration::from_millis(1));
    r.request(MUX, Request::ReadMux(m));
    r.sim.run_for(Duration::from_millis(1));
    let t: Vec<String> = r.trace().into_iter().map(|(f, _)| f).collect();
    assert_eq!(t, ["44C#038813", "44B#038813", "44C#83", "44B#038813"]);
    assert_eq!(r.sim.node::<Server>(r.server).unwrap().app.table[3], 5000);
}

#[test]
fn controlled_event_is_silent_until_enabled_and_after_disabled() {
    let mut r = rig();
    let bus = r.bus;
    let server = r.server;
    let raise = |r: &mut Rig, data: [u8; 2]| {
        r.sim
            .bus_mut(bus)
            .unwrap()
            .with_node::<Server, _>(server, |s, _, out| s.raise(&data, out))
            .unwrap()
    };
    assert!(!raise(&mut r, [0, 0x80]));
    r.sim.run_for(Duration::from_millis(1));
    assert!(r.trace().is_empty());
    r.request(EVENT, Request::ControlEvent(true));
    r.sim.run_for(Duration::from_millis(1));
    assert!(raise(&mut r, [0, 0x80]));
    r.sim.run_for(Duration::from_millis(1));
    r.request(EVENT, Request::ControlEvent(false));
    r.sim.run_for(Duration::from_millis(1));
    assert!(!raise(&mut r, [0, 0x00]));
    r.sim.run_for(Duration::from_millis(1));
    let t: Vec<String> = r.trace().into_iter().map(|(f, _)| f).collect();
    assert_eq!(t, ["1AE#30", "1AD#30", "1AD#100080", "1AE#20", "1AD#20"]);
    let ev = r.events();
    assert!(matches!(
        ev[0],
        ClientEvent::EventState { enabled: true, .. }
    ));
    assert!(
        matches!(ev[2], ClientEvent::Notified { object: EVENT, data, .. } if data.as_slice() == [0, 0x80])
    );
    assert!(matches!(
        ev[3],
        ClientEvent::EventState { enabled: false, .. }
    ));
}

#[test]
fn malformed_event_control_is_answered_with_the_unchanged_state_and_r() {
    let mut r = rig();
    let client = r.client;
    r.sim
        .transmit(client, Frame::std(430, &[0x31]).unwrap())
        .unwrap();
    r.sim.run_for(Duration::from_millis(1));
    let t: Vec<String> = r.trace().into_iter().map(|(f, _)| f).collect();
    assert_eq!(t, ["1AE#31", "1AD#280000"]);
}

#[test]
fn a_request_without_confirmation_times_out_exactly() {
    let mut r = rig();
    let server = r.server;
    r.sim
        .bus_mut(r.bus)
        .unwrap()
        .set_powered(server, false)
        .unwrap();
    // Keep the request acknowledged by a third, silent node.
    struct Silent;
    impl Node for Silent {
        fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
        fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
        fn next_deadline(&self) -> Option<Instant> {
            None
        }
    }
    r.sim.attach(r.bus, Silent, PortConfig::default()).unwrap();
    r.request(MUX, Request::ReadMux(Mux::new(0).unwrap()));
    let busy = r
        .sim
        .bus_mut(r.bus)
        .unwrap()
        .with_node::<CmsClient, _>(r.client, |c, now, out| {
            c.read_mux(MUX, Mux::new(0).unwrap(), now, out)
        })
        .unwrap();
    assert_eq!(busy, Err(cantwin_cal::ClientError::Busy(2)));
    r.sim.run_for(Duration::from_secs(1));
    assert_eq!(
        r.events(),
        [ClientEvent::TimedOut {
            object: MUX,
            request: Request::ReadMux(Mux::new(0).unwrap()),
            at: Instant::from_nanos(500_000_000),
        }]
    );
}
