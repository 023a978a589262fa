//! A report as text: a terminal summary, JUnit XML (one test case per case, so CI
//! systems show each), JSON and a single-file HTML page with every case's frames.

use std::fmt::Write as _;

use cantwin_report::escape;

use crate::report::{Area, CaseReport, Direction, Report, Severity, Verdict};

/// The terminal summary: one line per case that did not pass, counts per area and the
/// overall result.
pub fn summary(report: &Report) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{} (node {}) over {}, profile {}",
        report.device, report.node, report.transport, report.profile
    );
    for c in &report.cases {
        if c.verdict != Verdict::Pass {
            let sev = if c.severity == Severity::Advisory && c.verdict == Verdict::Fail {
                " (advisory)"
            } else {
                ""
            };
            let _ = writeln!(
                s,
                "  {:<13} {} [{}]{sev}: {}",
                c.verdict.word(),
                c.id,
                c.clause,
                c.detail
            );
        }
    }
    for area in Area::ALL {
        let cases: Vec<&CaseReport> = report.cases.iter().filter(|c| c.area == area).collect();
        if cases.is_empty() {
            continue;
        }
        let n = |v| cases.iter().filter(|c| c.verdict == v).count();
        let _ = writeln!(
            s,
            "{:<18} {:>3} pass {:>3} fail {:>3} deviation {:>3} not supported {:>3} skipped",
            area.title(),
            n(Verdict::Pass),
            n(Verdict::Fail),
            n(Verdict::Deviation),
            n(Verdict::NotSupported),
            n(Verdict::Skipped)
        );
    }
    if let Some(why) = &report.stopped {
        let _ = writeln!(s, "run stopped: {why}");
    }
    let failed = report.mandatory_failures().count();
    let _ = writeln!(
        s,
        "{}: {} cases, {failed} mandatory failures, {:.3} s",
        if report.passed() { "PASSED" } else { "FAILED" },
        report.cases.len(),
        report.duration_us as f64 / 1e6
    );
    s
}

fn xml(text: &str) -> String {
    // XML 1.0 cannot carry most control characters even escaped.
    escape(text)
        .chars()
        .map(|c| {
            if c.is_control() && c != '\n' && c != '\t' {
                ' '
            } else {
                c
            }
        })
        .collect()
}

fn frames_text(c: &CaseReport) -> String {
    let mut s = String::new();
    for f in &c.frames {
        let dir = match f.dir {
            Direction::Stimulus => "->",
            Direction::Response => "<-",
        };
        let _ = writeln!(s, "{:>12} us {dir} {}", f.t_us, f.frame);
    }
    if c.frames_omitted > 0 {
        let _ = writeln!(s, "({} more frames not logged)", c.frames_omitted);
    }
    s
}

