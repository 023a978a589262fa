//! The screen of `cantwin monitor`: [`draw`] is a pure function of the model
//! ([`NetworkView`]) and the UI state ([`Ui`]), so tests render it into a test backend;
//! [`Ui::on_key`] is the only place keys change anything.
//!
//! Keys: `q` quits (also Ctrl-C), `↑`/`↓` (or `k`/`j`) select a node, `space` pauses the
//! frame stream, `PgUp`/`PgDn` scroll it (pausing it), `Home` goes to the oldest frame kept,
//! `End` back to the live end, `/` edits the filter (`Enter` applies, `Esc` cancels), `c`
//! clears it.

use cantwin_can::{Duration, Instant};
use cantwin_monitor::{Filter, FrameEntry, Led, NetworkView, NodeInfo};
use cantwin_report::canopen::hex_bytes;
use ratatui::Frame;
use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Cell, Paragraph, Row, Sparkline, Table, TableState};

/// Frames a `PgUp`/`PgDn` moves.
pub const PAGE: usize = 10;

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
                            self.message = None;
                        }
                        Err(e) => self.message = Some(format!("filter: {e}")),
                    }
                    self.editing = None;
                }
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
        match key.code {
            KeyCode::Char('q') | KeyCode::Esc => return Flow::Quit,
            KeyCode::Up | KeyCode::Char('k') => self.move_selection(view, false),
            KeyCode::Down | KeyCode::Char('j') => self.move_selection(view, true),
            KeyCode::Char(' ') | KeyCode::Char('p') => {
                if self.paused_at.is_some() {
                    self.paused_at = None;
                    self.scroll = 0;
                } else {
                    self.pause(view);
                }
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
            KeyCode::End => {
                self.paused_at = None;
                self.scroll = 0;
            }
            KeyCode::Char('/') | KeyCode::Char('f') => {
                self.editing = Some(self.filter.to_string());
            }
            KeyCode::Char('c') => {
                self.filter = Filter::default();
                self.scroll = 0;
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

fn nodes_table(f: &mut Frame<'_>, area: Rect, view: &NetworkView, ui: &Ui) {
    let now = view.now();
    let header = Row::new([
        "ID",
        "name",
        "kind",
        "NMT",
        "HB age",
        "RUN",
        "ERR",
        "ER",
        "last EMCY",
    ])
    .style(Style::default().add_modifier(Modifier::BOLD));
    let rows: Vec<Row<'_>> = view
        .nodes()
        .map(|n| {
            let leds = n.leds(now);
            Row::new(vec![
                Cell::from(n.id.to_string()),
                Cell::from(n.display_name().to_string()),
                Cell::from(n.kind.as_ref().map(|k| k.name.clone()).unwrap_or_default()),
                Cell::from(n.state_name()),
                Cell::from(n.heartbeat_age(now).map(age).unwrap_or_else(|| "-".into())),
                led_cell(leds.run, Color::Green),
                led_cell(leds.err, Color::Red),
                Cell::from(
                    n.error_register
                        .map(|r| format!("{r:02X}"))
                        .unwrap_or_else(|| "-".into()),
                ),
                Cell::from(emcy_text(n)),
            ])
        })
        .collect();
    let widths = [
        Constraint::Length(3),
        Constraint::Length(12),
        Constraint::Length(12),
        Constraint::Length(15),
        Constraint::Length(8),
        Constraint::Length(12),
        Constraint::Length(12),
        Constraint::Length(2),
        Constraint::Min(10),
    ];
    let selected = ui
        .selected_node(view)
        .and_then(|s| view.nodes().position(|n| n.id == s.id));
    let table = Table::new(rows, widths)
        .header(header)
        .block(Block::bordered().title(format!(" nodes ({}) ", view.nodes().len())))
        .row_highlight_style(Style::default().add_modifier(Modifier::REVERSED))
        .highlight_symbol(">");
    let mut state = TableState::default().with_selected(selected);
    f.render_stateful_widget(table, area, &mut state);
}

fn load_panel(f: &mut Frame<'_>, area: Rect, view: &NetworkView) {
    let load = view.load();
    let block = Block::bordered().title(format!(
        " bus load ({} kbit/s, {} ms windows) ",
        load.bit_rate().bits_per_second() / 1000,
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
    // The last window is still filling: the figures are those of the one before.
    let complete = loads.len().saturating_sub(1);
    let now_load = complete.checked_sub(1).map(|i| loads[i]).unwrap_or(0.0);
    let now_fps = complete.checked_sub(1).map(|i| fps[i]).unwrap_or(0.0);
    let peak = loads[..complete].iter().copied().fold(0.0, f64::max);
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

fn frame_line(e: &FrameEntry) -> Line<'static> {
    let colour = match e.service {
        cantwin_monitor::Service::Emcy => Color::Red,
        cantwin_monitor::Service::Nmt => Color::Magenta,
        cantwin_monitor::Service::Heartbeat => Color::Green,
        cantwin_monitor::Service::Sdo => Color::Blue,
        cantwin_monitor::Service::Pdo => Color::Cyan,
        _ => Color::Reset,
    };
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

fn frames_panel(f: &mut Frame<'_>, area: Rect, view: &NetworkView, ui: &Ui) {
    let state = if ui.paused_at.is_some() {
        "PAUSED"
    } else {
        "LIVE"
    };
    let filter = if ui.filter.is_empty() {
        String::new()
    } else {
        format!(" filter: {} ·", ui.filter)
    };
    let block = Block::bordered().title(format!(
        " frames · {state} ·{filter} {} kept, {} dropped ",
        view.frames().len(),
        view.dropped_frames()
    ));
    let rows = usize::from(block.inner(area).height);
    let lines: Vec<Line<'_>> = ui.visible(view, rows).into_iter().map(frame_line).collect();
    f.render_widget(Paragraph::new(lines).block(block), area);
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
            n.kind
                .as_ref()
                .map(|k| k.name.as_str())
                .unwrap_or("kind unknown")
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
    let heartbeat = match (n.heartbeat_age(now), n.heartbeat_period) {
        (Some(a), Some(p)) => format!("heartbeat {} ago, every {}", age(a), age(p)),
        (Some(a), None) => format!("heartbeat {} ago", age(a)),
        _ => "no heartbeat".into(),
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

/// The help line's text.
pub const HELP: &str = "q quit  ↑↓ node  space pause  PgUp/PgDn scroll  Home/End oldest/live  / filter  c clear filter";

fn help_line(ui: &Ui) -> Line<'static> {
    if let Some(text) = &ui.editing {
        return Line::from(vec![
            Span::styled("filter: ", Style::default().add_modifier(Modifier::BOLD)),
            Span::raw(format!("{text}▏")),
            Span::styled(
                "   Enter apply · Esc cancel · e.g. node=5 svc=emcy,hb,pdo,sdo id=0x180-0x1FF",
                Style::default().fg(Color::DarkGray),
            ),
        ]);
    }
    if let Some(m) = &ui.message {
        return Line::from(Span::styled(m.clone(), Style::default().fg(Color::Red)));
    }
    Line::from(Span::styled(HELP, Style::default().fg(Color::DarkGray)))
}

/// Draw the whole screen.
pub fn draw(f: &mut Frame<'_>, view: &NetworkView, ui: &Ui) {
    let [title, top, middle, help] = Layout::vertical([
        Constraint::Length(1),
        Constraint::Length((view.nodes().len() as u16 + 3).clamp(8, 16)),
        Constraint::Min(6),
        Constraint::Length(1),
    ])
    .areas(f.area());
    f.render_widget(
        Paragraph::new(Line::from(vec![
            Span::styled(
                "cantwin monitor",
                Style::default().add_modifier(Modifier::BOLD),
            ),
            Span::raw(format!(
                "  {}  bus time {} s",
                ui.source,
                seconds(view.now())
            )),
        ])),
        title,
    );
    let [nodes, load] =
        Layout::horizontal([Constraint::Percentage(68), Constraint::Percentage(32)]).areas(top);
    nodes_table(f, nodes, view, ui);
    load_panel(f, load, view);
    let [frames, device] =
        Layout::horizontal([Constraint::Percentage(62), Constraint::Percentage(38)]).areas(middle);
    frames_panel(f, frames, view, ui);
    device_panel(f, device, view, ui);
    f.render_widget(Paragraph::new(help_line(ui)), help);
}

#[cfg(test)]
mod tests;
