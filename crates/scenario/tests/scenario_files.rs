//! Scenario files: what they build, and errors that name file, line and key.
#![allow(clippy::unwrap_used)]

use cantwin_can::{Duration, Instant};
use cantwin_scenario::{BuildEnv, Registry, Scenario, ScenarioError};

fn err(text: &str) -> String {
    match Scenario::parse(text, "s.toml").and_then(|s| {
        s.build(&Registry::builtin(), &BuildEnv::default())
            .map(|_| ())
    }) {
        Ok(()) => panic!("expected an error for:\n{text}"),
        Err(e) => e.to_string(),
    }
}

const TWO_GENERATORS: &str = r#"
name = "two generators"
description = "generators at 1 and 2 ms"
seed = 5

[[bus]]
name = "can0"
bit_rate = "500k"

[[device]]
name = "fast"
kind = "generator"
bus = "can0"
id = 0x100
period_ms = 1
len = 2

[[device]]
name = "slow"
kind = "generator"
bus = "can0"
id = 0x200
period_ms = 2
start_ms = 0.5
count = 3
data = "CAFE"
"#;

#[test]
fn builds_buses_and_devices_that_run() {
    let s = Scenario::parse(TWO_GENERATORS, "two.toml").unwrap();
    assert_eq!(s.name, "two generators");
    assert_eq!(s.seed, 5);
    assert_eq!(s.buses.len(), 1);
    assert_eq!(s.buses[0].line, 6);
    assert_eq!(s.devices[1].line, 18);
    let mut built = s.build(&Registry::builtin(), &BuildEnv::default()).unwrap();
    let can0 = built.bus("can0").unwrap();
    let rec = built
        .sim
        .bus_mut(can0)
        .unwrap()
        .add_tap(cantwin_bus::Recorder::new());
    built
        .sim
        .run_until(Instant::ZERO + Duration::from_millis(10));
    let bus = built.sim.bus(can0).unwrap();
    let frames: Vec<String> = bus
        .tap::<cantwin_bus::Recorder>(rec)
        .unwrap()
        .frames()
        .map(|f| f.frame.to_string())
        .collect();
    // 0x100 every ms with a 2-byte counter (10 frames in 10 ms), 0x200 three times only.
    assert_eq!(frames.iter().filter(|f| f.starts_with("100#")).count(), 10);
    assert_eq!(frames.iter().filter(|f| *f == "200#CAFE").count(), 3);
    assert_eq!(frames[0], "100#0000");
    assert!(frames.contains(&"100#0900".to_string()));
}

#[test]
fn toml_syntax_errors_name_file_and_line() {
    let e = err("[[bus]]\nname = \"can0\"\nbit_rate = \n");
    assert!(e.starts_with("s.toml:3:"), "{e}");
}

#[test]
fn unknown_top_level_keys_are_refused() {
    let e = err("nmae = \"x\"\n[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n");
    assert!(e.starts_with("s.toml:1:"), "{e}");
    assert!(e.contains("nmae"), "{e}");
}

#[test]
fn bad_bit_rate_names_its_line_and_key() {
    let e = err("[[bus]]\nname = \"can0\"\nbit_rate = \"33k\"\n");
    assert_eq!(
        e,
        "s.toml:3: key `bus[0].bit_rate`: unsupported CAN bit rate \"33k\": use one of 10k, 20k, 50k, 100k, 125k, 250k, 500k, 800k, 1M"
    );
}

#[test]
fn a_scenario_needs_a_bus() {
    let e = err("name = \"empty\"\n");
    assert!(e.contains("at least one [[bus]]"), "{e}");
}

#[test]
fn duplicate_bus_and_device_names() {
    let e = err(
        "[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n",
    );
    assert_eq!(
        e,
        "s.toml:5: key `bus[1].name`: a bus named \"can0\" is already defined"
    );
    let dev =
        "[[device]]\nname = \"g\"\nkind = \"generator\"\nbus = \"can0\"\nid = 1\nperiod_ms = 1\n";
    let e = err(&format!(
        "[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n{dev}{dev}"
    ));
    assert_eq!(
        e,
        "s.toml:11: key `device[1].name`: a device named \"g\" is already defined"
    );
}

#[test]
fn device_on_unknown_bus() {
    let e = err(
        "[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n[[device]]\nname = \"g\"\nkind = \"generator\"\nbus = \"can9\"\n",
    );
    assert_eq!(
        e,
        "s.toml:7: key `device[0].bus`: no bus named \"can9\" (buses: can0)"
    );
}

#[test]
fn unknown_kind_lists_the_known_ones() {
    let e = err(
        "[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n[[device]]\nname = \"g\"\nkind = \"toaster\"\nbus = \"can0\"\n",
    );
    assert!(
        e.starts_with(
            "s.toml:4: key `device[0].kind`: unknown device kind \"toaster\" (kinds: generator"
        ),
        "{e}"
    );
}

#[test]
fn kind_settings_errors_name_line_and_key() {
    let base = "[[bus]]\nname = \"can0\"\nbit_rate = \"1M\"\n[[device]]\nname = \"g\"\nkind = \"generator\"\nbus = \"can0\"\n";
    assert_eq!(
        err(&format!("{base}period_ms = 1\n")),
        "s.toml:4: key `device[0].id`: a generator device needs `id`"
    );
    assert_eq!(
        err(&format!("{base}id = 0x800\nperiod_ms = 1\n")),
        "s.toml:8: key `device[0].id`: identifier 0x800 is out of range for a 11-bit frame"
    );
    let e = err(&format!("{base}id = \"x\"\nperiod_ms = 1\n"));
    assert!(e.starts_with("s.toml:8: key `device[0].id`: "), "{e}");
    let e = err(&format!("{base}id = 1\nperiod_ms = 1\nperoid = 3\n"));
    assert!(
        e.starts_with(
            "s.toml:10: key `device[0].peroid`: unknown key `peroid` for a generator device"
        ),
        "{e}"
    );
    assert_eq!(
        err(&format!("{base}id = 1\nperiod_ms = 0\n")),
        "s.toml:9: key `device[0].period_ms`: `period_ms` must be greater than 0"
    );
    assert_eq!(
        err(&format!("{base}id = 1\nperiod_ms = 1\ndata = \"XYZ\"\n")),
        "s.toml:10: key `device[0].data`: `data` is counter, random, or 0–8 bytes of hex"
    );
}

#[test]
fn missing_file_is_a_clear_error() {
    match Scenario::load("/nonexistent/dir/x.toml") {
        Err(ScenarioError::Io { file, .. }) => assert!(file.ends_with("x.toml")),
        other => panic!("{other:?}"),
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]
    /// Any text is either a scenario or an error with a location; never a panic.
    #[test]
    fn arbitrary_text_never_panics(text in "\\PC{0,200}") {
        let _ = Scenario::parse(&text, "p.toml").map(|s| s.build(&Registry::builtin(), &BuildEnv::default()).map(|_| ()));
    }

    /// Mutations of a valid file never panic.
    #[test]
    fn mutated_scenarios_never_panic(cut in 0usize..400, insert in "[a-z0-9=\"\\[\\]. \n]{0,12}") {
        let mut t = TWO_GENERATORS.to_string();
        let at = cut.min(t.len());
        if t.is_char_boundary(at) {
            t.insert_str(at, &insert);
        }
        let _ = Scenario::parse(&t, "p.toml").map(|s| s.build(&Registry::builtin(), &BuildEnv::default()).map(|_| ()));
    }
}
