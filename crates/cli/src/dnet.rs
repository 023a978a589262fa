//! `cantwin dnet`: a DeviceNet scanner on a bus: browse the devices by MAC ID, read and
//! write attributes over an explicit connection, exchange polled I/O.
//!
//! Explicit requests go over the Predefined Master/Slave Connection Set (Allocate with the
//! explicit choice, then Release) when class and instance fit the 8/8 body format the
//! slave grants on it; a wider class or instance (the ADV200 card's Parameter object with
//! instance = PAR above 255, EXP-CAN/DN-ADV manual §3.4.2 note 1) opens a UCMM connection
//! asking for 8/16 or 16/16 and closes it afterwards.
//!
//! A node coming on line first runs the duplicate MAC ID check (two requests 1 s apart, no
//! answer allowed; ODVA DeviceNet specification Vol. 1 §6, network access state machine):
//! every one-shot command spends those 2 s, `cantwin dnet shell` spends them once for many
//! commands.

use std::time::Duration as WallDuration;

use anyhow::{Context, Result, bail};
use cantwin_adv200::params::{def, par};
use cantwin_adv200::pdc::{self, Dir, Format, Item};
use cantwin_can::{Duration, Node, Outbox};
use cantwin_devicenet::eds::{EdsDate, EdsTime};
use cantwin_devicenet::scanner::explicit::{self, Outcome};
use cantwin_devicenet::wire::{choice, service, status};
use cantwin_devicenet::{MacId, Scanner, ScannerConfig, ScannerEvent};
use cantwin_twin::{DataSheetError, FileDate};

use crate::connect::{Link, Target};

#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    target: Target,
    /// The scanner's own MAC ID (0–63); it runs the duplicate MAC ID check first.
    #[arg(long = "mac", default_value_t = 0, global = true)]
    own_mac: u8,
    /// How long to wait for each answer, in seconds.
    #[arg(long, default_value_t = 1.0, global = true)]
    timeout: f64,
    #[command(subcommand)]
    command: Command,
}

/// How attribute data is shown and parsed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum ValueType {
    /// USINT.
    U8,
    /// UINT, little-endian.
    U16,
    /// UDINT, little-endian.
    U32,
    /// INT, little-endian.
    I16,
    /// DINT, little-endian.
    I32,
    /// SHORT_STRING: a length byte and the characters.
    ShortString,
    /// Raw bytes in hex.
    Bytes,
}

#[derive(Debug, clap::Subcommand)]
enum Command {
    /// List the devices by MAC ID with their identity (Identity object, Get_Attributes_All).
    #[command(
        after_help = "Examples:\n  cantwin dnet --scenario scenarios/adv200-devicenet.toml browse\n  \
                            cantwin dnet --socketcand 127.0.0.1:29536 --mac 62 browse --from 1 --to 20"
    )]
    Browse {
        /// First MAC ID to try.
        #[arg(long, default_value_t = 0)]
        from: u8,
        /// Last MAC ID to try.
        #[arg(long, default_value_t = 63)]
        to: u8,
    },
    /// Get_Attribute_Single over an explicit connection.
    #[command(
        after_help = "Examples:\n  cantwin dnet --socketcand 127.0.0.1:29536 get 12 1 1 1 --type u16      (Identity vendor ID)\n  \
                            cantwin dnet --socketcand 127.0.0.1:29536 get 12 1 1 7 --type short-string (product name)\n  \
                            cantwin dnet --scenario scenarios/adv200-devicenet.toml get 12 0x0F 600 1 --type i32  (ADV200 PAR 600)"
    )]
    Get {
        /// The device's MAC ID.
        #[arg(value_name = "MAC")]
        slave: u8,
        /// Class ID (decimal or 0x hex).
        #[arg(value_parser = parse_u16)]
        class: u16,
        /// Instance ID.
        #[arg(value_parser = parse_u16)]
        instance: u16,
        /// Attribute ID.
        #[arg(value_parser = parse_u8)]
        attribute: u8,
        /// How to show the value.
        #[arg(long = "type", value_enum, default_value_t = ValueType::Bytes)]
        ty: ValueType,
    },
    /// Set_Attribute_Single over an explicit connection.
    #[command(
        after_help = "Examples:\n  cantwin dnet --socketcand 127.0.0.1:29536 set 12 0x0F 600 1 1000 --type i16  (ADV200 PAR 600)\n  \
                            cantwin dnet --socketcand 127.0.0.1:29536 set 12 3 1 1 0x0C --type u8\n  \
                            cantwin dnet --scenario scenarios/adv200-devicenet.toml set 12 0x64 1 3 0A0B --type bytes"
    )]
    Set {
        /// The device's MAC ID.
        #[arg(value_name = "MAC")]
        slave: u8,
        /// Class ID (decimal or 0x hex).
        #[arg(value_parser = parse_u16)]
        class: u16,
        /// Instance ID.
        #[arg(value_parser = parse_u16)]
        instance: u16,
        /// Attribute ID.
        #[arg(value_parser = parse_u8)]
        attribute: u8,
        /// The value, as --type says (bytes: hex digits).
        #[arg(allow_hyphen_values = true)]
        value: String,
        /// How to encode the value.
        #[arg(long = "type", value_enum)]
        ty: ValueType,
    },
    /// Allocate the polled I/O connection, set its expected packet rate and exchange data.
    #[command(
        after_help = "Examples:\n  cantwin dnet --socketcand 127.0.0.1:29536 poll 12 --out 0300E803\n  \
                            cantwin dnet --scenario scenarios/adv200-devicenet.toml poll 12 --out 03000000 --count 10 --period-ms 50"
    )]
    Poll {
        /// The device's MAC ID.
        #[arg(value_name = "MAC")]
        slave: u8,
        /// Output data in hex (the poll command's bytes).
        #[arg(long, value_name = "HEX")]
        out: String,
        /// How many poll responses to print.
        #[arg(long, default_value_t = 1)]
        count: u32,
        /// Poll period in ms (also the expected packet rate set on the connection).
        #[arg(long, default_value_t = 100)]
        period_ms: u16,
        /// Print the bytes only: do not read an ADV200's PDC configuration to name its
        /// words.
        #[arg(long)]
        raw: bool,
    },
    /// Go on line once and read commands from standard input, one a line (browse, get,
    /// set, poll as above, without `cantwin dnet`; `help`; `quit` or end of input): the
    /// duplicate MAC ID check's 2 s are spent once.
    #[command(after_help = "Examples:
  cantwin dnet --socketcand 127.0.0.1:29536 shell
                              printf 'get 12 1 1 7 --type short-string\npoll 12 --out 0300E803\n' | cantwin dnet --scenario scenarios/adv200-devicenet.toml shell")]
    Shell,
    /// Print the ODVA EDS of a scenario's DeviceNet device (the ADV200 card with PAR 4000 =
    /// DeviceNet), generated from its object model: identity, polled I/O sizes, parameters.
    #[command(
        after_help = "Examples:\n  cantwin dnet eds --scenario scenarios/adv200-devicenet.toml --device drive\n  \
                            cantwin dnet eds --scenario scenarios/adv200-devicenet.toml --device drive -o adv200-dn.eds"
    )]
    Eds {
        /// The device's name in the scenario.
        #[arg(long)]
        device: String,
        /// Write the EDS to this file instead of printing it.
        #[arg(short, long, value_name = "FILE")]
        output: Option<std::path::PathBuf>,
    },
}

