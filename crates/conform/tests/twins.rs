//! Every area against the shipped CANopen twins in virtual time.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use cantwin_conform::{Area, Options, Profile, Report, Verdict, VirtualBus, run};
use cantwin_scenario::{BuildEnv, Registry, Scenario};

fn scenario(name: &str) -> PathBuf {
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    if data.join(name).exists() {
        return data.join(name);
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenarios")
        .join(name)
}

/// Runs every case against `device` of `file`, with the EDS made from its dictionary and
/// the twin's shipped profile.
fn conform(file: &str, device: &str) -> Report {
    conform_with(file, device, None, &Options::default())
}

/// As [`conform`]; `profile`: this profile file instead of the shipped one (`Some("")`:
/// the EDS alone).
fn conform_with(file: &str, device: &str, profile: Option<&str>, options: &Options) -> Report {
    let sc = Scenario::load(scenario(file)).unwrap();
    let built = sc
        .build(&Registry::builtin(), &BuildEnv::default())
        .unwrap();
    let dev = built.device(device).unwrap().clone();
    let node = dev.node_id.unwrap();
    let desc = built
        .sim
        .twin(dev.port)
        .unwrap()
        .dictionary()
        .unwrap()
        .description();
    let eds = cantwin_eds::from_od(
        desc,
        cantwin_eds::DeviceInfo::default(),
        cantwin_eds::FileInfo::new(format!("{device}.eds")),
    );
    let mut bus = VirtualBus::new(built.sim, dev.port.bus()).unwrap();
    let file = match profile {
        Some(text) => cantwin_conform::ProfileFile::parse(text).unwrap(),
        None => cantwin_conform::profile::shipped(&dev.kind),
    };
    let profile = Profile::from_eds(&eds).with_file(&file, "test");
    run(&mut bus, node, &eds, &profile, options, &mut |_| {})
}

/// Every deviation the shipped profile lists was observed, as the runner checks.
fn deviations_observed(r: &Report, kind: &str) {
    for d in cantwin_conform::profile::shipped(kind).deviations {
        let c = r.case(&d.case).unwrap();
        assert_eq!(c.verdict, Verdict::Deviation, "{}: {}", c.id, c.detail);
        assert_eq!(c.manual_section.as_deref(), Some(d.section.as_str()));
    }
}

fn show(r: &Report) -> String {
    cantwin_conform::output::summary(r)
}

#[test]
fn cia301_twin_passes_every_mandatory_case() {
    let r = conform("cia301-device.toml", "node5");
    assert!(r.passed(), "{}", show(&r));
    assert!(r.count(Verdict::Pass) > 30, "{}", show(&r));
}

#[test]
fn tm3_island_passes_every_mandatory_case() {
    let r = conform("tm3-island.toml", "island");
    assert!(r.passed(), "{}", show(&r));
    // Its profile claims RTR (its manual, objects 1800H-1837H): the case ran and passed.
    assert_eq!(r.case("pdo.rtr").unwrap().verdict, Verdict::Pass);
}

#[test]
fn eds_twin_of_example_io_passes_every_mandatory_case() {
    let r = conform("eds-device.toml", "io6");
    assert!(r.passed(), "{}", show(&r));
}

#[test]
fn adv200_canopen_passes_every_mandatory_case() {
    let r = conform("adv200-example.toml", "drive");
    assert!(r.passed(), "{}", show(&r));
    deviations_observed(&r, "adv200");
}

#[test]
fn adv200_ds402_passes_every_mandatory_case() {
    let r = conform("adv200-ds402.toml", "drive");
    assert!(r.passed(), "{}", show(&r));
    deviations_observed(&r, "adv200");
}

#[test]
fn cia402_servo_axis_passes_every_mandatory_case() {
    // The axis of scenarios/servo-axis.toml without the scenario's SYNC generator.
    let r = conform("servo-axis-alone.toml", "axis");
    assert!(r.passed(), "{}", show(&r));
    assert!(r.count(Verdict::Pass) > 30, "{}", show(&r));
}

fn sdo_only() -> Options {
    Options {
        only: vec![cantwin_conform::Area::Sdo],
        ..Options::default()
    }
}

#[test]
fn without_a_profile_an_expedited_only_server_is_reported_not_failed() {
    let r = conform_with("adv200-example.toml", "drive", Some(""), &sdo_only());
    let c = r.case("sdo.segmented-download").unwrap();
    assert_eq!(c.verdict, Verdict::NotSupported, "{}", c.detail);
    assert!(c.detail.contains("expedited-only"), "{}", c.detail);
    assert!(c.detail.contains("0x05040001"), "{}", c.detail);
    assert!(r.passed(), "{}", show(&r));
}

#[test]
fn an_unlisted_deviation_fails() {
    // The profile claims segmented transfers and lists no deviation.
    let r = conform_with(
        "adv200-example.toml",
        "drive",
        Some("[sdo]\nsegmented = true\n"),
        &sdo_only(),
    );
    let c = r.case("sdo.segmented-download").unwrap();
    assert_eq!(c.verdict, Verdict::Fail, "{}", c.detail);
    assert!(!r.passed());
}

#[test]
fn a_listed_deviation_that_is_not_observed_fails() {
    let profile = "[[deviation]]\ncase = \"sdo.segmented-download\"\nsection = \"§9\"\nbehaviour = \"expedited only\"\nabort = 0x05040001\n";
    let r = conform_with("cia301-device.toml", "node5", Some(profile), &sdo_only());
    let c = r.case("sdo.segmented-download").unwrap();
    assert_eq!(c.verdict, Verdict::Fail, "{}", c.detail);
    assert_eq!(c.manual_section.as_deref(), Some("§9"));
    assert!(c.detail.contains("not observed"), "{}", c.detail);
}

#[test]
fn a_deviation_with_another_abort_code_is_not_the_listed_one() {
    let profile = "[sdo]\nsegmented = false\n[[deviation]]\ncase = \"sdo.segmented-download\"\nsection = \"§9\"\nbehaviour = \"x\"\nabort = 0x06010000\n";
    let r = conform_with("adv200-example.toml", "drive", Some(profile), &sdo_only());
    assert_eq!(
        r.case("sdo.segmented-download").unwrap().verdict,
        Verdict::Fail
    );
}

#[test]
fn shipped_profiles_parse_and_name_cases_of_the_catalogue() {
    for text in [
        cantwin_conform::profile::ADV200,
        cantwin_conform::profile::STACK,
        cantwin_conform::profile::TM3,
    ] {
        cantwin_conform::ProfileFile::parse(text).unwrap();
    }
    assert!(matches!(
        cantwin_conform::ProfileFile::parse(
            "[[deviation]]\ncase = \"sdo.nope\"\nsection = \"1\"\nbehaviour = \"x\"\n"
        ),
        Err(cantwin_conform::ProfileError::UnknownCase(_))
    ));
}

/// Runs `options` against the `eds` twin "d" (node 9) of `name`.toml in tests/data, with
/// the file `name`.eds as its EDS.
fn conform_data_file(name: &str, options: &Options) -> Report {
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let sc = Scenario::load(data.join(format!("{name}.toml"))).unwrap();
    let built = sc
        .build(&Registry::builtin(), &BuildEnv::default())
        .unwrap();
    let dev = built.device("d").unwrap().clone();
    let eds_text = std::fs::read_to_string(data.join(format!("{name}.eds"))).unwrap();
    let eds = cantwin_eds::parse(&eds_text).unwrap();
    let mut bus = VirtualBus::new(built.sim, dev.port.bus()).unwrap();
    let profile = Profile::from_eds(&eds);
    run(&mut bus, 9, &eds, &profile, options, &mut |_| {})
}

#[test]
fn an_eight_byte_writable_entry_is_downloaded_in_two_segments() {
    // 0x2F00 (UNSIGNED64) is the only read-write entry of at most 8 bytes: a segment
    // carries at most 7 (CiA 301 §7.2.4.3.5), so the download takes two.
    let r = conform_data_file("u64-rw", &sdo_only());
    for id in ["sdo.segmented-download", "sdo.segmented-download-no-size"] {
        let c = r.case(id).unwrap();
        assert_eq!(c.verdict, Verdict::Pass, "{id}: {}", c.detail);
    }
    let c = r.case("sdo.segmented-download").unwrap();
    assert!(c.detail.contains("0x2F00"), "{}", c.detail);
    assert!(c.detail.contains("8 bytes in 2 segments"), "{}", c.detail);
}

/// CiA 301 §7.2.4.3.17: an `eds` twin of a file with a write-only entry and an entry with a
/// low limit inside its type's range gives the two aborts, so the cases run and pass (the
/// broken device without the check is caught, tests/broken.rs).
#[test]
fn cia301_7_2_4_3_17_write_only_and_low_limit_aborts_run_on_an_eds_twin() {
    let r = conform_data_file("access-limits", &sdo_only());
    assert!(r.passed(), "{}", show(&r));
    for (id, what) in [
        ("sdo.abort-write-only", "0x2010 sub 0"),
        ("sdo.abort-value-low", "-101 to 0x2011 sub 0"),
    ] {
        let c = r.case(id).unwrap();
        assert_eq!(c.verdict, Verdict::Pass, "{id}: {}", c.detail);
        assert!(c.detail.contains(what), "{id}: {}", c.detail);
    }
}

/// CiA 301 §7.3.4: the heartbeat consumer cases monitor a node-ID nobody on the bus uses;
/// node 6 is alive and heartbeating, so monitoring it would never time out.
#[test]
fn heartbeat_consumer_cases_monitor_a_node_id_free_on_the_bus() {
    let r = conform_with("two-nodes.toml", "node5", None, &Options::default());
    assert!(r.passed(), "{}", show(&r));
    let c = r.case("error-control.heartbeat-consumer").unwrap();
    assert_eq!(c.verdict, Verdict::Pass, "{}", c.detail);
    assert!(c.detail.contains("node 7"), "{}", c.detail);
}

/// CiA 301 §7.3.2.2.1: a device a master started before the run is put back into
/// PRE-OPERATIONAL before the first case, where every case expects it.
#[test]
fn a_device_started_before_the_run_is_put_into_pre_operational_first() {
    let r = conform_with("started-before.toml", "node5", None, &Options::default());
    assert!(r.passed(), "{}", show(&r));
    // The heartbeats of the first case report PRE-OPERATIONAL (0x7F), not OPERATIONAL.
    let first = r
        .cases
        .iter()
        .find(|c| c.frames.iter().any(|f| f.frame.starts_with("705#")))
        .unwrap();
    let beats: Vec<&str> = first
        .frames
        .iter()
        .map(|f| f.frame.as_str())
        .filter(|f| f.starts_with("705#"))
        .collect();
    assert!(!beats.is_empty(), "{}: {:?}", first.id, first.frames);
    assert!(
        beats.iter().all(|f| *f == "705#7F"),
        "{}: {beats:?}",
        first.id
    );
}

/// CiA 301 §7.2.5: the scenario's own master produces SYNC every 10 ms, so the cases that
/// count SYNCs and the TPDOs they trigger cannot be judged; they are skipped, not failed.
#[test]
fn cases_that_count_syncs_are_skipped_beside_another_sync_producer() {
    let r = conform("servo-axis.toml", "axis");
    assert!(r.passed(), "{}", show(&r));
    for id in [
        "pdo.transmission-sync",
        "pdo.transmission-cyclic",
        "sync.producer",
        "sync.counter",
    ] {
        let c = r.case(id).unwrap();
        assert_eq!(c.verdict, Verdict::Skipped, "{id}: {}", c.detail);
        assert_eq!(
            c.detail, "skipped: another SYNC producer on the bus",
            "{id}"
        );
    }
    // Without that producer the same cases run.
    let alone = conform("servo-axis-alone.toml", "axis");
    assert_eq!(
        alone.case("sync.producer").unwrap().verdict,
        Verdict::Pass,
        "{}",
        show(&alone)
    );
}

/// CiA 301 §7.5.2.37 (sub 3): the inhibit time is the minimum interval between two TPDOs.
/// TPDO 2 of the file has 100 ms: with a 50 ms event timer the TPDO comes every 100 ms,
/// and the event timer case expects that, not a TPDO every 50 ms.
#[test]
fn cia301_7_5_2_37_event_timer_case_keeps_to_a_longer_inhibit_time() {
    let options = Options {
        only: vec![Area::Pdo],
        ..Options::default()
    };
    let r = conform_data_file("pdo-unrunnable", &options);
    let c = r.case("pdo.event-timer").unwrap();
    assert_eq!(c.verdict, Verdict::Pass, "{}", c.detail);
    assert!(c.detail.contains("every 100 ms"), "{}", c.detail);
    assert!(c.detail.contains("inhibit time of 100 ms"), "{}", c.detail);
}

/// CiA 301 §7.5.2.36, §7.5.2.38: TPDO 1's file mapping names an object the file lacks, so
/// no device made from it can run TPDO 1. The PDO cases leave it out, say so, and run on
/// TPDO 2; a case that wrote TPDO 1's own mapping back would be refused by any device.
#[test]
fn cia301_7_5_2_38_pdo_cases_leave_out_a_pdo_whose_file_mapping_cannot_run() {
    let options = Options {
        only: vec![Area::Pdo],
        ..Options::default()
    };
    let r = conform_data_file("pdo-unrunnable", &options);
    assert!(r.passed(), "{}", show(&r));
    let c = r.case("pdo.cob-ids").unwrap();
    assert!(
        c.detail.contains("left out") && c.detail.contains("0x1800: TPDO 1 maps 0x6041"),
        "{}",
        c.detail
    );
    for (id, pdo) in [
        ("pdo.mapping-procedure", "0x1A01"),
        ("pdo.mapping-carried", "0x1A01"),
        ("pdo.cob-id-change-valid", "0x1801"),
        ("pdo.rtr", "289#"),
    ] {
        let c = r.case(id).unwrap();
        assert_eq!(c.verdict, Verdict::Pass, "{id}: {}", c.detail);
        assert!(c.detail.contains(pdo), "{id}: {}", c.detail);
    }
}

/// CiA 301 §7.2.4.3.17: after each refused request the SDO cases check that the server
/// serves again. A file without 0x1000 (python-canopen's datatypes.eds has none) fails the
/// file check only; the others read the first readable entry of the file instead.
#[test]
fn cia301_7_2_4_3_17_a_file_without_0x1000_fails_only_the_file_check() {
    let r = conform_data_file("no-device-type", &Options::default());
    let failed: Vec<&str> = r
        .cases
        .iter()
        .filter(|c| c.verdict == Verdict::Fail)
        .map(|c| c.id.as_str())
        .collect();
    assert_eq!(failed, ["eds.mandatory-objects"], "{}", show(&r));
    let c = r.case("sdo.expedited-upload").unwrap();
    assert!(c.detail.contains("0x1001 sub 0"), "{}", c.detail);
    for id in ["sdo.abort-toggle", "sdo.abort-timeout", "nmt.sdo-stopped"] {
        assert_eq!(r.case(id).unwrap().verdict, Verdict::Pass, "{id}");
    }
}
