//! The device's own acceptance filter: it passes exactly the identifiers its services react
//! to, follows COB-ID changes made through SDO, and filtering changes nothing the device
//! does.
#![allow(clippy::unwrap_used)]

mod device_harness;

use cantwin_can::{ControllerEvent, Duration, Frame, Id, Instant, Node, Outbox};
use cantwin_canopen::ObjectAccess;
use cantwin_canopen::device::{Device, DeviceConfig, Event};
use device_harness::*;
use proptest::prelude::*;

fn std_id(raw: u16) -> Id {
    Id::standard(raw).unwrap()
}

/// The identifiers in `0..0x800` the device accepts.
fn accepted(dev: &Device) -> Vec<u16> {
    (0..0x800u16).filter(|&r| dev.accepts(std_id(r))).collect()
}

/// An expedited SDO download of `value` to `index`/`sub` on node 5's default server; returns
/// the server's command byte (0x60 confirmed, 0x80 aborted).
fn sdo_write(h: &mut Harness, index: u16, sub: u8, value: u32) -> u8 {
    let [i0, i1] = index.to_le_bytes();
    let [v0, v1, v2, v3] = value.to_le_bytes();
    let t = h.now + Duration::from_millis(1);
    h.rx_frame(
        t,
        &Frame::data(std_id(0x605), &[0x23, i0, i1, sub, v0, v1, v2, v3]).unwrap(),
    );
    let answers: Vec<String> = h
        .take()
        .into_iter()
        .map(|(_, f)| f)
        .filter(|f| f.starts_with("585#"))
        .collect();
    assert_eq!(
        answers.len(),
        1,
        "one answer to the download of {index:04X}sub{sub}"
    );
    u8::from_str_radix(&answers[0][4..6], 16).unwrap()
}

#[test]
fn cia301_device_acceptance_filter_passes_exactly_its_cob_ids() {
    let h = Harness::booted();
    // NMT, SYNC, RPDO 1 (0x200 + node), TPDO 1 (0x180 + node, remote requests), the default
    // SDO server's requests, its own guarding requests. TIME (0x100) is neither consumed
    // nor produced by default, no heartbeat is monitored, no EMCY consumed.
    assert_eq!(accepted(&h.dev), [0x000, 0x080, 0x185, 0x205, 0x605, 0x705]);
    assert!(!h.dev.accepts(Id::extended(0x605).unwrap()));
    // A device without the filter passes everything, as a controller with an open filter.
    let open = device_with_config(
        &options(),
        DeviceConfig {
            acceptance_filter: false,
            ..DeviceConfig::new(5)
        },
    );
    assert_eq!(accepted(&open).len(), 0x800);
}

