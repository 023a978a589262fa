//! The HTML page: one file, inline CSS and SVG, a few lines of inline script for the
//! timeline filter, everything from the capture escaped.

use std::fmt::Write as _;

use crate::{Report, id_raw};

/// Escapes text for HTML element content and quoted attribute values.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

/// Seconds since the capture start, with microseconds.
fn rel(report: &Report, t_ns: u64) -> String {
    let d = t_ns.saturating_sub(report.start_ns);
    format!("{}.{:06}", d / 1_000_000_000, (d % 1_000_000_000) / 1_000)
}

fn ms(ns: Option<u64>) -> String {
    ns.map_or_else(|| "–".to_string(), |v| format!("{:.3}", v as f64 / 1e6))
}

const STYLE: &str = "body{font-family:sans-serif;margin:1.5em;color:#222}\
table{border-collapse:collapse;font-size:0.9em}\
td,th{border:1px solid #ccc;padding:2px 6px;text-align:left}\
th{background:#eee}td.n{text-align:right;font-family:monospace}\
td.t{font-family:monospace}tr.anomaly td{background:#fee}\
svg{background:#fafafa;border:1px solid #ccc}.note{color:#a40}";

const SCRIPT: &str = "function cantwinFilter(){\
var k=document.getElementById('kind').value;\
var q=document.getElementById('q').value.toLowerCase();\
var rows=document.querySelectorAll('#timeline tbody tr');\
for(var i=0;i<rows.length;i++){var r=rows[i];\
var ok=(k===''||r.dataset.kind===k)&&(q===''||r.textContent.toLowerCase().indexOf(q)>=0);\
r.style.display=ok?'':'none';}}";

/// Chart size in SVG user units.
const W: f64 = 800.0;
const H: f64 = 200.0;
/// Room above the plot for the top label.
const M: f64 = 10.0;

fn load_chart(out: &mut String, c: &crate::Channel) {
    let n = c.load.len().max(1);
    // The smallest of 1, 2, 5, 10, 20, 50, 100 % (and whole multiples of 100 % beyond,
    // for captures whose timestamps crowd frames) that holds the peak.
    let peak = c.peak_load();
    let top = [0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0]
        .into_iter()
        .find(|&t| peak <= t)
        .unwrap_or_else(|| peak.ceil());
    let _ = write!(
        out,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{W}\" height=\"{}\" viewBox=\"0 0 {W} {}\" role=\"img\">",
        M + H + 30.0,
        M + H + 30.0
    );
    let _ = write!(out, "<title>bus load of {}</title>", escape(&c.name));
    for q in 0..=4 {
        let y = M + H - H * f64::from(q) / 4.0;
        let _ = write!(
            out,
            "<line x1=\"40\" x2=\"{W}\" y1=\"{y:.1}\" y2=\"{y:.1}\" stroke=\"#ddd\"/>\
             <text x=\"0\" y=\"{:.1}\" font-size=\"10\">{}%</text>",
            y + 3.0,
            percent(top * 100.0 * f64::from(q) / 4.0)
        );
    }
    let mut points = String::new();
    for (i, l) in c.load.iter().enumerate() {
        let x = 40.0 + (W - 40.0) * i as f64 / n as f64;
        let x2 = 40.0 + (W - 40.0) * (i + 1) as f64 / n as f64;
        let y = M + H - H * (l / top).min(1.0);
        let _ = write!(points, "{x:.1},{y:.1} {x2:.1},{y:.1} ");
    }
    let _ = write!(
        out,
        "<polyline fill=\"none\" stroke=\"#36c\" stroke-width=\"1.5\" points=\"{}\"/>",
        points.trim_end()
    );
    let secs = (c.window_ns as f64 * n as f64) / 1e9;
    let _ = write!(
        out,
        "<text x=\"40\" y=\"{}\" font-size=\"10\">0 s</text>\
         <text x=\"{}\" y=\"{}\" font-size=\"10\" text-anchor=\"end\">{secs:.1} s</text></svg>",
        M + H + 15.0,
        W,
        M + H + 15.0
    );
}

/// `YYYY-MM-DD hh:mm:ss.uuuuuu` of nanoseconds since the Unix epoch (proleptic Gregorian
/// calendar, days to civil date as in the well-known era/day-of-era decomposition).
fn utc(ns: u64) -> String {
    let secs = ns / 1_000_000_000;
    let micros = (ns % 1_000_000_000) / 1_000;
    let days = secs / 86_400;
    let rem = secs % 86_400;
    let z = days + 719_468;
    let era = z / 146_097;
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1_460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + u64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02}:{:02}.{micros:06}",
        rem / 3_600,
        rem % 3_600 / 60,
        rem % 60
    )
}

