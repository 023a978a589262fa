//! The screen of `cantwin monitor`: [`draw`] is a pure function of the model
//! ([`NetworkView`]) and the UI state ([`Ui`]), so tests render it into a test backend;
//! [`Ui::on_key`] is the only place keys change anything.
//!
//! Keys: `q` quits (also Ctrl-C; `Esc` only leaves the filter editor or the device page),
//! `↑`/`↓` (or `k`/`j`) select a node, `t` toggles the scrolling and the fixed trace (one
//! row per identifier, overwritten by each frame, as CANalyzer and PCAN-View show a bus),
//! `space` pauses either, `PgUp`/`PgDn` scroll (the stream pauses), `Home` goes to the oldest
//! frame kept or the first row, `End` back to the live end, `/` edits the filter (`Enter`
//! applies, `Esc` cancels), `c` clears it, `Enter` shows the selected node's page on a
//! terminal too narrow to show it beside the trace.
//!
//! Below [`WIDE`] columns the screen stacks: the node table over the whole width, the load
//! on one line, the trace (or the device page) under it, so that an 80×24 terminal shows
//! every column and the decoded text.

use cantwin_can::{Duration, Instant};
use cantwin_monitor::fixed_trace::Row as FixedRow;
use cantwin_monitor::{Filter, FixedTrace, FrameEntry, Led, NetworkView, NodeInfo};
use cantwin_report::canopen::hex_bytes;
use ratatui::Frame;
use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Cell, Paragraph, Row, Sparkline, Table, TableState};

/// Frames a `PgUp`/`PgDn` moves.
pub const PAGE: usize = 10;

/// The narrowest terminal that shows the load and the device page beside the node table and
/// the trace; narrower ones stack them.
pub const WIDE: u16 = 120;

/// Which trace the lower part shows.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum TraceMode {
    /// Every frame, newest at the bottom.
    #[default]
    Scrolling,
    /// One row per identifier, overwritten in place.
    Fixed,
}

/// What the loop does after a key.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flow {
    /// Go on.
    Continue,
    /// Leave the monitor.
    Quit,
}

/// The state of the screen, apart from the model.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Ui {
    /// Where the bus is (shown in the title).
    pub source: String,
    /// The selected node (its node-ID).
    pub selected: Option<u8>,
    /// The newest frame shown while the stream is paused.
    pub paused_at: Option<u64>,
    /// Frames back from the newest shown.
    pub scroll: usize,
    /// The filter of the frame stream.
    pub filter: Filter,
    /// The filter text being typed, while editing.
    pub editing: Option<String>,
    /// A message for the help line (a filter that did not parse).
    pub message: Option<String>,
    /// The scrolling or the fixed trace.
    pub mode: TraceMode,
    /// The fixed trace as it was when paused.
    pub frozen: Option<FixedTrace>,
    /// Rows of the fixed trace scrolled past at the top.
    pub fixed_offset: usize,
    /// On a narrow terminal, the selected node's page is shown instead of the trace.
    pub device_page: bool,
    /// The bit rate of the load is the default, not the scenario's or a given one.
    pub bit_rate_assumed: bool,
}

impl Ui {
    /// A fresh screen for the bus at `source`.
    pub fn new(source: String) -> Ui {
        Ui {
            source,
            ..Ui::default()
        }
    }

