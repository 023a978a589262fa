//! Line charts as SVG, drawn here: a chart is a title, a unit and samples over a sliding
//! window of wall time; the browser shows the markup as it comes.

use std::fmt::Write as _;

/// Width and height of a chart in SVG user units (the page scales it).
const WIDTH: f64 = 360.0;
const HEIGHT: f64 = 140.0;
/// Plot area margins: room for the axis labels.
const LEFT: f64 = 46.0;
const RIGHT: f64 = 8.0;
const TOP: f64 = 22.0;
const BOTTOM: f64 = 20.0;

/// One series: its samples as (seconds before now, value), oldest first.
pub struct Series<'a> {
    /// The label in the legend.
    pub label: &'a str,
    /// The samples.
    pub points: &'a [(f64, f64)],
}

/// Escapes text for XML.
pub fn escape(text: &str) -> String {
    let mut s = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => s.push_str("&amp;"),
            '<' => s.push_str("&lt;"),
            '>' => s.push_str("&gt;"),
            '"' => s.push_str("&quot;"),
            '\'' => s.push_str("&#39;"),
            c => s.push(c),
        }
    }
    s
}

/// A "nice" step (1, 2 or 5 × 10ⁿ) for about `ticks` divisions of `span`.
fn nice_step(span: f64, ticks: f64) -> f64 {
    let raw = span / ticks;
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    let nice = if f <= 1.0 {
        1.0
    } else if f <= 2.0 {
        2.0
    } else if f <= 5.0 {
        5.0
    } else {
        10.0
    };
    nice * mag
}

/// The value range shown: the data's, widened to nice steps and never empty (a flat line
/// sits in the middle of a unit range).
fn y_range(series: &[Series<'_>]) -> (f64, f64, f64) {
    let values = series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .filter(|v| v.is_finite());
    let (mut lo, mut hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if !lo.is_finite() {
        (lo, hi) = (0.0, 1.0);
    }
    if hi - lo < 1e-9 {
        let pad = (hi.abs() * 0.1).max(1.0);
        lo -= pad;
        hi += pad;
    }
    let step = nice_step(hi - lo, 4.0);
    ((lo / step).floor() * step, (hi / step).ceil() * step, step)
}

fn fmt_tick(v: f64, step: f64) -> String {
    if step >= 1.0 || v == 0.0 {
        format!("{v:.0}")
    } else {
        let decimals = (-step.log10().floor()) as usize;
        format!("{v:.decimals$}")
    }
}

/// Colours of the series, in order (distinguishable on white, for colour-blind readers too).
const COLOURS: [&str; 4] = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd"];

/// A chart of `series` over the last `window_s` seconds, with `title` and `unit`.
pub fn chart(title: &str, unit: &str, window_s: f64, series: &[Series<'_>]) -> String {
    let (lo, hi, step) = y_range(series);
    let pw = WIDTH - LEFT - RIGHT;
    let ph = HEIGHT - TOP - BOTTOM;
    let x = |age: f64| LEFT + pw * (1.0 - (age / window_s).clamp(0.0, 1.0));
    let y = |v: f64| TOP + ph * (1.0 - (v - lo) / (hi - lo));
    let mut s = String::with_capacity(2048);
    let _ = write!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" viewBox=\"0 0 {WIDTH} {HEIGHT}\" class=\"chart\" role=\"img\" aria-label=\"{t}\">\
         <text x=\"{LEFT}\" y=\"14\" class=\"chart-title\">{t}{u}</text>",
        t = escape(title),
        u = if unit.is_empty() {
            String::new()
        } else {
            format!(" ({})", escape(unit))
        }
    );
    // Horizontal grid lines with their values.
    let mut v = lo;
    let mut n = 0;
    while v <= hi + step * 1e-6 && n < 12 {
        let yy = y(v);
        let _ = write!(
            s,
            "<line x1=\"{LEFT}\" x2=\"{:.1}\" y1=\"{yy:.1}\" y2=\"{yy:.1}\" class=\"grid\"/>\
             <text x=\"{:.1}\" y=\"{:.1}\" class=\"tick\" text-anchor=\"end\">{}</text>",
            WIDTH - RIGHT,
            LEFT - 4.0,
            yy + 3.5,
            fmt_tick(v, step)
        );
        v += step;
        n += 1;
    }
    // Time axis: the window's start, middle and now.
    for (age, anchor) in [
        (window_s, "start"),
        (window_s / 2.0, "middle"),
        (0.0, "end"),
    ] {
        let label = if age == 0.0 {
            "now".to_string()
        } else {
            format!("−{age:.0} s")
        };
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" class=\"tick\" text-anchor=\"{anchor}\">{label}</text>",
            x(age),
            HEIGHT - 5.0
        );
    }
    for (k, se) in series.iter().enumerate() {
        let colour = COLOURS[k % COLOURS.len()];
        let mut d = String::with_capacity(se.points.len() * 14);
        for (i, (age, v)) in se.points.iter().filter(|p| p.1.is_finite()).enumerate() {
            let _ = write!(
                d,
                "{}{:.1},{:.1}",
                if i == 0 { "M" } else { "L" },
                x(*age),
                y(*v)
            );
        }
        let _ = write!(
            s,
            "<path d=\"{d}\" fill=\"none\" stroke=\"{colour}\" stroke-width=\"1.6\" class=\"series\" data-series=\"{}\"/>",
            escape(se.label)
        );
        if series.len() > 1 {
            let lx = WIDTH - RIGHT - 90.0 * (series.len() - k) as f64;
            let _ = write!(
                s,
                "<rect x=\"{lx:.1}\" y=\"7\" width=\"10\" height=\"3\" fill=\"{colour}\"/>\
                 <text x=\"{:.1}\" y=\"12\" class=\"tick\">{}</text>",
                lx + 13.0,
                escape(se.label)
            );
        }
    }
    s.push_str("</svg>");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_chart_draws_each_series_as_a_path_scaled_into_the_plot_area() {
        let pts = [(60.0, 0.0), (30.0, 50.0), (0.0, 100.0)];
        let svg = chart(
            "speed",
            "rpm",
            60.0,
            &[Series {
                label: "speed",
                points: &pts,
            }],
        );
        assert!(svg.starts_with("<svg"), "{svg}");
        assert!(svg.contains("speed (rpm)"), "{svg}");
        // Oldest sample at the left edge of the plot, the newest at the right, the largest
        // value at the top.
        assert!(
            svg.contains(&format!("d=\"M{LEFT:.1},{:.1}", HEIGHT - BOTTOM)),
            "{svg}"
        );
        assert!(
            svg.contains(&format!("L{:.1},{TOP:.1}\"", WIDTH - RIGHT)),
            "{svg}"
        );
    }

    #[test]
    fn a_flat_or_empty_series_still_has_a_value_range() {
        let flat = [(10.0, 5.0), (0.0, 5.0)];
        let svg = chart(
            "x",
            "",
            60.0,
            &[Series {
                label: "x",
                points: &flat,
            }],
        );
        assert!(!svg.contains("NaN") && !svg.contains("inf"), "{svg}");
        let svg = chart(
            "x",
            "",
            60.0,
            &[Series {
                label: "x",
                points: &[],
            }],
        );
        assert!(svg.contains("d=\"\""), "{svg}");
    }

    #[test]
    fn titles_are_escaped() {
        let svg = chart("a<b & \"c\"", "", 60.0, &[]);
        assert!(svg.contains("a&lt;b &amp; &quot;c&quot;"), "{svg}");
    }
}
