//! The web dashboard in a real browser: `cantwin sim scenarios/plant.toml --web
//! 127.0.0.1:0` is opened in headless Chromium, driven by the system's chromedriver over the
//! W3C WebDriver protocol (a small client here on std's TCP). The page must show the
//! scenario's nodes, its controls must change what the bus and the page show, its charts must
//! zoom, place cursors, pause and export CSV under the page's Content-Security-Policy, and its
//! frame stream must be complete or say what it dropped.
//!
//! Skipped, saying so, when Chromium or chromedriver is not installed
//! (`scripts/test-all.sh` installs Debian's `chromium` and `chromium-driver`).
#![allow(clippy::unwrap_used)]

mod common;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

const CHROMEDRIVER: &str = "/usr/bin/chromedriver";
const CHROMIUM: &str = "/usr/bin/chromium";

/// Kills a child process when the test ends, passed or not.
struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// One HTTP/1.1 exchange: (status, body as JSON). The body is read by its Content-Length
/// (or chunks): chromedriver keeps connections open.
fn http(port: u16, method: &str, path: &str, body: Option<&Value>) -> (u16, Value) {
    http_with(port, method, path, "", body)
}

/// As [`http`], with `headers` (complete header lines) added to the request.
fn http_with(
    port: u16,
    method: &str,
    path: &str,
    headers: &str,
    body: Option<&Value>,
) -> (u16, Value) {
    let s = TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let body = body.map(|b| b.to_string()).unwrap_or_default();
    write!(
        &s,
        "{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nContent-Type: application/json\r\n{headers}Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )
    .unwrap();
    let mut r = BufReader::new(s);
    let mut line = String::new();
    r.read_line(&mut line).unwrap();
    let status: u16 = line.split_whitespace().nth(1).unwrap().parse().unwrap();
    let (mut length, mut chunked) = (None, false);
    loop {
        line.clear();
        r.read_line(&mut line).unwrap();
        let h = line.trim_end().to_ascii_lowercase();
        if h.is_empty() {
            break;
        }
        if let Some(v) = h.strip_prefix("content-length:") {
            length = v.trim().parse::<usize>().ok();
        }
        if h.starts_with("transfer-encoding:") && h.contains("chunked") {
            chunked = true;
        }
    }
    let mut payload = Vec::new();
    if chunked {
        loop {
            line.clear();
            r.read_line(&mut line).unwrap();
            let n = usize::from_str_radix(line.trim(), 16).unwrap();
            let mut chunk = vec![0; n + 2];
            r.read_exact(&mut chunk).unwrap();
            if n == 0 {
                break;
            }
            payload.extend_from_slice(&chunk[..n]);
        }
    } else if let Some(n) = length {
        payload.resize(n, 0);
        r.read_exact(&mut payload).unwrap();
    } else {
        r.read_to_end(&mut payload).unwrap();
    }
    let text = String::from_utf8_lossy(&payload).into_owned();
    (
        status,
        serde_json::from_str(&text).unwrap_or(Value::String(text)),
    )
}

/// The head of the answer to `GET path` (status line and header lines, lower case).
fn head(port: u16, path: &str) -> String {
    let s = TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    write!(
        &s,
        "GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut r = BufReader::new(s);
    let mut out = String::new();
    loop {
        let mut line = String::new();
        if r.read_line(&mut line).unwrap() == 0 || line.trim().is_empty() {
            break;
        }
        out.push_str(&line.to_ascii_lowercase());
    }
    out
}

/// A WebDriver session.
struct Browser {
    port: u16,
    session: String,
}

impl Browser {
    fn call(&self, method: &str, path: &str, body: Option<Value>) -> Value {
        let (status, v) = http(
            self.port,
            method,
            &format!("/session/{}{path}", self.session),
            body.as_ref(),
        );
        assert_eq!(status, 200, "{method} {path}: {v}");
        v["value"].clone()
    }

    fn js(&self, script: &str) -> Value {
        self.call(
            "POST",
            "/execute/sync",
            Some(json!({ "script": script, "args": [] })),
        )
    }

    /// Polls `script` until `done` accepts its value (at most 15 s).
    fn wait_for(&self, what: &str, script: &str, done: impl Fn(&Value) -> bool) -> Value {
        let deadline = Instant::now() + Duration::from_secs(15);
        loop {
            let v = self.js(script);
            if done(&v) {
                return v;
            }
            assert!(
                Instant::now() < deadline,
                "timed out waiting for {what}: {v}"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Clicks the element `css` as a user would (WebDriver element click).
    fn click(&self, css: &str) {
        let e = self.call(
            "POST",
            "/element",
            Some(json!({ "using": "css selector", "value": css })),
        );
        let id = e
            .as_object()
            .and_then(|o| o.values().next())
            .and_then(Value::as_str)
            .unwrap()
            .to_string();
        self.call("POST", &format!("/element/{id}/click"), Some(json!({})));
    }

    /// The WebDriver id of the element `css`.
    fn element(&self, css: &str) -> String {
        let e = self.call(
            "POST",
            "/element",
            Some(json!({ "using": "css selector", "value": css })),
        );
        e.as_object()
            .and_then(|o| o.values().next())
            .and_then(Value::as_str)
            .unwrap()
            .to_string()
    }

    /// Mouse actions (W3C WebDriver §17.5) on element `css`: `steps` are (x offset from the
    /// element's centre, button down?) pairs, each a move then a press or release.
    fn mouse(&self, css: &str, steps: &[(i64, bool)]) {
        let id = self.element(css);
        let mut actions = Vec::new();
        for (x, down) in steps {
            actions.push(json!({
                "type": "pointerMove", "duration": 50, "x": x, "y": 0,
                "origin": { "element-6066-11e4-a52e-4f735466cecf": id },
            }));
            actions.push(
                json!({ "type": if *down { "pointerDown" } else { "pointerUp" }, "button": 0 }),
            );
        }
        self.call(
            "POST",
            "/actions",
            Some(json!({ "actions": [{
                "type": "pointer", "id": "mouse", "parameters": { "pointerType": "mouse" },
                "actions": actions,
            }]})),
        );
        self.call("DELETE", "/actions", None);
    }

    /// Sets the fields of form `form` (JS) and clicks its submit button.
    fn submit(&self, form: &str, fields: &[(&str, &str)]) {
        self.submit_with(form, fields, "button[type=submit]");
    }

    /// Sets the fields of form `form` (JS) and clicks its button `button`.
    fn submit_with(&self, form: &str, fields: &[(&str, &str)], button: &str) {
        for (name, value) in fields {
            self.js(&format!(
                "const e = document.querySelector('{form} [name={name}]'); e.value = {v}; e.dispatchEvent(new Event('change'));",
                v = json!(value)
            ));
        }
        self.click(&format!("{form} {button}"));
    }

    fn message(&self, what: &str, class: &str, contains: &str) -> String {
        let v = self.wait_for(
            what,
            "const m = document.querySelector('#message'); return [m.className, m.textContent];",
            |v| {
                v[0].as_str().is_some_and(|c| c.contains(class))
                    && v[1].as_str().is_some_and(|t| t.contains(contains))
            },
        );
        v[1].as_str().unwrap().to_string()
    }
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

#[test]
fn web_dashboard_in_headless_chromium_shows_nodes_runs_controls_and_charts_zoom_cursors_csv() {
    if !Path::new(CHROMEDRIVER).exists() || !Path::new(CHROMIUM).exists() {
        eprintln!(
            "skipped: {CHROMIUM} or {CHROMEDRIVER} is not installed (Debian packages chromium, chromium-driver; scripts/test-all.sh installs them)"
        );
        return;
    }
    let started = Instant::now();
    let (_sim, url) = spawn_sim_with_web("60", &[]);
    // The page's policy allows its own script and style only: no inline code, no eval.
    let port_of_page: u16 = url
        .trim_start_matches("http://127.0.0.1:")
        .trim_end_matches('/')
        .parse()
        .unwrap();
    let page_head = head(port_of_page, "/");
    let csp = page_head
        .lines()
        .find_map(|l| l.strip_prefix("content-security-policy:"))
        .unwrap_or_else(|| panic!("no CSP: {page_head}"));
    assert!(
        csp.contains("script-src 'self'") && csp.contains("style-src 'self'"),
        "{csp}"
    );
    assert!(
        !csp.contains("unsafe-inline") && !csp.contains("unsafe-eval"),
        "{csp}"
    );
    for asset in ["/vendor/uplot.js", "/vendor/uplot.css", "/charts.js"] {
        let h = head(port_of_page, asset);
        assert!(h.starts_with("http/1.1 200"), "{asset}: {h}");
        assert!(h.contains("content-security-policy:"), "{asset}: {h}");
    }

    let port = free_port();
    let driver = Command::new(CHROMEDRIVER)
        .arg(format!("--port={port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let _driver = Killed(driver);
    let deadline = Instant::now() + Duration::from_secs(10);
    while TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(Instant::now() < deadline, "chromedriver did not start");
        std::thread::sleep(Duration::from_millis(50));
    }
    let profile = common::temp_dir("web-chromium-profile");
    let downloads = common::temp_dir("web-chromium-downloads");
    let (status, v) = http(
        port,
        "POST",
        "/session",
        Some(&json!({ "capabilities": { "alwaysMatch": {
            "browserName": "chrome",
            "goog:chromeOptions": {
                "binary": CHROMIUM,
                "args": [
                    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                    "--no-first-run", "--disable-background-networking",
                    "--disable-component-update", "--disable-sync",
                    "--window-size=1400,1000",
                    format!("--user-data-dir={}", profile.display()),
                ],
                "prefs": {
                    "download.default_directory": downloads.display().to_string(),
                    "download.prompt_for_download": false,
                },
            },
            "goog:loggingPrefs": { "browser": "ALL" },
        }}})),
    );
    assert_eq!(status, 200, "new session: {v}");
    let browser = Browser {
        port,
        session: v["value"]["sessionId"].as_str().unwrap().to_string(),
    };
    browser.call("POST", "/url", Some(json!({ "url": url })));

    // The page loads, connects to the event stream and shows every device of the scenario.
    let devices = browser.wait_for(
        "the node table",
        "return Array.from(document.querySelectorAll('#nodes tbody tr')).map(r => r.dataset.device);",
        |v| v.as_array().is_some_and(|a| a.len() == 4),
    );
    assert_eq!(devices, json!(["node5", "island", "drive", "opendrive"]));
    assert_eq!(
        browser.js("return document.querySelector('#link').textContent;"),
        "live"
    );
    let node5_state =
        "return document.querySelector('#nodes tr[data-device=node5] .nmt').textContent;";
    browser.wait_for("node 5's heartbeat", node5_state, |v| {
        v == "pre-operational"
    });

    // NMT start of node 5 from the page, in the words of `cantwin nmt`: its heartbeat
    // reports operational.
    browser.submit("#form-nmt", &[("device", "node5"), ("command", "start")]);
    browser.message("the NMT answer", "ok", "NMT start sent to node5 (node 5)");
    // The command is on the wire: the frame stream shows it, sent from the dashboard's
    // port, and node 5's heartbeat then reports operational.
    browser.wait_for(
        "the NMT frame in the stream",
        "return Array.from(document.querySelectorAll('#frames tbody tr')).map(r => r.textContent.replace(/\\s+/g, ' ')).join('\\n');",
        |v| {
            v.as_str().is_some_and(|t| {
                t.lines().any(|l| {
                    l.contains("dashboard") && l.contains("000") && l.contains("01 05")
                })
            })
        },
    );
    browser.wait_for("node 5 operational", node5_state, |v| v == "operational");

    // Setting a digital input of the TM3 island lights its lamp; a value a digital input
    // cannot take is refused with the reason.
    browser.submit(
        "#form-input",
        &[
            ("device", "island"),
            ("input", "digital_input.1.3"),
            ("value", "1"),
        ],
    );
    browser.message("the input answer", "ok", "island: digital_input.1.3 = 1");
    browser.wait_for(
        "input digital_input.1.3 on",
        "return document.querySelector('.panel[data-device=island] [data-value=\"digital_input.1.3\"]').dataset.on;",
        |v| v == "1",
    );
    browser.submit(
        "#form-input",
        &[
            ("device", "island"),
            ("input", "digital_input.1.3"),
            ("value", "2"),
        ],
    );
    let refused = browser.message("the refusal", "error", "digital_input.1.3");
    assert!(refused.contains("0 or 1"), "{refused}");

    // An SDO download the device refuses shows its abort code (0x2002 is limited to 100).
    browser.submit_with(
        "#form-sdo",
        &[
            ("device", "node5"),
            ("index", "0x2002"),
            ("sub", "0"),
            ("type", "u8"),
            ("value", "200"),
        ],
        "button[value=download]",
    );
    let abort = browser.message("the SDO abort", "error", "aborted by the device");
    assert!(abort.contains("0x06090031"), "{abort}");

    // An SDO upload answers with the value decoded by the dictionary's type and named as
    // in the EDS; a visible string is read as one.
    browser.submit_with(
        "#form-sdo",
        &[
            ("device", "node5"),
            ("index", "0x1017"),
            ("sub", "0"),
            ("type", "auto"),
        ],
        "button[value=upload]",
    );
    let up = browser.message("the SDO upload", "ok", "SDO upload");
    assert!(
        up.contains("1017sub0 \"Producer heartbeat time\" = 100 (0x0064, UNSIGNED16)"),
        "{up}"
    );
    browser.submit_with(
        "#form-sdo",
        &[
            ("device", "node5"),
            ("index", "0x1008"),
            ("sub", "0"),
            ("type", "vs"),
        ],
        "button[value=upload]",
    );
    let name = browser.message("the string upload", "ok", "1008sub0");
    assert!(
        name.contains("= \"cantwin plant node 5\" (VISIBLE_STRING)"),
        "{name}"
    );
    // A download of a typed value names the object and the value as written.
    browser.submit_with(
        "#form-sdo",
        &[
            ("device", "node5"),
            ("index", "0x1017"),
            ("sub", "0"),
            ("type", "u16"),
            ("value", "200"),
        ],
        "button[value=download]",
    );
    let down = browser.message("the SDO download", "ok", "SDO download");
    assert!(
        down.contains("\"Producer heartbeat time\" = 200 (0x00C8, UNSIGNED16): done"),
        "{down}"
    );

    // The charts: one per bus for the load and one for frames/s, drawn by uPlot; the axes
    // of these non-negative quantities start at zero however flat the samples are.
    let load = ".chart-card[data-signal='bus/can0/load']";
    let chart = "cantwinCharts.charts.find(c => c.key === 'bus/can0/load')";
    browser.wait_for(
        "the bus load chart with samples",
        &format!("const c = {chart}; return c ? c.u.data[0].length : 0;"),
        |v| v.as_u64().is_some_and(|n| n >= 4),
    );
    for key in [
        "bus/can0/load",
        "bus/can0/fps",
        "bus/can1/load",
        "bus/can1/fps",
    ] {
        let y = browser.js(&format!(
            "const c = cantwinCharts.charts.find(c => c.key === '{key}'); return [c.u.scales.y.min, c.u.scales.y.max, document.querySelectorAll(\".chart-card[data-signal='{key}'] canvas\").length];"
        ));
        assert_eq!(y[0], json!(0), "{key}: {y}");
        assert!(y[1].as_f64().unwrap() > 0.0, "{key}: {y}");
        assert!(y[2].as_u64().unwrap() >= 1, "{key} drawn on a canvas: {y}");
    }
    // Following the samples, not zoomed, until the user zooms.
    assert_eq!(
        browser.js(&format!(
            "return [{chart}.zoomed, document.querySelector(\"{load} .chart-state\").textContent];"
        )),
        json!([false, ""])
    );
    // Zoom: a drag across the plot narrows the x range and stops following.
    let span = format!("const u = {chart}.u; return [u.scales.x.min, u.scales.x.max];");
    let before = browser.js(&span);
    browser.mouse(&format!("{load} .u-over"), &[(-150, true), (50, false)]);
    let after = browser.wait_for("the zoom", &span, |v| v != &before);
    let width = |v: &Value| v[1].as_f64().unwrap() - v[0].as_f64().unwrap();
    assert!(width(&after) < width(&before) * 0.8, "{before} -> {after}");
    assert_eq!(browser.js(&format!("return {chart}.zoomed;")), json!(true));
    // Two clicks place cursors A and B; the readout gives Δt and Δvalue.
    browser.mouse(&format!("{load} .u-over"), &[(-100, true), (-100, false)]);
    browser.mouse(&format!("{load} .u-over"), &[(100, true), (100, false)]);
    let readout = browser.wait_for(
        "two cursors",
        &format!("const r = document.querySelector(\"{load} .chart-readout\"); return [r.textContent, r.dataset.dt];"),
        |v| v[0].as_str().is_some_and(|t| t.contains("Δt")),
    );
    let dt: f64 = readout[1].as_str().unwrap().parse().unwrap();
    assert!(dt > 0.0, "B right of A: {readout}");
    // CSV export: the samples in view, with a header naming the signal and its unit.
    browser.click(&format!("{load} button.csv"));
    let csv = browser.wait_for("the CSV export", &format!("return {chart}.lastCsv;"), |v| {
        v.as_str().is_some_and(|t| !t.is_empty())
    });
    let csv = csv.as_str().unwrap();
    // The browser saved it as a file, a blob: download the policy lets through.
    let saved = downloads.join("bus_can0_load.csv");
    let deadline = Instant::now() + Duration::from_secs(10);
    while std::fs::read_to_string(&saved).ok().as_deref() != Some(csv) {
        assert!(
            Instant::now() < deadline,
            "{} not saved as exported",
            saved.display()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("time_s,can0 bus load (%)"), "{csv}");
    let rows: Vec<(f64, f64)> = lines
        .map(|l| {
            let (t, v) = l.split_once(',').unwrap();
            (t.parse().unwrap(), v.parse().unwrap())
        })
        .collect();
    let (lo, hi) = (after[0].as_f64().unwrap(), after[1].as_f64().unwrap());
    assert!(!rows.is_empty(), "{csv}");
    assert!(
        rows.iter().all(|(t, v)| (lo..=hi).contains(t) && *v >= 0.0),
        "{csv}"
    );
    // Pause freezes the picture while the samples keep coming; Live follows again.
    browser.click(&format!("{load} button.live"));
    assert_eq!(browser.js(&format!("return {chart}.zoomed;")), json!(false));
    browser.click(&format!("{load} button.pause"));
    let frozen = browser.js(&format!("return {chart}.u.data[0].length;"));
    let kept = "return cantwinCharts.store.get('bus/can0/load').t.length;";
    let stored = browser.js(kept);
    browser.wait_for("samples while paused", kept, |v| v != &stored);
    assert_eq!(
        browser.js(&format!("return {chart}.u.data[0].length;")),
        frozen
    );
    browser.click(&format!("{load} button.pause"));
    browser.wait_for(
        "the chart after resuming",
        &format!("return {chart}.u.data[0].length;"),
        |v| v != &frozen,
    );
    // Any device's live value and any decoded PDO value can be charted (PDOs flow once the
    // nodes are operational).
    browser.submit("#form-nmt", &[("device", "all"), ("command", "start")]);
    browser.message("the NMT answer", "ok", "NMT start sent to all nodes");
    browser.wait_for(
        "the island's PDO values in the picker",
        "return Array.from(document.querySelectorAll('#signal-picker option')).some(o => o.value.startsWith('pdo/can0/3/TPDO2/'));",
        |v| v == &json!(true),
    );
    let picked = browser.js(
        "return Array.from(document.querySelectorAll('#signal-picker option')).map(o => o.value);",
    );
    let picked: Vec<&str> = picked
        .as_array()
        .unwrap()
        .iter()
        .filter_map(Value::as_str)
        .collect();
    let pdo = picked
        .iter()
        .find(|k| k.starts_with("pdo/can0/3/TPDO2/"))
        .unwrap_or_else(|| panic!("the island's analog inputs in the picker: {picked:?}"));
    assert!(
        picked.iter().any(|k| k.starts_with("device/drive/")),
        "{picked:?}"
    );
    browser.js(&format!(
        "document.querySelector('#signal-picker').value = '{pdo}';"
    ));
    browser.click("#form-chart button[type=submit]");
    browser.wait_for(
        "the PDO chart",
        &format!("const c = cantwinCharts.charts.find(c => c.key === '{pdo}'); return c ? c.u.data[0].length : 0;"),
        |v| v.as_u64().is_some_and(|n| n >= 1),
    );
    // A click on a device's live value charts it too (in one script: the panels are drawn
    // anew with each snapshot).
    browser.js(
        "document.querySelector(\".panel[data-device=drive] [data-signal='device/drive/speed']\").click();",
    );
    browser.wait_for(
        "the drive speed chart",
        "return cantwinCharts.charts.some(c => c.key === 'device/drive/speed') && document.querySelectorAll(\".chart-card[data-signal='device/drive/speed'] canvas\").length > 0;",
        |v| v == &json!(true),
    );
    // The charts shown are kept in the page's address, to be bookmarked.
    let hash = browser.js("return new URLSearchParams(location.hash.slice(1)).get('charts');");
    assert!(
        hash.as_str()
            .is_some_and(|h| h.contains("bus/can0/load") && h.contains(pdo)),
        "{hash}"
    );

    // The scrolling trace is complete: its rows are numbered, and where numbers are missing
    // a marker says how many rows were dropped.
    let rows = browser.js(
        "return Array.from(document.querySelectorAll('#frames tbody tr')).map(r => r.classList.contains('gap') ? -Number(r.dataset.dropped) - 1 : Number(r.dataset.seq));",
    );
    let rows: Vec<i64> = rows
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_i64().unwrap())
        .collect();
    assert!(rows.len() > 20, "{}", rows.len());
    let mut dropped = 0;
    let mut prev: Option<i64> = None;
    for r in &rows {
        if *r < 0 {
            dropped += -r - 1;
            continue;
        }
        if let Some(p) = prev {
            assert_eq!(
                p - r - 1,
                dropped,
                "rows {p} and {r}: {dropped} marked dropped"
            );
        }
        prev = Some(*r);
        dropped = 0;
    }
    // Pause holds the rows that come (the table stands still); Resume shows them, in order,
    // with no gap.
    let top = "return Number(document.querySelector('#frames tbody tr[data-seq]').dataset.seq);";
    browser.click("#frames-pause");
    let held_at = browser.js(top);
    browser.wait_for(
        "rows held while paused",
        "return document.querySelector('#frames-count').textContent;",
        |v| {
            v.as_str()
                .is_some_and(|t| t.starts_with("paused · ") && !t.starts_with("paused · 0 "))
        },
    );
    assert_eq!(browser.js(top), held_at, "the table stands still");
    browser.click("#frames-pause");
    let after = browser.js(top);
    assert!(after.as_i64() > held_at.as_i64(), "{held_at} -> {after}");
    let seqs = browser.js(
        "return Array.from(document.querySelectorAll('#frames tbody tr')).slice(0, 40).map(r => r.dataset.seq ? Number(r.dataset.seq) : -1);",
    );
    let seqs: Vec<i64> = seqs
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_i64().unwrap())
        .collect();
    assert!(
        seqs.windows(2).all(|w| w[0] == w[1] + 1),
        "contiguous after resuming: {seqs:?}"
    );

    // The fixed trace: one row per identifier, node 5's heartbeat counted with its cycle.
    browser.click("#view-fixed");
    let hb = browser.wait_for(
        "the fixed trace",
        "const r = document.querySelector('#fixed tr[data-bus=can0][data-id=\"705\"]'); return r ? [Number(r.querySelector('.count').textContent), r.querySelector('.cycle').textContent] : null;",
        |v| v[0].as_u64().is_some_and(|n| n > 2),
    );
    let cycle: f64 = hb[1].as_str().unwrap().parse().unwrap();
    assert!(
        (150.0..=250.0).contains(&cycle),
        "heartbeat every 200 ms now: {hb}"
    );
    let ids = browser.js("return Array.from(document.querySelectorAll('#fixed tbody tr')).map(r => r.dataset.bus + ':' + r.dataset.id);");
    let ids: Vec<&str> = ids
        .as_array()
        .unwrap()
        .iter()
        .filter_map(Value::as_str)
        .collect();
    let unique: std::collections::BTreeSet<&&str> = ids.iter().collect();
    assert_eq!(unique.len(), ids.len(), "one row per identifier: {ids:?}");
    assert!(
        ids.contains(&"can1:000"),
        "every bus, every sender (the dashboard's NMT on can1): {ids:?}"
    );

    // Nothing the page did was refused by its Content-Security-Policy. The policy is in
    // force and its refusals reach the log: an inline style attribute set here is refused,
    // the one refusal the log may hold.
    browser.js(
        "const d = document.createElement('div'); d.setAttribute('style', 'color: red'); document.body.appendChild(d);",
    );
    let logs = browser.call("POST", "/se/log", Some(json!({ "type": "browser" })));
    let refused: Vec<&Value> = logs
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| {
            e["message"]
                .as_str()
                .is_some_and(|m| m.contains("Content Security Policy"))
        })
        .collect();
    assert_eq!(refused.len(), 1, "{refused:?}");
    assert!(
        refused[0]["message"]
            .as_str()
            .is_some_and(|m| m.contains("inline style")),
        "{refused:?}"
    );

    browser.call("DELETE", "", None);
    let _ = std::fs::remove_dir_all(&profile);
    let _ = std::fs::remove_dir_all(&downloads);
    let took = started.elapsed();
    assert!(took < Duration::from_secs(30), "took {took:?}");
}

/// `cantwin sim plant.toml --web 127.0.0.1:0 --duration SECONDS [EXTRA]`, the child and the
/// dashboard's URL as its first line gives it (plain, or JSON with `--json`).
fn spawn_sim_with_web(seconds: &str, extra: &[&str]) -> (Killed, String) {
    let mut sim = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args(["sim", &common::scenario_file("plant.toml")])
        .args(["--web", "127.0.0.1:0", "--duration", seconds])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(sim.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let sim = Killed(sim);
    let addr = if extra.contains(&"--json") {
        let v: Value = serde_json::from_str(&line).unwrap();
        v["web"].as_str().unwrap().to_string()
    } else {
        line.strip_prefix("web ").unwrap().trim().to_string()
    };
    assert!(addr.starts_with("http://127.0.0.1:"), "{line}");
    (sim, addr)
}

/// `cantwin sim plant.toml --web 127.0.0.1:0 --duration 30 [EXTRA]`, the child and the
/// dashboard's port.
fn sim_with_web(extra: &[&str]) -> (Killed, u16) {
    let (sim, addr) = spawn_sim_with_web("30", extra);
    let port = addr
        .trim_start_matches("http://127.0.0.1:")
        .trim_end_matches('/')
        .parse()
        .unwrap();
    (sim, port)
}

#[test]
fn web_controls_answer_bad_requests_with_4xx_and_a_message() {
    let (_sim, port) = sim_with_web(&["--json"]);
    // Controls carry the run's token, which the page holds.
    let (_, page) = http(port, "GET", "/", None);
    let page = page.as_str().unwrap();
    let token = page
        .split("name=\"cantwin-token\" content=\"")
        .nth(1)
        .and_then(|r| r.split('"').next())
        .unwrap();
    let token = format!("X-Cantwin-Token: {token}\r\n");
    let post = |path: &str, body: &str| {
        let v: Value = serde_json::from_str(body).unwrap_or(Value::String(body.into()));
        http_with(port, "POST", path, &token, Some(&v))
    };
    let (status, v) = http_with(port, "POST", "/api/nmt", &token, None);
    assert_eq!(status, 400, "{v}");
    assert!(v["message"].as_str().unwrap().contains("not JSON"), "{v}");
    let (status, v) = post("/api/nmt", r#"{"device":"nobody","command":"stop"}"#);
    assert_eq!(status, 400, "{v}");
    assert!(
        v["message"]
            .as_str()
            .unwrap()
            .contains("no device \"nobody\""),
        "{v}"
    );
    let (status, v) = post("/api/nmt", r#"{"command":"halt"}"#);
    assert_eq!((status, v["ok"].clone()), (400, json!(false)), "{v}");
    assert!(
        v["message"]
            .as_str()
            .unwrap()
            .contains("start, stop, preop, reset, reset-comm"),
        "the words of `cantwin nmt`: {v}"
    );
    // `cantwin nmt reset` says `reset`; the older `reset-node` still works.
    for word in ["reset", "reset-node"] {
        let (status, v) = post("/api/nmt", &format!(r#"{{"command":"{word}"}}"#));
        assert_eq!(status, 200, "{word}: {v}");
        assert!(
            v["message"]
                .as_str()
                .unwrap()
                .starts_with("NMT reset node sent to all nodes"),
            "{v}"
        );
    }
    let (status, v) = post(
        "/api/sdo",
        r#"{"device":"node5","index":"0x1008","sub":0,"op":"erase","type":"vs"}"#,
    );
    assert_eq!(status, 400, "{v}");
    // `auto` writes a value as the type the device's dictionary gives the object; an object
    // it does not have needs the type given.
    let (status, v) = post(
        "/api/sdo",
        r#"{"device":"node5","index":"0x1017","sub":0,"type":"auto","value":"250"}"#,
    );
    assert_eq!(status, 200, "{v}");
    assert!(
        v["message"]
            .as_str()
            .unwrap()
            .ends_with("1017sub0 \"Producer heartbeat time\" = 250 (0x00FA, UNSIGNED16): done"),
        "{v}"
    );
    let (status, v) = post(
        "/api/sdo",
        r#"{"device":"node5","index":"0x5FFF","sub":0,"type":"auto","value":"1"}"#,
    );
    assert_eq!(status, 400, "{v}");
    assert!(
        v["message"]
            .as_str()
            .unwrap()
            .contains("give the value's type"),
        "{v}"
    );
    // The charts' window so far, for a page that opens late: every signal's samples.
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        let (status, h) = http(port, "GET", "/api/history", None);
        assert_eq!(status, 200, "{h}");
        let load = &h["series"]["bus/can0/load"];
        if load.as_array().is_some_and(|a| a.len() >= 2) {
            let t: Vec<f64> = load
                .as_array()
                .unwrap()
                .iter()
                .map(|p| p[0].as_f64().unwrap())
                .collect();
            assert!(t.windows(2).all(|w| w[0] < w[1]), "oldest first: {t:?}");
            assert!(
                h["series"]
                    .as_object()
                    .unwrap()
                    .keys()
                    .any(|k| k.starts_with("device/island/")),
                "{h}"
            );
            break;
        }
        assert!(Instant::now() < deadline, "{h}");
        std::thread::sleep(Duration::from_millis(100));
    }
    let (status, v) = post(
        "/api/sdo",
        r#"{"device":"node5","index":"0x10000","sub":0,"type":"u8","value":"1"}"#,
    );
    assert_eq!(status, 400, "{v}");
    assert!(v["message"].as_str().unwrap().contains("`index`"), "{v}");
    // The OPEN DRIVE speaks CAL: no CANopen node-ID to address an SDO to.
    let (status, v) = post(
        "/api/sdo",
        r#"{"device":"opendrive","index":"0x1000","sub":0,"type":"u32","value":"1"}"#,
    );
    assert_eq!(status, 400, "{v}");
    let (status, v) = post(
        "/api/input",
        r#"{"device":"drive","input":"analog_input.1","value":11}"#,
    );
    assert_eq!(status, 400, "{v}");
    assert!(v["message"].as_str().unwrap().contains("-10–10"), "{v}");
    // Raw counts of a TM3 analog input, volts of an ADV200 one.
    let (status, v) = post(
        "/api/input",
        r#"{"device":"island","input":"analog_input.3.0","value":5000}"#,
    );
    assert_eq!(status, 200, "{v}");
    let (status, v) = post(
        "/api/input",
        r#"{"device":"drive","input":"analog_input.2","value":-2.5}"#,
    );
    assert_eq!(status, 200, "{v}");
    // Faults use the vocabulary and checks of the scenarios' [[at]] tables.
    let (status, v) = post(
        "/api/fault",
        r#"{"action":"drop","bus":"can0","fraction":1.5}"#,
    );
    assert_eq!(status, 400, "{v}");
    assert!(v["message"].as_str().unwrap().contains("fraction"), "{v}");
    let (status, v) = post("/api/fault", r#"{"action":"melt"}"#);
    assert_eq!(status, 400, "{v}");
    assert!(
        v["message"].as_str().unwrap().contains("clear_faults"),
        "{v}"
    );
    let (status, v) = post("/api/fault", r#"{"action":"disconnect","device":"node5"}"#);
    assert_eq!((status, v["ok"].clone()), (200, json!(true)), "{v}");
    let (status, v) = post("/api/power", r#"{"device":"island"}"#);
    assert_eq!(status, 200, "{v}");
    let (status, v) = post("/api/power", r#"{"device":"island"}"#);
    assert_eq!(status, 400, "a second cycle while off: {v}");
    let (status, _) = http(port, "GET", "/no/such/page", None);
    assert_eq!(status, 404);
    // The cut cable shows in the snapshot: node 5 disconnected, the island unpowered.
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        let (_, s) = http(port, "GET", "/api/snapshot", None);
        let node = |name: &str| {
            s["nodes"]
                .as_array()
                .unwrap()
                .iter()
                .find(|n| n["device"] == name)
                .cloned()
                .unwrap()
        };
        if node("node5")["connected"] == json!(false) && node("island")["powered"] == json!(false) {
            break;
        }
        assert!(Instant::now() < deadline, "{s}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn web_refuses_a_non_loopback_address_without_allow_remote() {
    let (ok, _, err) = common::cantwin(&[
        "sim",
        &common::scenario_file("plant.toml"),
        "--web",
        "0.0.0.0:0",
        "--duration",
        "1",
    ]);
    assert!(!ok);
    assert!(err.contains("--allow-remote"), "{err}");
}

#[test]
fn web_names_a_socketcand_client_by_its_address_in_the_from_column() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_cantwin"))
        .args(["sim", &common::scenario_file("plant.toml")])
        .args(["--socketcand", "127.0.0.1:0", "--web", "127.0.0.1:0"])
        .args(["--duration", "20", "--json"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let _sim = Killed(child);
    let (mut gateway, mut web) = (None, None);
    while web.is_none() {
        let mut line = String::new();
        assert!(out.read_line(&mut line).unwrap() > 0, "no web line");
        let v: Value = serde_json::from_str(&line).unwrap();
        if v["gateway"] == "socketcand" {
            gateway = v["addr"].as_str().map(str::to_owned);
        }
        web = v["web"].as_str().map(str::to_owned);
    }
    let port: u16 = web
        .unwrap()
        .trim_start_matches("http://127.0.0.1:")
        .trim_end_matches('/')
        .parse()
        .unwrap();
    // A socketcand client (socketcand's protocol, rawmode) sends one frame on can0: an
    // outside master's SDO upload request of 0x1000 to node 127, which nobody answers.
    let mut client = TcpStream::connect(gateway.unwrap()).unwrap();
    client
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    let me = client.local_addr().unwrap();
    let mut greeting = [0u8; 6];
    client.read_exact(&mut greeting).unwrap();
    assert_eq!(&greeting, b"< hi >");
    write!(client, "< open can0 >< rawmode >").unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        // A snapshot carries the rows since the one before: send until one holds the frame.
        write!(client, "< send 67F 8 40 00 10 00 00 00 00 00 >").unwrap();
        std::thread::sleep(Duration::from_millis(100));
        let (_, s) = http(port, "GET", "/api/snapshot", None);
        let named = s["frames"]
            .as_array()
            .and_then(|rows| rows.iter().find(|r| r["id"] == "67F").cloned());
        if let Some(row) = named {
            assert_eq!(row["from"], json!(format!("socketcand {me}")), "{s}");
            // can0 carries CANopen nodes: the outside master's frame is decoded too.
            let text = row["text"].as_str().unwrap_or_default();
            assert!(!text.is_empty(), "{row}");
            break;
        }
        assert!(Instant::now() < deadline, "{s}");
    }
}
