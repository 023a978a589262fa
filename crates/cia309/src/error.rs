//! Why a request failed: an SDO abort code or one of the gateway's own error codes.

use cantwin_canopen::AbortCode;

/// Why a request failed: the SDO abort code or one of the gateway's own codes.
///
/// Shown as the gateway answers it: an abort code in hex (`0x06020000`, CiA 301 table 22),
/// a gateway code in decimal (`101`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum GwError {
    /// The SDO transfer was aborted with this code.
    #[error("{:#010X}", u32::from(*.0))]
    Abort(AbortCode),
    /// A CiA 309-3 gateway error code.
    #[error("{0}")]
    Code(u16),
}

impl GwError {
    /// 100: request not supported.
    pub const NOT_SUPPORTED: GwError = GwError::Code(100);
    /// 101: syntax error.
    pub const SYNTAX: GwError = GwError::Code(101);
    /// 102: request not processed due to internal state.
    pub const STATE: GwError = GwError::Code(102);
    /// 103: time-out.
    pub const TIMEOUT: GwError = GwError::Code(103);
    /// 105: no default node set.
    pub const NO_NODE: GwError = GwError::Code(105);
    /// 106: unsupported net.
    pub const NET: GwError = GwError::Code(106);
    /// 107: unsupported node.
    pub const NODE: GwError = GwError::Code(107);
    /// 501: LSS implementation- or manufacturer-specific error.
    pub const LSS_MANUFACTURER: GwError = GwError::Code(501);
    /// 502: LSS node-ID not supported.
    pub const LSS_NODE_ID: GwError = GwError::Code(502);
    /// 503: LSS bit-rate not supported.
    pub const LSS_BIT_RATE: GwError = GwError::Code(503);
    /// 504: LSS parameter storing failed.
    pub const LSS_STORE: GwError = GwError::Code(504);
}
