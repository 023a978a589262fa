//! DS 202-1 confirmed services: whatever the sequence of requests, every request a client
//! sends is confirmed exactly once, in order, with the server's answer, and no request
//! times out on a bus that loses nothing.
#![allow(clippy::unwrap_used)]

use cantwin_cal::{
    Application, ClientEvent, ClientObject, CmsClient, CmsServer, CobPair, Mux, ObjectIndex,
    ObjectKind, Payload, Request, ServerObject,
};
use cantwin_can::{Instant, Outbox};
use proptest::prelude::*;

/// Echoes writes; reads answer the multiplexor; multiplexors above 9 fail.
struct Echo;
impl Application for Echo {
    fn read_basic(&mut self, _: ObjectIndex, _: Instant) -> Result<Payload, Payload> {
        Ok(Payload::new(&[7]).unwrap())
    }
    fn write_basic(&mut self, _: ObjectIndex, d: &[u8], _: Instant) -> Result<Payload, Payload> {
        Ok(Payload::new(d).unwrap())
    }
    fn read_mux(&mut self, _: ObjectIndex, m: Mux, _: Instant) -> Result<Payload, Payload> {
        if m.raw() > 9 {
            Err(Payload::u16(1))
        } else {
            Ok(Payload::u16(u16::from(m.raw())))
        }
    }
    fn write_mux(
        &mut self,
        _: ObjectIndex,
        m: Mux,
        d: &[u8],
        _: Instant,
    ) -> Result<Payload, Payload> {
        if m.raw() > 9 {
            Err(Payload::u16(1))
        } else {
            Ok(Payload::new(d).unwrap())
        }
    }
}

fn request() -> impl Strategy<Value = (usize, Request)> {
    let data = prop::collection::vec(any::<u8>(), 0..=7).prop_map(|d| Payload::new(&d).unwrap());
    let m = (0u8..0x80).prop_map(|m| Mux::new(m).unwrap());
    prop_oneof![
        Just((0, Request::ReadBasic)),
        Just((0, Request::ReadBasicRemote)),
        data.clone().prop_map(|d| (0, Request::WriteBasic(d))),
        any::<bool>().prop_map(|e| (1, Request::ControlEvent(e))),
        m.clone().prop_map(|m| (2, Request::ReadMux(m))),
        (m, data).prop_map(|(m, d)| (2, Request::WriteMux(m, d))),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]
    #[test]
    fn every_request_is_confirmed_once_in_order(reqs in prop::collection::vec(request(), 1..30)) {
        let objs = [
            (ObjectKind::BasicVariable, CobPair::new(440, 439).unwrap()),
            (ObjectKind::ControlledEvent, CobPair::new(430, 429).unwrap()),
            (ObjectKind::MultiplexedVariable, CobPair::new(1100, 1099).unwrap()),
        ];
        let mut server = CmsServer::new(objs.iter().map(|&(kind, cobs)| ServerObject { kind, cobs }).collect()).unwrap();
        let mut client = CmsClient::new(objs.iter().map(|&(k, c)| ClientObject::new(k, c)).collect());
        let mut app = Echo;
        let (mut up, mut down) = (Outbox::new(), Outbox::new());
        let t = Instant::ZERO;
        for (obj, req) in reqs {
            client.request(ObjectIndex(obj), req, t, &mut up).unwrap();
            prop_assert_eq!(up.len(), 1);
            for f in up.drain() {
                prop_assert!(server.handle(&f, &mut app, t, &mut down));
            }
            prop_assert_eq!(down.len(), 1);
            for f in down.drain() {
                prop_assert!(client.handle(&f, t));
            }
            let mut ev: Vec<ClientEvent> = std::iter::from_fn(|| client.poll_event()).collect();
            if let Request::ControlEvent(e) = req {
                let state = matches!(ev.remove(0), ClientEvent::EventState { enabled, .. } if enabled == e);
                prop_assert!(state);
                prop_assert_eq!(server.event_enabled(ObjectIndex(1)), e);
            }
            prop_assert_eq!(ev.len(), 1);
            match (req, ev[0]) {
                (Request::WriteBasic(d), ClientEvent::Confirmed { data, request, .. }) => {
                    prop_assert_eq!(data, d);
                    prop_assert_eq!(request, req);
                }
                (Request::ReadMux(m) | Request::WriteMux(m, _), ClientEvent::Failed { error, .. }) => {
                    prop_assert!(m.raw() > 9);
                    prop_assert_eq!(error.as_u16(), Some(1));
                }
                (_, ClientEvent::Confirmed { request, .. }) => prop_assert_eq!(request, req),
                (_, other) => prop_assert!(false, "unexpected {:?}", other),
            }
            prop_assert!(!client.is_pending(ObjectIndex(obj)));
        }
        client.poll_timeouts(Instant::from_nanos(u64::MAX / 2));
        prop_assert_eq!(client.poll_event(), None);
    }
}
