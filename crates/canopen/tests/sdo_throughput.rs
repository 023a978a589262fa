//! SDO throughput on the virtual bus at 1 Mbit/s, in simulated time: 100 000 bytes by block
//! download and by segmented download. The server answers within the `on_frame` call that
//! delivers the request, so the bus never idles: the elapsed bus time is exactly the sum of
//! the frames' lengths.
#![allow(clippy::unwrap_used)]

mod sdo_harness;

use cantwin_bus::{BusConfig, PortConfig, Recorder, Simulation, TxOrder};
use cantwin_can::{BitRate, Frame, Id, Instant, Node, Outbox};
use cantwin_canopen::od::{ObjectDictionary, Value};
use cantwin_canopen::sdo::SdoServer;
use cantwin_canopen::sdo::crc::Crc16;
use cantwin_canopen::sdo::wire::{BlockSegment, Initiate, Mux, Request, Response};
use sdo_harness::{NODE, RX, TX, description, pattern};
use std::sync::Arc;

const SIZE: usize = 100_000;
const MUX: Mux = Mux::new(0x2003, 0);

/// A device that is only an SDO server over a dictionary.
struct Server {
    sdo: SdoServer,
    od: ObjectDictionary,
}

impl Node for Server {
    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        self.sdo.on_frame(frame, now, &mut self.od, out);
    }
    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        self.sdo.on_tick(now, &mut self.od, out);
    }
    fn next_deadline(&self) -> Option<Instant> {
        self.sdo.next_deadline()
    }
}

fn req(b: [u8; 8]) -> Frame {
    Frame::data_array(Id::standard(RX).unwrap(), b)
}

/// A client downloading `data` by block transfer as fast as the protocol allows.
struct BlockClient {
    data: Vec<u8>,
    next: usize,
    blksize: u8,
}

impl BlockClient {
    fn segments(&self) -> usize {
        self.data.len().div_ceil(7).max(1)
    }

    fn send_block(&mut self, out: &mut Outbox) {
        let n = usize::from(self.blksize).min(self.segments() - self.next);
        for k in 0..n {
            let i = self.next + k;
            let chunk =
                &self.data[(i * 7).min(self.data.len())..((i + 1) * 7).min(self.data.len())];
            let mut d = [0u8; 7];
            d[..chunk.len()].copy_from_slice(chunk);
            let seg = BlockSegment {
                last: i + 1 == self.segments(),
                seqno: k as u8 + 1,
                data: d,
            };
            out.push(req(seg.encode()));
        }
    }
}

