//! `cantwin lss`: an LSS master (CiA 305) on a bus: switch nodes to LSS configuration, give
//! them node-IDs and bit rates, store them, inquire their addresses, find them by fastscan.
//!
//! Each command runs on its own connection; a node stays in LSS configuration between
//! commands until `switch global waiting` (or a selective switch of another node).

use anyhow::{Context, Result, bail};
use cantwin_can::{BitRate, Duration, Outbox};
use cantwin_canopen::lss::wire::{UNCONFIGURED, table_index_of};
use cantwin_canopen::lss::{Address, Master, Mode, Outcome, Part, Service};
use std::time::Duration as WallDuration;

use serde_json::json;

use crate::connect::{Link, Target};
use crate::output;

/// Arguments of `cantwin lss`.
#[derive(Debug, clap::Args)]
pub struct LssArgs {
    #[command(flatten)]
    target: Target,
    /// How long each answer is awaited, in milliseconds (default 1000; 100 for each fastscan
    /// step).
    #[arg(long, value_name = "MS", global = true)]
    timeout: Option<u64>,
    #[command(subcommand)]
    command: LssCommand,
}

/// An LSS service.
#[derive(Debug, clap::Subcommand)]
enum LssCommand {
    /// Switch state: every node (global) or the node with an LSS address (selective).
    #[command(subcommand)]
    Switch(Switch),
    /// Configure node-ID of the node(s) in LSS configuration: 1–127, or 255 for none.
    #[command(after_help = "Examples:\n  cantwin lss --socketcand 127.0.0.1:29536 set-node 5")]
    SetNode {
        /// The node-ID it takes at its next reset communication.
        #[arg(value_parser = node_id)]
        node_id: u8,
    },
    /// Configure bit timing: a rate of the CiA 301 table (1M, 800k, 500k, 250k, 125k, 50k,
    /// 20k, 10k).
    #[command(
        after_help = "Examples:\n  cantwin lss --socketcand 127.0.0.1:29536 conf-bitrate 250k"
    )]
    ConfBitrate {
        /// The bit rate.
        rate: BitRate,
    },
    /// Activate bit timing: the nodes switch to the configured rate after the delay and stay
    /// silent for another delay.
    #[command(
        after_help = "Examples:\n  cantwin lss --socketcand 127.0.0.1:29536 activate-bitrate 100"
    )]
    ActivateBitrate {
        /// The switch delay in milliseconds.
        delay_ms: u16,
    },
    /// Store configuration: the node keeps its pending node-ID and bit rate for its next
    /// power-up.
    #[command(after_help = "Examples:\n  cantwin lss --socketcand 127.0.0.1:29536 store")]
    Store,
    /// Inquire the LSS address (all four parts, or one) or the node-ID of the node in LSS
    /// configuration.
    #[command(
        after_help = "Examples:\n  cantwin lss --socketcand 127.0.0.1:29536 inquire\n  \
                            cantwin lss --socketcand 127.0.0.1:29536 inquire node-id"
    )]
    Inquire {
        /// What to inquire.
        #[arg(value_enum, default_value_t = What::Address)]
        what: What,
    },
    /// Identify remote slaves: count the nodes whose address matches (vendor and product
    /// exactly, revision and serial within bounds), or those without node-ID.
    #[command(subcommand)]
    Identify(Identify),
    /// Fastscan: find one node without node-ID; it is left in LSS configuration.
    #[command(
        after_help = "Examples:\n  cantwin lss --socketcand 127.0.0.1:29536 fastscan\n  \
                            cantwin lss --socketcand 127.0.0.1:29536 --timeout 20 fastscan"
    )]
    Fastscan,
    /// Commission one node: select it (by address, or the first fastscan finds), configure
    /// its node-ID (and bit rate), store, and switch back to waiting, so that it boots.
    #[command(
        after_help = "Examples:\n  cantwin lss --socketcand 127.0.0.1:29536 commission 5 --fastscan\n  \
                            cantwin lss --socketcand 127.0.0.1:29536 commission 5 --address 0xCA7 305 0x10000 0x30 --bit-rate 500k"
    )]
    Commission {
        /// The node-ID to give.
        #[arg(value_parser = node_id)]
        node_id: u8,
        /// Select the node by its LSS address: vendor product revision serial.
        #[arg(long, num_args = 4, value_names = ["VENDOR", "PRODUCT", "REVISION", "SERIAL"], value_parser = number, conflicts_with = "fastscan")]
        address: Option<Vec<u32>>,
        /// Select the first node without node-ID that fastscan finds.
        #[arg(long)]
        fastscan: bool,
        /// Also configure this bit rate.
        #[arg(long)]
        bit_rate: Option<BitRate>,
        /// Do not store the configuration.
        #[arg(long)]
        no_store: bool,
    },
}