    /// The selected node: the one chosen, else the first.
    pub fn selected_node<'a>(&self, view: &'a NetworkView) -> Option<&'a NodeInfo> {
        self.selected
            .and_then(|id| view.node(id))
            .or_else(|| view.nodes().next())
    }

    fn move_selection(&mut self, view: &NetworkView, down: bool) {
        let ids: Vec<u8> = view.nodes().map(|n| n.id).collect();
        let Some(current) = self.selected_node(view).map(|n| n.id) else {
            return;
        };
        let i = ids.iter().position(|&id| id == current).unwrap_or(0);
        let next = if down {
            (i + 1).min(ids.len().saturating_sub(1))
        } else {
            i.saturating_sub(1)
        };
        self.selected = ids.get(next).copied();
    }

    fn pause(&mut self, view: &NetworkView) {
        if self.paused_at.is_none() {
            self.paused_at = view.frames().last().map(|e| e.seq);
        }
        if self.frozen.is_none() {
            self.frozen = Some(view.fixed_trace().clone());
        }
    }

    fn resume(&mut self) {
        self.paused_at = None;
        self.frozen = None;
        self.scroll = 0;
    }

    /// Whether the trace is paused.
    pub fn paused(&self) -> bool {
        self.paused_at.is_some() || self.frozen.is_some()
    }

    /// The fixed trace shown: the frozen one while paused, else the live one.
    pub fn fixed_trace<'a>(&'a self, view: &'a NetworkView) -> &'a FixedTrace {
        self.frozen.as_ref().unwrap_or(view.fixed_trace())
    }

    /// The rows of the fixed trace shown in `rows` lines: those passing the filter, from
    /// `fixed_offset` (kept within the rows).
    pub fn fixed_rows<'a>(&'a self, view: &'a NetworkView, rows: usize) -> Vec<&'a FixedRow> {
        let shown: Vec<&FixedRow> = self.fixed_trace(view).filtered(&self.filter).collect();
        let start = self.fixed_offset.min(shown.len().saturating_sub(rows));
        shown.into_iter().skip(start).take(rows).collect()
    }

    /// Handle a key press.
    pub fn on_key(&mut self, key: KeyEvent, view: &NetworkView) -> Flow {
        if key.code == KeyCode::Char('c') && key.modifiers.contains(KeyModifiers::CONTROL) {
            return Flow::Quit;
        }
        if let Some(text) = &mut self.editing {
            match key.code {
                KeyCode::Enter => {
                    match Filter::parse(text) {
                        Ok(f) => {
                            self.filter = f;
                            self.scroll = 0;
                            self.fixed_offset = 0;
                            self.message = None;
                        }
                        Err(e) => self.message = Some(format!("filter: {e}")),
                    }
                    self.editing = None;
                }
                // Esc leaves the editor and keeps the filter in force; it never quits.
                KeyCode::Esc => self.editing = None,
                KeyCode::Backspace => {
                    text.pop();
                }
                KeyCode::Char(c) => text.push(c),
                _ => {}
            }
            return Flow::Continue;
        }
        self.message = None;
        let fixed = self.mode == TraceMode::Fixed;
        match key.code {
            KeyCode::Char('q') => return Flow::Quit,
            // Esc steps back (out of the device page, clears a message); it never quits.
            KeyCode::Esc => self.device_page = false,
            KeyCode::Enter => self.device_page = !self.device_page,
            KeyCode::Up | KeyCode::Char('k') => self.move_selection(view, false),
            KeyCode::Down | KeyCode::Char('j') => self.move_selection(view, true),
            KeyCode::Char('t') => {
                self.mode = if fixed {
                    TraceMode::Scrolling
                } else {
                    TraceMode::Fixed
                };
                self.device_page = false;
            }
            KeyCode::Char(' ') | KeyCode::Char('p') => {
                if self.paused() {
                    self.resume();
                } else {
                    self.pause(view);
                }
            }
            KeyCode::PageUp if fixed => self.fixed_offset = self.fixed_offset.saturating_sub(PAGE),
            KeyCode::PageDown if fixed => {
                let rows = self.fixed_trace(view).filtered(&self.filter).count();
                self.fixed_offset = (self.fixed_offset + PAGE).min(rows.saturating_sub(1));
            }
            KeyCode::Home if fixed => self.fixed_offset = 0,
            KeyCode::End if fixed => {
                self.resume();
                self.fixed_offset = 0;
            }
            KeyCode::PageUp => {
                self.pause(view);
                self.scroll = self.scroll.saturating_add(PAGE);
            }
            KeyCode::PageDown => self.scroll = self.scroll.saturating_sub(PAGE),
            KeyCode::Home => {
                self.pause(view);
                self.scroll = view.frames().len();
            }
            KeyCode::End => self.resume(),
            KeyCode::Char('/') | KeyCode::Char('f') => {
                self.editing = Some(self.filter.to_string());
            }
            KeyCode::Char('c') => {
                self.filter = Filter::default();
                self.scroll = 0;
                self.fixed_offset = 0;
            }
            _ => {}
        }
        Flow::Continue
    }

    /// The frames the stream shows in `rows` lines, oldest first: those passing the filter,
    /// up to the pause point, `scroll` back from the newest (kept within the frames).
    pub fn visible<'a>(&self, view: &'a NetworkView, rows: usize) -> Vec<&'a FrameEntry> {
        let shown: Vec<&FrameEntry> = view
            .frames()
            .filter(|e| e.matches(&self.filter) && self.paused_at.is_none_or(|p| e.seq <= p))
            .collect();
        let back = self.scroll.min(shown.len().saturating_sub(rows));
        let end = shown.len() - back;
        shown[end.saturating_sub(rows)..end].to_vec()
    }
}

