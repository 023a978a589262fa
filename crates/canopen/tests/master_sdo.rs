//! SDO client against the SDO server on the virtual bus (CiA 301 §7.2.4): every mode and
//! size, aborts, timeouts, fallback, concurrency and progress.
#![allow(clippy::unwrap_used)]

mod master_support;

use cantwin_can::Duration;
use cantwin_canopen::AbortCode;
use cantwin_canopen::master::{Master, MasterConfig, MasterEvent, Mode, Mux, SdoEvent, TransferId};
use cantwin_canopen::od::Value;
use master_support::*;

const SIZES: [usize; 7] = [0, 1, 4, 7, 8, 889, 100_000];
const BIG: Mux = Mux::new(0x2003, 0);

fn net(master: Master) -> Net {
    Net::new(master, vec![Device::new(5)])
}

/// Runs until transfer `id` ends; returns its terminal event and the progress events.
fn finish(n: &mut Net, id: TransferId) -> (SdoEvent, Vec<SdoEvent>) {
    let mut others = Vec::new();
    loop {
        let (_, e) = n.next_event(Duration::from_secs(60)).expect("an event");
        match e {
            MasterEvent::Sdo { id: i, event, .. } if i == id => match event {
                SdoEvent::Completed { .. } | SdoEvent::Aborted { .. } => return (event, others),
                e => others.push(e),
            },
            e => panic!("unexpected {e:?}"),
        }
    }
}

fn download(n: &mut Net, mux: Mux, data: Vec<u8>, mode: Mode) -> SdoEvent {
    let id = n
        .with_master(|m, now, out| m.download(5, mux, data, mode, now, out))
        .unwrap();
    finish(n, id).0
}

fn upload(n: &mut Net, mux: Mux, mode: Mode) -> SdoEvent {
    let id = n
        .with_master(|m, now, out| m.upload(5, mux, mode, now, out))
        .unwrap();
    finish(n, id).0
}

fn completed(data: Vec<u8>) -> SdoEvent {
    SdoEvent::Completed { mux: BIG, data }
}

fn round_trip(mode: Mode, sizes: &[usize]) {
    let mut n = net(Master::new());
    for &size in sizes {
        let data = pattern(size);
        assert_eq!(
            download(&mut n, BIG, data.clone(), mode),
            completed(vec![]),
            "download {size} {mode:?}"
        );
        assert_eq!(
            n.device(0).od.get(0x2003, 0),
            Ok(Value::Domain(data.clone())),
            "{size}"
        );
        assert_eq!(
            upload(&mut n, BIG, mode),
            completed(data),
            "upload {size} {mode:?}"
        );
        // The client's last frame (a block upload's end response) is still on its way.
        n.run_for(Duration::from_millis(1));
        assert!(n.device(0).server.is_idle());
    }
}

#[test]
fn cia301_7_2_4_3_3_expedited_transfer_frames() {
    let mut n = net(Master::new());
    let mux = Mux::new(0x1017, 0);
    assert_eq!(
        download(&mut n, mux, vec![0xE8, 0x03], Mode::Expedited),
        SdoEvent::Completed { mux, data: vec![] }
    );
    assert_eq!(
        upload(&mut n, mux, Mode::Auto),
        SdoEvent::Completed {
            mux,
            data: vec![0xE8, 0x03]
        }
    );
    assert_eq!(
        n.frame_strings(),
        [
            "605#2B171000E8030000",
            "585#6017100000000000",
            "605#4017100000000000",
            "585#4B171000E8030000"
        ]
    );
}

#[test]
fn cia301_7_2_4_3_3_expedited_round_trip_of_1_and_4_bytes() {
    round_trip(Mode::Expedited, &[1, 4]);
}

#[test]
fn cia301_7_2_4_3_4_segmented_round_trip_of_every_size() {
    round_trip(Mode::Segmented, &SIZES);
}

