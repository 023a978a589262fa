//! `cantwin cal`: a CAL master for the TDE MACNO OPEN DRIVE (application 003): commands and
//! frequency reference (message 0), alarm events (message 1), parameters (message 2).

use std::time::Duration as WallDuration;

use anyhow::{Context, Result, bail};
use cantwin_cal::{ClientEvent, CmsClient, Payload, Request};
use cantwin_opendrive::messages::{
    self, Code, CommandByte, ErrorFlags, Message0State, centi_hz, error_text, message0_write,
    mux_entry,
};
use cantwin_opendrive::params::{ParId, Params};
use cantwin_opendrive::{MESSAGE_0, MESSAGE_1, MESSAGE_2};

use crate::connect::{Link, Target};

#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    target: Target,
    /// The drive's COB-ID parameters, as P180=440 (repeatable; defaults: the manual's
    /// P180 440, P181 439, P183 430, P184 429, P186 1100, P187 1099).
    #[arg(long = "cob", value_name = "PNNN=ID", global = true)]
    cobs: Vec<String>,
    /// How long to wait for a confirmation, in seconds.
    #[arg(long, default_value_t = 1.0, global = true)]
    timeout: f64,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum OnOff {
    On,
    Off,
}

impl OnOff {
    fn code(v: Option<OnOff>) -> Code {
        match v {
            None => Code::NoChange,
            Some(OnOff::On) => Code::Set,
            Some(OnOff::Off) => Code::Reset,
        }
    }
}

#[derive(Debug, clap::Subcommand)]
enum Command {
    /// Message 0: set or reset command bits (the reference is kept unless --ref is given).
    #[command(
        after_help = "Examples:\n  cantwin cal --scenario scenarios/opendrive.toml cmd --reference-remote on --command-remote on --start on --ref 50\n  \
                            cantwin cal --socketcand 127.0.0.1:29536 cmd --start off"
    )]
    Cmd {
        /// Reference from the field bus ("riferimento Remote").
        #[arg(long, value_enum)]
        reference_remote: Option<OnOff>,
        /// Commands from the field bus ("comando Remote").
        #[arg(long, value_enum)]
        command_remote: Option<OnOff>,
        /// CAN-Start (valid with command remote set).
        #[arg(long, value_enum)]
        start: Option<OnOff>,
        /// CAN-Reverse (valid with command remote set).
        #[arg(long, value_enum)]
        reverse: Option<OnOff>,
        /// Frequency reference in Hz (0.01 Hz resolution).
        #[arg(long = "ref", value_name = "HZ")]
        reference: Option<f64>,
    },
    /// Message 0: set the frequency reference in Hz, leaving the command bits as they are.
    #[command(
        after_help = "Examples:\n  cantwin cal --scenario scenarios/opendrive.toml ref 50.00"
    )]
    Ref {
        /// Hz, 0.01 Hz resolution.
        hz: f64,
    },
    /// Message 0: read the command state and the frequency reference in use.
    #[command(
        after_help = "Examples:\n  cantwin cal --socketcand 127.0.0.1:29536 read\n  cantwin cal --scenario scenarios/opendrive.toml read --remote"
    )]
    Read {
        /// Read with a remote frame on the response COB instead of a data frame.
        #[arg(long)]
        remote: bool,
    },
    /// Message 2: read or write a multiplexed parameter (by name or number; `param list`).
    #[command(
        after_help = "Examples:\n  cantwin cal --scenario scenarios/opendrive.toml param read max-frequency\n  \
                            cantwin cal --scenario scenarios/opendrive.toml param write stop-delay 5\n  cantwin cal param list"
    )]
    Param {
        #[command(subcommand)]
        action: ParamAction,
    },
    /// Message 1: enable or disable the alarm events, or watch notifications.
    #[command(
        after_help = "Examples:\n  cantwin cal --socketcand 127.0.0.1:29536 events enable\n  \
                            cantwin cal --socketcand 127.0.0.1:29536 events watch --seconds 30"
    )]
    Events {
        #[command(subcommand)]
        action: EventAction,
    },
}

