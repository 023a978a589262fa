//! Every area against the shipped CANopen twins in virtual time.

use std::path::PathBuf;

use cantwin_conform::{Options, Profile, Report, Verdict, VirtualBus, run};
use cantwin_scenario::{BuildEnv, Registry, Scenario};

fn scenario(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenarios").join(name)
}

/// Runs every case against `device` of `file`, with the EDS made from its dictionary.
fn conform(file: &str, device: &str) -> Report {
    let sc = Scenario::load(&scenario(file)).unwrap();
    let built = sc.build(&Registry::builtin(), &BuildEnv::default()).unwrap();
    let dev = built.device(device).unwrap().clone();
    let node = dev.node_id.unwrap();
    let desc = built.sim.twin(dev.port).unwrap().dictionary().unwrap().description();
    let eds = cantwin_eds::from_od(
        desc,
        cantwin_eds::DeviceInfo::default(),
        cantwin_eds::FileInfo::new(format!("{device}.eds")),
    );
    let mut bus = VirtualBus::new(built.sim, dev.port.bus()).unwrap();
    let profile = Profile::from_eds(&eds);
    run(&mut bus, node, &eds, &profile, &Options::default(), &mut |_| {})
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