fn parse_u16(s: &str) -> Result<u16, String> {
    let s = s.trim();
    let r = match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(h) => u16::from_str_radix(h, 16),
        None => s.parse(),
    };
    r.map_err(|_| format!("{s:?} is not a number 0–65535 (decimal or 0x hex)"))
}

fn parse_u8(s: &str) -> Result<u8, String> {
    let v = parse_u16(s)?;
    u8::try_from(v).map_err(|_| format!("{s:?} is not a number 0–255"))
}

fn parse_hex(s: &str) -> Result<Vec<u8>> {
    let digits: String = s
        .chars()
        .filter(|c| !c.is_whitespace() && *c != ':' && *c != '-')
        .collect();
    let digits = digits
        .strip_prefix("0x")
        .or_else(|| digits.strip_prefix("0X"))
        .unwrap_or(&digits);
    if digits.len() % 2 != 0 {
        bail!("{s:?}: hex data needs two digits a byte");
    }
    (0..digits.len())
        .step_by(2)
        .map(|i| {
            digits
                .get(i..i + 2)
                .and_then(|b| u8::from_str_radix(b, 16).ok())
                .with_context(|| format!("{s:?} is not hex data"))
        })
        .collect()
}

fn hex(data: &[u8]) -> String {
    data.iter().map(|b| format!("{b:02X}")).collect()
}

fn parse_int(s: &str) -> Result<i64> {
    let s = s.trim();
    let (neg, body) = match s.strip_prefix('-') {
        Some(b) => (true, b),
        None => (false, s),
    };
    let v = match body.strip_prefix("0x").or_else(|| body.strip_prefix("0X")) {
        Some(h) => i64::from_str_radix(h, 16),
        None => body.parse(),
    }
    .with_context(|| format!("{s:?} is not a number"))?;
    Ok(if neg { -v } else { v })
}

/// Encode `value` as `ty` says.
fn encode(value: &str, ty: ValueType) -> Result<Vec<u8>> {
    let range = |lo: i64, hi: i64| -> Result<i64> {
        let v = parse_int(value)?;
        if !(lo..=hi).contains(&v) {
            bail!("{value} is outside {lo}..={hi}");
        }
        Ok(v)
    };
    Ok(match ty {
        ValueType::U8 => vec![range(0, 0xFF)? as u8],
        ValueType::U16 => (range(0, 0xFFFF)? as u16).to_le_bytes().to_vec(),
        ValueType::U32 => (range(0, 0xFFFF_FFFF)? as u32).to_le_bytes().to_vec(),
        ValueType::I16 => (range(-0x8000, 0x7FFF)? as i16).to_le_bytes().to_vec(),
        ValueType::I32 => (range(-0x8000_0000, 0x7FFF_FFFF)? as i32)
            .to_le_bytes()
            .to_vec(),
        ValueType::ShortString => {
            let n = u8::try_from(value.len())
                .ok()
                .context("a SHORT_STRING holds at most 255 characters")?;
            let mut v = vec![n];
            v.extend_from_slice(value.as_bytes());
            v
        }
        ValueType::Bytes => parse_hex(value)?,
    })
}

/// Show reply `data` as `ty` says; data of the wrong length is shown in hex with a note.
fn decode(data: &[u8], ty: ValueType) -> String {
    let fixed = |n: usize| data.len() == n;
    match ty {
        ValueType::U8 if fixed(1) => data[0].to_string(),
        ValueType::U16 if fixed(2) => u16::from_le_bytes([data[0], data[1]]).to_string(),
        ValueType::I16 if fixed(2) => i16::from_le_bytes([data[0], data[1]]).to_string(),
        ValueType::U32 if fixed(4) => {
            u32::from_le_bytes([data[0], data[1], data[2], data[3]]).to_string()
        }
        ValueType::I32 if fixed(4) => {
            i32::from_le_bytes([data[0], data[1], data[2], data[3]]).to_string()
        }
        ValueType::ShortString if !data.is_empty() && usize::from(data[0]) == data.len() - 1 => {
            format!("{:?}", String::from_utf8_lossy(&data[1..]))
        }
        ValueType::Bytes => hex(data),
        _ => format!("{} ({} bytes, not a {ty:?})", hex(data), data.len()),
    }
}

