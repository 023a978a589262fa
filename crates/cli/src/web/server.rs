//! The dashboard's HTTP server: the page and its assets (built into the binary), the
//! snapshot stream as Server-Sent Events, and the controls as small JSON requests. It runs
//! on its own thread with a single-threaded runtime and reaches the simulation only through
//! the request queue and the snapshot watch channel.
//!
//! Every request passes the [`Policy`] of [`guard`] (Host, Origin, content
//! type, the run's token) before its handler; every answer carries the security headers;
//! [`listen`] bounds the connections and their time.

use std::convert::Infallible;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{Context, Result, anyhow, bail};
use axum::Router;
use axum::body::Bytes;
use axum::extract::{Request as HttpRequest, State};
use axum::http::{HeaderName, HeaderValue, StatusCode, header};
use axum::middleware::Next;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use cantwin_canopen::od::{DataType, Value as OdValue};
use cantwin_canopen::wire::NmtCs;
use serde_json::{Value, json};
use tokio::sync::Semaphore;
use tower_http::set_header::SetResponseHeaderLayer;

use super::guard::{self, Policy};
use super::listen::{self, Limits};
use super::{Command, Options, Outcome, Refusal, Request, SdoData};

const INDEX_HTML: &str = include_str!("assets/index.html");
const APP_JS: &str = include_str!("assets/app.js");
const CHARTS_JS: &str = include_str!("assets/charts.js");
const APP_CSS: &str = include_str!("assets/app.css");
/// The charting library, vendored unchanged (see `assets/vendor/README.md`).
const UPLOT_JS: &str = include_str!("assets/vendor/uPlot.iife.min.js");
const UPLOT_CSS: &str = include_str!("assets/vendor/uPlot.min.css");
const UPLOT_LICENSE: &str = include_str!("assets/vendor/uPlot.LICENSE");

/// Where the page's template takes the run's token.
const TOKEN_SLOT: &str = "{{token}}";

/// How long a control waits for the simulation's answer (an SDO download waits for the
/// device, at most its client timeout of 1 s).
const REPLY_TIMEOUT: Duration = Duration::from_secs(5);

/// The page's own script, style and connections only, no inline code, no framing
/// (CSP Level 3; `frame-ancestors` is the CSP form of X-Frame-Options). The charts are drawn
/// on canvases by the vendored library served from here, which places its elements through
/// the CSS object model (never inline `style` attributes, which `style-src 'self'` refuses);
/// a chart's CSV export is a `blob:` download, a navigation, which the policy leaves alone.
const CSP: &str = "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'";

/// The headers every answer carries (RFC 7034 X-Frame-Options, Fetch's nosniff, the
/// Referrer Policy spec's `no-referrer`, which keeps a `?token=` address out of Referer).
const SECURITY_HEADERS: [(&str, &str); 4] = [
    ("content-security-policy", CSP),
    ("x-frame-options", "DENY"),
    ("x-content-type-options", "nosniff"),
    ("referrer-policy", "no-referrer"),
];

#[derive(Clone)]
struct AppState {
    requests: mpsc::Sender<Request>,
    snapshots: tokio::sync::watch::Receiver<Arc<String>>,
    /// The page, with the run's token in it.
    index: Arc<String>,
    /// Places for event streams.
    streams: Arc<Semaphore>,
    max_streams: usize,
    /// How long a control's body may take to arrive whole.
    body_timeout: Duration,
}