#[derive(Debug, clap::Subcommand)]
enum Switch {
    /// Every node to LSS waiting or configuration.
    #[command(
        after_help = "Examples:\n  cantwin lss --socketcand 127.0.0.1:29536 switch global configuration"
    )]
    Global {
        /// The state.
        #[arg(value_enum)]
        state: State,
    },
    /// The node with this LSS address (0x1018 sub 1–4) to LSS configuration.
    #[command(
        after_help = "Examples:\n  cantwin lss --socketcand 127.0.0.1:29536 switch selective 0xCA7 305 0x10000 0x30"
    )]
    Selective {
        /// Vendor-ID.
        #[arg(value_parser = number)]
        vendor: u32,
        /// Product code.
        #[arg(value_parser = number)]
        product: u32,
        /// Revision number.
        #[arg(value_parser = number)]
        revision: u32,
        /// Serial number.
        #[arg(value_parser = number)]
        serial: u32,
    },
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum State {
    Waiting,
    Configuration,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum What {
    Address,
    Vendor,
    Product,
    Revision,
    Serial,
    NodeId,
}

#[derive(Debug, clap::Subcommand)]
enum Identify {
    /// Count the nodes whose address lies in the bounds.
    #[command(
        after_help = "Examples:\n  cantwin lss --socketcand 127.0.0.1:29536 identify remote 0xCA7 305 0 0xFFFFFFFF 0 0xFFFFFFFF"
    )]
    Remote {
        /// Vendor-ID.
        #[arg(value_parser = number)]
        vendor: u32,
        /// Product code.
        #[arg(value_parser = number)]
        product: u32,
        /// Lowest revision number.
        #[arg(value_parser = number)]
        revision_low: u32,
        /// Highest revision number.
        #[arg(value_parser = number)]
        revision_high: u32,
        /// Lowest serial number.
        #[arg(value_parser = number)]
        serial_low: u32,
        /// Highest serial number.
        #[arg(value_parser = number)]
        serial_high: u32,
    },
    /// Count the nodes without node-ID.
    #[command(
        after_help = "Examples:\n  cantwin lss --socketcand 127.0.0.1:29536 identify non-configured"
    )]
    NonConfigured,
}

/// A number, decimal or hex with `0x`.
fn number(text: &str) -> Result<u32, String> {
    let t = text.trim();
    match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(h) => u32::from_str_radix(h, 16),
        None => t.parse(),
    }
    .map_err(|e| format!("{text:?}: {e}"))
}

fn node_id(text: &str) -> Result<u8, String> {
    let n = number(text)?;
    match u8::try_from(n) {
        Ok(n) if (1..=127).contains(&n) || n == UNCONFIGURED => Ok(n),
        _ => Err(format!("a node-ID is 1–127, or 255 for none, not {n}")),
    }
}

/// Prints a result: `text`, or with `--json` the object.
fn say(text: impl std::fmt::Display, value: serde_json::Value) -> Result<()> {
    output::result(text, || value).context("writing the result")
}

fn address_json(a: &Address) -> serde_json::Value {
    json!({"vendor": a.vendor, "product": a.product, "revision": a.revision, "serial": a.serial})
}

fn address(a: &Address) -> String {
    format!(
        "vendor 0x{:08X} product 0x{:08X} revision 0x{:08X} serial 0x{:08X}",
        a.vendor, a.product, a.revision, a.serial
    )
}

