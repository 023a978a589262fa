//! Rewrites an EDS or DCF file in the canonical CiA 306 layout on standard output:
//! `cargo run --example eds_fmt -- file.eds`.
use std::process::ExitCode;

fn main() -> ExitCode {
    let Some(path) = std::env::args().nth(1) else {
        eprintln!("usage: eds_fmt <file.eds|file.dcf>");
        return ExitCode::FAILURE;
    };
    let parsed = std::fs::read(&path)
        .map_err(|e| e.to_string())
        .and_then(|b| cantwin_eds::parse_bytes(&b).map_err(|e| e.to_string()));
    match parsed {
        Ok(eds) => {
            print!("{}", cantwin_eds::write(&eds));
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("{path}: {e}");
            ExitCode::FAILURE
        }
    }
}