fn mac(v: u8, what: &str) -> Result<MacId> {
    MacId::new(v).map_err(|e| anyhow::anyhow!("{what} {v}: {e}"))
}

/// A scanner on a link, online.
struct Session {
    link: Link,
    scanner_mac: MacId,
    scanner: Scanner,
    timeout: f64,
}

/// Why a node waits before it talks, said when the wait is felt.
const DUPLICATE_MAC_NOTE: &str = "going on line: the duplicate MAC ID check takes 2 s (a DeviceNet node sends two Duplicate MAC ID Check requests 1 s apart and may talk only if nobody answers, as the ODVA specification requires of every node coming on line)";

impl Session {
    fn open(args: &Args) -> Result<Session> {
        if !(args.timeout.is_finite() && args.timeout > 0.0) {
            bail!("--timeout must be a positive number of seconds");
        }
        let own = mac(args.own_mac, "--mac")?;
        let mut config = ScannerConfig::new(own, 0, 0x00C0_FFEE);
        config.response_timeout = Duration::from_secs_f64(args.timeout);
        let mut scanner = Scanner::new(config);
        let link = Link::open(&args.target)?;
        let mut out = Outbox::new();
        scanner.on_power_up(link.now(), &mut out);
        for f in out.drain() {
            link.send(f)?;
        }
        let mut s = Session {
            link,
            scanner_mac: own,
            scanner,
            timeout: args.timeout,
        };
        // The duplicate MAC ID check: two requests 1 s apart (DeviceNet Vol. 1 §6).
        let mut online = None;
        s.link.run(
            &mut s.scanner,
            |sc| {
                while let Some(ev) = sc.poll_event() {
                    match ev {
                        ScannerEvent::Online => online = Some(true),
                        ScannerEvent::DuplicateMac => online = Some(false),
                        _ => {}
                    }
                }
                online.is_some()
            },
            WallDuration::from_secs(5),
        )?;
        match online {
            Some(true) => Ok(s),
            Some(false) => bail!(
                "another node answered the duplicate MAC ID check of MAC ID {own}: choose another --mac"
            ),
            None => bail!("the scanner did not get on line within 5 s"),
        }
    }

    /// Run until `n` events came (each queued operation reports exactly one) or the limit.
    fn collect(&mut self, n: usize) -> Result<Vec<ScannerEvent>> {
        let mut got = Vec::new();
        let limit = WallDuration::from_secs_f64(self.timeout * 3.0 * n as f64 + 1.0);
        self.link.run(
            &mut self.scanner,
            |sc| {
                while let Some(ev) = sc.poll_event() {
                    got.push(ev);
                }
                got.len() >= n
            },
            limit,
        )?;
        Ok(got)
    }

    /// One request over a connection opened for it and closed after it.
    fn request(
        &mut self,
        slave: MacId,
        service: u8,
        class: u16,
        instance: u16,
        data: &[u8],
    ) -> Result<Vec<u8>> {
        let connection = self
            .scanner
            .one_off_request(slave, service, class, instance, data)?;
        let events = self.collect(3)?;
        let how = connection.opening();
        match explicit::outcome(events, service) {
            Outcome::Reply(data) => Ok(data),
            Outcome::Error {
                service: svc,
                general,
                additional,
            } => Err(anyhow::anyhow!(
                "MAC ID {slave} answered {} with general status 0x{general:02X} ({}), additional code 0x{additional:02X}",
                if svc == service {
                    "the request".to_string()
                } else {
                    format!("service 0x{svc:02X}")
                },
                status::text(general)
            )),
            Outcome::RequestTimeout => Err(anyhow::anyhow!(
                "no answer from MAC ID {slave} within {} s (a device that refuses a Set may stay silent)",
                self.timeout
            )),
            Outcome::ConnectionTimeout => Err(anyhow::anyhow!(
                "no answer from MAC ID {slave} {how} within {} s",
                self.timeout
            )),
            Outcome::NoAnswer => Err(anyhow::anyhow!("no answer from MAC ID {slave} {how}")),
        }
    }
}

/// MAC IDs browsed at once: a bus port queues 32 frames (a CAN controller's transmit
/// buffer is no deeper), and each batch's Allocate requests go out together.
const BROWSE_BATCH: usize = 24;

/// What browse learnt of one device.
#[derive(Debug, Default)]
struct Found {
    /// Identity attributes 1–4, 6, 7 (None: not answered).
    vendor: Option<u16>,
    device_type: Option<u16>,
    product_code: Option<u16>,
    revision: Option<(u8, u8)>,
    serial: Option<u32>,
    name: Option<String>,
    /// The Allocate was refused (the set belongs to another master).
    refused: Option<(u8, u8)>,
}

fn u16_of(d: &[u8]) -> Option<u16> {
    Some(u16::from_le_bytes(d.try_into().ok()?))
}