#[derive(Debug, clap::Subcommand)]
enum ParamAction {
    /// List the multiplexor table.
    List,
    /// Read a multiplexor.
    Read {
        /// Name (e.g. max-frequency) or number (e.g. 0x00).
        mux: String,
    },
    /// Write a multiplexor.
    Write {
        /// Name or number.
        mux: String,
        /// The value in the multiplexor's unit, the manual's (Hz for max-frequency, s for
        /// stop-delay, % for thermal-current; see `param list`), rounded to its resolution.
        value: String,
    },
}

#[derive(Debug, clap::Subcommand)]
enum EventAction {
    /// Enable the alarm notifications.
    Enable,
    /// Disable them.
    Disable,
    /// Enable them and print every notification.
    Watch {
        /// Stop after this many seconds (default: until Ctrl-C).
        #[arg(long)]
        seconds: Option<f64>,
    },
}

fn client(cobs: &[String], timeout: f64) -> Result<CmsClient> {
    let mut params = Params::default();
    for c in cobs {
        let (id, value) = c
            .split_once('=')
            .with_context(|| format!("--cob {c:?}: expected PNNN=ID, e.g. P180=440"))?;
        let id: ParId = id
            .parse()
            .map_err(|e| anyhow::anyhow!("--cob {c:?}: {e}"))?;
        if !(180..=187).contains(&id.number) {
            bail!("--cob {c:?}: only the COB-ID parameters P180–P187 can be given");
        }
        let value: i32 = value
            .trim()
            .parse()
            .with_context(|| format!("--cob {c:?}: the COB-ID is a number 0–1760"))?;
        params
            .set(id, value)
            .map_err(|e| anyhow::anyhow!("--cob {c:?}: {e}"))?;
    }
    if !(timeout.is_finite() && timeout > 0.0) {
        bail!("--timeout must be a positive number of seconds");
    }
    let client = messages::master(|p| params.get(p)).map_err(|e| anyhow::anyhow!("{e}"))?;
    Ok(client.with_timeout(cantwin_can::Duration::from_secs_f64(timeout)))
}

/// Send one request and wait for its outcome.
fn exchange(
    link: &mut Link,
    client: &mut CmsClient,
    object: cantwin_cal::ObjectIndex,
    request: Request,
    timeout: f64,
) -> Result<Payload> {
    let now = link.now();
    let mut out = cantwin_can::Outbox::new();
    client
        .request(object, request, now, &mut out)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    for f in out.drain() {
        link.send(f)?;
    }
    let mut outcome = None;
    link.run(
        client,
        |c| {
            while let Some(ev) = c.poll_event() {
                match ev {
                    ClientEvent::Confirmed { data, .. } => outcome = Some(Ok(data)),
                    ClientEvent::EventState { enabled, .. } => {
                        outcome = Some(Ok(Payload::new(&[u8::from(enabled)]).unwrap_or_default()))
                    }
                    ClientEvent::Failed { error, .. } => {
                        let code = error.as_slice().first().copied().unwrap_or(0);
                        outcome = Some(Err(anyhow::anyhow!(
                            "the drive refused the request: error code {code} ({})",
                            error_text(u16::from(code))
                        )))
                    }
                    ClientEvent::TimedOut { .. } => {
                        outcome = Some(Err(anyhow::anyhow!(
                            "no answer from the drive within {timeout} s"
                        )))
                    }
                    ClientEvent::Notified { .. } => {}
                }
            }
            outcome.is_some()
        },
        WallDuration::from_secs_f64(timeout + 1.0),
    )?;
    outcome.unwrap_or_else(|| {
        Err(anyhow::anyhow!(
            "no answer from the drive within {timeout} s"
        ))
    })
}

