//! A small SDO test harness: a device with a test dictionary behind one SDO server, fed
//! request frames, with a minimal client for multi-frame transfers.
#![allow(dead_code, clippy::unwrap_used)]

use cantwin_can::{Duration, Frame, Id, Instant, Outbox};
use cantwin_canopen::od::{
    Access, DataType, ObjectDictionary, OdBuilder, OdDescription, SubObject, Value,
};
use cantwin_canopen::sdo::SdoServer;
use cantwin_canopen::sdo::crc::Crc16;
use cantwin_canopen::sdo::wire::{BlockSegment, Mux, Request, Response};
use cantwin_canopen::{AbortCode, ObjectAccess};
use std::sync::Arc;

pub const NODE: u8 = 5;
pub const RX: u16 = 0x605;
pub const TX: u16 = 0x585;

/// The dictionary all SDO tests use.
pub fn description() -> OdDescription {
    use DataType as T;
    OdBuilder::new()
        .var(
            0x1000,
            SubObject::new("Device type", T::Unsigned32, Access::Ro)
                .default(Value::Unsigned32(0x0002_0192)),
        )
        .var(
            0x1008,
            SubObject::new("Manufacturer device name", T::VisibleString, Access::Const)
                .default(Value::VisibleString("cantwin".into())),
        )
        .var(
            0x1017,
            SubObject::new("Producer heartbeat time", T::Unsigned16, Access::Rw),
        )
        .record(
            0x1018,
            "Identity object",
            [
                (
                    1,
                    SubObject::new("Vendor-ID", T::Unsigned32, Access::Ro)
                        .default(Value::Unsigned32(0x0000_0123)),
                ),
                (
                    2,
                    SubObject::new("Product code", T::Unsigned32, Access::Ro)
                        .default(Value::Unsigned32(0x0000_0456)),
                ),
            ],
        )
        .record(
            0x1200,
            "SDO server parameter",
            [
                (
                    1,
                    SubObject::new("COB-ID client->server", T::Unsigned32, Access::Ro)
                        .default_node_id_plus(Value::Unsigned32(0x600)),
                ),
                (
                    2,
                    SubObject::new("COB-ID server->client", T::Unsigned32, Access::Ro)
                        .default_node_id_plus(Value::Unsigned32(0x580)),
                ),
            ],
        )
        .var(
            0x2000,
            SubObject::new("Limited U8", T::Unsigned8, Access::Rw)
                .limits(Value::Unsigned8(10), Value::Unsigned8(100))
                .default(Value::Unsigned8(50)),
        )
        .var(
            0x2001,
            SubObject::new("Limited I16", T::Integer16, Access::Rw)
                .limits(Value::Integer16(-100), Value::Integer16(100)),
        )
        .var(
            0x2002,
            SubObject::new("Write-only U32", T::Unsigned32, Access::Wo),
        )
        .var(
            0x2003,
            SubObject::new("Big domain", T::Domain, Access::Rw).max_len(200_000),
        )
        .var(0x2004, SubObject::new("Flag", T::Boolean, Access::Rw))
        .var(0x2005, SubObject::new("U64", T::Unsigned64, Access::Rw))
        .var(
            0x2006,
            SubObject::new("Short string", T::VisibleString, Access::Rw).max_len(20),
        )
        .var(
            0x2007,
            SubObject::new("Unbounded domain", T::Domain, Access::Rw),
        )
        .var(
            0x2008,
            SubObject::new("Constant", T::Unsigned8, Access::Const).default(Value::Unsigned8(7)),
        )
        .var(
            0x2009,
            SubObject::new("Unicode", T::UnicodeString, Access::Rw).max_len(64),
        )
        .build()
        .unwrap()
}

/// The dictionary with one rw sub-object per basic data type at 0x4000 + type index.
pub fn every_type_description() -> OdDescription {
    let mut b = OdBuilder::new();
    for ty in DataType::ALL {
        b = b.var(
            0x4000 + ty.index(),
            SubObject::new(ty.name(), ty, Access::Rw),
        );
    }
    b.build().unwrap()
}

pub fn frame(id: u16, b: [u8; 8]) -> Frame {
    Frame::data_array(Id::standard(id).unwrap(), b)
}

pub struct Harness<A: ObjectAccess = ObjectDictionary> {
    pub server: SdoServer,
    pub access: A,
    pub now: Instant,
    pub out: Outbox,
}

impl Harness<ObjectDictionary> {
    pub fn new() -> Self {
        Harness::with(ObjectDictionary::new(Arc::new(description()), NODE))
    }
}