#[test]
fn cia301_7_2_4_3_4_auto_mode_round_trip_of_every_size() {
    round_trip(Mode::Auto, &SIZES);
}

#[test]
fn cia301_7_2_4_3_9_block_round_trip_of_every_size() {
    round_trip(Mode::Block { blksize: 127 }, &SIZES);
}

#[test]
fn cia301_7_2_4_3_9_block_round_trip_with_small_blocks() {
    round_trip(Mode::Block { blksize: 5 }, &[0, 8, 34, 35, 36, 889]);
}

#[test]
fn cia301_7_2_4_3_4_segmented_frames_of_8_bytes() {
    let mut n = net(Master::new());
    download(&mut n, BIG, pattern(8), Mode::Segmented);
    let d = pattern(8);
    assert_eq!(
        n.frame_strings(),
        [
            "605#2103200008000000".to_string(),
            "585#6003200000000000".into(),
            format!("605#00{}", hex(&d[..7])),
            "585#2000000000000000".into(),
            format!("605#1D{}000000000000", hex(&d[7..])),
            "585#3000000000000000".into(),
        ]
    );
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02X}")).collect()
}

#[test]
fn cia301_7_2_4_3_9_block_download_frames_of_8_bytes() {
    let mut n = net(Master::new());
    let d = pattern(8);
    download(&mut n, BIG, d.clone(), Mode::Block { blksize: 127 });
    let crc = cantwin_canopen::sdo::crc::Crc16::of(&d).to_le_bytes();
    assert_eq!(
        n.frame_strings(),
        [
            "605#C603200008000000".to_string(),
            "585#A40320007F000000".into(),
            format!("605#01{}", hex(&d[..7])),
            format!("605#82{}000000000000", hex(&d[7..])),
            "585#A2027F0000000000".into(),
            format!("605#D9{}0000000000", hex(&crc)),
            "585#A100000000000000".into(),
        ]
    );
}

#[test]
fn cia301_7_2_4_3_12_block_upload_frames_of_8_bytes() {
    let mut n = net(Master::new());
    let d = pattern(8);
    n.device(0)
        .od
        .set(0x2003, 0, &Value::Domain(d.clone()))
        .unwrap();
    assert_eq!(
        upload(&mut n, BIG, Mode::Block { blksize: 127 }),
        completed(d.clone())
    );
    n.run_for(Duration::from_millis(1));
    let crc = cantwin_canopen::sdo::crc::Crc16::of(&d).to_le_bytes();
    assert_eq!(
        n.frame_strings(),
        [
            "605#A40320007F000000".to_string(),
            "585#C603200008000000".into(),
            "605#A300000000000000".into(),
            format!("585#01{}", hex(&d[..7])),
            format!("585#82{}000000000000", hex(&d[7..])),
            "605#A2027F0000000000".into(),
            format!("585#D9{}0000000000", hex(&crc)),
            "605#A100000000000000".into(),
        ]
    );
}

#[test]
fn cia301_7_2_4_3_12_protocol_switch_threshold_falls_to_a_normal_upload() {
    let mut cfg = MasterConfig::default();
    cfg.sdo.pst = 21;
    let mut n = net(Master::with_config(cfg));
    let d = pattern(8);
    n.device(0)
        .od
        .set(0x2003, 0, &Value::Domain(d.clone()))
        .unwrap();
    assert_eq!(
        upload(&mut n, BIG, Mode::Block { blksize: 127 }),
        completed(d)
    );
    let f = n.frame_strings();
    // The server answers the block initiate with a segmented initiate upload response.
    assert_eq!(f[0], "605#A40320007F150000");
    assert_eq!(f[1], "585#4103200008000000");
    assert_eq!(f[2], "605#6000000000000000");
    assert_eq!(f.len(), 6);
    // And an expedited one for 4 bytes.
    let mux = Mux::new(0x1000, 0);
    assert_eq!(
        upload(&mut n, mux, Mode::Block { blksize: 127 }),
        SdoEvent::Completed {
            mux,
            data: DEVICE_TYPE.to_le_bytes().to_vec()
        }
    );
}

