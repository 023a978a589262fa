//! The CiA 309-3 ASCII mapping of CANopen, in the command syntax of CANopenNode's gateway
//! and its `cocomm` client: request lines parsed into bus operations, values encoded from
//! text, answers formatted. Sans-IO: the caller runs each [`BusOp`] on its bus (an SDO
//! transfer or an NMT command through a master) and hands the result back.
//!
//! A request is one line, `[<seq>] [[<net>] <node>] <command>`; the answer is one line
//! `[<seq>] OK`, `[<seq>] <value>` or `[<seq>] ERROR:<code>`, sent followed by CR LF
//! ([`EOL`]) on every channel, as CANopenNode's gateway sends it, where the code is the SDO
//! abort code in hex (`ERROR:0x06020000`, CiA 301 table 22) or one of the gateway's own
//! error codes in decimal (CiA 309-3): 100 request not supported, 101 syntax error, 102
//! request not processed due to internal state, 103 time-out, 105 no default node set, 106
//! unsupported net, 107 unsupported node, 501 LSS manufacturer-specific error, 502 LSS
//! node-ID not supported, 503 LSS bit rate not supported, 504 LSS storing failed. `help`
//! answers with its text alone (no sequence number, no `OK`), lines separated by LF.
//! A net is any number up to 0xFFFF and is not used (one network; above: 106).
//! `[<seq>]` is required (a line without it is
//! answered `ERROR:101` under the previous sequence number); the sequence number is shown as
//! a signed 32-bit number, as CANopenNode prints it; an empty line gets an empty answer.
//!
//! Commands:
//!
//! * `read <index> <sub> [<type>]` (or `r`): SDO upload; without a type the bytes in hex;
//! * `write <index> <sub> <type> <value>` (or `w`): SDO download;
//! * `start`, `stop`, `preop` (`preoperational`), `reset node`, `reset comm`
//!   (`reset communication`): NMT, node 0 addresses all nodes;
//! * `set network <net>`, `set node <node>`, `set sdo_timeout <ms>`, `set sdo_block <0|1>`;
//! * LSS (CiA 305, [`BusOp::Lss`]): `lss_switch_glob`, `lss_switch_sel`, `lss_set_node`,
//!   `lss_conf_bitrate`, `lss_activate_bitrate`, `lss_store`, `lss_inquire_addr`,
//!   `lss_get_node`, `_lss_fastscan`, `lss_allnodes`;
//! * `info`, `help` (`help datatype`, `help lss`).
//!
//! Types: `b`, `i8`…`i64`, `u8`…`u64` (decimal or `0x` hex), `x8`, `x16`, `x32`, `x64`
//! (unsigned, shown in hex), `r32`, `r64` (shown as C's `%g` shows them: `3.14159`,
//! `1e+08`), `vs` (text; in double quotes when it has spaces, a quote inside doubled; shown
//! quoted), `os`, `us`, `d` (MIME base64, RFC 2045, as CANopenNode's gateway), `hex` (bytes
//! as upper-case hex separated by spaces; on write a token may hold several bytes).
//!
//! One gateway serves one network: a request's net (up to [`NET_MAX`]) is taken and not
//! used, as by CANopenNode's gateway built for one network; each client has its own
//! [`Session`]: default node, SDO timeout and block setting.
//!
//! ```
//! use cantwin_canopen::sdo::wire::Mux;
//! use cantwin_cia309::{BusOp, GwError, Session, Step, request};
//!
//! # fn main() -> Result<(), &'static str> {
//! let mut client = Session::new(1000);
//! let Step::Answer(ok) = request("[1] set node 5", &mut client) else {
//!     return Err("set answers at once");
//! };
//! assert_eq!(ok, "[1] OK");
//! let Step::Bus(read) = request("[2] read 0x1017 0 u16", &mut client) else {
//!     return Err("a read goes to the bus");
//! };
//! assert_eq!(read.op(), &BusOp::Upload { node: 5, mux: Mux::new(0x1017, 0) });
//! // The SDO upload returned E8 03.
//! assert_eq!(read.finish(Ok(vec![0xE8, 0x03])), "[2] 1000");
//! let Step::Bus(read) = request("[3] read 0x1017 0 u16", &mut client) else {
//!     return Err("a read goes to the bus");
//! };
//! assert_eq!(read.finish(Err(GwError::TIMEOUT)), "[3] ERROR:103");
//! # Ok(())
//! # }
//! ```
#![forbid(unsafe_code)]

mod error;
mod real;
mod request;
mod value;

pub use error::GwError;
pub use request::{
    BusOp, EOL, FASTSCAN_TIMEOUT_MS, HELP, LSS_TIMEOUT_MS, LssOp, LssResult, NET_MAX, Pending,
    Session, Step, request,
};
pub use value::{MNEMONICS, data_type};