#[test]
fn cia301_device_acceptance_filter_follows_cob_ids_written_through_sdo() {
    let mut h = Harness::booted();
    // 0x1016 sub 1: monitor node 7's heartbeat (100 ms).
    assert_eq!(sdo_write(&mut h, 0x1016, 1, 0x0007_0064), 0x60);
    assert!(h.dev.accepts(std_id(0x707)));
    // 0x1005: SYNC on 0x081.
    assert_eq!(sdo_write(&mut h, 0x1005, 0, 0x81), 0x60);
    assert!(h.dev.accepts(std_id(0x081)));
    assert!(!h.dev.accepts(std_id(0x080)));
    // 0x1012: consume TIME (bit 31).
    assert_eq!(sdo_write(&mut h, 0x1012, 0, 0x8000_0100), 0x60);
    assert!(h.dev.accepts(std_id(0x100)));
    // 0x1028 sub 1: consume node 7's EMCY.
    assert_eq!(sdo_write(&mut h, 0x1028, 1, 0x87), 0x60);
    assert!(h.dev.accepts(std_id(0x087)));
    // 0x1400 sub 1: RPDO 1 invalid, then valid on 0x305.
    assert_eq!(sdo_write(&mut h, 0x1400, 1, 0x8000_0205), 0x60);
    assert!(!h.dev.accepts(std_id(0x205)));
    assert_eq!(sdo_write(&mut h, 0x1400, 1, 0x305), 0x60);
    assert!(h.dev.accepts(std_id(0x305)));
    // 0x1201: a second SDO server on 0x6C0 / 0x6A0 (outside the restricted CAN-IDs of
    // CiA 301 §7.3.5), which then answers there.
    assert!(!h.dev.accepts(std_id(0x6C0)));
    assert_eq!(sdo_write(&mut h, 0x1201, 2, 0x6A0), 0x60);
    assert_eq!(sdo_write(&mut h, 0x1201, 1, 0x6C0), 0x60);
    assert!(h.dev.accepts(std_id(0x6C0)));
    let t = h.now + Duration::from_millis(1);
    h.rx(t, "6C0#4000100000000000");
    let answers = h.take();
    assert_eq!(answers.len(), 1);
    assert!(answers[0].1.starts_with("6A0#43001000"), "{answers:?}");
    assert_eq!(
        accepted(&h.dev),
        [
            0x000, 0x081, 0x087, 0x100, 0x185, 0x305, 0x605, 0x6C0, 0x705, 0x707
        ]
    );
    // A refused write changes nothing: the SYNC identifier is fixed while produced.
    assert_eq!(sdo_write(&mut h, 0x1005, 0, 0x4000_0081), 0x60);
    assert_eq!(sdo_write(&mut h, 0x1005, 0, 0x4000_0082), 0x80);
    assert!(h.dev.accepts(std_id(0x081)));
    assert!(!h.dev.accepts(std_id(0x082)));
}

#[test]
fn cia301_device_acceptance_filter_opens_while_a_receive_overrun_waits_for_a_frame() {
    let mut h = Harness::booted();
    h.event(ms(1), ControllerEvent::RxOverrun);
    assert!(h.dev.accepts(std_id(0x333)));
    // Any frame received clears EMCY 0x8110 (CiA 301 table 21).
    h.rx(ms(2), "333#01");
    assert!(!h.dev.accepts(std_id(0x333)));
    assert!(!h.dev.emcy().is_active(0x8110));
}

/// One thing happening to the device.
#[derive(Debug, Clone)]
enum Step {
    Frame(Frame),
    Event(ControllerEvent),
    /// An expedited SDO download through the default server.
    Sdo(u16, u8, u32),
    /// A local write through `ObjectAccess`.
    Write(u16, u8, u32),
}

fn any_frame() -> impl Strategy<Value = Frame> {
    let ids = prop_oneof![
        // NMT, SYNC (default and rewritten), EMCY of node 7, TIME, TPDO/RPDO 1 and the
        // rewritten RPDO, SDO servers, heartbeats: what the steps below configure.
        proptest::sample::select(vec![
            0x000u16, 0x080, 0x081, 0x087, 0x100, 0x185, 0x205, 0x305, 0x585, 0x605, 0x640, 0x705,
            0x707, 0x708,
        ]),
        0u16..0x800,
    ];
    (
        ids,
        any::<bool>(),
        proptest::collection::vec(any::<u8>(), 0..=8),
        0u8..6,
    )
        .prop_map(|(id, remote, mut data, kind)| {
            // Well-formed messages often enough to reach the services' inner paths.
            match (id, kind) {
                (0x000, k) => {
                    data = vec![
                        [0x01, 0x02, 0x80, 0x81, 0x82, 0x01][usize::from(k)],
                        5 * (k % 2),
                    ]
                }
                (0x707 | 0x708, k) => {
                    data = vec![[0x00, 0x05, 0x7F, 0x04, 0x05, 0x05][usize::from(k)]]
                }
                (0x087 | 0x100 | 0x205 | 0x305, _) => data.resize(8, 0x11),
                (0x605, 0..=3) => {
                    data = vec![0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0];
                }
                _ => {}
            }
            let id = Id::standard(id).unwrap();
            if remote && id.as_raw() != 0 {
                Frame::remote(id, data.len() as u8).unwrap()
            } else {
                Frame::data(id, &data).unwrap()
            }
        })
}