/// Browse reads the Identity attributes one by one with Get_Attribute_Single rather than
/// Get_Attributes_All: the whole instance (36 bytes for the ADV200 card's 21-character
/// name) exceeds a small device's explicit message limit (the card: 32 bytes, manual §3.2),
/// which answers it with status 0x11.
fn browse(s: &mut Session, from: u8, to: u8) -> Result<()> {
    if from > to || to > 63 {
        bail!("--from {from} --to {to}: MAC IDs are 0–63, from ≤ to");
    }
    let own = s.scanner_mac;
    let macs: Vec<MacId> = (from..=to)
        .filter_map(|m| MacId::new(m).ok())
        .filter(|m| *m != own)
        .collect();
    let mut found: Vec<(MacId, Found)> = Vec::new();
    for batch in macs.chunks(BROWSE_BATCH) {
        for m in batch {
            s.scanner.allocate(*m, choice::EXPLICIT)?;
        }
        let mut present = Vec::new();
        for ev in s.collect(batch.len())? {
            match ev {
                ScannerEvent::Allocated { slave, .. } => present.push(slave),
                ScannerEvent::Error {
                    slave,
                    general,
                    additional,
                    ..
                } => found.push((
                    slave,
                    Found {
                        refused: Some((general, additional)),
                        ..Found::default()
                    },
                )),
                _ => {}
            }
        }
        const ATTRS: [u8; 6] = [1, 2, 3, 4, 6, 7];
        for m in &present {
            for a in ATTRS {
                s.scanner.get_attribute_single(*m, 1, 1, a)?;
            }
            s.scanner.release(*m, choice::EXPLICIT)?;
        }
        let mut answers: Vec<(MacId, Vec<u8>)> = Vec::new();
        let mut pending: std::collections::BTreeMap<MacId, usize> =
            present.iter().map(|m| (*m, 0)).collect();
        for ev in s.collect(present.len() * (ATTRS.len() + 1))? {
            let slave = match &ev {
                ScannerEvent::Response { slave, .. }
                | ScannerEvent::Error { slave, .. }
                | ScannerEvent::Timeout { slave, .. }
                | ScannerEvent::NotConnected { slave, .. } => *slave,
                _ => continue,
            };
            let Some(k) = pending.get_mut(&slave) else {
                continue;
            };
            // Each queued operation reports once, in order: attributes, then the Release.
            let attr = ATTRS.get(*k).copied();
            *k += 1;
            if let (Some(a), ScannerEvent::Response { data, .. }) = (attr, ev) {
                answers.push((slave, [vec![a], data].concat()));
            }
        }
        for m in present {
            let mut f = Found::default();
            for (_, d) in answers.iter().filter(|(x, _)| *x == m) {
                let (a, v) = (d[0], &d[1..]);
                match a {
                    1 => f.vendor = u16_of(v),
                    2 => f.device_type = u16_of(v),
                    3 => f.product_code = u16_of(v),
                    4 if v.len() == 2 => f.revision = Some((v[0], v[1])),
                    6 => f.serial = v.try_into().ok().map(u32::from_le_bytes),
                    7 if !v.is_empty() && usize::from(v[0]) == v.len() - 1 => {
                        f.name = Some(String::from_utf8_lossy(&v[1..]).into_owned())
                    }
                    _ => {}
                }
            }
            found.push((m, f));
        }
    }
    found.sort_by_key(|(m, _)| *m);
    if crate::output::json() {
        let devices: Vec<serde_json::Value> = found
            .iter()
            .map(|(m, f)| match f.refused {
                Some((g, a)) => serde_json::json!({
                    "mac": m.get(),
                    "refused": {"general_status": g, "additional_code": a, "text": status::text(g)},
                }),
                None => serde_json::json!({
                    "mac": m.get(),
                    "vendor": f.vendor,
                    "device_type": f.device_type,
                    "product_code": f.product_code,
                    "revision": f.revision.map(|(a, b)| format!("{a}.{b:03}")),
                    "serial": f.serial,
                    "product_name": f.name,
                }),
            })
            .collect();
        crate::output::emit(&serde_json::json!({"devices": devices, "found": found.len()}))?;
        return Ok(());
    }
    println!(
        "{:<4} {:<7} {:<12} {:<8} {:<9} {:<11} product name",
        "MAC", "vendor", "device type", "product", "revision", "serial"
    );
    let q = || "?".to_string();
    for (m, f) in &found {
        if let Some((g, a)) = f.refused {
            println!(
                "{:<4} (present; refused the Allocate: general status 0x{g:02X} ({}), additional code 0x{a:02X})",
                m.to_string(),
                status::text(g)
            );
            continue;
        }
        println!(
            "{:<4} {:<7} {:<12} {:<8} {:<9} {:<11} {}",
            m.to_string(),
            f.vendor.map_or_else(q, |v| v.to_string()),
            f.device_type.map_or_else(q, |v| format!("0x{v:04X}")),
            f.product_code.map_or_else(q, |v| v.to_string()),
            f.revision.map_or_else(q, |(a, b)| format!("{a}.{b:03}")),
            f.serial.map_or_else(q, |v| format!("0x{v:08X}")),
            f.name.clone().unwrap_or_else(q)
        );
    }
    println!("{} device(s) found", found.len());
    Ok(())
}

/// One word of an ADV200's process data: the channel placed there and what it carries.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Word {
    /// The placement (channel, width, signedness, fill).
    item: Item,
    /// The parameter it carries (`ipa`), with its name and unit, if any.
    name: Option<(String, &'static str)>,
}