/// A percentage without trailing zeros: `25`, `2.5`, `0.25`.
fn percent(v: f64) -> String {
    let s = format!("{v:.2}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// A row's text, with how often it repeated and when first and last: `… × 101, first
/// 0.500 s, last 10.500 s`.
fn with_repeats(report: &Report, text: &str, repeats: u64, first: u64, last: u64) -> String {
    if repeats <= 1 {
        return text.to_string();
    }
    format!(
        "{text} × {repeats}, first {} s, last {} s",
        rel(report, first),
        rel(report, last)
    )
}

/// Renders a report as one self-contained HTML page.
pub fn render_html(report: &Report) -> String {
    let mut o = String::new();
    o.push_str("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">");
    o.push_str("<title>cantwin capture report</title><style>");
    o.push_str(STYLE);
    o.push_str("</style></head><body>\n<h1>Capture report</h1>\n");
    let dur = report.end_ns.saturating_sub(report.start_ns);
    let _ = writeln!(
        o,
        "<p id=\"summary\">Start {} UTC, duration {:.3} s, {} channel(s), {} SDO transfer(s), {} anomalies. Times below are seconds from the start.</p>",
        utc(report.start_ns),
        dur as f64 / 1e9,
        report.channels.len(),
        report.sdo_total,
        report.anomalies.len()
    );

    o.push_str("<h2>Anomalies</h2>\n");
    if report.anomalies.is_empty() {
        o.push_str("<p>None found.</p>\n");
    } else {
        o.push_str("<table id=\"anomalies\"><thead><tr><th>time (s)</th><th>channel</th><th>kind</th><th>node</th><th>details</th></tr></thead><tbody>\n");
        for a in &report.anomalies {
            let _ = writeln!(
                o,
                "<tr class=\"anomaly\" data-kind=\"{}\"><td class=\"n\">{}</td><td>{}</td><td>{}</td><td class=\"n\">{}</td><td>{}</td></tr>",
                escape(a.kind.name()),
                rel(report, a.t_ns),
                escape(&a.channel),
                escape(a.kind.name()),
                a.node.map(|n| n.to_string()).unwrap_or_default(),
                escape(&with_repeats(report, &a.text, a.repeats, a.t_ns, a.last_ns))
            );
        }
        o.push_str("</tbody></table>\n");
    }

    o.push_str("<h2>Bus load</h2>\n");
    for c in &report.channels {
        let _ = writeln!(
            o,
            "<h3>{}</h3><p>{} bit/s{}, {}; {} frames, {} error frames, {} SYNC; mean load {:.2} %, peak {:.2} % (windows of {} ms).</p>",
            escape(&c.name),
            c.bit_rate.bits_per_second(),
            if c.bit_rate_assumed {
                " (assumed: the capture does not record the bit rate)"
            } else {
                ""
            },
            c.protocol.name(),
            c.frames,
            c.error_frames,
            c.syncs,
            c.mean_load() * 100.0,
            c.peak_load() * 100.0,
            c.window_ns / 1_000_000
        );
        load_chart(&mut o, c);
        o.push('\n');
    }

    o.push_str("<h2>Identifiers</h2>\n<table id=\"ids\"><thead><tr><th>channel</th><th>identifier</th><th>frames</th><th>bytes</th><th>share of bus (%)</th><th>min period (ms)</th><th>avg period (ms)</th><th>max period (ms)</th></tr></thead><tbody>\n");
    for s in &report.ids {
        let rate = report
            .channels
            .iter()
            .find(|c| c.name == s.channel)
            .map_or(1_000_000, |c| c.bit_rate.bits_per_second());
        let capacity = f64::from(rate) * (dur.max(1) as f64 / 1e9);
        let id = match s.id {
            cantwin_can::Id::Standard(_) => format!("0x{:03X}", id_raw(s.id)),
            cantwin_can::Id::Extended(_) => format!("0x{:08X}", id_raw(s.id)),
        };
        let _ = writeln!(
            o,
            "<tr><td>{}</td><td class=\"t\">{id}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{:.3}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td></tr>",
            escape(&s.channel),
            s.frames,
            s.bytes,
            s.bits as f64 / capacity * 100.0,
            ms(s.min_period_ns),
            ms(s.avg_period_ns()),
            ms(s.max_period_ns)
        );
    }
    o.push_str("</tbody></table>\n");

    o.push_str("<h2>Timeline</h2>\n<p><label>kind <select id=\"kind\" onchange=\"cantwinFilter()\"><option value=\"\">all</option>");
    let mut kinds: Vec<_> = report.timeline.iter().map(|r| r.kind).collect();
    kinds.sort();
    kinds.dedup();
    for k in kinds {
        let _ = write!(o, "<option>{}</option>", k.name());
    }
    o.push_str("</select></label> <label>search <input id=\"q\" oninput=\"cantwinFilter()\"></label></p>\n");
    if report.timeline_dropped > 0 {
        let _ = writeln!(
            o,
            "<p class=\"note\">The timeline shows the first {} rows; {} more were left out.</p>",
            report.timeline.len(),
            report.timeline_dropped
        );
    }
    o.push_str("<table id=\"timeline\"><thead><tr><th>time (s)</th><th>channel</th><th>kind</th><th>node</th><th>event</th></tr></thead><tbody>\n");
    for r in &report.timeline {
        let _ = writeln!(
            o,
            "<tr data-kind=\"{}\"><td class=\"n\">{}</td><td>{}</td><td>{}</td><td class=\"n\">{}</td><td>{}</td></tr>",
            r.kind.name(),
            rel(report, r.t_ns),
            escape(&r.channel),
            r.kind.name(),
            r.node.map(|n| n.to_string()).unwrap_or_default(),
            escape(&with_repeats(report, &r.text, r.repeats, r.t_ns, r.last_ns))
        );
    }
    o.push_str("</tbody></table>\n<script>");
    o.push_str(SCRIPT);
    o.push_str("</script>\n</body></html>\n");
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_dates() {
        assert_eq!(utc(0), "1970-01-01 00:00:00.000000");
        assert_eq!(utc(1_700_000_000_000_123_456), "2023-11-14 22:13:20.000123");
        // 29 February of a leap year.
        assert_eq!(utc(951_782_400_000_000_000), "2000-02-29 00:00:00.000000");
    }

    #[test]
    fn escape_markup_and_quotes() {
        assert_eq!(
            escape("<b a=\"x\">&'"),
            "&lt;b a=&quot;x&quot;&gt;&amp;&#39;"
        );
    }
}