impl<A: ObjectAccess> Harness<A> {
    pub fn with(access: A) -> Self {
        Harness {
            server: SdoServer::for_node(NODE),
            access,
            now: Instant::ZERO,
            out: Outbox::new(),
        }
    }

    /// Sends one request frame at the current time; returns the response frames' bytes,
    /// checking every response goes out on 0x580 + node-ID with 8 bytes.
    pub fn req(&mut self, b: [u8; 8]) -> Vec<[u8; 8]> {
        let handled =
            self.server
                .on_frame(&frame(RX, b), self.now, &mut self.access, &mut self.out);
        assert!(handled);
        self.drain()
    }

    pub fn drain(&mut self) -> Vec<[u8; 8]> {
        self.out
            .drain()
            .map(|f| {
                assert_eq!(f.id(), Id::standard(TX).unwrap());
                <[u8; 8]>::try_from(f.data_bytes()).unwrap()
            })
            .collect()
    }

    pub fn advance(&mut self, d: Duration) {
        self.now += d;
    }

    pub fn tick(&mut self) -> Vec<[u8; 8]> {
        self.server
            .on_tick(self.now, &mut self.access, &mut self.out);
        self.drain()
    }

    /// One request, exactly one response.
    pub fn one(&mut self, b: [u8; 8]) -> [u8; 8] {
        let r = self.req(b);
        assert_eq!(
            r.len(),
            1,
            "expected one response to {b:02X?}, got {r:02X?}"
        );
        r[0]
    }

