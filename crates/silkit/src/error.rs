//! Errors of the SIL Kit binding.

use std::path::PathBuf;

/// What went wrong talking to SIL Kit.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// `libSilKit.so` could not be opened.
    #[error(
        "SIL Kit is not available: libSilKit.so could not be loaded ({tried}). Install Vector SIL Kit 5 \
         (https://github.com/vectorgrp/sil-kit/releases) and set CANTWIN_SILKIT_LIB to its libSilKit.so, \
         or run scripts/fetch-silkit.sh in a cantwin checkout (it fetches SIL Kit 5.0.3 from the \
         silkit-py wheel on PyPI) and set CANTWIN_SILKIT_DIR to the directory it prints"
    )]
    NotFound {
        /// Each place tried, with why it failed.
        tried: String,
    },
    /// The library lacks a function this binding needs (not SIL Kit 5, or a damaged file).
    #[error("{library} is not a usable SIL Kit 5 library: it has no {symbol}")]
    MissingSymbol {
        /// The library file.
        library: PathBuf,
        /// The missing function.
        symbol: &'static str,
    },
    /// The library is a SIL Kit of another major version.
    #[error("{library} is SIL Kit {version}; cantwin needs SIL Kit 5")]
    WrongVersion {
        /// The library file.
        library: PathBuf,
        /// Its version.
        version: String,
    },
    /// A SIL Kit call failed.
    #[error("{function} failed: {message} (SIL Kit return code {code})")]
    Call {
        /// The C function.
        function: &'static str,
        /// `SilKit_ReturnCode`.
        code: i32,
        /// `SilKit_GetLastErrorString`, or the code's fixed text.
        message: String,
    },
    /// A string handed to SIL Kit contained a NUL byte.
    #[error("{what} {value:?} contains a NUL byte")]
    Nul {
        /// Which argument.
        what: &'static str,
        /// Its value.
        value: String,
    },
    /// The participant this handle belongs to was destroyed.
    #[error("the SIL Kit participant was destroyed")]
    Destroyed,
    /// A bounded wait ended before what it waited for happened.
    #[error("{waited_for} did not happen within {after:?} (the participant is {state:?})")]
    Timeout {
        /// What did not happen, e.g. "the lifecycle reaching Shutdown".
        waited_for: &'static str,
        /// The bound.
        after: std::time::Duration,
        /// The participant's state when the bound ran out.
        state: crate::types::ParticipantState,
    },
    /// The library does not offer an experimental function this binding needs.
    #[error("this SIL Kit library has no {0} (experimental API; SIL Kit 4.0.50 or later has it)")]
    NoExperimental(&'static str),
}