fn any_step() -> impl Strategy<Value = Step> {
    let targets = proptest::sample::select(vec![
        (0x1005u16, 0u8, 0x81u32),
        (0x1005, 0, 0x80),
        (0x1006, 0, 10_000),
        (0x1012, 0, 0x8000_0100),
        (0x1012, 0, 0x100),
        (0x1016, 1, 0x0007_0032),
        (0x1016, 2, 0x0008_0064),
        (0x1016, 1, 0),
        (0x1017, 0, 20),
        (0x1028, 1, 0x87),
        (0x1028, 1, 0x8000_0087),
        (0x1400, 1, 0x8000_0205),
        (0x1400, 1, 0x305),
        (0x1400, 5, 30),
        (0x1800, 1, 0x4000_0185),
        (0x1800, 2, 254),
        (0x1201, 1, 0x640),
        (0x1201, 2, 0x5C0),
        (0x1201, 1, 0x8000_0640),
    ]);
    prop_oneof![
        8 => any_frame().prop_map(Step::Frame),
        1 => proptest::sample::select(vec![
            ControllerEvent::ErrorPassive,
            ControllerEvent::ErrorActive,
            ControllerEvent::BusOffRecovered,
            ControllerEvent::RxOverrun,
        ])
        .prop_map(Step::Event),
        3 => targets.clone().prop_map(|(i, s, v)| Step::Sdo(i, s, v)),
        1 => targets.prop_map(|(i, s, v)| Step::Write(i, s, v)),
    ]
}

/// How frames reach the device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Delivery {
    /// Every frame, device filter off: the reference.
    Unfiltered,
    /// Only frames `accepts` passes, as the bus delivers them.
    Filtered,
    /// Every frame, device filter on: a driver that does not ask `accepts`.
    FilterInside,
}

/// What the device did: every frame with its time, and every event.
#[derive(Debug, PartialEq, Eq)]
enum Seen {
    Sent(u64, String),
    Event(u64, Event),
}

fn run(steps: &[(u64, Step)], delivery: Delivery) -> Vec<Seen> {
    let config = DeviceConfig {
        acceptance_filter: delivery != Delivery::Unfiltered,
        ..DeviceConfig::new(5)
    };
    let mut dev = device_with_config(&options(), config);
    let mut out = Outbox::new();
    let mut seen = Vec::new();
    let mut now = Instant::ZERO;
    let record = |dev: &mut Device, out: &mut Outbox, seen: &mut Vec<Seen>, now: Instant| {
        // Every frame the device sends is on the bus at once: confirm it.
        let sent: Vec<Frame> = out.drain().collect();
        for f in &sent {
            seen.push(Seen::Sent(now.as_nanos(), f.to_string()));
        }
        for f in &sent {
            dev.on_sent(f, now, out);
        }
        for f in out.drain() {
            seen.push(Seen::Sent(now.as_nanos(), f.to_string()));
        }
        while let Some(e) = dev.poll_event() {
            seen.push(Seen::Event(now.as_nanos(), e));
        }
    };
    dev.on_power_up(now, &mut out);
    record(&mut dev, &mut out, &mut seen, now);
    for (dt, step) in steps {
        let until = now + Duration::from_micros(*dt);
        while let Some(d) = dev.next_deadline().filter(|d| *d <= until) {
            now = d.max(now);
            dev.on_tick(now, &mut out);
            record(&mut dev, &mut out, &mut seen, now);
        }
        now = until;
        match step {
            Step::Frame(f) => {
                if delivery != Delivery::Filtered || dev.accepts(f.id()) {
                    dev.on_frame(f, now, &mut out);
                }
            }
            Step::Event(e) => dev.on_controller_event(*e, now, &mut out),
            Step::Sdo(index, sub, v) => {
                let [i0, i1] = index.to_le_bytes();
                let [v0, v1, v2, v3] = v.to_le_bytes();
                let f = Frame::data(std_id(0x605), &[0x23, i0, i1, *sub, v0, v1, v2, v3]).unwrap();
                if delivery != Delivery::Filtered || dev.accepts(f.id()) {
                    dev.on_frame(&f, now, &mut out);
                }
            }
            Step::Write(index, sub, v) => {
                let r = dev.write(*index, *sub, &v.to_le_bytes());
                seen.push(Seen::Sent(
                    now.as_nanos(),
                    format!("write {index:04X}sub{sub}: {r:?}"),
                ));
            }
        }
        record(&mut dev, &mut out, &mut seen, now);
    }
    let end = now + Duration::from_secs(1);
    while let Some(d) = dev.next_deadline().filter(|d| *d <= end) {
        now = d.max(now);
        dev.on_tick(now, &mut out);
        record(&mut dev, &mut out, &mut seen, now);
    }
    seen
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// The same traffic gives the same frames at the same instants and the same events,
    /// whether the device filters or not, and whoever applies the filter.
    #[test]
    fn cia301_device_acceptance_filter_changes_nothing_the_device_does(
        steps in proptest::collection::vec((0u64..40_000, any_step()), 1..80),
    ) {
        let reference = run(&steps, Delivery::Unfiltered);
        prop_assert_eq!(&run(&steps, Delivery::Filtered), &reference);
        prop_assert_eq!(&run(&steps, Delivery::FilterInside), &reference);
    }
}