/// Bus time as seconds with milliseconds.
pub fn seconds(t: Instant) -> String {
    let ms = t.as_nanos() / 1_000_000;
    format!("{}.{:03}", ms / 1000, ms % 1000)
}

fn age(d: Duration) -> String {
    let ms = d.as_nanos() / 1_000_000;
    if ms < 1000 {
        format!("{ms} ms")
    } else {
        format!("{:.1} s", ms as f64 / 1000.0)
    }
}

fn led_cell(led: Led, colour: Color) -> Cell<'static> {
    let style = match led {
        Led::Off | Led::Unknown => Style::default().fg(Color::DarkGray),
        _ => Style::default().fg(colour),
    };
    Cell::from(led.name()).style(style)
}

fn emcy_text(n: &NodeInfo) -> String {
    let meaning = n.emcy_meaning().unwrap_or_default();
    match &n.last_emcy {
        Some(e) if n.emcy_active => format!("0x{:04X} {meaning}", e.code),
        Some(e) => format!("0x{:04X} {meaning} (reset)", e.code),
        None => String::new(),
    }
}

/// A column as wide as its widest cell (or header), within `min..=max`.
fn fit<'a>(header: &str, cells: impl Iterator<Item = &'a str>, min: u16, max: u16) -> u16 {
    let widest = cells
        .map(|c| c.chars().count())
        .chain([header.chars().count()])
        .max()
        .unwrap_or(0);
    u16::try_from(widest).unwrap_or(max).clamp(min, max)
}