fn print_state(data: &[u8]) -> Result<()> {
    let s = Message0State::decode(data)
        .with_context(|| format!("message 0 answer {data:02X?} is malformed"))?;
    let c = s.commands;
    let on = |b: bool| if b { "on" } else { "off" };
    crate::output::result(
        format_args!(
            "reference {:.2} Hz  reference-remote {}  command-remote {}  start {}  reverse {}",
            f64::from(s.reference_centi_hz) / 100.0,
            on(c.reference_remote),
            on(c.command_remote),
            on(c.can_start),
            on(c.can_reverse)
        ),
        || {
            serde_json::json!({
                "reference_hz": f64::from(s.reference_centi_hz) / 100.0,
                "reference_remote": c.reference_remote,
                "command_remote": c.command_remote,
                "start": c.can_start,
                "reverse": c.can_reverse,
            })
        },
    )?;
    Ok(())
}

/// The alarm flags of a message 1 notification, in words.
pub(crate) fn describe_flags(data: &[u8]) -> String {
    match ErrorFlags::decode(data) {
        Some(f) => {
            let mut parts = Vec::new();
            if f.overload {
                parts.push("OVERLOAD (A2/A3)");
            }
            if f.overtemperature {
                parts.push("OVERTEMPERATURE (A4/A5)");
            }
            if f.overvoltage {
                parts.push("OVERVOLTAGE (A11)");
            }
            if parts.is_empty() {
                "no alarm".to_string()
            } else {
                parts.join(", ")
            }
        }
        None => format!("malformed notification {data:02X?}"),
    }
}