// ---- aborts ----

#[test]
fn cia301_7_2_4_3_17_server_abort_in_the_initiate_phase_of_every_mode() {
    let mut n = net(Master::new());
    let missing = Mux::new(0x3000, 0);
    let aborted = |code| SdoEvent::Aborted {
        mux: missing,
        code,
        by_server: true,
    };
    for mode in [Mode::Auto, Mode::Segmented, Mode::Block { blksize: 127 }] {
        assert_eq!(
            upload(&mut n, missing, mode),
            aborted(AbortCode::NO_OBJECT),
            "{mode:?}"
        );
        assert_eq!(
            download(&mut n, missing, pattern(20), mode),
            aborted(AbortCode::NO_OBJECT),
            "{mode:?}"
        );
    }
    assert_eq!(
        download(&mut n, missing, pattern(2), Mode::Expedited),
        aborted(AbortCode::NO_OBJECT)
    );
    let ro = Mux::new(0x1000, 0);
    assert_eq!(
        download(&mut n, ro, vec![1, 2, 3, 4], Mode::Expedited),
        SdoEvent::Aborted {
            mux: ro,
            code: AbortCode::READ_ONLY,
            by_server: true
        }
    );
}

#[test]
fn cia301_7_2_4_3_17_server_abort_at_the_end_of_a_block_download() {
    // 21 bytes do not fit a 20-byte string: the server checks the length when the data
    // is complete (or at the initiate, with the size indicated).
    let mut n = net(Master::new());
    let s = Mux::new(0x2006, 0);
    let r = download(&mut n, s, pattern(21), Mode::Block { blksize: 127 });
    assert!(
        matches!(
            r,
            SdoEvent::Aborted {
                by_server: true,
                ..
            }
        ),
        "{r:?}"
    );
    assert!(n.device(0).server.is_idle());
    let r = download(&mut n, s, pattern(21), Mode::Segmented);
    assert!(
        matches!(
            r,
            SdoEvent::Aborted {
                by_server: true,
                ..
            }
        ),
        "{r:?}"
    );
}

#[test]
fn cia301_7_2_4_3_17_client_abort_mid_transfer_reaches_the_server() {
    let mut n = net(Master::new());
    n.device(0)
        .od
        .set(0x2003, 0, &Value::Domain(pattern(889)))
        .unwrap();
    let id = n
        .with_master(|m, now, out| m.upload(5, BIG, Mode::Segmented, now, out))
        .unwrap();
    n.run_for(Duration::from_micros(1000));
    assert!(!n.device(0).server.is_idle());
    let found = n.with_master(|m, now, out| m.abort(id, AbortCode::DATA_TRANSFER, now, out));
    assert!(found);
    let (e, _) = finish(&mut n, id);
    assert_eq!(
        e,
        SdoEvent::Aborted {
            mux: BIG,
            code: AbortCode::DATA_TRANSFER,
            by_server: false
        }
    );
    n.run_for(Duration::from_millis(1));
    assert!(n.device(0).server.is_idle());
    assert!(
        n.frame_strings()
            .contains(&"605#8003200020000008".to_string())
    );
}

#[test]
fn cia301_7_2_4_3_17_silent_server_is_aborted_with_0x05040000_after_the_timeout() {
    let mut n = net(Master::new());
    n.device(0).silent = true;
    let id = n
        .with_master(|m, now, out| m.upload(5, BIG, Mode::Auto, now, out))
        .unwrap();
    let (e, _) = finish(&mut n, id);
    assert_eq!(
        e,
        SdoEvent::Aborted {
            mux: BIG,
            code: AbortCode::TIMEOUT,
            by_server: false
        }
    );
    n.run_for(Duration::from_millis(1));
    let f = n.frames();
    assert_eq!(f.len(), 2);
    assert_eq!(f[0].0, 0);
    // The abort goes out exactly 1 s (the default timeout) after the request was queued.
    assert_eq!(
        (f[1].0, f[1].2.as_str()),
        (1_000_000_000, "605#8003200000000405")
    );
}