/// The words of one direction of an ADV200's Process Data Channel, from its channels'
/// formats and `ipa` parameters (manual §1.3: the same placement as the PDOs; DeviceNet
/// polled I/O carries the words of all of them in a row, §3.5).
fn pdc_words(dir: Dir, channels: &[(Format, u16)]) -> Result<Vec<Word>> {
    let layout = pdc::place(dir, channels).map_err(|e| anyhow::anyhow!("the PDC: {e:?}"))?;
    Ok(layout
        .items()
        .map(|item| {
            let ipa = channels[usize::from(item.channel) - 1].1;
            let d = (!item.fill && ipa != 0).then(|| def(ipa)).flatten();
            let signed = match dir {
                Dir::M2S => item.signed,
                Dir::S2M => d.is_some_and(|d| d.ty.signed()),
            };
            // An M2S channel's `ipa` is the src parameter it feeds ("Ramp ref 1 src"): the
            // word is the value of what that src sets.
            let name = d.map(|d| {
                let name = match dir {
                    Dir::M2S => d.name.strip_suffix(" src").unwrap_or(&d.name),
                    Dir::S2M => &d.name,
                };
                (name.to_string(), d.unit)
            });
            Word {
                item: Item { signed, ..item },
                name,
            }
        })
        .collect())
}

/// `data` read as `words`: `name = value unit` per word (a fill as `fill`, a channel with no
/// parameter by its number), or why it does not fit.
fn describe_words(words: &[Word], data: &[u8]) -> String {
    let mut at = 0;
    let mut parts = Vec::new();
    for w in words {
        let n = usize::from(w.item.bits / 8);
        let Some(bytes) = data.get(at..at + n) else {
            return format!(
                "{} bytes, the PDC configuration has {}",
                data.len(),
                words
                    .iter()
                    .map(|w| usize::from(w.item.bits / 8))
                    .sum::<usize>()
            );
        };
        at += n;
        let raw = bytes
            .iter()
            .rev()
            .fold(0u64, |acc, b| (acc << 8) | u64::from(*b));
        let value = match (w.item.signed, n) {
            (true, 2) => i64::from(raw as u16 as i16),
            (true, _) => i64::from(raw as u32 as i32),
            (false, _) => raw as i64,
        };
        parts.push(match &w.name {
            _ if w.item.fill => "fill".to_string(),
            // Words without a unit are bit fields or codes (the status word): in hex.
            Some((name, "")) if !w.item.signed => {
                format!("{name} = 0x{raw:0width$X}", width = n * 2)
            }
            Some((name, "")) => format!("{name} = {value}"),
            Some((name, unit)) => format!("{name} = {value} {unit}"),
            None => format!("channel {} = {value}", w.item.channel),
        });
    }
    parts.join(", ")
}

/// Whether MAC ID `slave` is an ADV200 card (Identity attribute 7, product name).
fn is_adv200(s: &mut Session, slave: MacId) -> bool {
    matches!(
        s.request(slave, service::GET_ATTRIBUTE_SINGLE, 1, 1, &[7]),
        Ok(name) if name.get(1..).is_some_and(|n| n.starts_with(b"ADV200"))
    )
}

/// A drive parameter's value through the Parameter object (class 0x0F, instance = PAR,
/// attribute 1; every value a DWORD, manual §3.4.1).
fn read_param(s: &mut Session, slave: MacId, number: u16) -> Result<i64> {
    let data = s.request(slave, service::GET_ATTRIBUTE_SINGLE, 0x0F, number, &[1])?;
    let bytes: [u8; 4] = data
        .as_slice()
        .try_into()
        .map_err(|_| anyhow::anyhow!("PAR {number}: {} bytes, not a DWORD", data.len()))?;
    Ok(i64::from(i32::from_le_bytes(bytes)))
}

/// Reads an ADV200's channel formats and `ipa` parameters of one direction, up to the first
/// channel Not assigned (where the PDC ends, §1.3).
fn read_channels(s: &mut Session, slave: MacId, dir: Dir) -> Result<Vec<(Format, u16)>> {
    let mut channels = Vec::new();
    for n in 1..=cantwin_adv200::params::CHANNELS {
        let (sys, ipa) = match dir {
            Dir::M2S => (par::m2s_sys(n), par::m2s_ipa(n)),
            Dir::S2M => (par::s2m_sys(n), par::s2m_ipa(n)),
        };
        let format = Format::from_value(read_param(s, slave, sys)?);
        if format == Format::NotAssigned {
            channels.push((format, 0));
            break;
        }
        let ipa = u16::try_from(read_param(s, slave, ipa)?).unwrap_or(0);
        channels.push((format, ipa));
    }
    Ok(channels)
}

/// The words of an ADV200's polled I/O (inputs, outputs), or `None` for another device.
fn adv200_words(s: &mut Session, slave: MacId) -> Result<Option<(Vec<Word>, Vec<Word>)>> {
    if !is_adv200(s, slave) {
        return Ok(None);
    }
    let inputs = pdc_words(Dir::S2M, &read_channels(s, slave, Dir::S2M)?)?;
    let outputs = pdc_words(Dir::M2S, &read_channels(s, slave, Dir::M2S)?)?;
    Ok(Some((inputs, outputs)))
}

