//! STATUSTEXT: severities and a fixed 50-byte text built without `core::fmt`.

use mavlink::dialects::common::MavSeverity;

/// STATUSTEXT's text length (longer texts are cut there).
pub const TEXT_LEN: usize = 50;

/// MAVLink's `MAV_SEVERITY`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Severity {
    /// System is unusable.
    Emergency,
    /// Immediate action needed.
    Alert,
    /// Critical condition.
    Critical,
    /// Error.
    Error,
    /// Warning: a refusal, a blocker.
    Warning,
    /// Normal but significant.
    Notice,
    /// Information: state changes.
    Info,
    /// Debugging.
    Debug,
}

impl Severity {
    pub(crate) fn mav(self) -> MavSeverity {
        match self {
            Self::Emergency => MavSeverity::MAV_SEVERITY_EMERGENCY,
            Self::Alert => MavSeverity::MAV_SEVERITY_ALERT,
            Self::Critical => MavSeverity::MAV_SEVERITY_CRITICAL,
            Self::Error => MavSeverity::MAV_SEVERITY_ERROR,
            Self::Warning => MavSeverity::MAV_SEVERITY_WARNING,
            Self::Notice => MavSeverity::MAV_SEVERITY_NOTICE,
            Self::Info => MavSeverity::MAV_SEVERITY_INFO,
            Self::Debug => MavSeverity::MAV_SEVERITY_DEBUG,
        }
    }
}

/// A STATUSTEXT's text, appended piece by piece and cut at [`TEXT_LEN`] bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Text {
    buf: [u8; TEXT_LEN],
    len: usize,
}

impl Default for Text {
    fn default() -> Self {
        Self::new()
    }
}

impl Text {
    /// Empty.
    pub const fn new() -> Self {
        Self { buf: [0; TEXT_LEN], len: 0 }
    }

    /// Appends `s` (bytes past the limit are dropped).
    pub fn push(self, s: &str) -> Self {
        self.push_bytes(s.as_bytes())
    }

    /// Appends `bytes` (those past the limit are dropped).
    pub fn push_bytes(mut self, bytes: &[u8]) -> Self {
        for &byte in bytes {
            if let Some(slot) = self.buf.get_mut(self.len) {
                *slot = byte;
                self.len += 1;
            }
        }
        self
    }

    /// Appends a number in decimal.
    pub fn push_u32(self, mut n: u32) -> Self {
        let mut digits = [0u8; 10];
        let mut count = 0;
        loop {
            if let Some(d) = digits.get_mut(count) {
                *d = b'0' + (n % 10) as u8;
            }
            count += 1;
            n /= 10;
            if n == 0 || count == digits.len() {
                break;
            }
        }
        let mut out = self;
        for &d in digits.iter().take(count).rev() {
            if let Some(slot) = out.buf.get_mut(out.len) {
                *slot = d;
                out.len += 1;
            }
        }
        out
    }

    /// The bytes, zero-padded to [`TEXT_LEN`] as STATUSTEXT carries them.
    pub fn bytes(&self) -> [u8; TEXT_LEN] {
        self.buf
    }

    /// The text so far.
    pub fn as_bytes(&self) -> &[u8] {
        self.buf.get(..self.len).unwrap_or(&[])
    }
}