pub fn run(args: &Args) -> Result<()> {
    if let Command::Param {
        action: ParamAction::List,
    } = &args.command
    {
        if crate::output::json() {
            let list: Vec<serde_json::Value> = messages::MUX_TABLE
                .iter()
                .map(|e| {
                    serde_json::json!({
                        "mux": e.mux, "name": e.name, "readable": e.readable,
                        "writable": e.writable, "data": e.data, "unit": e.unit,
                    })
                })
                .collect();
            crate::output::emit(&serde_json::json!({ "multiplexors": list }))?;
            return Ok(());
        }
        println!(
            "{:<6} {:<18} {:<3} {:<5} data",
            "mux", "name", "r/w", "unit"
        );
        for e in messages::MUX_TABLE {
            let rw = format!(
                "{}{}",
                if e.readable { "r" } else { "-" },
                if e.writable { "w" } else { "-" }
            );
            println!(
                "0x{:02X}   {:<18} {rw:<3} {:<5} {}",
                e.mux, e.name, e.unit, e.data
            );
        }
        return Ok(());
    }
    let mut client = client(&args.cobs, args.timeout)?;
    let mut link = Link::open(&args.target)?;
    let t = args.timeout;
    match &args.command {
        Command::Cmd {
            reference_remote,
            command_remote,
            start,
            reverse,
            reference,
        } => {
            let reference = match reference {
                Some(hz) => {
                    centi_hz(*hz).with_context(|| format!("--ref {hz}: outside 0–655.35 Hz"))?
                }
                None => {
                    let data = exchange(&mut link, &mut client, MESSAGE_0, Request::ReadBasic, t)?;
                    Message0State::decode(data.as_slice())
                        .context("message 0 answer is malformed")?
                        .reference_centi_hz
                }
            };
            let cmd = CommandByte {
                reference_remote: OnOff::code(*reference_remote),
                command_remote: OnOff::code(*command_remote),
                can_start: OnOff::code(*start),
                can_reverse: OnOff::code(*reverse),
            };
            let payload =
                Payload::new(&message0_write(cmd, reference)).context("message 0 data")?;
            let data = exchange(
                &mut link,
                &mut client,
                MESSAGE_0,
                Request::WriteBasic(payload),
                t,
            )?;
            print_state(data.as_slice())
        }
        Command::Ref { hz } => {
            let reference =
                centi_hz(*hz).with_context(|| format!("{hz} Hz is outside 0–655.35 Hz"))?;
            let payload = Payload::new(&message0_write(CommandByte::default(), reference))
                .context("message 0 data")?;
            let data = exchange(
                &mut link,
                &mut client,
                MESSAGE_0,
                Request::WriteBasic(payload),
                t,
            )?;
            print_state(data.as_slice())
        }
        Command::Read { remote } => {
            let request = if *remote {
                Request::ReadBasicRemote
            } else {
                Request::ReadBasic
            };
            let data = exchange(&mut link, &mut client, MESSAGE_0, request, t)?;
            print_state(data.as_slice())
        }
        Command::Param { action } => {
            let (name, request) = match action {
                ParamAction::List => return Ok(()),
                ParamAction::Read { mux } => {
                    let e = mux_entry(mux).with_context(|| {
                        format!("no multiplexor {mux:?} (see `cantwin cal param list`)")
                    })?;
                    (
                        e.name,
                        Request::ReadMux(messages::mux(e).context("multiplexor")?),
                    )
                }
                ParamAction::Write { mux, value } => {
                    let e = mux_entry(mux).with_context(|| {
                        format!("no multiplexor {mux:?} (see `cantwin cal param list`)")
                    })?;
                    if !e.writable {
                        bail!("{} (0x{:02X}) is read-only", e.name, e.mux);
                    }
                    let data = value
                        .trim()
                        .parse::<f64>()
                        .ok()
                        .and_then(|v| e.data_of(v))
                        .with_context(|| {
                            format!(
                                "{} {value:?}: not a value in {} that fits its 16-bit data",
                                e.name,
                                if e.unit.is_empty() { "units" } else { e.unit }
                            )
                        })?;
                    (
                        e.name,
                        Request::WriteMux(
                            messages::mux(e).context("multiplexor")?,
                            Payload::u16(data),
                        ),
                    )
                }
            };
            let data = exchange(&mut link, &mut client, MESSAGE_2, request, t)?;
            let entry = mux_entry(name);
            let value = data
                .as_u16()
                .and_then(|v| entry.map(|e| (e.value_of(v), e.unit)));
            if crate::output::json() {
                crate::output::emit(&serde_json::json!({
                    "name": name,
                    "value": value.map(|(v, _)| v),
                    "unit": value.map(|(_, u)| u),
                    "data": crate::output::hex(data.as_slice()),
                }))?;
                return Ok(());
            }
            match (data.as_u16(), value) {
                (Some(d), Some((v, unit))) if !unit.is_empty() => {
                    println!("{name} = {v} {unit} (data {d} = 0x{d:04X})")
                }
                (Some(d), _) => println!("{name} = {d} (0x{d:04X})"),
                (None, _) => println!("{name} = {:02X?}", data.as_slice()),
            }
            Ok(())
        }
        Command::Events { action } => {
            let enable = !matches!(action, EventAction::Disable);
            exchange(
                &mut link,
                &mut client,
                MESSAGE_1,
                Request::ControlEvent(enable),
                t,
            )?;
            // With --watch this is a stream: this line, then one line per notification.
            crate::output::result(
                format_args!(
                    "alarm events {}",
                    if enable { "enabled" } else { "disabled" }
                ),
                || serde_json::json!({ "alarm_events": enable }),
            )?;
            if let EventAction::Watch { seconds } = action {
                let limit = seconds
                    .map(WallDuration::from_secs_f64)
                    .unwrap_or(WallDuration::MAX);
                link.run(
                    &mut client,
                    |c| {
                        while let Some(ev) = c.poll_event() {
                            if let ClientEvent::Notified { data, .. } = ev {
                                let text = describe_flags(data.as_slice());
                                if crate::output::json() {
                                    println!(
                                        "{}",
                                        serde_json::json!({
                                            "notification": text,
                                            "data": crate::output::hex(data.as_slice()),
                                        })
                                    );
                                } else {
                                    println!("notification: {text}");
                                }
                            }
                        }
                        false
                    },
                    limit.min(WallDuration::from_secs(365 * 86_400)),
                )?;
            }
            Ok(())
        }
    }
}
