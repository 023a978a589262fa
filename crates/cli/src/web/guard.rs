//! Who may talk to the dashboard, decided from a request's head alone (no I/O here).
//!
//! The dashboard's controls power-cycle devices, write objects, inject faults and send NMT, so
//! every page a browser opens must not be able to drive them:
//!
//! * `Host` must name the server as the user reached it: a loopback name with the served port,
//!   the bound address itself, or (under `--allow-remote`) a name given with `--allow-host`.
//!   A page that rebinds its own DNS name to 127.0.0.1 still sends its own name, and is refused
//!   (RFC 9110 §7.2: the Host field carries the target URI's authority).
//! * `Origin`, when a browser sends one, must be the page's own, `http://` and that Host
//!   (RFC 6454 §7: browsers send it on every cross-origin request and on same-origin POSTs).
//! * Requests that change state need `Content-Type: application/json`: a cross-origin page
//!   can only send one without a CORS preflight with a "simple" content type (form data,
//!   `text/plain`), so this alone keeps a page from posting blind (Fetch Standard §3.2.3,
//!   CORS-safelisted request headers).
//! * They also carry the run's secret token in `X-Cantwin-Token`; the dashboard's page holds
//!   it, and only a page read from the dashboard's own origin can learn it. Under
//!   `--allow-remote` reading needs the token too (header, or `?token=` for the page itself
//!   and the event stream, which a browser's EventSource cannot give headers).

use axum::http::{HeaderMap, Method, StatusCode, Uri, header};

/// The header that carries the run's token.
pub const TOKEN_HEADER: &str = "x-cantwin-token";

/// The page's script and style and the charting library carry no secret and are needed
/// before the token is known.
const PUBLIC_PATHS: [&str; 6] = [
    "/app.js",
    "/charts.js",
    "/app.css",
    "/vendor/uplot.js",
    "/vendor/uplot.css",
    "/vendor/uplot-license.txt",
];

/// What the dashboard accepts.
#[derive(Debug)]
pub struct Policy {
    /// Accepted `Host` values, lower case, always with a port (`name:port`, `[v6]:port`).
    hosts: Vec<String>,
    token: String,
    remote: bool,
}

/// A refusal: the status and the reason, for the answer's message.
pub type Refusal = (StatusCode, String);

impl Policy {
    /// The policy of a server on `port` bound to `bound` (an address literal), with the
    /// `extra` Host names given with `--allow-host` (only with `remote`).
    pub fn new(
        port: u16,
        bound: std::net::IpAddr,
        remote: bool,
        extra: &[String],
        token: String,
    ) -> Result<Policy, String> {
        let mut hosts = vec![
            format!("127.0.0.1:{port}"),
            format!("localhost:{port}"),
            format!("[::1]:{port}"),
        ];
        // Bound to all addresses, the server has no one address of its own to answer to.
        if !bound.is_unspecified() && !hosts.contains(&authority(bound, port)) {
            hosts.push(authority(bound, port));
        }
        for name in extra {
            let host = allowed_host(name, port)?;
            if !hosts.contains(&host) {
                hosts.push(host);
            }
        }
        Ok(Policy {
            hosts,
            token,
            remote,
        })
    }

    /// The Host names accepted, for messages.
    pub fn hosts(&self) -> &[String] {
        &self.hosts
    }

    /// Whether the request with this head may go on to its handler.
    pub fn check(&self, method: &Method, target: &Uri, headers: &HeaderMap) -> Result<(), Refusal> {
        let forbidden = |m: String| Err((StatusCode::FORBIDDEN, m));
        // A request line in absolute form names its own host, which would stand in for Host
        // (RFC 9112 §3.2.2); only proxies are sent those, and the dashboard is none.
        if target.authority().is_some() {
            return forbidden(format!(
                "the request names its target in absolute form ({target}), as to a proxy: the dashboard takes a path only"
            ));
        }
        let (path, query) = (target.path(), target.query());
        let Some(host) = text(headers, header::HOST) else {
            return forbidden("the request has no Host header".into());
        };
        let host = normalize_authority(host);
        if !self.hosts.contains(&host) {
            return forbidden(format!(
                "Host {host:?} is not this dashboard's address (accepted: {}); a web page that rebound its name to this address is refused{}",
                self.hosts.join(", "),
                if self.remote {
                    ""
                } else {
                    "; to serve other names use --allow-remote with --allow-host NAME"
                }
            ));
        }
        if headers.contains_key(header::ORIGIN) {
            let origin = text(headers, header::ORIGIN).unwrap_or("");
            let own = origin
                .strip_prefix("http://")
                .is_some_and(|a| normalize_authority(a) == host);
            if !own {
                return forbidden(format!(
                    "Origin {origin:?} is not this dashboard's own (http://{host}): requests from other web pages are refused"
                ));
            }
        }
        let reads = *method == Method::GET || *method == Method::HEAD;
        if !reads {
            let json = text(headers, header::CONTENT_TYPE).is_some_and(|ct| {
                ct.split(';')
                    .next()
                    .is_some_and(|m| m.trim().eq_ignore_ascii_case("application/json"))
            });
            if !json {
                return Err((
                    StatusCode::UNSUPPORTED_MEDIA_TYPE,
                    "controls take a JSON body with Content-Type: application/json".into(),
                ));
            }
            if !self.token_in(text(headers, TOKEN_HEADER)) {
                return forbidden(format!(
                    "controls need this run's token in the {TOKEN_HEADER} header (the dashboard's page has it)"
                ));
            }
        } else if self.remote && !PUBLIC_PATHS.contains(&path) {
            let from_query = query.and_then(|q| {
                q.split('&')
                    .find_map(|kv| kv.strip_prefix("token="))
                    .map(str::to_owned)
            });
            if !self.token_in(text(headers, TOKEN_HEADER)) && !self.token_in(from_query.as_deref())
            {
                return forbidden(format!(
                    "with --allow-remote the dashboard needs this run's token (?token= as in the address it printed, or the {TOKEN_HEADER} header)"
                ));
            }
        }
        Ok(())
    }