fn nodes_table(f: &mut Frame<'_>, area: Rect, view: &NetworkView, ui: &Ui) {
    let now = view.now();
    // The LED columns need room: on a narrow terminal the device page shows them.
    let wide = area.width >= WIDE * 68 / 100;
    let names: Vec<String> = view.nodes().map(|n| n.display_name().to_string()).collect();
    let kinds: Vec<String> = view
        .nodes()
        .map(|n| n.kind_label().unwrap_or_default())
        .collect();
    let mut header = vec!["ID", "name", "kind", "NMT", "HB age"];
    if wide {
        header.extend(["RUN", "ERR"]);
    }
    header.extend(["ER", "last EMCY"]);
    let rows: Vec<Row<'_>> = view
        .nodes()
        .zip(names.iter().zip(&kinds))
        .map(|(n, (name, kind))| {
            let leds = n.leds(now);
            let mut cells = vec![
                Cell::from(n.id.to_string()),
                Cell::from(name.clone()),
                Cell::from(kind.clone()),
                Cell::from(n.state_name()),
                Cell::from(n.heartbeat_age(now).map(age).unwrap_or_else(|| "-".into())),
            ];
            if wide {
                cells.push(led_cell(leds.run, Color::Green));
                cells.push(led_cell(leds.err, Color::Red));
            }
            cells.push(Cell::from(
                n.error_register
                    .map(|r| format!("{r:02X}"))
                    .unwrap_or_else(|| "-".into()),
            ));
            cells.push(Cell::from(emcy_text(n)));
            Row::new(cells)
        })
        .collect();
    let mut widths = vec![
        Constraint::Length(3),
        Constraint::Length(fit("name", names.iter().map(String::as_str), 4, 16)),
        Constraint::Length(fit("kind", kinds.iter().map(String::as_str), 4, 14)),
        // "pre-operational", the longest state name.
        Constraint::Length(15),
        Constraint::Length(8),
    ];
    if wide {
        widths.extend([Constraint::Length(12), Constraint::Length(12)]);
    }
    widths.extend([Constraint::Length(2), Constraint::Min(10)]);
    let selected = ui
        .selected_node(view)
        .and_then(|s| view.nodes().position(|n| n.id == s.id));
    let table = Table::new(rows, widths)
        .header(Row::new(header).style(Style::default().add_modifier(Modifier::BOLD)))
        .block(Block::bordered().title(format!(" nodes ({}) ", view.nodes().len())))
        .row_highlight_style(Style::default().add_modifier(Modifier::REVERSED))
        .highlight_symbol(">");
    let mut state = TableState::default().with_selected(selected);
    f.render_stateful_widget(table, area, &mut state);
}

/// The load and frame rate of the last complete window, the peak load, and the totals.
fn load_figures(view: &NetworkView) -> (f64, f64, f64) {
    let load = view.load();
    let loads = load.load_series();
    let fps = load.fps_series();
    // The last window is still filling: the figures are those of the one before.
    let complete = loads.len().saturating_sub(1);
    let now_load = complete.checked_sub(1).map(|i| loads[i]).unwrap_or(0.0);
    let now_fps = complete.checked_sub(1).map(|i| fps[i]).unwrap_or(0.0);
    let peak = loads[..complete].iter().copied().fold(0.0, f64::max);
    (now_load, peak, now_fps)
}

/// The load on one line, for narrow terminals.
fn load_line(view: &NetworkView, ui: &Ui) -> Line<'static> {
    let (now_load, peak, fps) = load_figures(view);
    let load = view.load();
    Line::from(vec![
        Span::styled(
            format!("load {:.1} %", now_load * 100.0),
            Style::default().fg(Color::Yellow),
        ),
        Span::raw(format!("  peak {:.1} %  ", peak * 100.0)),
        Span::styled(
            format!("{fps:.0} frames/s"),
            Style::default().fg(Color::Cyan),
        ),
        Span::raw(format!(
            "  ({} kbit/s{}, {} ms windows)",
            load.bit_rate().bits_per_second() / 1000,
            rate_note(ui),
            load.width().as_nanos() / 1_000_000
        )),
    ])
}

/// What the load's bit rate is based on, when it is no more than the default.
fn rate_note(ui: &Ui) -> &'static str {
    if ui.bit_rate_assumed { " assumed" } else { "" }
}

