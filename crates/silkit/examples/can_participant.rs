//! A plain SIL Kit CAN participant: one CAN controller on one network, frames sent at given
//! times, every event it sees printed on stdout. It knows nothing of cantwin's bus; the tests
//! run it as the foreign participant, and it is a starting point for one's own.
//!
//! ```text
//! can_participant --registry URI --name NAME --network NET [--step NS] [--bit-rate BPS]
//!                 [--send AT_NS:ID#HEX]... [--stop-at NS] [--exit-at NS] [--can-stop-at NS]
//! ```
//!
//! With `--step` it runs coordinated and synchronised (it must then be among the names a
//! system controller waits for): `AT_NS` is virtual time, each frame goes out in the first
//! step at or after it, and `--stop-at` stops the whole simulation. Without it it runs
//! autonomously, unsynchronised, and the times are nanoseconds of wall time after start.
//! `--exit-at` leaves abruptly, as a crashed participant does; `--can-stop-at` stops the CAN
//! controller. `ID#HEX` is candump's form
//! (`123#0102`, `12345678#` for an extended identifier, `123#R` for a remote frame).
//!
//! Output, one line per event: `rx TS ID#HEX`, `ack TS STATUS ID`, `state TS STATE`,
//! `error-state TS STATE`, then `final STATE`. TS is virtual nanoseconds.

use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use cantwin_silkit::{
    CanFrame, DirectionMask, FLAG_IDE, FLAG_RTR, OperationMode, Participant, ParticipantState,
    SilKit,
};

struct Options {
    registry: String,
    name: String,
    network: String,
    step: Option<u64>,
    bit_rate: u32,
    sends: Vec<(u64, CanFrame)>,
    stop_at: Option<u64>,
    exit_at: Option<u64>,
    can_stop_at: Option<u64>,
}

fn parse_frame(s: &str) -> Result<CanFrame, String> {
    let (id, data) = s.split_once('#').ok_or(format!("{s:?}: expected ID#HEX"))?;
    let raw = u32::from_str_radix(id, 16).map_err(|e| format!("{s:?}: {e}"))?;
    let mut flags = if id.len() > 3 { FLAG_IDE } else { 0 };
    let mut bytes = Vec::new();
    let dlc;
    if let Some(rest) = data.strip_prefix('R') {
        flags |= FLAG_RTR;
        dlc = if rest.is_empty() {
            0
        } else {
            rest.parse().map_err(|e| format!("{s:?}: {e}"))?
        };
    } else {
        if data.len() % 2 != 0 {
            return Err(format!("{s:?}: odd number of hex digits"));
        }
        for i in (0..data.len()).step_by(2) {
            bytes.push(u8::from_str_radix(&data[i..i + 2], 16).map_err(|e| format!("{s:?}: {e}"))?);
        }
        dlc = bytes.len() as u16;
    }
    Ok(CanFrame {
        id: raw,
        flags,
        dlc,
        data: bytes,
    })
}

fn parse() -> Result<Options, String> {
    let mut o = Options {
        registry: "silkit://localhost:8500".into(),
        name: "CanParticipant".into(),
        network: "can0".into(),
        step: None,
        bit_rate: 500_000,
        sends: Vec::new(),
        stop_at: None,
        exit_at: None,
        can_stop_at: None,
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().ok_or(format!("{a} needs a value"));
        let num = |v: String| v.parse::<u64>().map_err(|e| format!("{v:?}: {e}"));
        match a.as_str() {
            "--registry" => o.registry = value()?,
            "--name" => o.name = value()?,
            "--network" => o.network = value()?,
            "--step" => o.step = Some(num(value()?)?),
            "--bit-rate" => o.bit_rate = num(value()?)? as u32,
            "--stop-at" => o.stop_at = Some(num(value()?)?),
            "--exit-at" => o.exit_at = Some(num(value()?)?),
            "--can-stop-at" => o.can_stop_at = Some(num(value()?)?),
            "--send" => {
                let v = value()?;
                let (at, frame) = v
                    .split_once(':')
                    .ok_or(format!("{v:?}: expected AT_NS:ID#HEX"))?;
                o.sends.push((num(at.to_string())?, parse_frame(frame)?));
            }
            other => return Err(format!("unknown argument {other:?}")),
        }
    }
    o.sends.sort_by_key(|(at, _)| *at);
    Ok(o)
}