#[test]
fn cia301_7_2_4_3_17_configurable_timeout_in_a_block_download() {
    let mut cfg = MasterConfig::default();
    cfg.sdo.timeout = Duration::from_millis(50);
    let mut n = net(Master::with_config(cfg));
    let id = n
        .with_master(|m, now, out| {
            m.download(5, BIG, pattern(889), Mode::Block { blksize: 127 }, now, out)
        })
        .unwrap();
    // Let the initiate through, then silence the server mid-block.
    n.run_for(Duration::from_micros(300));
    n.device(0).silent = true;
    let (e, _) = finish(&mut n, id);
    assert_eq!(
        e,
        SdoEvent::Aborted {
            mux: BIG,
            code: AbortCode::TIMEOUT,
            by_server: false
        }
    );
    n.run_for(Duration::from_millis(1));
    let f = n.frames();
    let last = f.last().unwrap();
    assert_eq!(last.2, "605#8003200000000405");
    // The deadline runs from the initiate response, which started the block.
    let resp = f.iter().find(|r| r.2.starts_with("585#A4")).unwrap();
    assert_eq!(last.0, resp.1 + 50_000_000);
}

// ---- fallback ----

#[test]
fn cia301_7_2_4_3_9_block_refused_with_0x05040001_falls_back_to_segmented() {
    let mut dev = Device::new(5);
    dev.refuse_block = true;
    let mut n = Net::new(Master::new(), vec![dev]);
    let data = pattern(100);
    let id = n
        .with_master(|m, now, out| {
            m.download(5, BIG, data.clone(), Mode::Block { blksize: 127 }, now, out)
        })
        .unwrap();
    let (e, others) = finish(&mut n, id);
    assert_eq!(e, completed(vec![]));
    assert_eq!(
        others,
        [SdoEvent::FellBack {
            code: AbortCode::INVALID_COMMAND
        }]
    );
    let f = n.frame_strings();
    assert_eq!(
        &f[..3],
        [
            "605#C603200064000000",
            "585#8003200001000405",
            "605#2103200064000000"
        ]
    );
    assert_eq!(
        n.device(0).od.get(0x2003, 0),
        Ok(Value::Domain(data.clone()))
    );

    let id = n
        .with_master(|m, now, out| m.upload(5, BIG, Mode::Block { blksize: 127 }, now, out))
        .unwrap();
    let (e, others) = finish(&mut n, id);
    assert_eq!(e, completed(data));
    assert_eq!(
        others,
        [SdoEvent::FellBack {
            code: AbortCode::INVALID_COMMAND
        }]
    );
}

#[test]
fn cia301_7_2_4_3_9_fallback_can_be_switched_off() {
    let mut dev = Device::new(5);
    dev.refuse_block = true;
    let mut cfg = MasterConfig::default();
    cfg.sdo.fallback = false;
    let mut n = Net::new(Master::with_config(cfg), vec![dev]);
    let r = download(&mut n, BIG, pattern(10), Mode::Block { blksize: 127 });
    assert_eq!(
        r,
        SdoEvent::Aborted {
            mux: BIG,
            code: AbortCode::INVALID_COMMAND,
            by_server: true
        }
    );
}

// ---- concurrency and progress ----