/// Runs `service` to its end.
fn run(link: &mut Link, master: &mut Master, service: Service) -> Result<Outcome> {
    let mut out = Outbox::new();
    if master.start(service, link.now(), &mut out).is_err() {
        bail!("the LSS master is busy");
    }
    for f in out.drain() {
        link.send(f)?;
    }
    let mut outcome = master.poll();
    if outcome.is_none() {
        let per_step = WallDuration::from_nanos(master.timeout().as_nanos());
        link.run(
            master,
            |m| {
                outcome = m.poll();
                outcome.is_some()
            },
            per_step * 140 + WallDuration::from_secs(1),
        )?;
    }
    Ok(outcome.unwrap_or(Outcome::Timeout))
}

/// `Ok` for a confirmed service, else what went wrong.
fn confirmed(what: &str, o: Outcome) -> Result<()> {
    match o {
        Outcome::Done => Ok(()),
        Outcome::Timeout => bail!("{what}: no LSS slave answered"),
        Outcome::Refused { error, spec } => bail!(
            "{what}: the slave refused with error {error}{} (CiA 305: 1 not supported, 2 storage media access error, 255 manufacturer-specific)",
            if error == 0xFF {
                format!(", manufacturer error {spec}")
            } else {
                String::new()
            }
        ),
        other => bail!("{what}: unexpected answer {other:?}"),
    }
}