fn show(frame: &CanFrame) -> String {
    let id = if frame.flags & FLAG_IDE != 0 {
        format!("{:08X}", frame.id)
    } else {
        format!("{:03X}", frame.id)
    };
    if frame.flags & FLAG_RTR != 0 {
        return format!("{id}#R{}", frame.dlc);
    }
    let hex: String = frame.data.iter().map(|b| format!("{b:02X}")).collect();
    format!("{id}#{hex}")
}

/// Print one line at once (stdout is a pipe in the tests).
fn say(line: String) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}");
    let _ = out.flush();
}

fn main() {
    if let Err(e) = run() {
        eprintln!("can_participant: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let o = parse()?;
    let kit = SilKit::load()?;
    let config = r#"{"Logging":{"Sinks":[{"Type":"Stdout","Level":"Off"}]}}"#;
    let participant = Participant::create(&kit, &o.name, &o.registry, config)?;
    let can = participant.can_controller(&format!("{}-CAN", o.name), &o.network)?;
    can.on_frame(DirectionMask::Receive, |ev| {
        say(format!("rx {} {}", ev.timestamp, show(&ev.frame)));
    })?;
    can.on_transmit(|ev| {
        say(format!(
            "ack {} {:?} {:X}",
            ev.timestamp, ev.status, ev.can_id
        ))
    })?;
    can.on_state_change(|ev| say(format!("state {} {:?}", ev.timestamp, ev.state)))?;
    can.on_error_state_change(|ev| {
        say(format!("error-state {} {:?}", ev.timestamp, ev.error_state));
    })?;
    let mode = if o.step.is_some() {
        OperationMode::Coordinated
    } else {
        OperationMode::Autonomous
    };
    let lifecycle = participant.lifecycle(mode)?;
    {
        let can = can.clone();
        let rate = o.bit_rate;
        lifecycle.on_communication_ready(move || {
            if let Err(e) = can.set_baud_rate(rate, 0, 0).and_then(|()| can.start()) {
                eprintln!("can_participant: starting the controller: {e}");
            }
        })?;
    }
    let pending = Arc::new(Mutex::new(o.sends.clone()));
    let stopped = Arc::new(AtomicBool::new(false));
    // Send what is due at `now`, stop or leave when it is time.
    let act = {
        let (can, lifecycle, pending, stopped) = (
            can.clone(),
            lifecycle.clone(),
            Arc::clone(&pending),
            Arc::clone(&stopped),
        );
        let (stop_at, exit_at, can_stop_at) = (o.stop_at, o.exit_at, o.can_stop_at);
        let can_stopped = AtomicBool::new(false);
        move |now: u64| {
            if can_stop_at.is_some_and(|t| now >= t) && !can_stopped.swap(true, Ordering::SeqCst) {
                if let Err(e) = can.stop() {
                    eprintln!("can_participant: stopping the controller: {e}");
                }
            }
            if exit_at.is_some_and(|t| now >= t) {
                say("exit".into());
                std::process::exit(0);
            }
            let mut p = pending.lock().unwrap_or_else(|e| e.into_inner());
            while p.first().is_some_and(|(at, _)| *at <= now) {
                let (_, frame) = p.remove(0);
                if let Err(e) = can.send(&frame, frame.id as usize) {
                    eprintln!("can_participant: send: {e}");
                }
            }
            drop(p);
            if stop_at.is_some_and(|t| now >= t) && !stopped.swap(true, Ordering::SeqCst) {
                let _ = lifecycle.stop("can_participant: --stop-at reached");
            }
        }
    };
    if let Some(step) = o.step {
        let ts = lifecycle.time_sync()?;
        ts.on_step(step, move |now, _duration| act(now))?;
        lifecycle.start()?;
    } else {
        lifecycle.start()?;
        let started = Instant::now();
        let lc = lifecycle.clone();
        std::thread::spawn(move || {
            loop {
                let now = started.elapsed().as_nanos() as u64;
                act(now);
                let ended = matches!(
                    lc.state(),
                    Ok(ParticipantState::Stopping
                        | ParticipantState::Stopped
                        | ParticipantState::ShuttingDown
                        | ParticipantState::Shutdown
                        | ParticipantState::Error
                        | ParticipantState::Aborting)
                        | Err(_)
                );
                if stopped.load(Ordering::SeqCst) || ended {
                    break;
                }
                std::thread::sleep(Duration::from_micros(200));
            }
        });
    }
    let state = participant.wait_for_lifecycle(&lifecycle)?;
    say(format!("final {state:?}"));
    Ok(())
}