impl Node for BlockClient {
    fn on_power_up(&mut self, _: Instant, out: &mut Outbox) {
        let size = Some(self.data.len() as u32);
        out.push(req(Request::BlockDownloadInitiate {
            mux: MUX,
            crc: true,
            size,
        }
        .encode()));
    }
    fn on_frame(&mut self, frame: &Frame, _: Instant, out: &mut Outbox) {
        let Ok(b) = <[u8; 8]>::try_from(frame.data_bytes()) else {
            return;
        };
        match Response::decode(&b).unwrap() {
            Response::BlockDownloadInitiate { blksize, .. } => {
                self.blksize = blksize;
                self.send_block(out);
            }
            Response::BlockDownloadAck { ackseq, blksize } => {
                self.next += usize::from(ackseq);
                self.blksize = blksize;
                if self.next == self.segments() {
                    let unused = (self.segments() * 7 - self.data.len()) as u8;
                    let crc = Crc16::of(&self.data);
                    out.push(req(Request::BlockDownloadEnd { unused, crc }.encode()));
                } else {
                    self.send_block(out);
                }
            }
            Response::BlockDownloadEnd => {}
            other => panic!("unexpected {other:?}"),
        }
    }
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

/// A client downloading `data` by segmented transfer.
struct SegmentedClient {
    data: Vec<u8>,
    next: usize,
    toggle: bool,
}

impl SegmentedClient {
    fn send_segment(&mut self, out: &mut Outbox) {
        let chunk = &self.data[self.next..(self.next + 7).min(self.data.len())];
        let mut d = [0u8; 7];
        d[..chunk.len()].copy_from_slice(chunk);
        self.next += chunk.len();
        let last = self.next == self.data.len();
        let r = Request::DownloadSegment {
            toggle: self.toggle,
            last,
            len: chunk.len() as u8,
            data: d,
        };
        out.push(req(r.encode()));
    }
}

impl Node for SegmentedClient {
    fn on_power_up(&mut self, _: Instant, out: &mut Outbox) {
        let init = Initiate::Segmented {
            size: Some(self.data.len() as u32),
        };
        out.push(req(Request::InitiateDownload { mux: MUX, init }.encode()));
    }
    fn on_frame(&mut self, frame: &Frame, _: Instant, out: &mut Outbox) {
        let Ok(b) = <[u8; 8]>::try_from(frame.data_bytes()) else {
            return;
        };
        match Response::decode(&b).unwrap() {
            Response::InitiateDownload { .. } => self.send_segment(out),
            Response::DownloadSegment { toggle } => {
                assert_eq!(toggle, self.toggle);
                self.toggle = !self.toggle;
                if self.next < self.data.len() {
                    self.send_segment(out);
                }
            }
            other => panic!("unexpected {other:?}"),
        }
    }
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

/// A client uploading by block transfer, acknowledging every block as it completes.
struct BlockUploadClient {
    data: Vec<u8>,
    /// 0: waiting for the initiate response; 1: receiving segments; 2: waiting for the end.
    phase: u8,
    seq: u8,
}

impl Node for BlockUploadClient {
    fn on_power_up(&mut self, _: Instant, out: &mut Outbox) {
        let r = Request::BlockUploadInitiate {
            mux: MUX,
            crc: true,
            blksize: 127,
            pst: 0,
        };
        out.push(req(r.encode()));
    }
    fn on_frame(&mut self, frame: &Frame, _: Instant, out: &mut Outbox) {
        let Ok(b) = <[u8; 8]>::try_from(frame.data_bytes()) else {
            return;
        };
        match self.phase {
            0 => {
                assert!(matches!(
                    Response::decode(&b),
                    Ok(Response::BlockUploadInitiate { .. })
                ));
                self.phase = 1;
                out.push(req(Request::BlockUploadStart.encode()));
            }
            1 => {
                let seg = BlockSegment::decode(&b);
                assert_eq!(seg.seqno, self.seq + 1);
                self.seq = seg.seqno;
                self.data.extend_from_slice(&seg.data);
                if seg.last || seg.seqno == 127 {
                    let ack = Request::BlockUploadAck {
                        ackseq: seg.seqno,
                        blksize: 127,
                    };
                    out.push(req(ack.encode()));
                    self.seq = 0;
                    if seg.last {
                        self.phase = 2;
                    }
                }
            }
            _ => {
                let Ok(Response::BlockUploadEnd { unused, crc }) = Response::decode(&b) else {
                    panic!("unexpected {b:02X?}")
                };
                self.data.truncate(self.data.len() - usize::from(unused));
                assert_eq!(crc, Crc16::of(&self.data));
                out.push(req(Request::BlockUploadEnd.encode()));
            }
        }
    }
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

struct Run {
    /// (id, bits on the bus including intermission) of every frame, in order.
    frames: Vec<(u16, u32, [u8; 8])>,
    /// From the start of the first frame to the end of the last one's intermission.
    elapsed_ns: u64,
    stored: Value,
}

fn run<C: Node + Send + 'static>(client: C) -> Run {
    run_with(client, None)
}

fn run_with<C: Node + Send + 'static>(client: C, stored: Option<&[u8]>) -> Run {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let mut server = Server {
        sdo: SdoServer::for_node(NODE),
        od: ObjectDictionary::new(Arc::new(description()), NODE),
    };
    if let Some(data) = stored {
        server
            .od
            .set(0x2003, 0, &Value::Domain(data.to_vec()))
            .unwrap();
    }
    let port = PortConfig::default()
        .with_queue_depth(128)
        .with_order(TxOrder::Fifo);
    let server_port = sim.attach(bus, server, port).unwrap();
    sim.attach(bus, client, port).unwrap();
    let tap = sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    sim.run_until(Instant::from_nanos(10_000_000_000));
    let rec = sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
    let all: Vec<_> = rec.frames().cloned().collect();
    assert!(all.iter().all(|f| !f.dropped));
    let first = all.first().unwrap();
    let last = all.last().unwrap();
    let stored = sim
        .node::<Server>(server_port)
        .unwrap()
        .od
        .get(0x2003, 0)
        .unwrap();
    Run {
        frames: all
            .iter()
            .map(|f| {
                (
                    f.frame.id().as_raw() as u16,
                    f.bits,
                    <[u8; 8]>::try_from(f.frame.data_bytes()).unwrap(),
                )
            })
            .collect(),
        elapsed_ns: (last.idle_at - first.start).as_nanos(),
        stored,
    }
}

