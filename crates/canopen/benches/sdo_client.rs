//! SDO client hot path: one expedited upload round trip (CiA 301 §7.2.4.3.6) on
//! [`SdoClient`] alone (request out, canned response in, event out), and the `sdo`
//! benchmark's workload on a simulated bus: [`SdoBenchClient`] reading 0x1000 from a
//! CiA 301 device again and again, beside a client that only encodes requests and decodes
//! responses, the floor the bench client is measured against.
#![allow(clippy::unwrap_used, missing_docs)]

use cantwin_bus::{BusConfig, PortConfig, Simulation, TxOrder};
use cantwin_can::{BitRate, Duration, Frame, Id, Instant, Node, Outbox};
use cantwin_canopen::bench::{Filtering, NetworkDevice, SdoBenchClient, SdoWork};
use cantwin_canopen::device::{Device, DeviceConfig};
use cantwin_canopen::master::{Mode, SdoClient, SdoEvent};
use cantwin_canopen::objects::{Cia301Options, cia301_defaults};
use cantwin_canopen::od::OdBuilder;
use cantwin_canopen::sdo::wire::{Initiate, Mux, Request, Response};
use criterion::{Criterion, black_box, criterion_group, criterion_main};
use std::sync::Arc;

const NODE: u8 = 5;

/// Bus time simulated per iteration on the bus: about 43 round trips at 1 Mbit/s.
const SLICE: Duration = Duration::from_millis(10);

/// A client that asks for 0x1000 sub 0 as soon as an answer arrives and only counts the
/// expedited answers: the work any client must do, with no transfer state.
struct RawClient {
    round_trips: u64,
}

impl RawClient {
    fn ask(out: &mut Outbox) {
        let r = Request::InitiateUpload {
            mux: Mux::new(0x1000, 0),
        };
        out.push(Frame::data_array(
            Id::standard(0x600 + u16::from(NODE)).unwrap(),
            r.encode(),
        ));
    }
}

impl Node for RawClient {
    fn on_power_up(&mut self, _: Instant, out: &mut Outbox) {
        Self::ask(out);
    }
    fn on_frame(&mut self, frame: &Frame, _: Instant, out: &mut Outbox) {
        let b = <[u8; 8]>::try_from(frame.data_bytes()).unwrap();
        if let Ok(Response::InitiateUpload {
            init: Initiate::Expedited { .. },
            ..
        }) = Response::decode(&b)
        {
            self.round_trips += 1;
        }
        Self::ask(out);
    }
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
    fn accepts(&self, id: Id) -> bool {
        id.as_raw() == 0x580 + u32::from(NODE)
    }
    fn acceptance_version(&self) -> Option<u64> {
        Some(0)
    }
}

/// A bus with a CiA 301 device (heartbeat every 100 ms) and `client`, as the `sdo`
/// benchmark builds it.
fn bus<C: Node + Send + 'static>(client: C) -> Simulation {
    let desc = Arc::new(
        cia301_defaults(OdBuilder::new(), &Cia301Options::default())
            .build()
            .unwrap(),
    );
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let port = PortConfig::default()
        .with_queue_depth(256)
        .with_order(TxOrder::Fifo);
    let device = Device::new(desc, DeviceConfig::new(NODE)).unwrap();
    sim.attach(
        bus,
        NetworkDevice::new(device, Filtering::Device, 100),
        port,
    )
    .unwrap();
    sim.attach(bus, client, port).unwrap();
    sim
}

fn bench(c: &mut Criterion) {
    let mut client = SdoClient::for_node(NODE).unwrap();
    let mut out = Outbox::new();
    let answer = Frame::std(0x585, &[0x43, 0x00, 0x10, 0x00, 0x91, 0x01, 0x00, 0x00]).unwrap();
    c.bench_function("sdo_client/expedited_upload_round_trip", |b| {
        b.iter(|| {
            out.clear();
            client
                .start_upload(0x1000, 0, Mode::Expedited, Instant::ZERO, &mut out)
                .unwrap();
            client.on_frame(black_box(&answer), Instant::ZERO, &mut out);
            match client.poll_event() {
                Some(SdoEvent::Completed { data, .. }) => {
                    black_box(&data);
                }
                e => panic!("{e:?}"),
            }
        })
    });

    let mut sim = bus(RawClient { round_trips: 0 });
    c.bench_function("bus/raw_client_10ms", |b| {
        b.iter(|| {
            let t = sim.now() + SLICE;
            sim.run_until(t);
        })
    });

    let work = SdoWork::UploadLoop {
        mux: Mux::new(0x1000, 0),
    };
    let mut sim = bus(SdoBenchClient::new(NODE, work).unwrap());
    c.bench_function("bus/sdo_bench_client_10ms", |b| {
        b.iter(|| {
            let t = sim.now() + SLICE;
            sim.run_until(t);
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