fn poll(
    s: &mut Session,
    slave: MacId,
    output: &[u8],
    count: u32,
    period_ms: u16,
    raw: bool,
) -> Result<()> {
    if period_ms == 0 {
        bail!("--period-ms must be at least 1");
    }
    // Read before the poll connection exists: the card's explicit messages and the PDC
    // configuration (parameters take effect at a drive reset, so they are what it runs).
    let words = if raw { None } else { adv200_words(s, slave)? };
    let sc = &mut s.scanner;
    sc.allocate(slave, choice::EXPLICIT | choice::POLLED)?;
    // Connection instance 2 is the polled I/O connection; attribute 7 its produced size.
    sc.get_attribute_single(slave, 5, 2, 7)?;
    sc.set_expected_packet_rate(slave, 2, period_ms)?;
    let events = s.collect(3)?;
    let mut input_size = None;
    let mut epr = None;
    let mut failure = None;
    for ev in &events {
        match ev {
            ScannerEvent::Allocated { .. } => {}
            ScannerEvent::Error {
                service,
                general,
                additional,
                ..
            } => {
                failure.get_or_insert_with(|| {
                    format!(
                        "MAC ID {slave} refused service 0x{service:02X}: general status 0x{general:02X} ({}), additional code 0x{additional:02X}",
                        status::text(*general)
                    )
                });
            }
            ScannerEvent::Timeout { service, .. } | ScannerEvent::NotConnected { service, .. } => {
                failure.get_or_insert_with(|| {
                    format!("no answer from MAC ID {slave} to service 0x{service:02X}")
                });
            }
            ScannerEvent::Response { service, data, .. } if data.len() == 2 => {
                let v = u16::from_le_bytes([data[0], data[1]]);
                match *service {
                    service::GET_ATTRIBUTE_SINGLE => input_size = Some(v),
                    // The Set reply carries the rate the device uses (rounded up to its
                    // timer resolution).
                    _ => epr = Some(v),
                }
            }
            _ => {}
        }
    }
    let release = |s: &mut Session| -> Result<()> {
        s.scanner
            .release(slave, choice::EXPLICIT | choice::POLLED)?;
        s.collect(1)?;
        Ok(())
    };
    let (Some(input_size), None) = (input_size, &failure) else {
        // Leave nothing allocated behind (an Allocate refused frees nothing: harmless).
        release(s)?;
        bail!(
            "{}",
            failure.unwrap_or_else(|| "the polled connection's produced size was not read".into())
        );
    };
    let json = crate::output::json();
    if json {
        // A stream: this line, then one line per poll response.
        crate::output::emit(&serde_json::json!({
            "mac": slave.get(),
            "output_bytes": output.len(),
            "input_bytes": input_size,
            "period_ms": period_ms,
            "expected_packet_rate_ms": epr.unwrap_or(period_ms),
            "output_decoded": words.as_ref().map(|(_, outputs)| describe_words(outputs, output)),
        }))?;
    } else {
        println!(
            "polled I/O allocated: {} bytes out, {input_size} bytes in, every {period_ms} ms (expected packet rate {} ms)",
            output.len(),
            epr.unwrap_or(period_ms)
        );
        if let Some((_, outputs)) = &words {
            println!("output: {}", describe_words(outputs, output));
        }
    }
    let now = s.link.now();
    s.scanner.start_polling(
        slave,
        Duration::from_millis(u64::from(period_ms)),
        output,
        input_size,
        now,
    );
    let mut seen = 0u32;
    let limit = WallDuration::from_secs_f64(
        f64::from(count) * f64::from(period_ms) / 1000.0 + s.timeout + 1.0,
    );
    let start = s.link.now();
    s.link.run(
        &mut s.scanner,
        |sc| {
            while let Some(ev) = sc.poll_event() {
                if let ScannerEvent::PollResponse { slave: m, data } = ev
                    && m == slave
                    && seen < count
                {
                    seen += 1;
                    let decoded = words
                        .as_ref()
                        .map(|(inputs, _)| describe_words(inputs, &data));
                    if json {
                        let mut v =
                            serde_json::json!({"input": seen, "data": crate::output::hex(&data)});
                        if let Some(text) = &decoded {
                            v["decoded"] = serde_json::json!(text);
                        }
                        println!("{v}");
                    } else {
                        println!("input {seen}: {}", hex(&data));
                        if let Some(text) = decoded {
                            println!("  {text}");
                        }
                    }
                }
            }
            seen >= count
        },
        limit,
    )?;
    let elapsed = s.link.now() - start;
    s.scanner.stop_polling(slave);
    s.scanner
        .release(slave, choice::EXPLICIT | choice::POLLED)?;
    s.collect(1)?;
    if seen < count {
        bail!(
            "{seen} of {count} poll responses from MAC ID {slave} in {:.3} s",
            elapsed.as_secs_f64()
        );
    }
    Ok(())
}

pub fn run(args: &Args) -> Result<()> {
    if let Command::Eds { device, output } = &args.command {
        let text = eds_text(&args.target, device)?;
        return match output {
            Some(path) => {
                std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
            }
            None => {
                print!("{text}");
                Ok(())
            }
        };
    }
    if matches!(args.command, Command::Shell) {
        return shell(args);
    }
    // The wait is felt at a terminal: say why, and how to spend it once.
    if std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        eprintln!("{DUPLICATE_MAC_NOTE}; `cantwin dnet shell` spends them once for many commands");
    }
    let mut s = Session::open(args)?;
    execute(&mut s, &args.command)
}

