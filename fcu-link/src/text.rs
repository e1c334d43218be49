//! STATUSTEXT: severities and a text of up to [`TEXT_MAX_LEN`] bytes built without `core::fmt`.
//!
//! A text longer than one STATUSTEXT's [`TEXT_LEN`] bytes goes out in chunks, as MAVLink 2's
//! extension fields of STATUSTEXT have it: every chunk of one text carries the same nonzero
//! `id` (one per text, counting up) and its `chunk_seq` (0, 1, ...); the last chunk is
//! NUL-terminated (a text of a whole number of chunks is followed by an empty one), which
//! tells the receiver the text ended. A text that fits in one chunk keeps `id` 0, "the only
//! chunk". MAVProxy and QGroundControl reassemble them; a receiver that does not know the
//! extensions shows each chunk as a line.

use mavlink::dialects::common::MavSeverity;

/// One STATUSTEXT's text length.
pub const TEXT_LEN: usize = 50;

/// The longest text: four chunks (longer texts are cut there).
pub const TEXT_MAX_LEN: usize = 4 * TEXT_LEN;

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

/// A STATUSTEXT's text, appended piece by piece and cut at [`TEXT_MAX_LEN`] bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Text {
    buf: [u8; TEXT_MAX_LEN],
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
        Self { buf: [0; TEXT_MAX_LEN], len: 0 }
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

    /// How many STATUSTEXTs carry it (see the module docs): one when it fits in one, else
    /// one per [`TEXT_LEN`] bytes begun plus, after a whole number of them, an empty one that
    /// ends it.
    pub fn chunks(&self) -> usize {
        if self.len <= TEXT_LEN {
            1
        } else {
            self.len / TEXT_LEN + 1
        }
    }

    /// Chunk `seq`'s text, NUL-padded to [`TEXT_LEN`] as STATUSTEXT carries it.
    pub fn chunk(&self, seq: usize) -> [u8; TEXT_LEN] {
        let mut out = [0u8; TEXT_LEN];
        let start = seq.saturating_mul(TEXT_LEN).min(self.len);
        let end = start.saturating_add(TEXT_LEN).min(self.len);
        if let (Some(dst), Some(src)) = (out.get_mut(..end - start), self.buf.get(start..end)) {
            dst.copy_from_slice(src);
        }
        out
    }

    /// The text so far.
    pub fn as_bytes(&self) -> &[u8] {
        self.buf.get(..self.len).unwrap_or(&[])
    }
}

#[cfg(test)]
mod tests {
    use mavlink::dialects::common::{MavMessage, MavSeverity, HEARTBEAT_DATA};

    use super::*;
    use crate::test_support::*;
    use crate::{Link, LinkConfig, STATION_GONE_MS};

    /// One STATUSTEXT as the `mavlink` crate decodes it, with the extensions `id` and
    /// `chunk_seq` (which the crate, built without extensions, leaves out) from its payload.
    #[derive(Debug, PartialEq)]
    struct Chunk {
        severity: MavSeverity,
        text: [u8; TEXT_LEN],
        id: u16,
        seq: u8,
    }

    fn chunks(sent: &[Sent]) -> Vec<Chunk> {
        sent.iter()
            .filter_map(|s| match &s.message {
                MavMessage::STATUSTEXT(t) => {
                    let mut payload = s.payload.clone();
                    payload.resize(54, 0);
                    Some(Chunk {
                        severity: t.severity,
                        text: *t.text,
                        id: u16::from_le_bytes([payload[51], payload[52]]),
                        seq: payload[53],
                    })
                }
                _ => None,
            })
            .collect()
    }

    /// What a receiver that follows MAVLink's rules shows: the chunks of one id in `chunk_seq`
    /// order up to the first NUL; a chunk of id 0 on its own.
    fn reassemble(chunks: &[Chunk]) -> Vec<(MavSeverity, Vec<u8>)> {
        let mut texts = Vec::new();
        let mut at = 0;
        while at < chunks.len() {
            let first = &chunks[at];
            let mut text = Vec::new();
            let mut seq = 0;
            loop {
                let chunk = &chunks[at];
                assert_eq!((chunk.id, chunk.seq, chunk.severity), (first.id, seq, first.severity), "chunk {at}");
                at += 1;
                let end = chunk.text.iter().position(|&b| b == 0);
                text.extend_from_slice(&chunk.text[..end.unwrap_or(TEXT_LEN)]);
                if first.id == 0 || end.is_some() {
                    break;
                }
                assert!(at < chunks.len(), "a text without its end");
                seq += 1;
            }
            texts.push((first.severity, text));
        }
        texts
    }

    fn text_of(len: usize) -> Vec<u8> {
        (0..len).map(|i| b'a' + (i % 26) as u8).collect()
    }

    #[test]
    fn a_statustext_longer_than_50_bytes_goes_out_whole_in_chunks() {
        let mut link: TestLink = Link::new(LinkConfig::DEFAULT);
        let lengths = [5, 50, 51, 100, 120, 200, 260];
        let mut sent = Vec::new();
        for &len in &lengths {
            assert!(link.send_text(Severity::Warning, &text_of(len)), "{len} bytes");
            sent.extend(drain(&mut link));
        }
        let chunks = chunks(&sent);
        let texts = reassemble(&chunks);
        let expected: Vec<(MavSeverity, Vec<u8>)> =
            lengths.iter().map(|&len| (MavSeverity::MAV_SEVERITY_WARNING, text_of(len.min(TEXT_MAX_LEN)))).collect();
        assert_eq!(texts, expected);
        // A text that fits in one keeps id 0; each longer one has its own, counting up.
        let ids: Vec<u16> = chunks.iter().filter(|c| c.seq == 0).map(|c| c.id).collect();
        assert_eq!(ids, [0, 0, 1, 2, 3, 4, 5]);
        // Whole chunks are followed by an empty one that ends the text: 100 bytes in three.
        assert_eq!(chunks.iter().filter(|c| c.id == 2).count(), 3);
        assert_eq!(chunks.iter().filter(|c| c.id == 4).count(), 5);
    }

    #[test]
    fn a_chunked_statustext_goes_out_all_or_not_at_all() {
        // Room for two 63-byte chunks, not for the third of a 120-byte text.
        let mut link: Link<140> = Link::new(LinkConfig::DEFAULT);
        assert!(!link.send_text(Severity::Info, &text_of(120)));
        assert!(drain(&mut link).is_empty());
        assert_eq!(link.stats().tx_dropped, 3);
        assert!(link.send_text(Severity::Info, &text_of(90)));
        assert_eq!(reassemble(&chunks(&drain(&mut link))), [(MavSeverity::MAV_SEVERITY_INFO, text_of(90))]);
    }

    #[test]
    fn a_long_greeting_is_resent_chunked_to_a_station_that_connects_later() {
        let mut link: TestLink = Link::new(LinkConfig::DEFAULT);
        let mut mock = Mock::new();
        let greeting = b"saved parameters refused (snapshot 2: layout of another build; snapshot 1: bad CRC): defaults";
        assert!(greeting.len() > TEXT_LEN);
        assert!(link.greet(Severity::Warning, greeting));
        let at_boot = reassemble(&chunks(&drain(&mut link)));
        assert_eq!(at_boot, [(MavSeverity::MAV_SEVERITY_WARNING, greeting.to_vec())]);
        link.receive(&v2(&HEARTBEAT_DATA::DEFAULT), STATION_GONE_MS + 1, &mut mock);
        let later = reassemble(&chunks(&drain(&mut link)));
        assert_eq!(later, at_boot);
    }
}
