//! Prints the Markdown documentation of an EDS file: `cargo run --example eds_doc -- file.eds`.
use std::process::ExitCode;

fn main() -> ExitCode {
    let Some(path) = std::env::args().nth(1) else {
        eprintln!("usage: eds_doc <file.eds>");
        return ExitCode::FAILURE;
    };
    let bytes = match std::fs::read(&path) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("{path}: {e}");
            return ExitCode::FAILURE;
        }
    };
    match cantwin_eds::parse_bytes(&bytes) {
        Ok(eds) => {
            print!("{}", cantwin_eds::render_markdown(&eds));
            eprint!("{}", eds.check());
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("{path}: {e}");
            ExitCode::FAILURE
        }
    }
}
