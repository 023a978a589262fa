//! `cantwin`: digital twins of CAN fieldbus devices, from the command line.

mod ascii_gateway;
mod bench;
mod benchmarks_md;
mod cal;
mod canopen;
mod capture_tap;
mod check;
mod conform;
mod connect;
mod demo;
mod demo_adv200;
mod demo_canopen;
mod demo_devicenet;
mod demo_opendrive;
mod demo_tm3;
mod dnet;
mod drive;
mod dump;
mod eds;
mod fuzz;
mod lss;
mod monitor;
mod monitor_ui;
mod output;
mod replay;
mod report;
mod scenario_cmd;
mod silkit;
mod sim;
mod web;

use anyhow::Result;
use clap::{Parser, Subcommand};

/// Digital twins of CAN fieldbus devices (CANopen, DeviceNet, CAL) on a virtual bus that
/// behaves like the wire.
#[derive(Debug, Parser)]
#[command(name = "cantwin", version, about, long_about = None)]
#[command(
    after_help = "Examples:\n  cantwin demo\n  cantwin bench bus\n  cantwin dump capture.pcap"
)]
struct Cli {
    /// Print results as JSON for programs: one object per result, or one object per line
    /// (JSON Lines) for streams (trace, dump, cal events, scenario check). Errors stay text
    /// on standard error, with a non-zero exit status.
    #[arg(long, global = true)]
    json: bool,
    /// No progress bars on standard error.
    #[arg(long, short, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the embedded demo network in virtual time and print what happened.
    #[command(after_help = "Examples:\n  cantwin demo\n  cantwin demo --verbose")]
    Demo(demo::Args),
    /// Run a scenario paced to the wall clock, with gateways for external tools.
    #[command(
        after_help = "Examples:\n  cantwin sim scenarios/cia301-device.toml --socketcand 29536\n  \
                            cantwin sim scenarios/cia301-device.toml --socketcand 0 --duration 60\n  \
                            cantwin sim scenario.toml --slcan 127.0.0.1:29537 --slcan-bus can0\n  \
                            cantwin sim scenarios/plant.toml --web 8080\n  \
                            cantwin sim scenarios/plant.toml --web 0.0.0.0:8080 --allow-remote --allow-host plant.lan\n  \
                            cantwin sim scenarios/plant.toml --web 8080 --web-max-connections 16 --web-max-streams 4\n\n\
                            Once a gateway accepts connections it prints one line per bus it serves,\n\
                            and the web dashboard its address (with the run's token under --allow-remote):\n  \
                            socketcand 127.0.0.1:29536 can0\n  slcan 127.0.0.1:29537 can0\n  web http://127.0.0.1:8080/\n  \
                            web http://plant.lan:8080/?token=5f0c…"
    )]
    Sim(sim::Args),
    /// Print a capture (pcap, pcapng or candump log), one frame a line, decoded with --decode.
    #[command(
        after_help = "Examples:\n  cantwin dump capture.pcap\n  cantwin dump candump-2024-01-01.log\n  \
                            cantwin dump run.log --decode --eds 5=device.eds\n  \
                            cantwin dump dnet.log --decode --protocol devicenet\n  \
                            cantwin dump run.log --decode --scenario scenarios/opendrive.toml"
    )]
    Dump(dump::Args),
    /// Check, document and commission CiA 306 EDS/DCF files.
    #[command(
        after_help = "Examples:\n  cantwin eds check device.eds\n  cantwin eds doc device.eds -o device.md\n  \
                            cantwin eds dcf device.eds --node-id 5 -o node5.dcf"
    )]
    Eds(eds::Args),
    /// A CAL master for the OPEN DRIVE (application 003): commands, reference, parameters, alarm events.
    #[command(
        after_help = "Examples:\n  cantwin cal --scenario scenarios/opendrive.toml cmd --reference-remote on --command-remote on --start on --ref 50\n  \
                            cantwin cal --socketcand 127.0.0.1:29536 read\n  cantwin cal --socketcand 127.0.0.1:29536 param read max-frequency\n  \
                            cantwin cal --socketcand 127.0.0.1:29536 events watch"
    )]
    Cal(cal::Args),
    /// A DeviceNet scanner: browse devices, get and set attributes, polled I/O, a shell that
    /// stays on line.
    #[command(
        after_help = "Examples:\n  cantwin dnet --socketcand 127.0.0.1:29536 browse\n  \
                            cantwin dnet --socketcand 127.0.0.1:29536 shell\n  \
                            cantwin dnet --socketcand 127.0.0.1:29536 get 12 1 1 7 --type short-string\n  \
                            cantwin dnet --scenario scenarios/adv200-devicenet.toml poll 12 --out 0300E803"
    )]
    Dnet(dnet::Args),
    /// SDO read and write (CiA 309-3 type mnemonics), with progress for large domains.
    #[command(
        after_help = "Examples:\n  cantwin sdo --socketcand 127.0.0.1:29536 read 5 0x1008 0 vs\n  \
                            cantwin sdo --scenario scenarios/cia301-device.toml write 5 0x1017 0 u16 500\n  \
                            cantwin sdo --socketcand 127.0.0.1:29536 --mode block read 5 0x2000 0 --output domain.bin"
    )]
    Sdo(canopen::SdoArgs),
    /// CiA 402 drives: power state, mode of operation, profile position and velocity moves,
    /// homing.
    #[command(
        after_help = "Examples:\n  cantwin drive --socketcand 127.0.0.1:29536 state 2 enable\n  \
                            cantwin drive --socketcand 127.0.0.1:29536 mode 2 pp\n  \
                            cantwin drive --socketcand 127.0.0.1:29536 move pp 2 100000\n  \
                            cantwin drive --socketcand 127.0.0.1:29536 home 2 35\n  \
                            cantwin drive --scenario scenarios/adv200-ds402.toml state 2 enable"
    )]
    Drive(drive::DriveArgs),
    /// Send an NMT command to one node or all: start, stop, preop, reset, reset-comm.
    #[command(
        after_help = "Examples:\n  cantwin nmt --socketcand 127.0.0.1:29536 start 5\n  cantwin nmt --socketcand 127.0.0.1:29536 reset-comm all"
    )]
    Nmt(canopen::NmtArgs),
    /// LSS master (CiA 305): switch nodes to LSS configuration, set node-IDs and bit rates,
    /// store, inquire addresses, identify, fastscan, commission a node without node-ID.
    #[command(
        after_help = "Examples:\n  cantwin lss --socketcand 127.0.0.1:29536 commission 5 --fastscan\n  \
                            cantwin lss --socketcand 127.0.0.1:29536 switch global configuration\n  \
                            cantwin lss --socketcand 127.0.0.1:29536 set-node 5\n  \
                            cantwin lss --socketcand 127.0.0.1:29536 conf-bitrate 500k\n  \
                            cantwin lss --socketcand 127.0.0.1:29536 store\n  \
                            cantwin lss --socketcand 127.0.0.1:29536 inquire\n  \
                            cantwin lss --socketcand 127.0.0.1:29536 switch global waiting"
    )]
    Lss(lss::LssArgs),
    /// Find the CANopen nodes on a bus (SDO upload of 0x1000 to ids 1–127).
    #[command(
        after_help = "Examples:\n  cantwin scan --socketcand 127.0.0.1:29536\n  cantwin scan --scenario scenarios/cia301-device.toml"
    )]
    Scan(canopen::ScanArgs),
    /// Print the frames on a bus, decoded: NMT, SYNC, EMCY with meanings, SDO, PDO values named from an EDS.
    #[command(
        after_help = "Examples:\n  cantwin trace --socketcand 127.0.0.1:29536\n  \
                            cantwin trace --socketcand 127.0.0.1:29536 --eds 5=device.eds --seconds 10"
    )]
    Trace(canopen::TraceArgs),
    /// A live view of a CANopen bus in the terminal: nodes with NMT state, heartbeat, LEDs and
    /// EMCY, decoded frames with filters, bus load, and the selected device's PDO values.
    #[command(
        after_help = "Examples:\n  cantwin monitor --scenario scenarios/monitor-network.toml\n  \
                            cantwin monitor --socketcand 127.0.0.1:29536 --names scenarios/monitor-network.toml\n  \
                            cantwin monitor --socketcand 127.0.0.1:29536 --bit-rate 250k --eds 5=device.eds\n\n\
                            Keys: q quit (Esc only leaves the filter editor or the device page), up/down select a node,\n\
                            t fixed/scrolling trace, space pause, PgUp/PgDn scroll, Home/End oldest/live,\n\
                            / filter (node=5 svc=emcy,hb,lss id=0x180-0x1FF), c clear filter,\n\
                            Enter device page (below 120 columns)"
    )]
    Monitor(monitor::Args),
    /// A CiA 309-3 ASCII gateway (CANopenNode/cocomm syntax) on stdin/stdout or TCP.
    #[command(
        after_help = "Examples:\n  echo '[1] 5 read 0x1008 0 vs' | cantwin gateway --socketcand 127.0.0.1:29536\n  \
                            cantwin gateway --listen 6000 --scenario scenarios/cia301-device.toml"
    )]
    Gateway(ascii_gateway::GatewayArgs),
    /// Write one self-contained HTML page about a capture: bus load, identifiers, decoded timeline, anomalies.
    #[command(after_help = "Examples:\n  cantwin report capture.pcap\n  \
                            cantwin report run.log --bit-rate can0=500k --eds 5=device.eds -o run.html\n  \
                            cantwin report dnet.log --protocol can0=devicenet --bit-rate 125k")]
    Report(report::Args),
    /// Run named benchmarks (release build recommended) and optionally record them.
    #[command(
        after_help = "Examples:\n  cantwin bench bus\n  cantwin bench bus --seconds 10\n  \
                            cantwin bench network sdo --trials 9\n  cantwin bench bus --write"
    )]
    Bench(bench::Args),
    /// Fuzz every decoder and state machine that reads outside input; print cases and failures.
    #[command(
        after_help = "Examples:\n  cantwin fuzz --cases 100000\n  cantwin fuzz --list\n  cantwin fuzz --cases 5000 eds twin-cia301"
    )]
    Fuzz(fuzz::Args),
    /// Check scenario files without running them: syntax, keys, kinds, node-IDs, script.
    #[command(
        after_help = "Examples:\n  cantwin scenario check scenarios/*.toml\n  cantwin scenario check --json my-rig.toml"
    )]
    Scenario(scenario_cmd::Args),
    /// Re-inject a capture's master frames into a scenario's twins in virtual time and diff
    /// the twins' answers against the capture (`--help` tells which frames are the master's).
    #[command(
        after_help = "Examples:\n  cantwin replay run.pcap --scenario scenarios/cia301-device.toml\n  \
                            cantwin replay run.log --scenario rig.toml --tolerance-ms 5 --master-ids 000,605",
        after_long_help = replay::LONG_HELP
    )]
    Replay(replay::Args),
    /// Vector SIL Kit: be the CAN network simulator of a SIL Kit co-simulation (twins join
    /// one with `cantwin sim --silkit`).
    #[command(
        after_help = "Examples:\n  cantwin silkit netsim --registry silkit://127.0.0.1:8500 --network can0\n  \
                            cantwin silkit netsim --registry silkit://10.0.0.5:8500 --network CAN1 --network CAN2 --bit-rate 250k"
    )]
    Silkit(silkit::Args),
    /// Run the CiA 301/306 conformance cases against one device: EDS, SDO, OD, PDO,
    /// SYNC/EMCY/TIME, error control, NMT, store/restore; JUnit, JSON and HTML reports.
    #[command(
        after_help = "Examples:\n  cantwin conform --scenario scenarios/cia301-device.toml --node-id 5 --eds node5.eds --junit conform.xml\n  \
                            cantwin conform --socketcand 127.0.0.1:29536 --node-id 5 --eds device.eds --profile device.profile.toml --html conform.html\n  \
                            cantwin conform --list"
    )]
    Conform(conform::Args),
}

