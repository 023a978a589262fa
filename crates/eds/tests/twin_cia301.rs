//! A device from any EDS or DCF answers as CiA 301 says, with the file's types and access
//! rules: every object over SDO expedited, segmented and block (§7.2.4.3), read-only,
//! write-only, const and limits with their abort codes, PDO mapping as the file allows
//! (§7.4.7.1), heartbeat (§7.2.8.3.2.3), EMCY (§7.2.7) and NMT (§7.2.8.3.1), a DCF's
//! `ParameterValue`s as its configuration. The device is the one the `eds` kind builds
//! (`configured` then `to_od`), driven here by the stack's own SDO client, frame by frame.
#![allow(clippy::unwrap_used)]

use cantwin_can::{Frame, Id, Instant, Node, Outbox};
use cantwin_canopen::device::{Device, DeviceConfig};
use cantwin_canopen::master::sdo_client::{Mode, SdoClient, SdoEvent};
use cantwin_canopen::od::{Access, DataType, OdDescription, Value};
use cantwin_canopen::{AbortCode, ObjectAccess};
use cantwin_eds::{configured, load_bytes, to_od};
use std::path::PathBuf;
use std::sync::Arc;

fn corpus(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/corpus")
        .join(name)
}

fn description(name: &str) -> (OdDescription, Option<u8>) {
    let l = load_bytes(&std::fs::read(corpus(name)).unwrap());
    // The irregular files have their errors (read past); the others have none.
    assert!(
        name.starts_with("irregular/") || l.report.is_ok(),
        "{name}\n{}",
        l.report
    );
    let node = l.eds.commissioning.as_ref().and_then(|c| c.node_id);
    (to_od(&configured(&l.eds)).unwrap(), node)
}

fn ms(v: u64) -> Instant {
    Instant::from_nanos(v * 1_000_000)
}

/// A device and an SDO client on one loopback: every frame of one reaches the other.
struct Rig {
    dev: Device,
    node: u8,
    client: SdoClient,
    now: Instant,
    /// Frames the device sent that the client did not take.
    heard: Vec<(Instant, Frame)>,
}

impl Rig {
    fn new(desc: OdDescription, node: u8) -> Rig {
        let mut dev = Device::new(Arc::new(desc), DeviceConfig::new(node)).unwrap();
        let mut out = Outbox::new();
        dev.on_power_up(Instant::ZERO, &mut out);
        let mut heard: Vec<(Instant, Frame)> = out.drain().map(|f| (Instant::ZERO, f)).collect();
        // The loopback confirms the boot-up message as the bus does; the EMCYs of the reset
        // wait for it (CiA 301 §7.2.7.1).
        for (_, f) in heard.clone() {
            dev.on_sent(&f, Instant::ZERO, &mut out);
        }
        heard.extend(out.drain().map(|f| (Instant::ZERO, f)));
        Rig {
            dev,
            node,
            client: SdoClient::for_node(node).unwrap(),
            now: Instant::ZERO,
            heard,
        }
    }

    /// Delivers frames both ways until nothing moves.
    fn pump(&mut self, mut from_client: Outbox) {
        for _ in 0..10_000 {
            let mut from_dev = Outbox::new();
            for f in from_client.drain() {
                self.dev.on_frame(&f, self.now, &mut from_dev);
            }
            let from_dev = self.confirm(&mut from_dev);
            if from_dev.is_empty() {
                return;
            }
            for f in from_dev {
                if !self.client.on_frame(&f, self.now, &mut from_client) {
                    self.heard.push((self.now, f));
                }
            }
        }
        panic!("the transfer does not end");
    }

    /// The frames of `out`, each confirmed to the device as the bus does once it is sent
    /// (EMCYs wait for the boot-up message and for the SDO answer they follow), with what
    /// the device queues on that.
    fn confirm(&mut self, out: &mut Outbox) -> Vec<Frame> {
        let mut sent = Vec::new();
        while !out.is_empty() {
            let frames: Vec<Frame> = out.drain().collect();
            for f in frames {
                self.dev.on_sent(&f, self.now, out);
                sent.push(f);
            }
        }
        sent
    }