/// The running server.
pub struct Server {
    url: String,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

/// A positive number of seconds, at most an hour.
fn seconds(v: f64, flag: &str) -> Result<Duration> {
    if v.is_finite() && v > 0.0 && v <= 3600.0 {
        Ok(Duration::from_secs_f64(v))
    } else {
        bail!("{flag} must be a number of seconds above 0 and at most 3600, not {v}")
    }
}

impl Server {
    /// Binds `addr` (loopback only unless `allow_remote`) and serves on a thread of its own.
    pub(super) fn start(
        addr: SocketAddr,
        allow_remote: bool,
        options: &Options,
        requests: mpsc::Sender<Request>,
        snapshots: tokio::sync::watch::Receiver<Arc<String>>,
    ) -> Result<Server> {
        if !allow_remote && !addr.ip().is_loopback() {
            bail!(
                "--web {addr}: not a loopback address; anyone who can reach it could control the simulated devices (add --allow-remote to allow it)"
            );
        }
        if !allow_remote && !options.allow_host.is_empty() {
            bail!(
                "--allow-host needs --allow-remote: without it the dashboard answers to loopback names only"
            );
        }
        // More than the process could hold open anyway (descriptors) is a mistake.
        const MOST: usize = 65_536;
        for (flag, n) in [
            ("--web-max-connections", options.web_max_connections),
            ("--web-max-streams", options.web_max_streams),
        ] {
            if !(1..=MOST).contains(&n) {
                bail!("{flag} must be 1 to {MOST}, not {n}");
            }
        }
        if options.web_max_streams >= options.web_max_connections {
            bail!(
                "--web-max-streams ({}) must be below --web-max-connections ({}): each open page needs a connection for its controls besides its event stream",
                options.web_max_streams,
                options.web_max_connections
            );
        }
        let limits = Limits {
            max_connections: options.web_max_connections,
            header_timeout: seconds(options.web_header_timeout, "--web-header-timeout")?,
            idle_timeout: seconds(options.web_idle_timeout, "--web-idle-timeout")?,
        };
        let listener = std::net::TcpListener::bind(addr)
            .with_context(|| format!("starting the web dashboard on {addr}"))?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let token = guard::new_token().map_err(|e| anyhow!("starting the web dashboard: {e}"))?;
        let policy = Policy::new(
            addr.port(),
            addr.ip(),
            allow_remote,
            &options.allow_host,
            token.clone(),
        )
        .map_err(|e| anyhow!(e))?;
        // The address to give the user: a name they allowed, else the bound address (its
        // loopback form when bound to all addresses).
        let shown = match options.allow_host.first() {
            Some(name) => guard::allowed_host(name, addr.port()).map_err(|e| anyhow!(e))?,
            None if addr.ip().is_unspecified() => format!("127.0.0.1:{}", addr.port()),
            None => addr.to_string(),
        };
        let url = if allow_remote {
            format!("http://{shown}/?token={token}")
        } else {
            format!("http://{shown}/")
        };
        if allow_remote {
            eprintln!(
                "cantwin sim: warning: --allow-remote: the web dashboard on {addr} obeys anyone who can reach it and has its address with the token ({url}); its controls power-cycle devices, write objects, inject faults and send NMT. It speaks plain HTTP: anyone on the network path can read the token. Host names accepted: {}",
                policy.hosts().join(", ")
            );
            if options.allow_host.is_empty() && addr.ip().is_unspecified() {
                eprintln!(
                    "cantwin sim: note: bound to all addresses without --allow-host, the dashboard answers only to the names above; give the name or address remote browsers use with --allow-host NAME"
                );
            }
        }
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_io()
            .enable_time()
            .build()
            .context("starting the web server's runtime")?;
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let app = router(
            AppState {
                requests,
                snapshots,
                index: Arc::new(INDEX_HTML.replace(TOKEN_SLOT, &token)),
                streams: Arc::new(Semaphore::new(options.web_max_streams)),
                max_streams: options.web_max_streams,
                body_timeout: limits.header_timeout,
            },
            Arc::new(policy),
        );
        let refusal = over_capacity(options.web_max_connections);
        let thread = std::thread::Builder::new()
            .name("cantwin-web".into())
            .spawn(move || {
                runtime.block_on(async move {
                    let Ok(listener) = tokio::net::TcpListener::from_std(listener) else {
                        eprintln!("cantwin sim: the web dashboard could not take its socket");
                        return;
                    };
                    listen::serve(listener, app, limits, refusal, async {
                        let _ = stopped.await;
                    })
                    .await;
                });
                // The runtime ends here, and with it every open connection.
            })
            .context("starting the web server thread")?;
        Ok(Server {
            url,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// The page's address to give the user (with the token under `--allow-remote`).
    pub fn url(&self) -> &str {
        &self.url
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
            // The thread ends with its runtime; a join would only wait for the last poll.
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

/// The whole answer to a connection over the cap, written before it is closed.
fn over_capacity(max: usize) -> Arc<[u8]> {
    let body = json!({
        "ok": false,
        "message": format!("the dashboard serves {max} connections at once (--web-max-connections); try again later"),
    })
    .to_string();
    let mut head = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\ncontent-length: {}\r\nconnection: close\r\nretry-after: 1\r\n",
        body.len()
    );
    for (k, v) in SECURITY_HEADERS {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    head.push_str("\r\n");
    head.push_str(&body);
    head.into_bytes().into()
}

fn router(state: AppState, policy: Arc<Policy>) -> Router {
    let mut app = Router::new()
        .route("/", get(index))
        .route(
            "/app.js",
            get(|| async { asset("text/javascript; charset=utf-8", APP_JS) }),
        )
        .route(
            "/charts.js",
            get(|| async { asset("text/javascript; charset=utf-8", CHARTS_JS) }),
        )
        .route(
            "/app.css",
            get(|| async { asset("text/css; charset=utf-8", APP_CSS) }),
        )
        .route(
            "/vendor/uplot.js",
            get(|| async { asset("text/javascript; charset=utf-8", UPLOT_JS) }),
        )
        .route(
            "/vendor/uplot.css",
            get(|| async { asset("text/css; charset=utf-8", UPLOT_CSS) }),
        )
        .route(
            "/vendor/uplot-license.txt",
            get(|| async { asset("text/plain; charset=utf-8", UPLOT_LICENSE) }),
        )
        .route("/api/history", get(history))
        .route("/api/snapshot", get(snapshot))
        .route("/events", get(events))
        .route("/api/nmt", post(nmt))
        .route("/api/input", post(input))
        .route("/api/sdo", post(sdo))
        .route("/api/power", post(power))
        .route("/api/fault", post(fault))
        .fallback(|| async { answer(StatusCode::NOT_FOUND, false, "no such page".into()) })
        .with_state(state)
        .layer(axum::middleware::from_fn_with_state(policy, admit));
    // Added last, so outermost: refusals carry the headers too.
    for (name, value) in SECURITY_HEADERS {
        app = app.layer(SetResponseHeaderLayer::overriding(
            HeaderName::from_static(name),
            HeaderValue::from_static(value),
        ));
    }
    app
}

/// Lets a request through to its handler only if the [`Policy`] admits its head.
async fn admit(State(policy): State<Arc<Policy>>, req: HttpRequest, next: Next) -> Response {
    match policy.check(req.method(), req.uri(), req.headers()) {
        Ok(()) => next.run(req).await,
        Err((status, reason)) => answer(status, false, reason),
    }
}

async fn index(State(s): State<AppState>) -> Response {
    (
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            // The page holds the run's token: no cache keeps it.
            (header::CACHE_CONTROL, "no-store"),
        ],
        s.index.as_str().to_owned(),
    )
        .into_response()
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

/// Every chart signal's samples over the window, asked of the simulation (it keeps them).
async fn history(State(s): State<AppState>) -> Response {
    let (reply, outcome) = tokio::sync::oneshot::channel::<Outcome>();
    if s.requests
        .send(Request {
            command: Command::History,
            reply,
        })
        .is_err()
    {
        return answer(
            StatusCode::SERVICE_UNAVAILABLE,
            false,
            "the simulation has stopped".into(),
        );
    }
    match tokio::time::timeout(REPLY_TIMEOUT, outcome).await {
        Ok(Ok(Ok(body))) => ([(header::CONTENT_TYPE, "application/json")], body).into_response(),
        Ok(Ok(Err(_)) | Err(_)) => answer(
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

async fn snapshot(State(s): State<AppState>) -> Response {
    let body = s.snapshots.borrow().as_str().to_owned();
    ([(header::CONTENT_TYPE, "application/json")], body).into_response()
}

async fn events(State(s): State<AppState>) -> Response {
    // The stream holds its place until it ends (the client goes away or the connection
    // is closed as idle).
    let Ok(place) = s.streams.clone().try_acquire_owned() else {
        return answer(
            StatusCode::SERVICE_UNAVAILABLE,
            false,
            format!(
                "the dashboard serves {} event streams at once (--web-max-streams); close another page",
                s.max_streams
            ),
        );
    };
    let mut rx = s.snapshots.clone();
    // The newest snapshot goes out at once, then each new one.
    rx.mark_changed();
    let stream = futures_util::stream::unfold((rx, place), |(mut rx, place)| async move {
        rx.changed().await.ok()?;
        let data = rx.borrow_and_update().clone();
        let event = Event::default().event("snapshot").data(data.as_str());
        Some((Ok::<_, Infallible>(event), (rx, place)))
    });
    Sse::new(stream)
        .keep_alive(KeepAlive::default())
        .into_response()
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

/// The longest control body taken: the controls' JSON objects are well under 1 KiB.
const MAX_BODY: usize = 64 * 1024;

/// Reads the body whole within the request timeout, so a client that trickles it byte by
/// byte (never idle, never done) cannot hold its connection; parses it with `parse` and runs
/// the command. A bad body is HTTP 400, a slow one 408, a long one 413.
async fn control(
    s: &AppState,
    request: axum::body::Body,
    parse: fn(&Body) -> Result<Command, String>,
) -> Response {
    let bytes =
        match tokio::time::timeout(s.body_timeout, axum::body::to_bytes(request, MAX_BODY)).await {
            Ok(Ok(bytes)) => bytes,
            Ok(Err(_)) => {
                return answer(
                    StatusCode::PAYLOAD_TOO_LARGE,
                    false,
                    format!("the request body is cut off or longer than {MAX_BODY} bytes"),
                );
            }
            Err(_) => {
                return answer(
                    StatusCode::REQUEST_TIMEOUT,
                    false,
                    format!(
                        "the request body did not arrive within {} s (--web-header-timeout)",
                        s.body_timeout.as_secs_f64()
                    ),
                );
            }
        };
    match body(&bytes).and_then(|m| parse(&m)) {
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

async fn nmt(State(s): State<AppState>, request: axum::body::Body) -> Response {
    control(&s, request, nmt_command).await
}

/// The NMT command a word names: the words of `cantwin nmt` (start, stop, preop, reset,
/// reset-comm), and the older words of this endpoint (reset-node), which keep working.
fn nmt_cs(word: &str) -> Option<NmtCs> {
    Some(match word {
        "start" => NmtCs::Start,
        "stop" => NmtCs::Stop,
        "preop" => NmtCs::EnterPreOperational,
        "reset" | "reset-node" => NmtCs::ResetNode,
        "reset-comm" => NmtCs::ResetCommunication,
        _ => return None,
    })
}

fn nmt_command(m: &Body) -> Result<Command, String> {
    let word = text(m, "command")?;
    let cs = nmt_cs(word).ok_or_else(|| {
        format!("unknown NMT command {word:?} (start, stop, preop, reset, reset-comm)")
    })?;
    let device = match m.get("device") {
        None | Some(Value::Null) => None,
        Some(Value::String(d)) if d == "all" => None,
        Some(Value::String(d)) if !d.is_empty() => Some(d.clone()),
        Some(_) => return Err("`device` must be a device name or \"all\"".into()),
    };
    Ok(Command::Nmt { device, cs })
}

async fn input(State(s): State<AppState>, request: axum::body::Body) -> Response {
    control(&s, request, input_command).await
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

/// The type a request names: a CiA 309-3 mnemonic (`u16`, `i32`, `vs`, `r32` …), `hex` for
/// raw bytes (`None`), or `auto` for the type the device's dictionary gives the object.
#[derive(Debug)]
enum Ty {
    Typed(DataType),
    Hex,
    Auto,
}

fn sdo_type(name: &str) -> Result<Ty, String> {
    match name {
        "hex" => Ok(Ty::Hex),
        "auto" => Ok(Ty::Auto),
        m => cantwin_cia309::data_type(m).map(Ty::Typed).ok_or_else(|| {
            let all: Vec<&str> = cantwin_cia309::MNEMONICS.iter().map(|(m, _)| *m).collect();
            format!(
                "unknown type {m:?} (auto, hex, or a CiA 309-3 mnemonic: {})",
                all.join(" ")
            )
        }),
    }
}

/// The little-endian bytes of `value` as CiA 301 data type `ty` (§7.1), or hex bytes.
fn encode_value(ty: Option<DataType>, value: &str) -> Result<Vec<u8>, String> {
    match ty {
        Some(ty) => OdValue::parse(ty, value.trim())
            .map(|v| v.to_le_bytes())
            .map_err(|e| format!("{value:?} is not a {ty}: {e}")),
        None => {
            let digits: String = value.chars().filter(|c| !c.is_whitespace()).collect();
            if digits.is_empty() || digits.len() % 2 != 0 {
                return Err(format!(
                    "{value:?}: hex bytes are pairs of digits, e.g. E8 03"
                ));
            }
            (0..digits.len())
                .step_by(2)
                .map(|i| {
                    digits
                        .get(i..i + 2)
                        .and_then(|d| u8::from_str_radix(d, 16).ok())
                })
                .collect::<Option<Vec<u8>>>()
                .ok_or_else(|| format!("{value:?} is not hex bytes"))
        }
    }
}

async fn sdo(State(s): State<AppState>, request: axum::body::Body) -> Response {
    control(&s, request, sdo_command).await
}

/// `{"device", "index", "sub", "op": "download" | "upload", "type", "value"}`; `op` is
/// `download` when absent (`write` and `read`, the words of `cantwin sdo`, are taken too).
fn sdo_command(m: &Body) -> Result<Command, String> {
    let device = text(m, "device")?.to_string();
    let index = integer(m, "index")?;
    let index =
        u16::try_from(index).map_err(|_| format!("`index` is 0x0000–0xFFFF, not {index}"))?;
    let sub = integer(m, "sub")?;
    let sub = u8::try_from(sub).map_err(|_| format!("`sub` is 0–255, not {sub}"))?;
    let ty = match m.get("type") {
        None | Some(Value::Null) => Ty::Auto,
        Some(_) => sdo_type(text(m, "type")?)?,
    };
    let upload = match m.get("op") {
        None | Some(Value::Null) => false,
        Some(_) => match text(m, "op")? {
            "download" | "write" => false,
            "upload" | "read" => true,
            other => {
                return Err(format!(
                    "unknown SDO operation {other:?} (download, upload)"
                ));
            }
        },
    };
    if upload {
        return Ok(Command::SdoUpload {
            device,
            index,
            sub,
            ty: match ty {
                Ty::Typed(t) => Some(t),
                Ty::Hex | Ty::Auto => None,
            },
        });
    }
    let value = match m.get("value") {
        Some(Value::String(v)) => v.clone(),
        Some(Value::Number(n)) => n.to_string(),
        _ => return Err("`value` is missing".into()),
    };
    let data = match ty {
        Ty::Typed(t) => SdoData::Encoded {
            ty: Some(t),
            bytes: encode_value(Some(t), &value)?,
        },
        Ty::Hex => SdoData::Encoded {
            ty: None,
            bytes: encode_value(None, &value)?,
        },
        Ty::Auto => SdoData::Text(value),
    };
    Ok(Command::SdoDownload {
        device,
        index,
        sub,
        data,
    })
}

async fn power(State(s): State<AppState>, request: axum::body::Body) -> Response {
    control(&s, request, |m| {
        Ok(Command::PowerCycle {
            device: text(m, "device")?.to_string(),
        })
    })
    .await
}

async fn fault(State(s): State<AppState>, request: axum::body::Body) -> Response {
    control(&s, request, fault_command).await
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

    fn typed(name: &str) -> Option<DataType> {
        match sdo_type(name) {
            Ok(Ty::Typed(t)) => Some(t),
            _ => None,
        }
    }

    #[test]
    fn cia301_values_encode_little_endian_within_their_type() {
        let enc = |ty: &str, v: &str| encode_value(typed(ty), v);
        assert_eq!(enc("u16", "1000"), Ok(vec![0xE8, 0x03]));
        assert_eq!(enc("u32", "0x12345678"), Ok(vec![0x78, 0x56, 0x34, 0x12]));
        assert_eq!(enc("i8", "-1"), Ok(vec![0xFF]));
        assert_eq!(enc("vs", "Pump 3"), Ok(b"Pump 3".to_vec()));
        assert_eq!(encode_value(None, "e8 03"), Ok(vec![0xE8, 0x03]));
        assert!(enc("u8", "256").is_err());
        assert!(encode_value(None, "e8 0").is_err());
        assert!(
            encode_value(None, "é8").is_err(),
            "no panic on a multi-byte character"
        );
        assert!(sdo_type("f32").unwrap_err().contains("vs"));
    }

    #[test]
    fn nmt_takes_the_words_of_the_cli_and_the_older_ones() {
        let cs = |w: &str| nmt_cs(w);
        assert_eq!(cs("start"), Some(NmtCs::Start));
        assert_eq!(cs("stop"), Some(NmtCs::Stop));
        assert_eq!(cs("preop"), Some(NmtCs::EnterPreOperational));
        assert_eq!(cs("reset"), Some(NmtCs::ResetNode));
        assert_eq!(cs("reset-node"), Some(NmtCs::ResetNode));
        assert_eq!(cs("reset-comm"), Some(NmtCs::ResetCommunication));
        assert_eq!(cs("halt"), None);
    }

    #[test]
    fn sdo_requests_name_an_upload_or_a_download_and_a_type() {
        let body = |v: serde_json::Value| v.as_object().unwrap().clone();
        let up = sdo_command(&body(json!({
            "device": "node5", "index": "0x1008", "sub": 0, "op": "upload", "type": "vs"
        })))
        .unwrap();
        assert!(
            matches!(
                up,
                Command::SdoUpload {
                    index: 0x1008,
                    sub: 0,
                    ty: Some(DataType::VisibleString),
                    ..
                }
            ),
            "{up:?}"
        );
        let down = sdo_command(&body(json!({
            "device": "node5", "index": "0x1017", "sub": 0, "type": "u16", "value": "1000"
        })))
        .unwrap();
        assert!(
            matches!(&down, Command::SdoDownload { data: SdoData::Encoded { ty: Some(DataType::Unsigned16), bytes }, .. } if bytes == &[0xE8, 0x03]),
            "{down:?}"
        );
        let auto = sdo_command(&body(json!({
            "device": "node5", "index": "0x1017", "sub": 0, "type": "auto", "value": "1000"
        })))
        .unwrap();
        assert!(
            matches!(&auto, Command::SdoDownload { data: SdoData::Text(t), .. } if t == "1000"),
            "{auto:?}"
        );
        let bad = sdo_command(&body(json!({
            "device": "node5", "index": 1, "sub": 0, "op": "erase", "type": "u8", "value": "1"
        })));
        assert!(bad.unwrap_err().contains("upload"));
    }
}