/// Runs `cantwin lss`.
pub fn run_lss(args: &LssArgs) -> Result<()> {
    let default_ms = match args.command {
        LssCommand::Fastscan => 100,
        _ => 1000,
    };
    let ms = args.timeout.unwrap_or(default_ms);
    if ms == 0 {
        bail!("--timeout must be greater than 0");
    }
    let mut master = Master::new(Duration::from_millis(ms));
    let mut link = Link::open(&args.target)?;
    // A socketcand server may forward the first bus frames to a new client some tens of
    // milliseconds late; a short answer time would take that for silence (fastscan: for a 1
    // bit). Listen for a moment before the first request.
    link.run(&mut master, |_| false, WallDuration::from_millis(100))?;
    let l = &mut link;
    let m = &mut master;
    match &args.command {
        LssCommand::Switch(Switch::Global { state }) => {
            let mode = match state {
                State::Waiting => Mode::Waiting,
                State::Configuration => Mode::Configuration,
            };
            run(l, m, Service::SwitchGlobal(mode))?;
            say("OK", json!({"service": "switch global", "ok": true}))?;
        }
        LssCommand::Switch(Switch::Selective {
            vendor,
            product,
            revision,
            serial,
        }) => {
            let a = Address {
                vendor: *vendor,
                product: *product,
                revision: *revision,
                serial: *serial,
            };
            confirmed(
                "switch state selective",
                run(l, m, Service::SwitchSelective(a))?,
            )?;
            say(
                format_args!("OK: {} is in LSS configuration", address(&a)),
                json!({"service": "switch selective", "ok": true, "address": address_json(&a)}),
            )?;
        }
        LssCommand::SetNode { node_id } => {
            confirmed(
                "configure node-ID",
                run(l, m, Service::ConfigureNodeId(*node_id))?,
            )?;
            say(
                format_args!(
                    "OK: node-ID {node_id} pending (active at the next reset communication)"
                ),
                json!({"service": "configure node-ID", "ok": true, "node_id": node_id}),
            )?;
        }
        LssCommand::ConfBitrate { rate } => {
            let index = table_index_of(*rate)
                .with_context(|| format!("{rate} has no entry in the CiA 301 bit timing table"))?;
            let s = Service::ConfigureBitTiming { table: 0, index };
            confirmed("configure bit timing", run(l, m, s)?)?;
            say(
                format_args!("OK: {rate} pending (table index {index})"),
                json!({"service": "configure bit timing", "ok": true, "bit_rate": rate.bits_per_second(), "table_index": index}),
            )?;
        }
        LssCommand::ActivateBitrate { delay_ms } => {
            run(l, m, Service::ActivateBitTiming(*delay_ms))?;
            say(
                "OK",
                json!({"service": "activate bit timing", "ok": true, "delay_ms": delay_ms}),
            )?;
        }
        LssCommand::Store => {
            confirmed(
                "store configuration",
                run(l, m, Service::StoreConfiguration)?,
            )?;
            say(
                "OK: stored",
                json!({"service": "store configuration", "ok": true}),
            )?;
        }
        LssCommand::Inquire { what } => {
            let service = match what {
                What::Address => Service::InquireAddress,
                What::Vendor => Service::Inquire(Part::Vendor),
                What::Product => Service::Inquire(Part::Product),
                What::Revision => Service::Inquire(Part::Revision),
                What::Serial => Service::Inquire(Part::Serial),
                What::NodeId => Service::InquireNodeId,
            };
            match run(l, m, service)? {
                Outcome::Address(a) => say(address(&a), json!({"address": address_json(&a)}))?,
                Outcome::Value(v) => say(format_args!("0x{v:08X}"), json!({"value": v}))?,
                Outcome::NodeId(UNCONFIGURED) => {
                    say("0xFF (no node-ID)", json!({"node_id": UNCONFIGURED}))?
                }
                Outcome::NodeId(n) => say(n, json!({"node_id": n}))?,
                Outcome::Timeout => bail!("no LSS slave in configuration answered"),
                other => bail!("unexpected answer {other:?}"),
            }
        }
        LssCommand::Identify(which) => {
            let service = match which {
                Identify::Remote {
                    vendor,
                    product,
                    revision_low,
                    revision_high,
                    serial_low,
                    serial_high,
                } => Service::IdentifyRemote {
                    vendor: *vendor,
                    product: *product,
                    revision: (*revision_low, *revision_high),
                    serial: (*serial_low, *serial_high),
                },
                Identify::NonConfigured => Service::IdentifyNonConfigured,
            };
            match run(l, m, service)? {
                Outcome::Identified(n) => {
                    say(format_args!("{n} node(s) answered"), json!({"answered": n}))?
                }
                other => bail!("unexpected answer {other:?}"),
            }
        }
        LssCommand::Fastscan => match run(l, m, Service::Fastscan)? {
            Outcome::Address(a) => say(
                format_args!("{} (now in LSS configuration)", address(&a)),
                json!({"address": address_json(&a)}),
            )?,
            _ => bail!("fastscan found no node without node-ID"),
        },
        LssCommand::Commission {
            node_id,
            address: by_address,
            fastscan,
            bit_rate,
            no_store,
        } => {
            let found = match (by_address, fastscan) {
                (Some(v), _) => {
                    let a = Address {
                        vendor: v[0],
                        product: v[1],
                        revision: v[2],
                        serial: v[3],
                    };
                    confirmed(
                        "switch state selective",
                        run(l, m, Service::SwitchSelective(a))?,
                    )?;
                    a
                }
                (None, true) => {
                    m.set_timeout(Duration::from_millis(args.timeout.unwrap_or(100)));
                    let o = run(l, m, Service::Fastscan)?;
                    m.set_timeout(Duration::from_millis(ms));
                    match o {
                        Outcome::Address(a) => a,
                        _ => bail!("fastscan found no node without node-ID"),
                    }
                }
                (None, false) => bail!("say which node: --address V P R S or --fastscan"),
            };
            confirmed(
                "configure node-ID",
                run(l, m, Service::ConfigureNodeId(*node_id))?,
            )?;
            if let Some(rate) = bit_rate {
                let index = table_index_of(*rate).with_context(|| {
                    format!("{rate} has no entry in the CiA 301 bit timing table")
                })?;
                let s = Service::ConfigureBitTiming { table: 0, index };
                confirmed("configure bit timing", run(l, m, s)?)?;
            }
            if !no_store {
                confirmed(
                    "store configuration",
                    run(l, m, Service::StoreConfiguration)?,
                )?;
            }
            run(l, m, Service::SwitchGlobal(Mode::Waiting))?;
            // A node that had no node-ID boots with it now; one that had one takes it at its
            // next reset communication (CiA 305 §4.4.1).
            say(
                format_args!("OK: {} has node-ID {node_id}", address(&found)),
                json!({"ok": true, "address": address_json(&found), "node_id": node_id}),
            )?;
        }
    }
    // Let the last frame (switch state global and activate bit timing get no answer) leave
    // before the link closes.
    link.run(&mut master, |_| false, WallDuration::from_millis(100))?;
    Ok(())
}