    fn finish(&mut self) -> Result<Vec<u8>, AbortCode> {
        while let Some(e) = self.client.poll_event() {
            match e {
                SdoEvent::Completed { data, .. } => return Ok(data),
                SdoEvent::Aborted { code, .. } => return Err(code),
                _ => {}
            }
        }
        panic!("no answer");
    }

    fn upload(&mut self, index: u16, sub: u8, mode: Mode) -> Result<Vec<u8>, AbortCode> {
        let mut out = Outbox::new();
        self.client
            .start_upload(index, sub, mode, self.now, &mut out)
            .unwrap();
        self.pump(out);
        self.finish()
    }

    fn download(&mut self, index: u16, sub: u8, data: &[u8], mode: Mode) -> Result<(), AbortCode> {
        let mut out = Outbox::new();
        self.client
            .start_download(index, sub, data.to_vec(), mode, self.now, &mut out)
            .unwrap();
        self.pump(out);
        self.finish().map(|_| ())
    }

    fn send(&mut self, id: u16, data: &[u8]) {
        let mut out = Outbox::new();
        self.dev.on_frame(
            &Frame::data(Id::standard(id).unwrap(), data).unwrap(),
            self.now,
            &mut out,
        );
        let sent = self.confirm(&mut out);
        self.heard.extend(sent.into_iter().map(|f| (self.now, f)));
    }

    fn run_until(&mut self, t: Instant) {
        while let Some(d) = self.dev.next_deadline() {
            if d > t {
                break;
            }
            self.now = d.max(self.now);
            let mut out = Outbox::new();
            self.dev.on_tick(self.now, &mut out);
            let sent = self.confirm(&mut out);
            self.heard.extend(sent.into_iter().map(|f| (self.now, f)));
        }
        self.now = t.max(self.now);
    }