    /// Compares in time independent of where the strings differ, so the answer's timing
    /// tells nothing about a guess.
    fn token_in(&self, given: Option<&str>) -> bool {
        let Some(given) = given else { return false };
        let (a, b) = (given.as_bytes(), self.token.as_bytes());
        a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
    }
}

/// A fresh token: 128 bits from the operating system's generator, as hex.
pub fn new_token() -> Result<String, String> {
    let mut bytes = [0u8; 16];
    getrandom::fill(&mut bytes)
        .map_err(|e| format!("the operating system gave no random bytes for the token: {e}"))?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

fn text(headers: &HeaderMap, name: impl axum::http::header::AsHeaderName) -> Option<&str> {
    headers.get(name).and_then(|v| v.to_str().ok())
}

/// `addr:port` as a Host header writes it (IPv6 in brackets).
fn authority(ip: std::net::IpAddr, port: u16) -> String {
    match ip {
        std::net::IpAddr::V4(v4) => format!("{v4}:{port}"),
        std::net::IpAddr::V6(v6) => format!("[{v6}]:{port}"),
    }
}

/// Whether `s` ends in `:PORT` (outside an IPv6 literal's brackets).
fn split_port(s: &str) -> (&str, Option<&str>) {
    match s.rfind(':') {
        Some(i)
            if !s[i + 1..].is_empty()
                && s[i + 1..].bytes().all(|b| b.is_ascii_digit())
                && (s.starts_with('[') && s[..i].ends_with(']') || !s[..i].contains(':')) =>
        {
            (&s[..i], Some(&s[i + 1..]))
        }
        _ => (s, None),
    }
}

/// A Host value (or an Origin's authority) lower case and with its port, 80 when absent
/// (the default port of `http`, RFC 9110 §4.2.1).
fn normalize_authority(s: &str) -> String {
    let s = s.trim().to_ascii_lowercase();
    match split_port(&s) {
        (_, Some(_)) => s,
        (name, None) => format!("{name}:80"),
    }
}

/// An `--allow-host` value as a Host value: NAME takes the served port, NAME:PORT its own.
pub fn allowed_host(name: &str, port: u16) -> Result<String, String> {
    let lower = name.trim().to_ascii_lowercase();
    let (bare, given) = split_port(&lower);
    let valid = !bare.is_empty()
        && bare
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"-._[]:".contains(&b))
        && given.is_none_or(|p| p.parse::<u16>().is_ok());
    if !valid {
        return Err(format!(
            "--allow-host {name:?}: expected a host name or address, optionally with :PORT (e.g. plant.lan or plant.lan:8080)"
        ));
    }
    Ok(match given {
        Some(_) => lower,
        None => format!("{bare}:{port}"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::http::HeaderValue;

    fn head(pairs: &[(&'static str, &str)]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for (k, v) in pairs {
            h.insert(
                *k,
                HeaderValue::from_str(v).unwrap_or(HeaderValue::from_static("?")),
            );
        }
        h
    }

    fn policy(remote: bool, extra: &[&str]) -> Policy {
        let extra: Vec<String> = extra.iter().map(|s| s.to_string()).collect();
        Policy::new(
            8080,
            std::net::Ipv4Addr::LOCALHOST.into(),
            remote,
            &extra,
            "t0k".into(),
        )
        .unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn host_and_origin_must_name_the_served_port_and_the_pages_own_origin() {
        let p = policy(false, &[]);
        let get =
            |h: &[(&'static str, &str)]| p.check(&Method::GET, &Uri::from_static("/"), &head(h));
        assert!(get(&[("host", "127.0.0.1:8080")]).is_ok());
        assert!(get(&[("host", "LOCALHOST:8080")]).is_ok());
        assert!(get(&[("host", "[::1]:8080")]).is_ok());
        assert!(get(&[("host", "127.0.0.1:8081")]).is_err());
        assert!(get(&[("host", "localhost")]).is_err());
        assert!(get(&[("host", "attacker.example:8080")]).is_err());
        assert!(get(&[]).is_err());
        let absolute = Uri::from_static("http://attacker.example/api/snapshot");
        let h = head(&[("host", "127.0.0.1:8080")]);
        assert_eq!(
            p.check(&Method::GET, &absolute, &h).map_err(|e| e.0),
            Err(StatusCode::FORBIDDEN)
        );
        let own = [
            ("host", "localhost:8080"),
            ("origin", "http://localhost:8080"),
        ];
        assert!(get(&own).is_ok());
        for origin in [
            "http://127.0.0.1:8080",
            "null",
            "https://localhost:8080",
            "http://attacker.example",
        ] {
            let r = get(&[("host", "localhost:8080"), ("origin", origin)]);
            assert_eq!(r.map_err(|e| e.0), Err(StatusCode::FORBIDDEN), "{origin}");
        }
    }

    #[test]
    fn allow_host_names_take_the_served_port_unless_they_give_one() {
        let p = policy(true, &["Plant.lan", "proxy.lan:80", "[fe80::1]"]);
        let token = [("x-cantwin-token", "t0k")];
        let get = |host: &str| {
            let mut h = head(&token);
            h.insert(
                "host",
                HeaderValue::from_str(host).unwrap_or(HeaderValue::from_static("?")),
            );
            p.check(&Method::GET, &Uri::from_static("/"), &h)
        };
        assert!(get("plant.lan:8080").is_ok());
        assert!(get("plant.lan").is_err());
        assert!(get("proxy.lan").is_ok());
        assert!(get("[fe80::1]:8080").is_ok());
        assert!(allowed_host("a b", 1).is_err());
        assert!(allowed_host("", 1).is_err());
        assert!(allowed_host("x:99999", 1).is_err());
    }

    #[test]
    fn controls_need_json_and_the_token_and_remote_reads_need_the_token() {
        let local = policy(false, &[]);
        let host = ("host", "127.0.0.1:8080");
        let post = |p: &Policy, h: &[(&'static str, &str)]| {
            p.check(&Method::POST, &Uri::from_static("/api/nmt"), &head(h))
                .map_err(|e| e.0)
        };
        assert_eq!(
            post(&local, &[host, ("x-cantwin-token", "t0k")]),
            Err(StatusCode::UNSUPPORTED_MEDIA_TYPE)
        );
        let plain = [
            host,
            ("content-type", "text/plain"),
            ("x-cantwin-token", "t0k"),
        ];
        assert_eq!(
            post(&local, &plain),
            Err(StatusCode::UNSUPPORTED_MEDIA_TYPE)
        );
        let json = ("content-type", "application/json; charset=utf-8");
        assert_eq!(post(&local, &[host, json]), Err(StatusCode::FORBIDDEN));
        let wrong = [host, json, ("x-cantwin-token", "t0K")];
        assert_eq!(post(&local, &wrong), Err(StatusCode::FORBIDDEN));
        assert_eq!(
            post(&local, &[host, json, ("x-cantwin-token", "t0k")]),
            Ok(())
        );
        // Reading: free on loopback, with the token under --allow-remote.
        let read = |p: &Policy, path: &str, q: Option<&str>| {
            let target: Uri = match q {
                Some(q) => format!("{path}?{q}"),
                None => path.to_string(),
            }
            .parse()
            .unwrap_or_default();
            p.check(&Method::GET, &target, &head(&[host]))
                .map_err(|e| e.0)
        };
        assert_eq!(read(&local, "/api/snapshot", None), Ok(()));
        let remote = policy(true, &[]);
        assert_eq!(
            read(&remote, "/api/snapshot", None),
            Err(StatusCode::FORBIDDEN)
        );
        assert_eq!(
            read(&remote, "/events", Some("token=nope")),
            Err(StatusCode::FORBIDDEN)
        );
        assert_eq!(read(&remote, "/events", Some("a=1&token=t0k")), Ok(()));
        assert_eq!(read(&remote, "/app.js", None), Ok(()));
        // The charts' script and library carry no secret; their samples are the run's.
        for public in ["/charts.js", "/vendor/uplot.js", "/vendor/uplot.css"] {
            assert_eq!(read(&remote, public, None), Ok(()), "{public}");
        }
        assert_eq!(
            read(&remote, "/api/history", None),
            Err(StatusCode::FORBIDDEN)
        );
    }

    #[test]
    fn tokens_are_128_random_bits_in_hex() {
        let (a, b) = (new_token(), new_token());
        let a = a.unwrap_or_default();
        assert_eq!(a.len(), 32);
        assert!(a.bytes().all(|c| c.is_ascii_hexdigit()));
        assert_ne!(Ok(a), b);
    }
}