/// One command on a scanner that is on line.
fn execute(s: &mut Session, command: &Command) -> Result<()> {
    match command {
        Command::Browse { from, to } => browse(s, *from, *to),
        Command::Get {
            slave,
            class,
            instance,
            attribute,
            ty,
        } => {
            let slave = mac(*slave, "MAC ID")?;
            let data = s.request(
                slave,
                service::GET_ATTRIBUTE_SINGLE,
                *class,
                *instance,
                &[*attribute],
            )?;
            crate::output::result(decode(&data, *ty), || {
                serde_json::json!({
                    "mac": slave.get(),
                    "class": class, "instance": instance, "attribute": attribute,
                    "data": crate::output::hex(&data),
                    "value": decode(&data, *ty),
                })
            })?;
            Ok(())
        }
        Command::Set {
            slave,
            class,
            instance,
            attribute,
            value,
            ty,
        } => {
            let slave = mac(*slave, "MAC ID")?;
            let mut data = vec![*attribute];
            data.extend(encode(value, *ty)?);
            s.request(
                slave,
                service::SET_ATTRIBUTE_SINGLE,
                *class,
                *instance,
                &data,
            )?;
            crate::output::result("ok", || {
                serde_json::json!({
                    "mac": slave.get(),
                    "class": class, "instance": instance, "attribute": attribute,
                    "set": crate::output::hex(&data[1..]),
                })
            })?;
            Ok(())
        }
        Command::Poll {
            slave,
            out,
            count,
            period_ms,
            raw,
        } => {
            let slave = mac(*slave, "MAC ID")?;
            let output = parse_hex(out)?;
            poll(s, slave, &output, *count, *period_ms, *raw)
        }
        Command::Shell => bail!("the shell is already running"),
        Command::Eds { .. } => bail!(
            "eds reads a scenario file, not the bus: run `cantwin dnet eds` outside the shell"
        ),
    }
}

/// A command line of the shell, parsed with the subcommands' own parser.
#[derive(Debug, clap::Parser)]
#[command(
    name = "dnet",
    no_binary_name = true,
    disable_help_subcommand = true,
    override_usage = "<COMMAND> [ARGS]…"
)]
struct ShellLine {
    #[command(subcommand)]
    command: Command,
}

/// `line` split into words: blanks separate them, double quotes group (a short string with
/// spaces), a backslash escapes the next character.
fn words(line: &str) -> Result<Vec<String>> {
    let mut out = Vec::new();
    let mut word: Option<String> = None;
    let mut quoted = false;
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        match c {
            '\\' => {
                let next = chars.next().context("a backslash at the end of the line")?;
                word.get_or_insert_with(String::new).push(next);
            }
            '"' => {
                quoted = !quoted;
                word.get_or_insert_with(String::new);
            }
            c if c.is_whitespace() && !quoted => {
                if let Some(w) = word.take() {
                    out.push(w);
                }
            }
            c => word.get_or_insert_with(String::new).push(c),
        }
    }
    if quoted {
        bail!("a quote is not closed");
    }
    out.extend(word);
    Ok(out)
}

/// The help of the shell.
const SHELL_HELP: &str = "commands: browse [--from N --to N] | get MAC CLASS INSTANCE ATTRIBUTE [--type T] | set MAC CLASS INSTANCE ATTRIBUTE VALUE --type T | poll MAC --out HEX [--count N] [--period-ms MS] [--raw] | help [COMMAND] | quit";

/// `cantwin dnet shell`: one node on line, many commands from standard input.
fn shell(args: &Args) -> Result<()> {
    use std::io::{BufRead, IsTerminal, Write};
    let interactive = std::io::stdin().is_terminal();
    eprintln!("{DUPLICATE_MAC_NOTE}; this shell stays on line, so its commands do not wait");
    let mut s = Session::open(args)?;
    eprintln!("on line as MAC ID {}; {SHELL_HELP}", s.scanner_mac);
    let stdin = std::io::stdin();
    let mut failed = 0u32;
    let mut lines = stdin.lock().lines();
    loop {
        if interactive {
            print!("dnet> ");
            std::io::stdout().flush().ok();
        }
        let Some(line) = lines.next() else { break };
        let line = line.context("reading standard input")?;
        let words = match words(&line) {
            Ok(w) => w,
            Err(e) => {
                eprintln!("error: {e}");
                failed += 1;
                continue;
            }
        };
        match words.first().map(String::as_str) {
            None => continue,
            Some("quit" | "exit") => break,
            Some("help") if words.len() == 1 => {
                println!("{SHELL_HELP}");
                continue;
            }
            Some("help") => {
                let mut w = words[1..].to_vec();
                w.push("--help".into());
                if let Err(e) = <ShellLine as clap::Parser>::try_parse_from(w) {
                    print!("{e}");
                }
                continue;
            }
            _ => {}
        }
        match <ShellLine as clap::Parser>::try_parse_from(&words) {
            Ok(parsed) => {
                if let Err(e) = execute(&mut s, &parsed.command) {
                    eprintln!("error: {e:#}");
                    failed += 1;
                }
            }
            Err(e) => {
                eprint!("{}", e.render());
                failed += 1;
            }
        }
        std::io::stdout().flush().ok();
    }
    if failed > 0 {
        bail!("{failed} command(s) failed");
    }
    Ok(())
}

/// Days since 1970-01-01 to a (year, month, day) civil date (the proleptic Gregorian
/// calendar's 400-year cycle of 146097 days).
fn civil(days: i64) -> (i64, u8, u8) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = (doy - (153 * mp + 2) / 5 + 1) as u8;
    let month = if mp < 10 { mp + 3 } else { mp - 9 } as u8;
    let year = yoe + era * 400 + i64::from(month <= 2);
    (year, month, day)
}

/// The file's date: `SOURCE_DATE_EPOCH` when set (reproducible output), else now (UTC).
fn file_date() -> (EdsDate, EdsTime) {
    let secs = std::env::var("SOURCE_DATE_EPOCH")
        .ok()
        .and_then(|v| v.trim().parse::<i64>().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| i64::try_from(d.as_secs()).unwrap_or(0))
        });
    let (year, month, day) = civil(secs.div_euclid(86_400));
    let t = secs.rem_euclid(86_400);
    (
        EdsDate {
            month,
            day,
            year: u16::try_from(year).unwrap_or(1970),
        },
        EdsTime {
            hour: (t / 3600) as u8,
            minute: (t / 60 % 60) as u8,
            second: (t % 60) as u8,
        },
    )
}