#[test]
fn cia301_7_2_4_sixteen_concurrent_transfers_to_sixteen_servers() {
    let devices = (1..=16).map(Device::new).collect();
    // A single FIFO transmit queue: with a priority queue the lowest node-ID's requests
    // would win every arbitration and the transfers would run one after the other on the
    // wire, though all of them are open at once in the master.
    let fifo = cantwin_bus::PortConfig::default().with_order(cantwin_bus::TxOrder::Fifo);
    let mut n = Net::with_master_port(Master::new(), devices, fifo);
    let mut ids = Vec::new();
    for node in 1..=16u8 {
        let data = pattern(889 + usize::from(node));
        let mode = if node % 2 == 0 {
            Mode::Block { blksize: 127 }
        } else {
            Mode::Segmented
        };
        ids.push(
            n.with_master(|m, now, out| m.download(node, BIG, data, mode, now, out))
                .unwrap(),
        );
    }
    let mut done = Vec::new();
    while done.len() < 16 {
        let (t, e) = n.next_event(Duration::from_secs(5)).unwrap();
        if let MasterEvent::Sdo {
            node,
            event: SdoEvent::Completed { .. },
            ..
        } = e
        {
            done.push((node, t));
        }
    }
    for node in 1..=16usize {
        assert_eq!(
            n.device(node - 1).od.get(0x2003, 0),
            Ok(Value::Domain(pattern(889 + node)))
        );
    }
    // Concurrent, not one after the other: every server's initiate is answered before the
    // first transfer completes.
    let first_done = done.iter().map(|d| d.1).min().unwrap().as_nanos();
    let f = n.frames();
    for node in 1..=16u16 {
        let ack = f
            .iter()
            .find(|r| r.2.starts_with(&format!("{:03X}#", 0x580 + node)))
            .unwrap();
        assert!(
            ack.1 <= first_done,
            "node {node} answered after the first completion"
        );
    }
    // And uploads back, all at once.
    let ids: Vec<_> = (1..=16u8)
        .map(|node| {
            n.with_master(|m, now, out| m.upload(node, BIG, Mode::Block { blksize: 64 }, now, out))
                .unwrap()
        })
        .collect();
    let mut got = 0;
    while got < 16 {
        let (_, e) = n.next_event(Duration::from_secs(5)).unwrap();
        if let MasterEvent::Sdo {
            id,
            node,
            event: SdoEvent::Completed { data, .. },
        } = e
        {
            assert!(ids.contains(&id));
            assert_eq!(data, pattern(889 + usize::from(node)));
            got += 1;
        }
    }
}

#[test]
fn cia301_7_2_4_transfers_to_one_node_queue_in_order() {
    let mut n = net(Master::new());
    let a = n
        .with_master(|m, now, out| m.download(5, BIG, pattern(50), Mode::Segmented, now, out))
        .unwrap();
    let b = n
        .with_master(|m, now, out| m.upload(5, BIG, Mode::Segmented, now, out))
        .unwrap();
    let ev = n.events(Duration::from_secs(1));
    let ids: Vec<_> = ev
        .iter()
        .map(|(_, e)| match e {
            MasterEvent::Sdo { id, .. } => *id,
            e => panic!("{e:?}"),
        })
        .collect();
    assert_eq!(ids, [a, b]);
    assert_eq!(
        ev[1].1,
        MasterEvent::Sdo {
            id: b,
            node: 5,
            event: completed(pattern(50))
        }
    );
}

#[test]
fn cia301_7_2_4_3_9_progress_of_a_large_block_upload() {
    let mut cfg = MasterConfig::default();
    cfg.sdo.progress_step = Some(10_000);
    let mut n = net(Master::with_config(cfg));
    n.device(0)
        .od
        .set(0x2003, 0, &Value::Domain(pattern(100_000)))
        .unwrap();
    let id = n
        .with_master(|m, now, out| m.upload(5, BIG, Mode::Block { blksize: 127 }, now, out))
        .unwrap();
    let (e, progress) = finish(&mut n, id);
    assert_eq!(e, completed(pattern(100_000)));
    let done: Vec<u32> = progress
        .iter()
        .map(|p| match p {
            SdoEvent::Progress { done, total } => {
                assert_eq!(*total, Some(100_000));
                *done
            }
            e => panic!("{e:?}"),
        })
        .collect();
    // One event per 10 blocks of 889 bytes, then the total.
    assert_eq!(done.len(), 10, "{done:?}");
    assert!(done.windows(2).all(|w| w[0] < w[1]));
    assert_eq!(done.last(), Some(&100_000));
}