fn load_panel(f: &mut Frame<'_>, area: Rect, view: &NetworkView, ui: &Ui) {
    let load = view.load();
    let block = Block::bordered().title(format!(
        " bus load ({} kbit/s{}, {} ms windows) ",
        load.bit_rate().bits_per_second() / 1000,
        rate_note(ui),
        load.width().as_nanos() / 1_000_000
    ));
    let inner = block.inner(area);
    f.render_widget(block, area);
    let [load_text, load_chart, fps_text, fps_chart] = Layout::vertical([
        Constraint::Length(1),
        Constraint::Fill(1),
        Constraint::Length(1),
        Constraint::Fill(1),
    ])
    .areas(inner);
    let width = usize::from(inner.width);
    let loads = load.load_series();
    let fps = load.fps_series();
    let complete = loads.len().saturating_sub(1);
    let (now_load, peak, now_fps) = load_figures(view);
    f.render_widget(
        Paragraph::new(format!(
            "load {:.1} %  peak {:.1} %",
            now_load * 100.0,
            peak * 100.0
        )),
        load_text,
    );
    f.render_widget(
        Paragraph::new(format!(
            "{now_fps:.0} frames/s  {} frames",
            view.total_frames()
        )),
        fps_text,
    );
    // Newest at the right; per mille so that small loads still show.
    let tail = |series: &[f64], scale: f64| -> Vec<u64> {
        let start = complete.saturating_sub(width);
        series[start..complete]
            .iter()
            .map(|v| (v * scale).round() as u64)
            .collect()
    };
    f.render_widget(
        Sparkline::default()
            .data(tail(&loads, 1000.0))
            .style(Style::default().fg(Color::Yellow)),
        load_chart,
    );
    f.render_widget(
        Sparkline::default()
            .data(tail(&fps, 1.0))
            .style(Style::default().fg(Color::Cyan)),
        fps_chart,
    );
}

fn service_colour(service: cantwin_monitor::Service) -> Color {
    match service {
        cantwin_monitor::Service::Emcy => Color::Red,
        cantwin_monitor::Service::Nmt => Color::Magenta,
        cantwin_monitor::Service::Heartbeat => Color::Green,
        cantwin_monitor::Service::Sdo => Color::Blue,
        cantwin_monitor::Service::Pdo => Color::Cyan,
        cantwin_monitor::Service::Lss => Color::Yellow,
        _ => Color::Reset,
    }
}

fn frame_line(e: &FrameEntry) -> Line<'static> {
    let colour = service_colour(e.service);
    let id = if e.frame.is_extended() {
        format!("{:08X}", e.frame.id().as_raw())
    } else {
        format!("{:03X}", e.frame.id().as_raw())
    };
    let data = if e.frame.is_remote() {
        format!("R{}", e.frame.dlc())
    } else {
        hex_bytes(e.frame.data_bytes())
    };
    Line::from(vec![
        Span::raw(format!("{:>9} ", seconds(e.at))),
        Span::styled(format!("{id:>8} "), Style::default().fg(colour)),
        Span::raw(format!("{data:<23} ")),
        Span::styled(e.text.clone(), Style::default().fg(colour)),
    ])
}

/// Milliseconds with one decimal, for cycle times.
fn millis(d: Option<Duration>) -> String {
    match d {
        Some(d) => format!("{:.1}", d.as_nanos() as f64 / 1e6),
        None => "-".to_string(),
    }
}

/// The identifier as the frame lines show it: 3 hex digits, 8 for extended ones, `R` after a
/// remote request's.
fn id_text(key: &cantwin_monitor::fixed_trace::RowKey) -> String {
    let id = if key.extended {
        format!("{:08X}", key.id)
    } else {
        format!("{:03X}", key.id)
    };
    if key.remote { format!("{id}R") } else { id }
}

/// Widths of the fixed trace's columns: identifier (room for an extended one and `R`),
/// count, Δt, min, max, data.
const FIXED_COLUMNS: [usize; 6] = [9, 7, 8, 8, 8, 23];

/// The identifier column's width when only standard identifiers are shown (`70C`, `70CR`).
const STANDARD_ID_WIDTH: usize = 4;

/// The inner width below which the fixed trace leaves out the data bytes, so that the
/// decoded text keeps its room (the scrolling trace shows both).
const FIXED_DATA_WIDTH: u16 = 100;