/// Build the scenario, power it up, and describe the device's DeviceNet object model.
fn eds_text(target: &Target, device: &str) -> Result<String> {
    let file = target
        .scenario
        .as_ref()
        .context("say which scenario holds the device: --scenario FILE")?;
    let scenario = cantwin_scenario::Scenario::load(file)?;
    let mut built = scenario.build(
        &cantwin_scenario::Registry::builtin(),
        &cantwin_scenario::BuildEnv::default(),
    )?;
    let port = built
        .device(device)
        .with_context(|| format!("{} has no device {device:?}", file.display()))?
        .port;
    // Power-up happens at the first instant; the card reads PAR 4000 then.
    built
        .sim
        .run_until(cantwin_can::Instant::from_nanos(1_000_000));
    let (date, time) = file_date();
    let written = FileDate {
        year: date.year,
        month: date.month,
        day: date.day,
        hour: time.hour,
        minute: time.minute,
        second: time.second,
    };
    let sheet = built
        .sim
        .twin(port)
        .map_or(Err(DataSheetError::None), |t| t.data_sheet(&written));
    match sheet {
        Ok(text) => Ok(text),
        Err(DataSheetError::None) => bail!(
            "{device:?} is not an ADV200 drive: only its DeviceNet personality has an EDS generator"
        ),
        Err(DataSheetError::Unavailable(why)) => bail!("{device:?} {why}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_encode_little_endian_and_decode_back() {
        assert_eq!(encode("1000", ValueType::I16).unwrap(), [0xE8, 0x03]);
        assert_eq!(
            encode("-2", ValueType::I32).unwrap(),
            [0xFE, 0xFF, 0xFF, 0xFF]
        );
        assert_eq!(encode("0x0C", ValueType::U8).unwrap(), [0x0C]);
        assert_eq!(
            encode("ab", ValueType::ShortString).unwrap(),
            [2, b'a', b'b']
        );
        assert_eq!(encode("0A 0b", ValueType::Bytes).unwrap(), [0x0A, 0x0B]);
        assert!(encode("256", ValueType::U8).is_err());
        assert!(encode("0A0", ValueType::Bytes).is_err());
        assert_eq!(decode(&[0xFE, 0xFF, 0xFF, 0xFF], ValueType::I32), "-2");
        assert_eq!(decode(&[2, b'a', b'b'], ValueType::ShortString), "\"ab\"");
        assert_eq!(decode(&[1], ValueType::U16), "01 (1 bytes, not a U16)");
    }

    /// The manual's worked example (§1.6): S2M channels Word comp mon (status word), Motor
    /// speed and Analog inp 2 mon, all 16 bits; M2S Word decomp and Ramp ref 1.
    #[test]
    fn manual_1_6_pdc_words_are_named_from_the_channel_parameters() {
        let ipa = |name: &str| {
            cantwin_adv200::params::catalog()
                .iter()
                .find(|d| d.name == name)
                .map(|d| d.par)
                .unwrap()
        };
        let s2m = [
            (Format::Eu, ipa("Word comp mon")),
            (Format::Eu, ipa("Motor speed")),
            (Format::Count16, ipa("Analog inp 2 mon")),
            (Format::NotAssigned, 0),
        ];
        let words = pdc_words(Dir::S2M, &s2m).unwrap();
        assert_eq!(words.len(), 3);
        assert_eq!(
            describe_words(&words, &[0x03, 0x01, 0xDC, 0x05, 0x00, 0x10]),
            "Word comp mon = 0x0103, Motor speed = 1500 rpm, Analog inp 2 mon = 4096 cnt"
        );
        // A negative speed is signed as its parameter is.
        assert!(
            describe_words(&words, &[0, 0, 0x24, 0xFA, 0, 0]).contains("Motor speed = -1500 rpm")
        );
        assert_eq!(
            describe_words(&words, &[0x03, 0x01]),
            "2 bytes, the PDC configuration has 6"
        );
        let m2s = [
            (Format::Count16, ipa("Word decomp src")),
            (Format::Count16, ipa("Ramp ref 1 src")),
            (Format::NotAssigned, 0),
        ];
        let words = pdc_words(Dir::M2S, &m2s).unwrap();
        assert_eq!(
            describe_words(&words, &[0x03, 0x00, 0xE8, 0x03]),
            "Word decomp = 3, Ramp ref 1 = 1000"
        );
    }

    #[test]
    fn shell_words_split_on_blanks_and_group_quotes() {
        assert_eq!(
            words("  get 12 1 1 7 ").unwrap(),
            ["get", "12", "1", "1", "7"]
        );
        assert_eq!(
            words(r#"set 12 1 1 7 "a b" --type short-string"#).unwrap(),
            ["set", "12", "1", "1", "7", "a b", "--type", "short-string"]
        );
        assert_eq!(words(r#"x \"y"#).unwrap(), ["x", "\"y"]);
        assert!(words(r#"set "a"#).is_err());
        assert!(words("end \\").is_err());
    }

    #[test]
    fn civil_dates_from_days_since_1970() {
        assert_eq!(civil(0), (1970, 1, 1));
        assert_eq!(civil(11_016), (2000, 2, 29));
        assert_eq!(civil(20_415), (2025, 11, 23));
    }
}