/// At 1 Mbit/s one bit is 1000 ns.
const BIT_NS: u64 = 1000;

#[test]
fn cia301_7_2_4_3_9_block_download_of_100000_bytes_reaches_95_percent_of_the_bus_limit() {
    let data = pattern(SIZE);
    let r = run(BlockClient {
        data: data.clone(),
        next: 0,
        blksize: 0,
    });
    assert_eq!(r.stored, Value::Domain(data));
    // The bus never idled: elapsed time is the sum of all frame lengths.
    let all_bits: u64 = r.frames.iter().map(|f| u64::from(f.1)).sum();
    assert_eq!(r.elapsed_ns, all_bits * BIT_NS);
    // The bus limit for 7-byte segments: nothing on the bus but the 14 286 data segments,
    // back to back.
    let n_segments = SIZE.div_ceil(7);
    // Frames on RX: initiate, the segments, the end request; on TX: initiate response, 113
    // acknowledgements, end response.
    let rx: Vec<_> = r.frames.iter().filter(|f| f.0 == RX).collect();
    let tx: Vec<_> = r.frames.iter().filter(|f| f.0 == TX).collect();
    assert_eq!(rx.len(), 1 + n_segments + 1);
    assert_eq!(tx.len(), 1 + n_segments.div_ceil(127) + 1);
    let limit_bits: u64 = rx[1..=n_segments].iter().map(|f| u64::from(f.1)).sum();
    let ratio = limit_bits as f64 / all_bits as f64;
    eprintln!(
        "block download: {all_bits} bit times, {:.2} % of the bus limit",
        ratio * 100.0
    );
    assert!(
        ratio >= 0.95,
        "block download at {:.2} % of the bus limit",
        ratio * 100.0
    );
}

#[test]
fn cia301_7_2_4_3_4_segmented_download_of_100000_bytes_reaches_95_percent_of_the_request_response_limit()
 {
    let data = pattern(SIZE);
    let r = run(SegmentedClient {
        data: data.clone(),
        next: 0,
        toggle: false,
    });
    assert_eq!(r.stored, Value::Domain(data));
    let all_bits: u64 = r.frames.iter().map(|f| u64::from(f.1)).sum();
    assert_eq!(r.elapsed_ns, all_bits * BIT_NS);
    // The request/response limit: each segment request followed at once by its response,
    // nothing else on the bus (the initiate exchange is the overhead).
    let n_segments = SIZE.div_ceil(7);
    assert_eq!(r.frames.len(), 2 + 2 * n_segments);
    let limit_bits: u64 = r.frames[2..].iter().map(|f| u64::from(f.1)).sum();
    let ratio = limit_bits as f64 / all_bits as f64;
    eprintln!(
        "segmented download: {all_bits} bit times, {:.2} % of the limit",
        ratio * 100.0
    );
    assert!(
        ratio >= 0.95,
        "segmented download at {:.2} % of the request/response limit",
        ratio * 100.0
    );
}

#[test]
fn cia301_7_2_4_3_12_block_upload_of_100000_bytes_reaches_95_percent_of_the_bus_limit() {
    let data = pattern(SIZE);
    let r = run_with(
        BlockUploadClient {
            data: Vec::new(),
            phase: 0,
            seq: 0,
        },
        Some(&data),
    );
    let all_bits: u64 = r.frames.iter().map(|f| u64::from(f.1)).sum();
    assert_eq!(r.elapsed_ns, all_bits * BIT_NS);
    let n_segments = SIZE.div_ceil(7);
    let tx: Vec<_> = r.frames.iter().filter(|f| f.0 == TX).collect();
    // Initiate response, the segments, the end request.
    assert_eq!(tx.len(), 1 + n_segments + 1);
    let limit_bits: u64 = tx[1..=n_segments].iter().map(|f| u64::from(f.1)).sum();
    let ratio = limit_bits as f64 / all_bits as f64;
    eprintln!(
        "block upload: {all_bits} bit times, {:.2} % of the bus limit",
        ratio * 100.0
    );
    assert!(
        ratio >= 0.95,
        "block upload at {:.2} % of the bus limit",
        ratio * 100.0
    );
    // The last frame is the client's end response.
    assert_eq!(r.frames.last().unwrap().2, [0xA1, 0, 0, 0, 0, 0, 0, 0]);
}