#[test]
fn cia301_device_acceptance_filter_changes_nothing_in_a_long_conversation() {
    // NMT start, SYNCs every 10 ms, node 7's heartbeats, SDO traffic to the device and to
    // other nodes, foreign PDOs: three seconds with and without the filter.
    let mut steps = vec![
        (0, Step::Sdo(0x1016, 1, 0x0007_0032)),
        (100, Step::Sdo(0x1017, 0, 20)),
        (100, Step::Frame(frame("000#0100"))),
    ];
    for k in 0..300u64 {
        steps.push((3_000, Step::Frame(frame("080#"))));
        steps.push((
            500,
            Step::Frame(frame(&format!("{:03X}#0102", 0x181 + k % 4))),
        ));
        if k % 3 == 0 {
            steps.push((500, Step::Frame(frame("707#05"))));
        }
        steps.push((500, Step::Frame(frame("606#4000100000000000"))));
        steps.push((500, Step::Frame(frame("205#2A"))));
        if k % 50 == 25 {
            steps.push((500, Step::Frame(frame("605#4001100000000000"))));
        }
    }
    let reference = run(&steps, Delivery::Unfiltered);
    assert!(reference.len() > 600, "{}", reference.len());
    assert_eq!(run(&steps, Delivery::Filtered), reference);
    assert_eq!(run(&steps, Delivery::FilterInside), reference);
}

#[test]
fn cia301_device_acceptance_version_changes_with_the_filter_only() {
    let mut h = Harness::booted();
    let v0 = h.dev.acceptance_version();
    assert!(
        v0.is_some(),
        "a device keeps a version, so a bus keeps its verdicts"
    );
    // Calls that change no COB-ID leave it: a communication cycle period written, a SYNC
    // received.
    assert_eq!(sdo_write(&mut h, 0x1006, 0, 0), 0x60);
    let t = h.now + Duration::from_millis(1);
    h.rx(t, "080#");
    assert_eq!(h.dev.acceptance_version(), v0);
    // 0x1005: SYNC on 0x081 changes what passes, and the version with it.
    assert_eq!(sdo_write(&mut h, 0x1005, 0, 0x81), 0x60);
    let v1 = h.dev.acceptance_version();
    assert_ne!(v1, v0);
    // The same COB-ID written again passes the same identifiers: the version stays.
    assert_eq!(sdo_write(&mut h, 0x1005, 0, 0x81), 0x60);
    assert_eq!(h.dev.acceptance_version(), v1);
}