fn fixed_header(with_data: bool, id: usize) -> Line<'static> {
    let [_, count, dt, min, max, data] = FIXED_COLUMNS;
    let data = if with_data {
        format!("{:<data$} ", "last data")
    } else {
        String::new()
    };
    Line::from(Span::styled(
        format!(
            "{:>id$} {:>count$} {:>dt$} {:>min$} {:>max$} {data}decoded",
            "ID", "count", "Δt ms", "min ms", "max ms"
        ),
        Style::default().add_modifier(Modifier::BOLD),
    ))
}

/// One row of the fixed trace: the bytes the last frame changed stand out (the delta).
/// Without room for the data, a frame without decoded text shows its bytes instead.
fn fixed_line(r: &FixedRow, with_data: bool, id: usize) -> Line<'static> {
    let [_, count, dt, min, max, data] = FIXED_COLUMNS;
    let colour = service_colour(r.service());
    let mut spans = vec![
        Span::styled(
            format!("{:>id$} ", id_text(&r.key)),
            Style::default().fg(colour),
        ),
        Span::raw(format!(
            "{:>count$} {:>dt$} {:>min$} {:>max$} ",
            r.count,
            millis(r.cycle.last),
            millis(r.cycle.min),
            millis(r.cycle.max)
        )),
    ];
    let frame = &r.last.frame;
    if !with_data && !r.last.text.is_empty() {
        spans.push(Span::styled(
            r.last.text.clone(),
            Style::default().fg(colour),
        ));
        return Line::from(spans);
    }
    let mut used = 0;
    if frame.is_remote() {
        let text = format!("R{}", frame.dlc());
        used = text.len();
        spans.push(Span::raw(text));
    } else {
        for (i, b) in frame.data_bytes().iter().enumerate() {
            if i > 0 {
                spans.push(Span::raw(" "));
                used += 1;
            }
            let style = if r.changed & (1 << i) != 0 {
                Style::default()
                    .fg(Color::Yellow)
                    .add_modifier(Modifier::BOLD)
            } else {
                Style::default()
            };
            spans.push(Span::styled(format!("{b:02X}"), style));
            used += 2;
        }
    }
    spans.push(Span::raw(" ".repeat(data.saturating_sub(used) + 1)));
    spans.push(Span::styled(
        r.last.text.clone(),
        Style::default().fg(colour),
    ));
    Line::from(spans)
}

fn state_word(ui: &Ui) -> &'static str {
    if ui.paused() { "PAUSED" } else { "LIVE" }
}

fn filter_text(ui: &Ui) -> String {
    if ui.filter.is_empty() {
        String::new()
    } else {
        format!(" filter: {} ·", ui.filter)
    }
}

fn fixed_panel(f: &mut Frame<'_>, area: Rect, view: &NetworkView, ui: &Ui) {
    let trace = ui.fixed_trace(view);
    let full = if trace.overflow() > 0 {
        format!(
            ", {} frames of further identifiers not shown (table full)",
            trace.overflow()
        )
    } else {
        String::new()
    };
    let block = Block::bordered().title(format!(
        " fixed trace · {} ·{} {} identifiers{full} ",
        state_word(ui),
        filter_text(ui),
        trace.rows().len()
    ));
    let inner = block.inner(area);
    let with_data = inner.width >= FIXED_DATA_WIDTH;
    let rows = usize::from(inner.height).saturating_sub(1);
    let shown = ui.fixed_rows(view, rows);
    let id = if shown.iter().any(|r| r.key.extended) {
        FIXED_COLUMNS[0]
    } else {
        STANDARD_ID_WIDTH
    };
    let mut lines = vec![fixed_header(with_data, id)];
    lines.extend(shown.into_iter().map(|r| fixed_line(r, with_data, id)));
    f.render_widget(Paragraph::new(lines).block(block), area);
}