    /// The device's own answer to a read (what the SDO server serves).
    fn local(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, AbortCode> {
        let mut buf = vec![0; 4096];
        let info = self.dev.read(index, sub, 0, &mut buf)?;
        buf.truncate(info.copied);
        Ok(buf)
    }

    fn take(&mut self) -> Vec<(u64, u16, Vec<u8>)> {
        std::mem::take(&mut self.heard)
            .into_iter()
            .map(|(t, f)| {
                let Id::Standard(id) = f.id() else { panic!() };
                (
                    t.as_nanos() / 1_000_000,
                    id.as_raw(),
                    f.data_bytes().to_vec(),
                )
            })
            .collect()
    }
}

const FILES: [&str; 7] = [
    "sample_like.dcf",
    "datatypes_like.eds",
    "servo_like.eds",
    "irregular/i04_access_case.eds",
    "irregular/i10_limits.eds",
    "irregular/i13_lely_values.eds",
    "irregular/i14_bytes.eds",
];

/// CiA 301 §7.2.4.3: every readable object reads the same in all three protocols, as the
/// dictionary holds it; write-only objects abort 0x06010001; read-only and const objects
/// refuse writes with 0x06010002; a value past a limit aborts 0x06090031 (above) or
/// 0x06090032 (below); a value of the wrong length 0x06070010/12/13.
#[test]
fn cia301_7_2_4_sdo_against_every_object_with_the_files_types_and_access() {
    for name in FILES {
        let (desc, node) = description(name);
        let node = node.unwrap_or(5);
        let mut rig = Rig::new(desc.clone(), node);
        let mut checked = 0;
        for o in desc.objects() {
            for (sub, d) in o.subs() {
                let index = o.index();
                let here = format!("{name} {index:04X}:{sub}");
                checked += 1;
                let held = rig.local(index, sub);
                let bytes = held
                    .clone()
                    .unwrap_or_else(|_| rig.dev.od().get(index, sub).unwrap().to_le_bytes());
                // CiA 301 §7.5.2.4: the error history holds no entry yet; a sub-index past
                // the number of errors has no data (0x08000024).
                if index == 0x1003 && sub > 0 {
                    let r = rig.upload(index, sub, Mode::Expedited);
                    assert_eq!(r, Err(AbortCode::from_u32(0x0800_0024)), "{here}");
                    continue;
                }
                if d.access == Access::Wo {
                    assert_eq!(
                        rig.upload(index, sub, Mode::Expedited),
                        Err(AbortCode::from_u32(0x0601_0001)),
                        "{here}"
                    );
                } else {
                    for mode in [Mode::Expedited, Mode::Segmented, Mode::Block { blksize: 7 }] {
                        assert_eq!(
                            rig.upload(index, sub, mode),
                            Ok(bytes.clone()),
                            "{here} {mode:?}"
                        );
                    }
                }
                if matches!(d.access, Access::Ro | Access::Const) {
                    let r = rig.download(index, sub, &bytes.clone().max(vec![0]), Mode::Auto);
                    assert_eq!(r, Err(AbortCode::from_u32(0x0601_0002)), "{here}");
                    continue;
                }
                if let Some(size) = d.data_type.fixed_size() {
                    let r = rig.download(index, sub, &vec![0; size + 1], Mode::Segmented);
                    let code = r.unwrap_err().to_u32();
                    assert!(
                        [0x0607_0010, 0x0607_0012].contains(&code),
                        "{here}: {code:#010X}"
                    );
                }
                if let Some(high) = d.high_limit.as_ref().and_then(Value::as_i128)
                    && let Ok(v) = Value::from_integer(d.data_type, high + 1)
                {
                    let r = rig.download(index, sub, &v.to_le_bytes(), Mode::Auto);
                    assert_eq!(r, Err(AbortCode::from_u32(0x0609_0031)), "{here}");
                }
                if let Some(low) = d.low_limit.as_ref().and_then(Value::as_i128)
                    && let Ok(v) = Value::from_integer(d.data_type, low - 1)
                {
                    let r = rig.download(index, sub, &v.to_le_bytes(), Mode::Auto);
                    assert_eq!(r, Err(AbortCode::from_u32(0x0609_0032)), "{here}");
                }
                // The value the device holds is accepted back, in every protocol, and a
                // string or byte value longer than four bytes goes segmented and by block.
                if index >= 0x2000 {
                    for mode in [Mode::Expedited, Mode::Segmented, Mode::Block { blksize: 4 }] {
                        let data = match d.data_type {
                            DataType::VisibleString => b"written by block".to_vec(),
                            DataType::OctetString | DataType::Domain => (0u8..40).collect(),
                            _ => bytes.clone(),
                        };
                        if mode == Mode::Expedited && !(1..=4).contains(&data.len()) {
                            continue;
                        }
                        rig.download(index, sub, &data, mode)
                            .unwrap_or_else(|e| panic!("{here} {mode:?}: {e}"));
                        if d.access != Access::Wo {
                            assert_eq!(
                                rig.upload(index, sub, Mode::Segmented),
                                Ok(data),
                                "{here} {mode:?}"
                            );
                        }
                    }
                }
            }
        }
        assert!(checked > 5, "{name}: {checked}");
    }
}

/// CiA 301 §7.4.7.1: the servo's TPDO 1 is mapped as the file allows (a const object is not
/// mappable: 0x06040041; a mappable one is), then sent on SYNC in operational.
#[test]
fn cia301_7_4_pdo_mapping_as_the_file_allows_and_nmt() {
    let (desc, _) = description("servo_like.eds");
    let mut rig = Rig::new(desc, 5);
    assert_eq!(rig.take(), [(0, 0x705, vec![0])]);
    let x = |v: u32| v.to_le_bytes().to_vec();
    rig.download(0x1800, 1, &x(0x8000_0185), Mode::Auto)
        .unwrap();
    rig.download(0x1A00, 0, &[0], Mode::Auto).unwrap();
    assert_eq!(
        rig.download(0x1A00, 1, &x(0x6502_0020), Mode::Auto),
        Err(AbortCode::from_u32(0x0604_0041))
    );
    rig.download(0x1A00, 1, &x(0x2000_0010), Mode::Auto)
        .unwrap();
    // A dummy entry (0x0005, UNSIGNED8, one of the file's DEFTYPE objects) fills a byte of
    // an RPDO, never of a TPDO.
    assert!(
        rig.download(0x1A00, 2, &x(0x0005_0008), Mode::Auto)
            .is_err()
    );
    rig.download(0x1400, 1, &x(0x8000_0205), Mode::Auto)
        .unwrap();
    rig.download(0x1600, 0, &[0], Mode::Auto).unwrap();
    rig.download(0x1600, 1, &x(0x0005_0008), Mode::Auto)
        .unwrap();
    rig.download(0x1600, 2, &x(0x6040_0010), Mode::Auto)
        .unwrap();
    rig.download(0x1600, 0, &[2], Mode::Auto).unwrap();
    rig.download(0x1400, 1, &x(0x0000_0205), Mode::Auto)
        .unwrap();
    rig.download(0x1A00, 0, &[1], Mode::Auto).unwrap();
    rig.download(0x1800, 2, &[1], Mode::Auto).unwrap();
    rig.download(0x1800, 1, &x(0x0000_0185), Mode::Auto)
        .unwrap();
    rig.take();
    // Pre-operational: no PDO on SYNC.
    rig.send(0x080, &[]);
    assert!(rig.take().is_empty());
    rig.send(0x000, &[0x01, 5]);
    rig.send(0x080, &[]);
    assert_eq!(rig.take(), [(0, 0x185, vec![25, 0])]);
    // The RPDO's first byte goes nowhere, the next two are the controlword.
    rig.send(0x205, &[0xAA, 0x0F, 0x00]);
    assert_eq!(rig.upload(0x6040, 0, Mode::Expedited), Ok(vec![0x0F, 0x00]));
    // Stopped: no SDO answer; reset node: boot-up again.
    rig.send(0x000, &[0x02, 5]);
    rig.send(0x605, &[0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]);
    assert!(rig.take().is_empty());
    rig.send(0x000, &[0x81, 5]);
    rig.run_until(ms(1));
    assert_eq!(rig.take().last().unwrap().1, 0x705);
}

/// CiA 301 §7.2.8.3.2.3 and §7.2.7: a DCF's ParameterValue of 0x1017 (50 ms) configures the
/// heartbeat; an EMCY goes out on the file's COB-ID ($NODEID+0x80 → 0xA1 for node 0x21).
#[test]
fn cia306_dcf_parameter_values_configure_heartbeat_and_emcy() {
    let (desc, node) = description("irregular/i12_dcf.dcf");
    let mut rig = Rig::new(desc, node.unwrap());
    assert_eq!(rig.node, 0x21);
    rig.take();
    rig.run_until(ms(120));
    let beats: Vec<(u64, u16)> = rig.take().into_iter().map(|(t, id, _)| (t, id)).collect();
    assert_eq!(beats, [(50, 0x721), (100, 0x721)]);
    assert_eq!(rig.upload(0x2000, 0, Mode::Expedited), Ok(vec![0xDC, 0x05]));
    assert!(rig.dev.emcy().raise(0x5000, [1, 2, 3, 4, 5]));
    rig.run_until(ms(121));
    let emcy: Vec<_> = rig
        .take()
        .into_iter()
        .filter(|(_, id, _)| *id == 0xA1)
        .collect();
    assert_eq!(emcy.len(), 1);
    assert_eq!(&emcy[0].2[..2], &[0x00, 0x50]);
}

/// A default text beyond ISO 646 (CiA 301 §7.1.6 defines none: a vendor's `€`, a German
/// `ü`) reads over SDO as the file's text in UTF-8, in every protocol, not as `?`.
#[test]
fn cia301_7_1_6_a_visible_string_beyond_iso_646_reads_as_the_files_text() {
    let (desc, _) = description("irregular/i16_utf8.eds");
    let mut rig = Rig::new(desc, 6);
    for mode in [Mode::Expedited, Mode::Segmented, Mode::Block { blksize: 7 }] {
        let mode_name = format!("{mode:?}");
        let got = rig.upload(0x2000, 0, mode);
        assert_eq!(
            got.as_deref(),
            Ok("5 € pro Stück".as_bytes()),
            "{mode_name}"
        );
    }
}