    /// Expedited or segmented download, as a client chooses by size.
    pub fn download(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode> {
        let mux = Mux::new(index, sub);
        if (1..=4).contains(&data.len()) {
            let mut d = [0u8; 4];
            d[..data.len()].copy_from_slice(data);
            let init = cantwin_canopen::sdo::wire::Initiate::Expedited {
                data: d,
                len: Some(data.len() as u8),
            };
            return check(
                self.one(Request::InitiateDownload { mux, init }.encode()),
                Response::InitiateDownload { mux },
            );
        }
        let init = cantwin_canopen::sdo::wire::Initiate::Segmented {
            size: Some(data.len() as u32),
        };
        check(
            self.one(Request::InitiateDownload { mux, init }.encode()),
            Response::InitiateDownload { mux },
        )?;
        let mut toggle = false;
        let chunks: Vec<&[u8]> = if data.is_empty() {
            vec![&[][..]]
        } else {
            data.chunks(7).collect()
        };
        for (i, c) in chunks.iter().enumerate() {
            let mut d = [0u8; 7];
            d[..c.len()].copy_from_slice(c);
            let last = i + 1 == chunks.len();
            let r = self.one(
                Request::DownloadSegment {
                    toggle,
                    last,
                    len: c.len() as u8,
                    data: d,
                }
                .encode(),
            );
            check(r, Response::DownloadSegment { toggle })?;
            toggle = !toggle;
        }
        Ok(())
    }

    /// Expedited or segmented upload.
    pub fn upload(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, AbortCode> {
        let mux = Mux::new(index, sub);
        let r = Response::decode(&self.one(Request::InitiateUpload { mux }.encode())).unwrap();
        match r {
            Response::Abort { code, .. } => Err(code),
            Response::InitiateUpload {
                init: cantwin_canopen::sdo::wire::Initiate::Expedited { data, len },
                ..
            } => Ok(data[..usize::from(len.unwrap())].to_vec()),
            Response::InitiateUpload {
                init: cantwin_canopen::sdo::wire::Initiate::Segmented { size },
                ..
            } => {
                let mut v = Vec::new();
                let mut toggle = false;
                loop {
                    match Response::decode(&self.one(Request::UploadSegment { toggle }.encode()))
                        .unwrap()
                    {
                        Response::UploadSegment {
                            toggle: t,
                            last,
                            len,
                            data,
                        } => {
                            assert_eq!(t, toggle);
                            v.extend_from_slice(&data[..usize::from(len)]);
                            if last {
                                break;
                            }
                        }
                        Response::Abort { code, .. } => return Err(code),
                        other => panic!("unexpected {other:?}"),
                    }
                    toggle = !toggle;
                }
                assert_eq!(Some(v.len() as u32), size);
                Ok(v)
            }
            other => panic!("unexpected {other:?}"),
        }
    }

    /// A block download as a well-behaved client does it; returns every response frame.
    pub fn block_download(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
        crc: bool,
    ) -> Result<Vec<[u8; 8]>, AbortCode> {
        let mux = Mux::new(index, sub);
        let mut all = Vec::new();
        let r = self.one(
            Request::BlockDownloadInitiate {
                mux,
                crc,
                size: Some(data.len() as u32),
            }
            .encode(),
        );
        all.push(r);
        let mut blksize = match Response::decode(&r).unwrap() {
            Response::BlockDownloadInitiate { blksize, .. } => blksize,
            Response::Abort { code, .. } => return Err(code),
            other => panic!("unexpected {other:?}"),
        };
        let segs: Vec<&[u8]> = if data.is_empty() {
            vec![&[][..]]
        } else {
            data.chunks(7).collect()
        };
        let mut next = 0;
        while next < segs.len() {
            let mut acked = None;
            for seqno in 1..=blksize {
                let i = next + usize::from(seqno) - 1;
                if i >= segs.len() {
                    break;
                }
                let mut d = [0u8; 7];
                d[..segs[i].len()].copy_from_slice(segs[i]);
                let r = self.req(
                    BlockSegment {
                        last: i + 1 == segs.len(),
                        seqno,
                        data: d,
                    }
                    .encode(),
                );
                if let Some(r) = r.first() {
                    all.push(*r);
                    acked = Some(*r);
                }
            }
            match Response::decode(&acked.expect("an acknowledgement at the end of the block"))
                .unwrap()
            {
                Response::BlockDownloadAck { ackseq, blksize: b } => {
                    next += usize::from(ackseq);
                    blksize = b;
                }
                Response::Abort { code, .. } => return Err(code),
                other => panic!("unexpected {other:?}"),
            }
        }
        let unused = if data.is_empty() {
            7
        } else {
            (7 - data.len() % 7) % 7
        } as u8;
        let r = self.one(
            Request::BlockDownloadEnd {
                unused,
                crc: if crc { Crc16::of(data) } else { 0 },
            }
            .encode(),
        );
        all.push(r);
        match Response::decode(&r).unwrap() {
            Response::BlockDownloadEnd => Ok(all),
            Response::Abort { code, .. } => Err(code),
            other => panic!("unexpected {other:?}"),
        }
    }

    /// A block upload as a well-behaved client does it; returns the data and every frame
    /// the server sent.
    pub fn block_upload(
        &mut self,
        index: u16,
        sub: u8,
        blksize: u8,
        crc: bool,
    ) -> Result<(Vec<u8>, Vec<[u8; 8]>), AbortCode> {
        let mux = Mux::new(index, sub);
        let mut all = Vec::new();
        let r = self.one(
            Request::BlockUploadInitiate {
                mux,
                crc,
                blksize,
                pst: 0,
            }
            .encode(),
        );
        all.push(r);
        let size = match Response::decode(&r).unwrap() {
            Response::BlockUploadInitiate { size, .. } => size.unwrap(),
            Response::Abort { code, .. } => return Err(code),
            other => panic!("unexpected {other:?}"),
        };
        let mut data = Vec::new();
        let mut frames = self.req(Request::BlockUploadStart.encode());
        loop {
            all.extend_from_slice(&frames);
            let mut last = false;
            let mut ackseq = 0;
            for f in &frames {
                let s = BlockSegment::decode(f);
                assert_eq!(s.seqno, ackseq + 1);
                ackseq = s.seqno;
                data.extend_from_slice(&s.data);
                last = s.last;
            }
            frames = self.req(Request::BlockUploadAck { ackseq, blksize }.encode());
            if last {
                break;
            }
        }
        assert_eq!(frames.len(), 1);
        all.push(frames[0]);
        match Response::decode(&frames[0]).unwrap() {
            Response::BlockUploadEnd { unused, crc: c } => {
                data.truncate(data.len() - usize::from(unused));
                assert_eq!(data.len() as u32, size);
                if crc {
                    assert_eq!(c, Crc16::of(&data));
                }
            }
            other => panic!("unexpected {other:?}"),
        }
        assert!(self.req(Request::BlockUploadEnd.encode()).is_empty());
        assert!(self.server.is_idle());
        Ok((data, all))
    }
}

fn check(got: [u8; 8], want: Response) -> Result<(), AbortCode> {
    match Response::decode(&got).unwrap() {
        Response::Abort { code, .. } => Err(code),
        r => {
            assert_eq!(r, want);
            Ok(())
        }
    }
}

/// The abort frame the server sends.
pub fn abort(index: u16, sub: u8, code: AbortCode) -> [u8; 8] {
    Response::Abort {
        mux: Mux::new(index, sub),
        code,
    }
    .encode()
}

/// Deterministic test data.
pub fn pattern(n: usize) -> Vec<u8> {
    (0..n).map(|i| (i * 7 + i / 251) as u8).collect()
}