#[test]
fn cia301_7_2_4_3_4_progress_of_a_segmented_download() {
    let mut cfg = MasterConfig::default();
    cfg.sdo.progress_step = Some(7 * 100);
    let mut n = net(Master::with_config(cfg));
    let id = n
        .with_master(|m, now, out| m.download(5, BIG, pattern(7 * 350), Mode::Segmented, now, out))
        .unwrap();
    let (_, progress) = finish(&mut n, id);
    assert_eq!(
        progress,
        [700, 1400, 2100, 2450].map(|done| SdoEvent::Progress {
            done,
            total: Some(2450)
        })
    );
}

// ---- lost segments ----

fn drop_attempt(n: &mut Net, attempt: u64) {
    use cantwin_bus::{FaultRule, FrameSelector};
    n.sim
        .bus_mut(n.bus)
        .unwrap()
        .inject(FaultRule::drop(FrameSelector::Attempt(attempt)));
}

#[test]
fn cia301_7_2_4_3_10_block_download_repeats_from_ackseq_plus_1() {
    let mut n = net(Master::new());
    // Attempts: 0 initiate, 1 response, 2.. segments 1..10; segment 3 is lost.
    drop_attempt(&mut n, 4);
    let data = pattern(70);
    assert_eq!(
        download(&mut n, BIG, data.clone(), Mode::Block { blksize: 127 }),
        completed(vec![])
    );
    assert_eq!(
        n.device(0).od.get(0x2003, 0),
        Ok(Value::Domain(data.clone()))
    );
    let f = n.frame_strings();
    let ack = f.iter().position(|s| s.starts_with("585#A2")).unwrap();
    assert_eq!(f[ack], "585#A2027F0000000000");
    // The next block starts with the lost segment's data, numbered 1 again.
    assert_eq!(f[ack + 1], format!("605#01{}", hex(&data[14..21])));
    assert_eq!(f[ack + 8], format!("605#88{}", hex(&data[63..70])));
    assert_eq!(f[ack + 9], "585#A2087F0000000000");
}

#[test]
fn cia301_7_2_4_3_13_block_upload_acknowledges_the_last_segment_in_order() {
    let mut n = net(Master::new());
    let data = pattern(70);
    n.device(0)
        .od
        .set(0x2003, 0, &Value::Domain(data.clone()))
        .unwrap();
    // Attempts: 0 initiate, 1 response, 2 start, 3.. segments 1..10; segment 3 is lost.
    drop_attempt(&mut n, 5);
    assert_eq!(
        upload(&mut n, BIG, Mode::Block { blksize: 127 }),
        completed(data.clone())
    );
    let f = n.frame_strings();
    let ack = f.iter().position(|s| s.starts_with("605#A2")).unwrap();
    assert_eq!(f[ack], "605#A2027F0000000000");
    assert_eq!(f[ack + 1], format!("585#01{}", hex(&data[14..21])));
}

#[test]
fn cia301_7_2_4_3_10_server_block_size_is_followed() {
    let mut d = Device::new(5);
    d.server.set_block_size(4);
    let mut n = Net::new(Master::new(), vec![d]);
    let data = pattern(100);
    assert_eq!(
        download(&mut n, BIG, data.clone(), Mode::Block { blksize: 127 }),
        completed(vec![])
    );
    assert_eq!(n.device(0).od.get(0x2003, 0), Ok(Value::Domain(data)));
    let f = n.frame_strings();
    assert_eq!(f[1], "585#A403200004000000");
    // 15 segments in blocks of 4: acknowledgements after segments 4, 8, 12 and the last.
    let acks: Vec<&str> = f
        .iter()
        .filter(|s| s.starts_with("585#A2"))
        .map(String::as_str)
        .collect();
    assert_eq!(
        acks,
        [
            "585#A204040000000000",
            "585#A204040000000000",
            "585#A204040000000000",
            "585#A203040000000000"
        ]
    );
}