/// JUnit XML: a test suite per area, a test case per case; mandatory failures as
/// `<failure>`, advisory failures and cases not run as `<skipped>` with the reason.
pub fn junit(report: &Report) -> String {
    let mut s = String::from("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    let failures = report.mandatory_failures().count();
    // A run that stopped (the device did not answer, the transport failed) is an error
    // of the run itself, not a case's: a suite "run" with one erroneous case carries it,
    // so that a CI system does not show the cases it never ran as a clean result.
    let errors = usize::from(report.stopped.is_some());
    let _ = writeln!(
        s,
        "<testsuites name=\"cantwin conform {}\" tests=\"{}\" failures=\"{failures}\" errors=\"{errors}\" time=\"{:.6}\">",
        xml(&report.device),
        report.cases.len() + errors,
        report.duration_us as f64 / 1e6
    );
    if let Some(why) = &report.stopped {
        let _ = writeln!(
            s,
            "  <testsuite name=\"run\" tests=\"1\" failures=\"0\" errors=\"1\" skipped=\"0\">\n    <testcase classname=\"conform.run\" name=\"run\" time=\"{:.6}\"><error message=\"the run stopped: {}\"/></testcase>\n  </testsuite>",
            report.duration_us as f64 / 1e6,
            xml(why)
        );
    }
    for area in Area::ALL {
        let cases: Vec<&CaseReport> = report.cases.iter().filter(|c| c.area == area).collect();
        if cases.is_empty() {
            continue;
        }
        let f = cases
            .iter()
            .filter(|c| c.verdict == Verdict::Fail && c.severity == Severity::Mandatory)
            .count();
        let sk = cases
            .iter()
            .filter(|c| {
                matches!(c.verdict, Verdict::Skipped | Verdict::NotSupported)
                    || (c.verdict == Verdict::Fail && c.severity == Severity::Advisory)
            })
            .count();
        let _ = writeln!(
            s,
            "  <testsuite name=\"{}\" tests=\"{}\" failures=\"{f}\" skipped=\"{sk}\">",
            area.name(),
            cases.len()
        );
        for c in cases {
            let _ = write!(
                s,
                "    <testcase classname=\"conform.{}\" name=\"{}\" time=\"{:.6}\">",
                area.name(),
                xml(&c.id),
                c.duration_us as f64 / 1e6
            );
            let msg = xml(&format!("{} [{}]", c.detail, c.clause));
            match (c.verdict, c.severity) {
                (Verdict::Fail, Severity::Mandatory) => {
                    let _ = write!(
                        s,
                        "<failure message=\"{msg}\">{}</failure>",
                        xml(&frames_text(c))
                    );
                }
                (Verdict::Fail, Severity::Advisory) => {
                    let _ = write!(s, "<skipped message=\"advisory: {msg}\"/>");
                }
                (Verdict::Skipped | Verdict::NotSupported, _) => {
                    let _ = write!(s, "<skipped message=\"{} {msg}\"/>", c.verdict.word());
                }
                (Verdict::Deviation, _) => {
                    let sec = c.manual_section.as_deref().unwrap_or_default();
                    let _ = write!(
                        s,
                        "<system-out>deviation ({}): {msg}</system-out>",
                        xml(sec)
                    );
                }
                (Verdict::Pass, _) => {
                    let _ = write!(s, "<system-out>{msg}</system-out>");
                }
            }
            s.push_str("</testcase>\n");
        }
        s.push_str("  </testsuite>\n");
    }
    s.push_str("</testsuites>\n");
    s
}

/// The report as JSON (the [`Report`] structure).
pub fn json(report: &Report) -> String {
    serde_json::to_string_pretty(report).unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"))
}

const STYLE: &str = "body{font-family:sans-serif;margin:1.5em;color:#222}\
table{border-collapse:collapse;font-size:0.9em}\
td,th{border:1px solid #ccc;padding:2px 6px;text-align:left;vertical-align:top}\
th{background:#eee}td.t{font-family:monospace}pre{margin:0;font-size:0.85em}\
tr.fail td{background:#fee}tr.deviation td{background:#ffd}tr.ns td{color:#666}\
details summary{cursor:pointer}.note{color:#a40}";

/// The HTML page: the summary per area, then every case with its clause, verdict, detail
/// and its stimulus and response frames. One file, inline CSS, everything escaped.
pub fn html(report: &Report) -> String {
    let mut s = String::new();
    let title = format!("cantwin conform: {} (node {})", report.device, report.node);
    let _ = write!(
        s,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title><style>{STYLE}</style></head><body>\n<h1>{}</h1>\n",
        escape(&title),
        escape(&title)
    );
    let _ = writeln!(
        s,
        "<p>Transport: {} · profile: {} · {} cases in {:.3} s · <b>{}</b></p>",
        escape(&report.transport),
        escape(&report.profile),
        report.cases.len(),
        report.duration_us as f64 / 1e6,
        if report.passed() { "passed" } else { "FAILED" }
    );
    if let Some(why) = &report.stopped {
        let _ = writeln!(s, "<p class=\"note\">Run stopped: {}</p>", escape(why));
    }
    s.push_str("<table><thead><tr><th>Area</th><th>pass</th><th>fail</th><th>deviation</th><th>not supported</th><th>skipped</th></tr></thead><tbody>\n");
    for area in Area::ALL {
        let cases: Vec<&CaseReport> = report.cases.iter().filter(|c| c.area == area).collect();
        if cases.is_empty() {
            continue;
        }
        let n = |v| cases.iter().filter(|c| c.verdict == v).count();
        let _ = writeln!(
            s,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(area.title()),
            n(Verdict::Pass),
            n(Verdict::Fail),
            n(Verdict::Deviation),
            n(Verdict::NotSupported),
            n(Verdict::Skipped)
        );
    }
    s.push_str("</tbody></table>\n<h2>Cases</h2>\n<table id=\"cases\"><thead><tr><th>Case</th><th>Clause</th><th>Verdict</th><th>What was observed</th><th>Frames</th></tr></thead><tbody>\n");
    for c in &report.cases {
        let class = match c.verdict {
            Verdict::Fail => "fail",
            Verdict::Deviation => "deviation",
            Verdict::NotSupported | Verdict::Skipped => "ns",
            Verdict::Pass => "pass",
        };
        let sev = if c.severity == Severity::Advisory {
            " (advisory)"
        } else {
            ""
        };
        let section = c
            .manual_section
            .as_deref()
            .map(|m| format!("<br>manual: {}", escape(m)))
            .unwrap_or_default();
        let _ = write!(
            s,
            "<tr class=\"{class}\"><td class=\"t\">{}<br><small>{}</small></td><td>{}</td><td>{}{sev}</td><td>{}{section}</td><td>",
            escape(&c.id),
            escape(&c.title),
            escape(&c.clause),
            escape(c.verdict.word()),
            escape(&c.detail)
        );
        if !c.frames.is_empty() {
            let _ = write!(
                s,
                "<details><summary>{} frames</summary><pre>",
                c.frames.len() as u64 + c.frames_omitted
            );
            for f in &c.frames {
                let dir = match f.dir {
                    Direction::Stimulus => "stimulus",
                    Direction::Response => "response",
                };
                let _ = writeln!(
                    s,
                    "{:>10.6} {dir:<8} {}",
                    f.t_us as f64 / 1e6,
                    escape(&f.frame)
                );
            }
            if c.frames_omitted > 0 {
                let _ = writeln!(s, "({} more frames not logged)", c.frames_omitted);
            }
            s.push_str("</pre></details>");
        }
        s.push_str("</td></tr>\n");
    }
    s.push_str("</tbody></table>\n</body></html>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::LoggedFrame;

    fn report() -> Report {
        let case = |id: &str, area, severity, verdict, detail: &str| CaseReport {
            id: id.into(),
            area,
            title: "t".into(),
            clause: "CiA 301 §7.2.4.3.17".into(),
            severity,
            verdict,
            detail: detail.into(),
            manual_section: None,
            frames: vec![LoggedFrame {
                t_us: 1500,
                dir: Direction::Stimulus,
                frame: "605#4000100000000000".into(),
            }],
            frames_omitted: 2,
            duration_us: 10,
        };
        Report {
            device: "a <b> & \"c\"".into(),
            node: 5,
            transport: "virtual bus can0".into(),
            profile: "EDS".into(),
            cases: vec![
                case(
                    "sdo.a",
                    Area::Sdo,
                    Severity::Mandatory,
                    Verdict::Fail,
                    "got <1> & 2",
                ),
                case("sdo.b", Area::Sdo, Severity::Advisory, Verdict::Fail, "x"),
                case("nmt.c", Area::Nmt, Severity::Mandatory, Verdict::Pass, "ok"),
            ],
            stopped: None,
            duration_us: 30,
        }
    }

    #[test]
    fn junit_has_a_suite_per_area_and_fails_only_mandatory_cases_escaped() {
        let x = junit(&report());
        assert_eq!(x.matches("<testsuite ").count(), 2);
        assert_eq!(x.matches("<testcase ").count(), 3);
        assert_eq!(x.matches("<failure ").count(), 1);
        assert!(x.contains("failures=\"1\""));
        assert!(x.contains("got &lt;1&gt; &amp; 2"), "{x}");
        assert!(x.contains("a &lt;b&gt; &amp; &quot;c&quot;"), "{x}");
        assert!(x.contains("<skipped message=\"advisory: x"), "{x}");
        assert!(
            x.contains("605#4000100000000000"),
            "the failure carries its frames"
        );
        assert!(x.contains("(2 more frames not logged)"));
    }

    #[test]
    fn junit_of_a_stopped_run_carries_an_error() {
        let mut r = report();
        let clean = junit(&r);
        assert!(clean.contains("errors=\"0\""), "{clean}");
        assert!(!clean.contains("<error "), "{clean}");
        r.stopped = Some("node 5 does not answer <1000>".into());
        let x = junit(&r);
        assert!(x.contains("errors=\"1\""), "{x}");
        assert_eq!(x.matches("<error ").count(), 1, "{x}");
        assert!(
            x.contains("<error message=\"the run stopped: node 5 does not answer &lt;1000&gt;\"/>"),
            "{x}"
        );
        assert_eq!(x.matches("<testcase ").count(), 4);
    }

    #[test]
    fn html_escapes_and_shows_frames_and_clauses() {
        let h = html(&report());
        assert!(h.starts_with("<!DOCTYPE html>"));
        assert!(h.contains("a &lt;b&gt; &amp;"));
        assert!(h.contains("got &lt;1&gt; &amp; 2"));
        assert!(h.contains("0.001500 stimulus 605#4000100000000000"), "{h}");
        assert!(h.contains("CiA 301 §7.2.4.3.17"));
        assert!(h.contains("<b>FAILED</b>"));
    }

    #[test]
    fn summary_and_json_agree_with_the_report() {
        let r = report();
        let s = summary(&r);
        assert!(s.contains("FAILED: 3 cases, 1 mandatory failures"), "{s}");
        assert!(s.contains("(advisory)"));
        let back: Report = serde_json::from_str(&json(&r)).unwrap();
        assert_eq!(back, r);
    }
}
