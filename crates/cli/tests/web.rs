//! The web dashboard in a real browser: `cantwin sim scenarios/plant.toml --web
//! 127.0.0.1:0` is opened in headless Chromium, driven by the system's chromedriver over the
//! W3C WebDriver protocol (a small client here on std's TCP). The page must show the
//! scenario's nodes, its controls must change what the bus and the page show, and its charts
//! must move.
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

    /// Sets the fields of form `form` (JS) and clicks its submit button.
    fn submit(&self, form: &str, fields: &[(&str, &str)]) {
        for (name, value) in fields {
            self.js(&format!(
                "const e = document.querySelector('{form} [name={name}]'); e.value = {v}; e.dispatchEvent(new Event('change'));",
                v = json!(value)
            ));
        }
        self.click(&format!("{form} button[type=submit]"));
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
fn web_dashboard_in_headless_chromium_shows_nodes_runs_controls_and_moves_its_charts() {
    if !Path::new(CHROMEDRIVER).exists() || !Path::new(CHROMIUM).exists() {
        eprintln!(
            "skipped: {CHROMIUM} or {CHROMEDRIVER} is not installed (Debian packages chromium, chromium-driver; scripts/test-all.sh installs them)"
        );
        return;
    }
    let started = Instant::now();
    let (_sim, url) = spawn_sim_with_web("60", &[]);

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
            },
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

    // NMT start of node 5 from the page: its heartbeat reports operational.
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
    browser.submit(
        "#form-sdo",
        &[
            ("device", "node5"),
            ("index", "0x2002"),
            ("sub", "0"),
            ("type", "u8"),
            ("value", "200"),
        ],
    );
    let abort = browser.message("the SDO abort", "error", "aborted by the device");
    assert!(abort.contains("0x06090031"), "{abort}");

    // The charts move: the bus load path of can0 changes between two snapshots.
    let path =
        "return document.querySelector('.card[data-bus=can0] path.series').getAttribute('d');";
    let first = browser.js(path);
    browser.wait_for("the bus load chart to move", path, |v| {
        v != &first && v.as_str().is_some_and(|d| d.starts_with('M'))
    });

    browser.call("DELETE", "", None);
    let _ = std::fs::remove_dir_all(&profile);
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