/// Block upload of `size` bytes at 1 Mbit/s: the time the data segments occupy the bus as
/// a fraction of the whole transfer (initiate, acknowledgements and end included) — the
/// bus limit being data segments back to back.
fn block_upload_bus_fraction(size: usize) -> f64 {
    let mut n = net(Master::new());
    let data = pattern(size);
    n.device(0)
        .od
        .set(0x2007, 0, &Value::Domain(data.clone()))
        .unwrap();
    let mux = Mux::new(0x2007, 0);
    let start = n.now();
    let id = n
        .with_master(|m, now, out| m.upload(5, mux, Mode::Block { blksize: 127 }, now, out))
        .unwrap();
    let (e, _) = finish(&mut n, id);
    assert_eq!(e, SdoEvent::Completed { mux, data });
    n.run_for(Duration::from_millis(1));
    let rec = n
        .sim
        .bus(n.bus)
        .unwrap()
        .tap::<cantwin_bus::Recorder>(n.tap)
        .unwrap();
    // Every server frame but the initiate response (first) and the end (last) is a data
    // segment.
    let server: Vec<_> = rec
        .frames()
        .filter(|r| r.frame.id().as_raw() == 0x585)
        .collect();
    let segments = &server[1..server.len() - 1];
    assert_eq!(segments.len(), size.div_ceil(7));
    let segment_ns: u64 = segments
        .iter()
        .map(|r| r.idle_at.as_nanos() - r.start.as_nanos())
        .sum();
    let end = rec.frames().last().unwrap().idle_at.as_nanos();
    let total = end - start.as_nanos();
    let fraction = segment_ns as f64 / total as f64;
    let goodput = size as f64 * 8.0 / (total as f64 / 1e9);
    println!(
        "block upload of {size} bytes at 1 Mbit/s: {:.3} s simulated, {:.1} kbit/s of data, segments occupy {:.2} % of the transfer",
        total as f64 / 1e9,
        goodput / 1e3,
        fraction * 100.0
    );
    fraction
}

#[test]
fn cia301_7_2_4_3_12_block_upload_of_100_000_bytes_uses_over_90_percent_of_the_bus() {
    let f = block_upload_bus_fraction(100_000);
    assert!(f >= 0.90, "{f}");
}

/// The benchmark: `cargo test -p cantwin-canopen --test master_sdo -- --ignored --nocapture`.
#[test]
#[ignore = "benchmark: 17 s of simulated traffic"]
fn cia301_7_2_4_3_12_block_upload_of_1_mib_uses_over_90_percent_of_the_bus() {
    let f = block_upload_bus_fraction(1 << 20);
    assert!(f >= 0.90, "{f}");
}

#[test]
fn cia301_7_2_4_3_9_block_download_through_a_4_frame_transmit_queue() {
    // The master paces its frames by their transmit confirmations: with its window no
    // larger than the controller queue, a block of 127 segments never overflows it.
    let port = cantwin_bus::PortConfig::default().with_queue_depth(4);
    let cfg = MasterConfig {
        tx_window: Some(4),
        ..MasterConfig::default()
    };
    let mut n = Net::with_master_port(Master::with_config(cfg), vec![Device::new(5)], port);
    let data = pattern(100_000);
    assert_eq!(
        download(&mut n, BIG, data.clone(), Mode::Block { blksize: 127 }),
        completed(vec![])
    );
    assert_eq!(n.device(0).od.get(0x2003, 0), Ok(Value::Domain(data)));
    let status = n.sim.bus(n.bus).unwrap().port_status(n.master).unwrap();
    assert_eq!(status.stats.tx_dropped, 0);
}