fn frames_panel(f: &mut Frame<'_>, area: Rect, view: &NetworkView, ui: &Ui) {
    let block = Block::bordered().title(format!(
        " frames · {} ·{} {} kept, {} dropped ",
        state_word(ui),
        filter_text(ui),
        view.frames().len(),
        view.dropped_frames()
    ));
    let rows = usize::from(block.inner(area).height);
    let lines: Vec<Line<'_>> = ui.visible(view, rows).into_iter().map(frame_line).collect();
    f.render_widget(Paragraph::new(lines).block(block), area);
}

fn trace_panel(f: &mut Frame<'_>, area: Rect, view: &NetworkView, ui: &Ui) {
    match ui.mode {
        TraceMode::Scrolling => frames_panel(f, area, view, ui),
        TraceMode::Fixed => fixed_panel(f, area, view, ui),
    }
}

fn device_panel(f: &mut Frame<'_>, area: Rect, view: &NetworkView, ui: &Ui) {
    let Some(n) = ui.selected_node(view) else {
        f.render_widget(
            Paragraph::new("no node heard yet").block(Block::bordered().title(" device ")),
            area,
        );
        return;
    };
    let now = view.now();
    let leds = n.leds(now);
    let mut lines = vec![Line::from(vec![
        Span::styled(
            format!("node {}", n.id),
            Style::default().add_modifier(Modifier::BOLD),
        ),
        Span::raw(format!(
            "  {}  {}",
            n.display_name(),
            n.kind_label().unwrap_or_else(|| "kind unknown".into())
        )),
    ])];
    let mut id_parts = Vec::new();
    if let Some(t) = n.device_type {
        id_parts.push(format!("device type 0x{t:08X}"));
    }
    if let Some(name) = &n.device_name {
        id_parts.push(format!("name {name:?}"));
    }
    let ident = n.identity;
    for (label, v) in [
        ("vendor", ident.vendor_id),
        ("product", ident.product_code),
        ("revision", ident.revision),
        ("serial", ident.serial),
    ] {
        if let Some(v) = v {
            id_parts.push(format!("{label} 0x{v:08X}"));
        }
    }
    if !id_parts.is_empty() {
        lines.push(Line::from(id_parts.join("  ")));
    }
    // Heartbeat and node guarding are different services (CiA 301 §7.2.8.3.2).
    let service = n.error_control().unwrap_or("heartbeat");
    let heartbeat = match (n.heartbeat_age(now), n.heartbeat_period) {
        (Some(a), Some(p)) => format!("{service} {} ago, every {}", age(a), age(p)),
        (Some(a), None) => format!("{service} {} ago", age(a)),
        _ => "no heartbeat or node guarding".into(),
    };
    lines.push(Line::from(format!("NMT {}  {heartbeat}", n.state_name())));
    lines.push(Line::from(format!(
        "RUN {}  ERR {}  error register {}",
        leds.run,
        leds.err,
        n.error_register
            .map(|r| format!("0x{r:02X}"))
            .unwrap_or_else(|| "-".into())
    )));
    if let Some(e) = &n.last_emcy {
        lines.push(Line::from(Span::styled(
            format!(
                "EMCY 0x{:04X} {}{} register 0x{:02X} data {} at {} s",
                e.code,
                n.emcy_meaning().unwrap_or_default(),
                if n.emcy_active { "" } else { " (reset)" },
                e.register,
                hex_bytes(&e.manufacturer),
                seconds(e.at)
            ),
            Style::default().fg(Color::Red),
        )));
    }
    lines.push(Line::from(format!(
        "frames {}  EMCY {}  boot-ups {}",
        n.frames, n.emcy_count, n.boot_ups
    )));
    if n.values.is_empty() {
        if n.kind.is_none() {
            lines.push(Line::from("no PDO values: the device kind is unknown"));
        } else {
            lines.push(Line::from("no PDO values yet"));
        }
    } else {
        let width = n
            .values
            .iter()
            .map(|(v, _)| v.name.len())
            .max()
            .unwrap_or(0);
        lines.push(Line::from(Span::styled(
            "values",
            Style::default().add_modifier(Modifier::BOLD),
        )));
        for (v, at) in &n.values {
            lines.push(Line::from(format!(
                "  {:<width$}  {}  ({}, {} ago)",
                v.name,
                v.text,
                cantwin_monitor::kind::pdo_label(v.pdo),
                age(Duration::from_nanos(
                    now.as_nanos().saturating_sub(at.as_nanos())
                ))
            )));
        }
    }
    f.render_widget(
        Paragraph::new(lines).block(Block::bordered().title(" device ")),
        area,
    );
}

