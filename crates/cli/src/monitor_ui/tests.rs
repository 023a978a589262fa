//! Snapshot tests of the monitor's screen: the shipped monitor network runs in virtual time,
//! its frames feed a `NetworkView`, and the screen is drawn into ratatui's `TestBackend`.

use cantwin_bus::Recorder;
use cantwin_can::{Duration, Frame, Id, Instant};
use cantwin_monitor::{Config, NetworkView};
use cantwin_scenario::Scenario;
use ratatui::Terminal;
use ratatui::backend::TestBackend;
use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use ratatui::style::{Color, Modifier};

use super::*;
use crate::monitor::{declared_nodes, view_for_scenario};

const WIDTH: u16 = 180;
const HEIGHT: u16 = 50;

fn scenario(name: &str) -> Scenario {
    Scenario::load(format!(
        "{}/../../scenarios/{name}",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap()
}

/// The monitor network after `ms` of virtual time, every frame pushed at its end of frame.
fn network(ms: u64) -> NetworkView {
    let (mut view, mut built) = view_for_scenario(
        &scenario("monitor-network.toml"),
        None,
        Config::default(),
        None,
        &[],
    )
    .unwrap();
    let bus = built.bus("can0").unwrap();
    let tap = built.sim.bus_mut(bus).unwrap().add_tap(Recorder::new());
    let end = Instant::from_nanos(ms * 1_000_000);
    built.sim.run_until(end);
    let recorder = built.sim.bus(bus).unwrap().tap::<Recorder>(tap).unwrap();
    for r in recorder.frames().filter(|r| !r.dropped) {
        view.push(r.end, &r.frame);
    }
    view.advance(end);
    view
}

fn render(view: &NetworkView, ui: &Ui) -> Vec<String> {
    render_at(view, ui, WIDTH, HEIGHT)
}

fn render_at(view: &NetworkView, ui: &Ui, width: u16, height: u16) -> Vec<String> {
    let mut terminal = Terminal::new(TestBackend::new(width, height)).unwrap();
    terminal.draw(|f| draw(f, view, ui)).unwrap();
    let buffer = terminal.backend().buffer();
    (0..height)
        .map(|y| {
            (0..width)
                .map(|x| buffer[(x, y)].symbol().to_string())
                .collect::<String>()
        })
        .collect()
}

fn key(code: KeyCode) -> KeyEvent {
    KeyEvent::new(code, KeyModifiers::NONE)
}

/// The line of the node table for `id`: it starts with the id in the first column.
fn node_row(screen: &[String], id: u8) -> String {
    screen
        .iter()
        .find(|l| {
            let first = l
                .trim_start_matches(['│', '>', ' '])
                .split_whitespace()
                .next();
            first == Some(id.to_string().as_str())
        })
        .cloned()
        .unwrap_or_default()
}

/// Whether one line of the screen holds `name` followed by `value`.
fn shows(screen: &[String], name: &str, value: &str) -> bool {
    screen.iter().any(|l| {
        l.find(name)
            .is_some_and(|i| l[i + name.len()..].contains(value))
    })
}

#[test]
fn scenario_nodes_are_declared_with_ids_and_kinds() {
    let built = scenario("monitor-network.toml")
        .build(&cantwin_scenario::Registry::builtin(), &Default::default())
        .unwrap();
    let nodes: Vec<(u8, String, Option<String>)> = declared_nodes(&built)
        .into_iter()
        .map(|d| (d.node, d.name, d.kind.map(|k| k.name)))
        .collect();
    assert_eq!(
        nodes,
        [
            (3, "island".to_string(), Some("TM3".to_string())),
            (5, "node5".to_string(), None),
            (12, "drive".to_string(), Some("ADV200".to_string())),
        ]
    );
}

#[test]
fn monitor_screen_shows_nodes_states_emcy_and_live_values() {
    let view = network(1_700);
    let screen = render(&view, &Ui::new("scenario monitor-network.toml".into()));
    let text = screen.join("\n");
    assert!(text.contains("cantwin monitor"), "{text}");
    assert!(text.contains("bus time 1.700 s"), "{text}");
    // Every node is operational after the NMT start at 300 ms, with a recent heartbeat.
    for (id, name) in [(3, "island"), (5, "node5"), (12, "drive")] {
        let row = node_row(&screen, id);
        assert!(row.contains(name), "node {id}: {row:?}\n{text}");
        assert!(row.contains("operational"), "node {id}: {row:?}");
        assert!(!row.contains("pre-operational"), "node {id}: {row:?}");
        let hb = view.node(id).unwrap().heartbeat_age(view.now()).unwrap();
        assert!(hb < Duration::from_millis(200), "node {id}: {hb:?}");
        assert!(row.contains(" ms"), "node {id}: {row:?}");
    }
    // Node 5 raised EMCY 0x4210 at 1.5 s through its trigger object.
    let row5 = node_row(&screen, 5);
    assert!(row5.contains("0x4210 temperature"), "{row5:?}");
    // The error register is sent with the EMCY: bit 0 generic, bit 1 temperature… as the
    // twin sets it; the table shows the model's value.
    let er = view.node(5).unwrap().error_register.unwrap();
    assert!(row5.contains(&format!(" {er:02X} ")), "{row5:?}");
    assert!(
        text.contains("EMCY node 5 code 0x4210 (temperature)"),
        "{text}"
    );
    // The coupler's own code from its manual, not the generic table's "unknown".
    let row3 = node_row(&screen, 3);
    assert!(row3.contains("0x0080 analog input interrupts"), "{row3:?}");
    // The first node (3, the TM3 island) is selected: its panel shows decoded CiA 401 inputs.
    assert!(text.contains("node 3  island  TM3"), "{text}");
    let di = view.node(3).unwrap().value("DI byte 1").unwrap();
    assert!(
        shows(&screen, "  DI byte 1 ", &di.text),
        "{}\n{text}",
        di.text
    );
    // Inputs 0 and 5 of module 1 are on.
    assert_eq!(di.text, "0010_0001");
    assert!(
        text.contains("bus load (500 kbit/s, 100 ms windows)"),
        "{text}"
    );
    assert!(text.contains(HELP), "{text}");
}

#[test]
fn the_selected_drive_shows_its_pdo_values() {
    let view = network(1_700);
    let mut ui = Ui::new(String::new());
    ui.on_key(key(KeyCode::Down), &view);
    ui.on_key(key(KeyCode::Down), &view);
    assert_eq!(ui.selected, Some(12));
    let screen = render(&view, &ui);
    let text = screen.join("\n");
    assert!(text.contains("node 12  drive  ADV200"), "{text}");
    // The generator's RPDO1: enable + start, 1500 rpm.
    assert!(
        shows(&screen, "  control word ", "0x0003 enable, start"),
        "{text}"
    );
    assert!(
        shows(&screen, "  ramp ref 1 ", "1500 rpm  (RPDO1"),
        "{text}"
    );
    // The drive's TPDO1: enable state and drive ok, digital input 4 on, the motor turning.
    assert!(
        shows(&screen, "  status word ", "enable state, drive ok, DI 4"),
        "{text}"
    );
    let speed = view.node(12).unwrap().value("motor speed").unwrap();
    assert!(shows(&screen, "  motor speed ", &speed.text), "{text}");
    assert!(
        speed.text.ends_with(" rpm") && speed.text != "0 rpm",
        "{}",
        speed.text
    );
    // One more Down stays on the last node.
    ui.on_key(key(KeyCode::Down), &view);
    assert_eq!(ui.selected, Some(12));
}

#[test]
fn filter_keys_narrow_the_stream_and_bad_filters_say_why() {
    let view = network(1_700);
    let mut ui = Ui::new(String::new());
    assert_eq!(ui.on_key(key(KeyCode::Char('/')), &view), Flow::Continue);
    for c in "svc=emcy".chars() {
        ui.on_key(key(KeyCode::Char(c)), &view);
    }
    // While typing, `q` is text, not quit.
    assert_eq!(ui.on_key(key(KeyCode::Char('q')), &view), Flow::Continue);
    ui.on_key(key(KeyCode::Backspace), &view);
    assert!(render(&view, &ui).join("\n").contains("filter: svc=emcy"));
    ui.on_key(key(KeyCode::Enter), &view);
    assert_eq!(ui.filter, Filter::parse("svc=emcy").unwrap());
    let shown = ui.visible(&view, 100);
    assert!(!shown.is_empty());
    assert!(
        shown
            .iter()
            .all(|e| e.service == cantwin_monitor::Service::Emcy)
    );
    let text = render(&view, &ui).join("\n");
    assert!(text.contains("filter: svc=emcy"), "{text}");
    assert!(!text.contains("TPDO1 node 12"), "{text}");
    ui.on_key(key(KeyCode::Char('/')), &view);
    for c in " node=200".chars() {
        ui.on_key(key(KeyCode::Char(c)), &view);
    }
    ui.on_key(key(KeyCode::Enter), &view);
    assert_eq!(ui.filter, Filter::parse("svc=emcy").unwrap(), "kept");
    let text = render(&view, &ui).join("\n");
    assert!(
        text.contains("filter: node 200 is not a node-ID 1-127"),
        "{text}"
    );
    ui.on_key(key(KeyCode::Char('c')), &view);
    assert!(ui.filter.is_empty());
    assert_eq!(ui.on_key(key(KeyCode::Char('q')), &view), Flow::Quit);
    assert_eq!(
        ui.on_key(
            KeyEvent::new(KeyCode::Char('c'), KeyModifiers::CONTROL),
            &view
        ),
        Flow::Quit
    );
}

#[test]
fn pause_freezes_the_stream_and_scrolling_stays_within_it() {
    let mut view = NetworkView::new(Config::default());
    let f = |i: u64| Frame::data(Id::standard(0x181).unwrap(), &i.to_le_bytes()).unwrap();
    for i in 0..50 {
        view.push(Instant::from_nanos(i * 1_000_000), &f(i));
    }
    let mut ui = Ui::new(String::new());
    let seqs = |ui: &Ui, view: &NetworkView| -> Vec<u64> {
        ui.visible(view, 5).iter().map(|e| e.seq).collect()
    };
    assert_eq!(seqs(&ui, &view), [45, 46, 47, 48, 49]);
    ui.on_key(key(KeyCode::Char(' ')), &view);
    view.push(Instant::from_nanos(60_000_000), &f(50));
    assert_eq!(seqs(&ui, &view), [45, 46, 47, 48, 49], "paused");
    assert!(render(&view, &ui).join("\n").contains("PAUSED"));
    ui.on_key(key(KeyCode::PageUp), &view);
    assert_eq!(seqs(&ui, &view), [35, 36, 37, 38, 39]);
    ui.on_key(key(KeyCode::Home), &view);
    assert_eq!(seqs(&ui, &view), [0, 1, 2, 3, 4]);
    ui.on_key(key(KeyCode::PageDown), &view);
    ui.on_key(key(KeyCode::End), &view);
    assert_eq!(ui.paused_at, None);
    assert_eq!(seqs(&ui, &view), [46, 47, 48, 49, 50]);
    // PgUp from live pauses at the newest frame.
    ui.on_key(key(KeyCode::PageUp), &view);
    assert_eq!(ui.paused_at, Some(50));
    ui.on_key(key(KeyCode::Char(' ')), &view);
    assert_eq!((ui.paused_at, ui.scroll), (None, 0));
}

#[test]
fn an_empty_bus_renders_without_nodes() {
    let view = NetworkView::new(Config::default());
    let mut ui = Ui::new("socketcand 127.0.0.1:29536 can0".into());
    // Keys on an empty view change nothing and do not panic.
    for code in [KeyCode::Up, KeyCode::Down, KeyCode::Home, KeyCode::PageUp] {
        ui.on_key(key(code), &view);
    }
    let text = render(&view, &ui).join("\n");
    assert!(text.contains("no node heard yet"), "{text}");
    assert!(text.contains("nodes (0)"), "{text}");
    assert!(text.contains("socketcand 127.0.0.1:29536 can0"), "{text}");
}

#[test]
fn a_generic_twin_has_its_pdo_values_named_from_its_dictionary() {
    let view = network(1_700);
    let mut ui = Ui::new(String::new());
    ui.on_key(key(KeyCode::Down), &view);
    assert_eq!(ui.selected, Some(5));
    let screen = render(&view, &ui);
    let text = screen.join("\n");
    let n5 = view.node(5).unwrap();
    assert!(n5.kind.is_none());
    // TPDO1 maps 0x2100 sub 1 (UNSIGNED16, "Input 1"): the value is bytes 0-1 of the last
    // TPDO1, little-endian.
    let first = &n5.values[0].0;
    assert_eq!(first.name, "Input 1");
    let last = view
        .frames()
        .rev()
        .find(|e| e.frame.id().as_raw() == 0x185)
        .unwrap();
    let d = last.frame.data_bytes();
    assert_eq!(
        first.text,
        u16::from_le_bytes([d[0], d[1]]).to_string(),
        "{first:?}"
    );
    assert!(
        shows(&screen, &format!("  {} ", first.name), &first.text),
        "{text}"
    );
    assert!(
        text.contains(&format!("{}={}", first.name, first.text)),
        "{text}"
    );
}

#[test]
fn small_terminals_get_what_fits() {
    let view = network(700);
    let mut ui = Ui::new("scenario monitor-network.toml".into());
    ui.on_key(key(KeyCode::PageUp), &view);
    for (w, h) in [(1, 1), (20, 5), (80, 24), (100, 12)] {
        let screen = render_at(&view, &ui, w, h);
        assert_eq!(screen.len(), usize::from(h));
    }
    // A standard 80×24 terminal still shows the title, the nodes and the help line.
    let screen = render_at(&view, &ui, 80, 24);
    assert!(screen[0].starts_with("cantwin monitor"), "{}", screen[0]);
    assert!(
        node_row(&screen, 12).contains("drive"),
        "{}",
        screen.join("\n")
    );
    assert!(screen[23].starts_with("q quit"), "{}", screen[23]);
}

/// The line of the fixed trace for identifier `id` (as the table prints it).
fn fixed_row(screen: &[String], id: &str) -> String {
    screen
        .iter()
        .find(|l| l.trim_start_matches(['│', ' ']).split_whitespace().next() == Some(id))
        .cloned()
        .unwrap_or_default()
}

#[test]
fn t_toggles_the_fixed_trace_one_row_per_identifier() {
    let view = network(1_700);
    let mut ui = Ui::new(String::new());
    assert_eq!(ui.on_key(key(KeyCode::Char('t')), &view), Flow::Continue);
    assert_eq!(ui.mode, TraceMode::Fixed);
    let screen = render(&view, &ui);
    let text = screen.join("\n");
    let rows = view.fixed_trace().rows().len();
    assert!(
        text.contains(&format!("fixed trace · LIVE · {rows} identifiers")),
        "{text}"
    );
    assert!(text.contains("Δt ms") && text.contains("min ms") && text.contains("max ms"));
    // The drive's heartbeat (0x70C): its count, its cycle times and its last state decoded.
    let key70c = cantwin_monitor::fixed_trace::RowKey {
        id: 0x70C,
        extended: false,
        remote: false,
    };
    let hb = view.fixed_trace().row(&key70c).unwrap();
    let line = fixed_row(&screen, "70C");
    let words: Vec<&str> = line
        .trim_start_matches(['│', ' '])
        .split_whitespace()
        .collect();
    assert_eq!(words[1], hb.count.to_string(), "{line}");
    assert_eq!(words[2], millis(hb.cycle.last), "{line}");
    assert_eq!(words[3], millis(hb.cycle.min), "{line}");
    assert_eq!(words[4], millis(hb.cycle.max), "{line}");
    assert!(line.contains("HEARTBEAT node 12 operational"), "{line}");
    // One line per identifier: the 0x70C row appears once although many heartbeats came.
    assert!(hb.count > 5);
    assert_eq!(
        screen
            .iter()
            .filter(|l| l.contains("HEARTBEAT node 12"))
            .count(),
        1
    );
    // t again: the scrolling trace, every frame.
    ui.on_key(key(KeyCode::Char('t')), &view);
    let text = render(&view, &ui).join("\n");
    assert!(text.contains("frames · LIVE"), "{text}");
    assert!(text.matches("HEARTBEAT node 12").count() > 1, "{text}");
}

#[test]
fn the_fixed_trace_marks_the_bytes_the_last_frame_changed_and_pauses() {
    let mut view = NetworkView::new(Config::default());
    let f = |d: &[u8]| Frame::data(Id::standard(0x181).unwrap(), d).unwrap();
    view.push(Instant::from_nanos(0), &f(&[0x11, 0x22, 0x33]));
    view.push(Instant::from_nanos(10_000_000), &f(&[0x11, 0x99, 0x33]));
    let mut ui = Ui::new(String::new());
    ui.on_key(key(KeyCode::Char('t')), &view);
    let mut terminal = Terminal::new(TestBackend::new(WIDTH, HEIGHT)).unwrap();
    terminal.draw(|fr| draw(fr, &view, &ui)).unwrap();
    let buffer = terminal.backend().buffer().clone();
    let (y, line) = (0..HEIGHT)
        .map(|y| {
            let l: String = (0..WIDTH)
                .map(|x| buffer[(x, y)].symbol().to_string())
                .collect();
            (y, l)
        })
        .find(|(_, l)| l.contains("11 99 33"))
        .unwrap();
    let x = |text: &str| {
        line.find(text)
            .map(|i| line[..i].chars().count() as u16)
            .unwrap()
    };
    let changed = &buffer[(x("99"), y)];
    let same = &buffer[(x("11 99"), y)];
    assert_eq!(changed.fg, Color::Yellow);
    assert!(changed.modifier.contains(Modifier::BOLD));
    assert_ne!(same.fg, Color::Yellow);
    // Paused, the table stays as it was while frames go on.
    ui.on_key(key(KeyCode::Char(' ')), &view);
    view.push(Instant::from_nanos(20_000_000), &f(&[0x00]));
    let text = render(&view, &ui).join("\n");
    assert!(text.contains("fixed trace · PAUSED"), "{text}");
    assert!(text.contains("11 99 33"), "{text}");
    ui.on_key(key(KeyCode::Char(' ')), &view);
    let text = render(&view, &ui).join("\n");
    assert!(
        !text.contains("11 99 33") && text.contains("LIVE"),
        "{text}"
    );
}

#[test]
fn esc_leaves_the_filter_editor_and_never_quits() {
    let view = network(700);
    let mut ui = Ui::new(String::new());
    // A rejected filter, then Esc: the monitor goes on.
    ui.on_key(key(KeyCode::Char('/')), &view);
    for c in "node=200".chars() {
        ui.on_key(key(c_code(c)), &view);
    }
    ui.on_key(key(KeyCode::Enter), &view);
    assert!(ui.message.is_some());
    assert_eq!(ui.on_key(key(KeyCode::Esc), &view), Flow::Continue);
    // Esc while editing leaves the editor, keeping the filter in force.
    ui.on_key(key(KeyCode::Char('/')), &view);
    assert!(ui.editing.is_some());
    assert_eq!(ui.on_key(key(KeyCode::Esc), &view), Flow::Continue);
    assert!(ui.editing.is_none());
    assert_eq!(ui.on_key(key(KeyCode::Esc), &view), Flow::Continue);
    assert_eq!(ui.on_key(key(KeyCode::Char('q')), &view), Flow::Quit);
}

fn c_code(c: char) -> KeyCode {
    KeyCode::Char(c)
}

#[test]
fn an_80x24_terminal_shows_whole_names_states_kinds_and_decoded_text() {
    let view = network(1_700);
    let mut ui = Ui::new("scenario monitor-network.toml".into());
    let screen = render_at(&view, &ui, 80, 24);
    let text = screen.join("\n");
    for (id, name, kind) in [
        (3, "island", "TM3"),
        (5, "node5", "CiA 301"),
        (12, "drive", "ADV200"),
    ] {
        let row = node_row(&screen, id);
        assert!(
            row.contains(&format!(" {name} ")),
            "node {id}: {row:?}\n{text}"
        );
        assert!(
            row.contains(&format!(" {kind} ")),
            "node {id}: {row:?}\n{text}"
        );
        assert!(row.contains(" operational "), "node {id}: {row:?}\n{text}");
    }
    assert!(
        node_row(&screen, 5).contains("0x4210 temperature"),
        "{text}"
    );
    // The load on one line, the decoded frames below it.
    assert!(text.contains("frames/s"), "{text}");
    assert!(text.contains("(500 kbit/s, 100 ms windows)"), "{text}");
    assert!(
        text.contains("HEARTBEAT node") || text.contains("TPDO1 node"),
        "{text}"
    );
    assert!(screen[23].starts_with("q quit"), "{}", screen[23]);
    // The title keeps the trace mode and the bus time; only the source's tail may be cut.
    assert!(
        screen[0].starts_with("cantwin monitor  scrolling trace  bus time "),
        "{}",
        screen[0]
    );
    assert!(HELP_NARROW.chars().count() <= 80);
    assert!(
        screen[23].trim_end().ends_with("/ filter"),
        "{}",
        screen[23]
    );
    // The fixed trace fits too, with its decoded text.
    ui.on_key(key(KeyCode::Char('t')), &view);
    let screen = render_at(&view, &ui, 80, 24);
    assert!(
        screen[0].starts_with("cantwin monitor  fixed trace  bus time "),
        "{}",
        screen[0]
    );
    let line = fixed_row(&screen, "18C");
    assert!(
        line.contains("TPDO1 node 12: status word="),
        "{}",
        screen.join("\n")
    );
    // PgDn scrolls the rows (the last page stays full): the heartbeats come into view.
    ui.on_key(key(KeyCode::PageDown), &view);
    ui.on_key(key(KeyCode::PageDown), &view);
    let screen = render_at(&view, &ui, 80, 24);
    assert!(
        fixed_row(&screen, "70C").contains("HEARTBEAT node 12 operational"),
        "{}",
        screen.join("\n")
    );
    ui.on_key(key(KeyCode::Home), &view);
    // Enter shows the selected node's page in place of the trace; Esc goes back.
    ui.on_key(key(KeyCode::Enter), &view);
    let text = render_at(&view, &ui, 80, 24).join("\n");
    assert!(text.contains("node 3  island  TM3"), "{text}");
    assert!(text.contains("DI byte 1"), "{text}");
    assert!(
        text.contains("heartbeat") && text.contains(" ago, every "),
        "{text}"
    );
    ui.on_key(key(KeyCode::Esc), &view);
    assert!(
        render_at(&view, &ui, 80, 24)
            .join("\n")
            .contains("fixed trace")
    );
}

#[test]
fn the_load_says_when_its_bit_rate_is_assumed() {
    let view = NetworkView::new(Config::default());
    let mut ui = Ui::new(String::new());
    ui.bit_rate_assumed = true;
    let wide = render(&view, &ui).join("\n");
    assert!(
        wide.contains("bus load (500 kbit/s assumed, 100 ms windows)"),
        "{wide}"
    );
    let narrow = render_at(&view, &ui, 80, 24).join("\n");
    assert!(
        narrow.contains("(500 kbit/s assumed, 100 ms windows)"),
        "{narrow}"
    );
}

#[test]
fn the_fixed_trace_widens_its_identifier_column_for_extended_identifiers() {
    let mut view = NetworkView::new(Config::default());
    view.push(
        Instant::from_nanos(0),
        &Frame::data(Id::standard(0x181).unwrap(), &[1]).unwrap(),
    );
    let mut ui = Ui::new(String::new());
    ui.on_key(key(KeyCode::Char('t')), &view);
    let screen = render_at(&view, &ui, 80, 24);
    assert!(
        screen.iter().any(|l| l.starts_with("│ 181 ")),
        "{}",
        screen.join("\n")
    );
    view.push(
        Instant::from_nanos(1_000_000),
        &Frame::data(Id::extended(0x18FF_0001).unwrap(), &[2]).unwrap(),
    );
    let screen = render_at(&view, &ui, 80, 24);
    assert!(
        screen.iter().any(|l| l.starts_with("│      181 ")),
        "{}",
        screen.join("\n")
    );
    assert!(
        screen.iter().any(|l| l.starts_with("│ 18FF0001 ")),
        "{}",
        screen.join("\n")
    );
}
