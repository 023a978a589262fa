//! The dashboard's HTTP server: the page and its assets (built into the binary), the
//! snapshot stream as Server-Sent Events, and the controls as small JSON requests. It runs
//! on its own thread with a single-threaded runtime and reaches the simulation only through
//! the request queue and the snapshot watch channel.

use std::convert::Infallible;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use axum::Router;
use axum::body::Bytes;
use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use cantwin_canopen::wire::NmtCs;
use serde_json::{Value, json};

use super::{Command, Outcome, Refusal, Request};

const INDEX_HTML: &str = include_str!("assets/index.html");
const APP_JS: &str = include_str!("assets/app.js");
const APP_CSS: &str = include_str!("assets/app.css");

/// How long a control waits for the simulation's answer (an SDO download waits for the
/// device, at most its client timeout of 1 s).
const REPLY_TIMEOUT: Duration = Duration::from_secs(5);

#[derive(Clone)]
struct AppState {
    requests: mpsc::Sender<Request>,
    snapshots: tokio::sync::watch::Receiver<Arc<String>>,
}

/// The running server.
pub struct Server {
    addr: SocketAddr,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl Server {
    /// Binds `addr` (loopback only unless `allow_remote`) and serves on a thread of its own.
    pub(super) fn start(
        addr: SocketAddr,
        allow_remote: bool,
        requests: mpsc::Sender<Request>,
        snapshots: tokio::sync::watch::Receiver<Arc<String>>,
    ) -> Result<Server> {
        if !allow_remote && !addr.ip().is_loopback() {
            bail!(
                "--web {addr}: not a loopback address; anyone who can reach it could control the simulated devices (add --allow-remote to allow it)"
            );
        }
        let listener = std::net::TcpListener::bind(addr)
            .with_context(|| format!("starting the web dashboard on {addr}"))?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_io()
            .enable_time()
            .build()
            .context("starting the web server's runtime")?;
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let app = router(AppState {
            requests,
            snapshots,
        });
        let thread = std::thread::Builder::new()
            .name("cantwin-web".into())
            .spawn(move || {
                runtime.block_on(async move {
                    let Ok(listener) = tokio::net::TcpListener::from_std(listener) else {
                        eprintln!("cantwin sim: the web dashboard could not take its socket");
                        return;
                    };
                    let serve = axum::serve(listener, app).with_graceful_shutdown(async {
                        let _ = stopped.await;
                    });
                    if let Err(e) = serve.await {
                        eprintln!("cantwin sim: the web dashboard stopped: {e}");
                    }
                });
            })
            .context("starting the web server thread")?;
        Ok(Server {
            addr,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// The address it listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Stops serving (open event streams end).
    pub fn shutdown(mut self) {
        self.stop_now();
    }

    fn stop_now(&mut self) {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        if let Some(t) = self.thread.take() {
            // Open SSE streams keep a graceful shutdown waiting; the process ends anyway.
            if t.is_finished() {
                let _ = t.join();
            }
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.stop_now();
    }
}

fn router(state: AppState) -> Router {
    Router::new()
        .route(
            "/",
            get(|| async { asset("text/html; charset=utf-8", INDEX_HTML) }),
        )
        .route(
            "/app.js",
            get(|| async { asset("text/javascript; charset=utf-8", APP_JS) }),
        )
        .route(
            "/app.css",
            get(|| async { asset("text/css; charset=utf-8", APP_CSS) }),
        )
        .route("/api/snapshot", get(snapshot))
        .route("/events", get(events))
        .route("/api/nmt", post(nmt))
        .route("/api/input", post(input))
        .route("/api/sdo", post(sdo))
        .route("/api/power", post(power))
        .route("/api/fault", post(fault))
        .fallback(|| async { answer(StatusCode::NOT_FOUND, false, "no such page".into()) })
        .with_state(state)
}

fn asset(content_type: &'static str, body: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, content_type),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}

fn answer(status: StatusCode, ok: bool, message: String) -> Response {
    (status, axum::Json(json!({ "ok": ok, "message": message }))).into_response()
}

fn bad(message: impl Into<String>) -> Response {
    answer(StatusCode::BAD_REQUEST, false, message.into())
}

async fn snapshot(State(s): State<AppState>) -> Response {
    let body = s.snapshots.borrow().as_str().to_owned();
    ([(header::CONTENT_TYPE, "application/json")], body).into_response()
}

async fn events(State(s): State<AppState>) -> impl IntoResponse {
    let mut rx = s.snapshots.clone();
    // The newest snapshot goes out at once, then each new one.
    rx.mark_changed();
    let stream = futures_util::stream::unfold(rx, |mut rx| async move {
        rx.changed().await.ok()?;
        let data = rx.borrow_and_update().clone();
        let event = Event::default().event("snapshot").data(data.as_str());
        Some((Ok::<_, Infallible>(event), rx))
    });
    Sse::new(stream).keep_alive(KeepAlive::default())
}

/// Sends `command` to the simulation and turns its outcome into a response.
async fn run(s: &AppState, command: Command) -> Response {
    let (reply, outcome) = tokio::sync::oneshot::channel::<Outcome>();
    if s.requests.send(Request { command, reply }).is_err() {
        return answer(
            StatusCode::SERVICE_UNAVAILABLE,
            false,
            "the simulation has stopped".into(),
        );
    }
    match tokio::time::timeout(REPLY_TIMEOUT, outcome).await {
        Ok(Ok(Ok(message))) => answer(StatusCode::OK, true, message),
        Ok(Ok(Err(Refusal::BadRequest(m)))) => bad(m),
        Ok(Ok(Err(Refusal::Failed(m)))) => answer(StatusCode::UNPROCESSABLE_ENTITY, false, m),
        Ok(Err(_)) => answer(
            StatusCode::SERVICE_UNAVAILABLE,
            false,
            "the simulation has stopped".into(),
        ),
        Err(_) => answer(
            StatusCode::GATEWAY_TIMEOUT,
            false,
            format!(
                "no answer from the simulation within {} s",
                REPLY_TIMEOUT.as_secs()
            ),
        ),
    }
}

type Body = serde_json::Map<String, Value>;

/// The request body as a JSON object.
fn body(bytes: &Bytes) -> Result<Body, String> {
    match serde_json::from_slice::<Value>(bytes) {
        Ok(Value::Object(m)) => Ok(m),
        Ok(_) => Err("the request body must be a JSON object".into()),
        Err(e) => Err(format!("the request body is not JSON: {e}")),
    }
}

/// Parses the body with `parse` and runs the command; a bad body is HTTP 400.
async fn control(
    s: &AppState,
    bytes: &Bytes,
    parse: fn(&Body) -> Result<Command, String>,
) -> Response {
    match body(bytes).and_then(|m| parse(&m)) {
        Ok(command) => run(s, command).await,
        Err(e) => bad(e),
    }
}

fn text<'a>(m: &'a Body, key: &str) -> Result<&'a str, String> {
    match m.get(key) {
        Some(Value::String(s)) if !s.is_empty() => Ok(s),
        Some(_) => Err(format!("`{key}` must be a non-empty string")),
        None => Err(format!("`{key}` is missing")),
    }
}

/// An integer given as a JSON number or as a decimal or 0x-hex string.
fn integer(m: &Body, key: &str) -> Result<i64, String> {
    let v = m.get(key).ok_or_else(|| format!("`{key}` is missing"))?;
    let parsed = match v {
        Value::Number(n) => n.as_i64(),
        Value::String(s) => parse_int(s.trim()),
        _ => None,
    };
    parsed.ok_or_else(|| format!("`{key}` must be an integer (decimal or 0x…), not {v}"))
}

fn parse_int(s: &str) -> Option<i64> {
    let (neg, s) = match s.strip_prefix('-') {
        Some(r) => (true, r),
        None => (false, s),
    };
    let v = match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(h) => i64::from_str_radix(h, 16).ok()?,
        None => s.parse::<i64>().ok()?,
    };
    Some(if neg { -v } else { v })
}

async fn nmt(State(s): State<AppState>, bytes: Bytes) -> Response {
    control(&s, &bytes, nmt_command).await
}

fn nmt_command(m: &Body) -> Result<Command, String> {
    let cs = match text(m, "command")? {
        "start" => NmtCs::Start,
        "stop" => NmtCs::Stop,
        "preop" => NmtCs::EnterPreOperational,
        "reset-node" => NmtCs::ResetNode,
        "reset-comm" => NmtCs::ResetCommunication,
        other => {
            return Err(format!(
                "unknown NMT command {other:?} (start, stop, preop, reset-node, reset-comm)"
            ));
        }
    };
    let device = match m.get("device") {
        None | Some(Value::Null) => None,
        Some(Value::String(d)) if d == "all" => None,
        Some(Value::String(d)) if !d.is_empty() => Some(d.clone()),
        Some(_) => return Err("`device` must be a device name or \"all\"".into()),
    };
    Ok(Command::Nmt { device, cs })
}

async fn input(State(s): State<AppState>, bytes: Bytes) -> Response {
    control(&s, &bytes, input_command).await
}

fn input_command(m: &Body) -> Result<Command, String> {
    let device = text(m, "device")?.to_string();
    let input = text(m, "input")?.to_string();
    let value = match m.get("value") {
        Some(Value::Number(n)) => n.as_f64(),
        Some(Value::Bool(b)) => Some(if *b { 1.0 } else { 0.0 }),
        Some(Value::String(v)) => match v.trim() {
            "on" | "true" => Some(1.0),
            "off" | "false" => Some(0.0),
            v => v.parse::<f64>().ok(),
        },
        _ => None,
    };
    let value = value
        .filter(|v| v.is_finite())
        .ok_or("`value` must be a number, true/false or on/off")?;
    Ok(Command::SetInput {
        device,
        input,
        value,
    })
}

/// The little-endian bytes of `value` as CiA 301 data type `ty` (§7.1.4), or hex bytes.
fn encode_value(ty: &str, value: &str) -> Result<Vec<u8>, String> {
    let int = |min: i64, max: i64| {
        parse_int(value.trim())
            .filter(|v| (min..=max).contains(v))
            .ok_or_else(|| format!("{value:?} is not a {ty} ({min}..={max})"))
    };
    Ok(match ty {
        "u8" => vec![int(0, 0xFF)? as u8],
        "u16" => (int(0, 0xFFFF)? as u16).to_le_bytes().to_vec(),
        "u32" => (int(0, 0xFFFF_FFFF)? as u32).to_le_bytes().to_vec(),
        "i8" => (int(-0x80, 0x7F)? as i8).to_le_bytes().to_vec(),
        "i16" => (int(-0x8000, 0x7FFF)? as i16).to_le_bytes().to_vec(),
        "i32" => (int(-0x8000_0000, 0x7FFF_FFFF)? as i32)
            .to_le_bytes()
            .to_vec(),
        "hex" => {
            let digits: String = value.chars().filter(|c| !c.is_whitespace()).collect();
            if digits.is_empty() || digits.len() % 2 != 0 {
                return Err(format!(
                    "{value:?}: hex bytes are pairs of digits, e.g. E8 03"
                ));
            }
            (0..digits.len())
                .step_by(2)
                .map(|i| u8::from_str_radix(&digits[i..i + 2], 16))
                .collect::<Result<Vec<u8>, _>>()
                .map_err(|_| format!("{value:?} is not hex bytes"))?
        }
        other => {
            return Err(format!(
                "unknown type {other:?} (u8, u16, u32, i8, i16, i32, hex)"
            ));
        }
    })
}

async fn sdo(State(s): State<AppState>, bytes: Bytes) -> Response {
    control(&s, &bytes, sdo_command).await
}

fn sdo_command(m: &Body) -> Result<Command, String> {
    let device = text(m, "device")?.to_string();
    let index = integer(m, "index")?;
    let index =
        u16::try_from(index).map_err(|_| format!("`index` is 0x0000–0xFFFF, not {index}"))?;
    let sub = integer(m, "sub")?;
    let sub = u8::try_from(sub).map_err(|_| format!("`sub` is 0–255, not {sub}"))?;
    let ty = text(m, "type")?;
    let value = match m.get("value") {
        Some(Value::String(v)) => v.clone(),
        Some(Value::Number(n)) => n.to_string(),
        _ => return Err("`value` is missing".into()),
    };
    let data = encode_value(ty, &value)?;
    Ok(Command::Sdo {
        device,
        index,
        sub,
        data,
    })
}

async fn power(State(s): State<AppState>, bytes: Bytes) -> Response {
    control(&s, &bytes, |m| {
        Ok(Command::PowerCycle {
            device: text(m, "device")?.to_string(),
        })
    })
    .await
}

async fn fault(State(s): State<AppState>, bytes: Bytes) -> Response {
    control(&s, &bytes, fault_command).await
}

/// The body as an `[[at]]` table of the scenario files.
fn fault_command(m: &Body) -> Result<Command, String> {
    let mut table = toml::Table::new();
    for (k, v) in m {
        // Fields the form left empty are absent.
        let value = match v {
            Value::Null => continue,
            Value::String(s) if s.trim().is_empty() => continue,
            // Fractions are floats even when written as 0 or 1.
            Value::Number(n) if k == "fraction" => n.as_f64().map(toml::Value::Float),
            Value::String(s) if k == "fraction" => s.trim().parse().ok().map(toml::Value::Float),
            Value::String(s) if k == "count" => s.trim().parse().ok().map(toml::Value::Integer),
            Value::Number(n) => n
                .as_i64()
                .map(toml::Value::Integer)
                .or(n.as_f64().map(toml::Value::Float)),
            Value::String(s) => Some(toml::Value::String(s.clone())),
            Value::Bool(b) => Some(toml::Value::Boolean(*b)),
            _ => None,
        };
        let value = value.ok_or_else(|| format!("`{k}` has a value of the wrong type"))?;
        table.insert(k.clone(), value);
    }
    if !table.contains_key("action") {
        return Err("`action` is missing".into());
    }
    Ok(Command::Fault(table))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia301_values_encode_little_endian_within_their_type() {
        assert_eq!(encode_value("u16", "1000"), Ok(vec![0xE8, 0x03]));
        assert_eq!(
            encode_value("u32", "0x12345678"),
            Ok(vec![0x78, 0x56, 0x34, 0x12])
        );
        assert_eq!(encode_value("i8", "-1"), Ok(vec![0xFF]));
        assert_eq!(encode_value("hex", "e8 03"), Ok(vec![0xE8, 0x03]));
        assert!(encode_value("u8", "256").is_err());
        assert!(encode_value("hex", "e8 0").is_err());
        assert!(encode_value("f32", "1").is_err());
    }
}