fn run(cli: Cli) -> Result<()> {
    output::configure(cli.json, cli.quiet);
    match cli.command {
        Command::Demo(args) => demo::run(&args),
        Command::Bench(args) => bench::run(&args),
        Command::Fuzz(args) => fuzz::run(&args),
        Command::Sim(args) => sim::run(&args),
        Command::Dump(args) => dump::run(&args),
        Command::Eds(args) => eds::run(&args),
        Command::Cal(args) => cal::run(&args),
        Command::Dnet(args) => dnet::run(&args),
        Command::Sdo(args) => canopen::run_sdo(&args),
        Command::Drive(args) => drive::run(&args),
        Command::Nmt(args) => canopen::run_nmt(&args),
        Command::Scan(args) => canopen::run_scan(&args),
        Command::Trace(args) => canopen::run_trace(&args),
        Command::Monitor(args) => monitor::run(&args),
        Command::Gateway(args) => ascii_gateway::run(&args),
        Command::Lss(args) => lss::run_lss(&args),
        Command::Report(args) => report::run(&args),
        Command::Scenario(args) => scenario_cmd::run(&args),
        Command::Replay(args) => replay::run(&args),
        Command::Silkit(args) => silkit::run(&args),
        Command::Conform(args) => conform::run(&args),
    }
}

/// Ends the process quietly when standard output is a closed pipe (`cantwin trace | head`),
/// as command-line tools do, instead of panicking in `println!`.
fn exit_quietly_on_broken_pipe() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let message = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if message.contains("failed printing to stdout") && message.contains("Broken pipe") {
            // 128 + SIGPIPE, what a shell reports for a process ended by a closed pipe.
            std::process::exit(141);
        }
        default(info);
    }));
}

fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
            || c.to_string().ends_with("Broken pipe (os error 32)")
    })
}

fn main() -> std::process::ExitCode {
    exit_quietly_on_broken_pipe();
    // Errors are for the person at the terminal: the message and its causes, no backtrace.
    match run(Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        // Output into a closed pipe is the reader's choice, not a failure worth a message.
        Err(e) if is_broken_pipe(&e) => std::process::ExitCode::from(141),
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn cli_definition_is_consistent() {
        Cli::command().debug_assert();
    }
}