/// The help line's text on a wide terminal.
pub const HELP: &str = "q quit  ↑↓ node  t fixed/scrolling trace  space pause  PgUp/PgDn scroll  Home/End oldest/live  / filter  c clear filter";

/// The help line's text on a narrow terminal (at most 80 columns).
pub const HELP_NARROW: &str =
    "q quit  ↑↓ node  Enter device  t fixed/scroll  space pause  PgUp/PgDn  / filter";

fn help_line(ui: &Ui, wide: bool) -> Line<'static> {
    if let Some(text) = &ui.editing {
        return Line::from(vec![
            Span::styled("filter: ", Style::default().add_modifier(Modifier::BOLD)),
            Span::raw(format!("{text}▏")),
            Span::styled(
                "   Enter apply · Esc cancel · e.g. node=5 svc=emcy,hb,pdo,sdo,lss id=0x180-0x1FF",
                Style::default().fg(Color::DarkGray),
            ),
        ]);
    }
    if let Some(m) = &ui.message {
        return Line::from(Span::styled(m.clone(), Style::default().fg(Color::Red)));
    }
    let help = if wide { HELP } else { HELP_NARROW };
    Line::from(Span::styled(help, Style::default().fg(Color::DarkGray)))
}

/// Draw the whole screen.
pub fn draw(f: &mut Frame<'_>, view: &NetworkView, ui: &Ui) {
    let wide = f.area().width >= WIDE;
    let table_rows = view.nodes().len() as u16 + 3;
    let [title, top, load, middle, help] = Layout::vertical([
        Constraint::Length(1),
        if wide {
            Constraint::Length(table_rows.clamp(8, 16))
        } else {
            Constraint::Length(table_rows.clamp(4, 9))
        },
        Constraint::Length(u16::from(!wide)),
        Constraint::Min(6),
        Constraint::Length(1),
    ])
    .areas(f.area());
    let mode = match ui.mode {
        TraceMode::Scrolling => "scrolling trace",
        TraceMode::Fixed => "fixed trace",
    };
    f.render_widget(
        Paragraph::new(Line::from(vec![
            Span::styled(
                "cantwin monitor",
                Style::default().add_modifier(Modifier::BOLD),
            ),
            // The source last: on a narrow terminal it is what the edge cuts, never the
            // trace mode or the time.
            Span::raw(format!(
                "  {mode}  bus time {} s  {}",
                seconds(view.now()),
                ui.source
            )),
        ])),
        title,
    );
    if wide {
        let [nodes, load] =
            Layout::horizontal([Constraint::Percentage(68), Constraint::Percentage(32)]).areas(top);
        nodes_table(f, nodes, view, ui);
        load_panel(f, load, view, ui);
        let [frames, device] =
            Layout::horizontal([Constraint::Percentage(62), Constraint::Percentage(38)])
                .areas(middle);
        trace_panel(f, frames, view, ui);
        device_panel(f, device, view, ui);
    } else {
        nodes_table(f, top, view, ui);
        f.render_widget(Paragraph::new(load_line(view, ui)), load);
        if ui.device_page {
            device_panel(f, middle, view, ui);
        } else {
            trace_panel(f, middle, view, ui);
        }
    }
    f.render_widget(Paragraph::new(help_line(ui, wide)), help);
}

#[cfg(test)]
mod tests;
