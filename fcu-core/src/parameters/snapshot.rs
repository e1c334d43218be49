//! The parameter set as it is kept in flash: whole snapshots in two sectors used in rotation.
//!
//! Pure: the firmware hands in the two sectors as words (flash is memory-mapped) and carries
//! out the [`SavePlan`] this module makes; the tests run the same on an in-RAM model.
//!
//! # A snapshot
//!
//! [`RECORD_WORDS`] 32-bit words, written in order, the commit word last:
//!
//! | word | content |
//! |---|---|
//! | 0 | [`MAGIC`] |
//! | 1 | sequence number (one more than the newest snapshot's) |
//! | 2 | [`LAYOUT_HASH`]: the table's names and order |
//! | 3 | the number of values ([`COUNT`]) |
//! | 4.. | the values, `f32` bits, in table order |
//! | then | CRC-32 (IEEE) of the words before it, little-endian bytes |
//! | last | [`COMMIT`] |
//!
//! A sector holds [`SLOTS`] snapshots one after the other. A save goes to the slot after the
//! last one written in the sector holding the newest snapshot; when that sector is full, the
//! other is erased and the save goes to its first slot. So a save never touches the newest
//! snapshot, and a sector is erased only when the newest snapshot is in the other one.
//!
//! # A power cut
//!
//! Flash programs a word by clearing bits (erased is `0xFFFF_FFFF`), and a word cut short
//! has only some of its bits cleared; an erase cut short leaves words partly set. A snapshot
//! counts only with its commit word exactly [`COMMIT`] (a partly programmed one differs, its
//! bits still set), its CRC right and its magic, layout and length those of this firmware:
//! a cut anywhere in a save leaves the old newest snapshot intact and the new one either whole
//! or not counted; a cut in an erase leaves the newest snapshot, in the other sector, intact.
//! Loading takes the valid snapshot with the highest sequence number.
//!
//! # Why not `sequential-storage`
//!
//! That crate keeps key-value items and queues over a `NorFlash` with async access, wear
//! levelling over many pages and its own garbage collection. Here the need is one fixed-size
//! record holding the whole set, rewritten every few minutes at most: one commit word makes
//! the power-cut argument short enough to test exhaustively (every word of a save, every word
//! of an erase, below), the code is a few hundred bytes against a flash budget counted in
//! them, it needs no wrapper for the F401's 16 KB sectors nor an async flash driver, and the
//! layout hash refuses another firmware's set where a key-value map would read it key by key.
//! Wear: 73 saves per erase, 10 000 erase cycles per sector: over a million saves.

use super::{COUNT, LAYOUT_HASH};

/// Words in a 16 KB sector.
pub const SECTOR_WORDS: usize = 4096;
/// Words in a snapshot.
pub const RECORD_WORDS: usize = COUNT + 6;
/// Snapshots per sector.
pub const SLOTS: usize = SECTOR_WORDS / RECORD_WORDS;
/// The first word of a snapshot ("FCUP").
pub const MAGIC: u32 = 0x5055_4346;
/// The last word, written last ("DONE").
pub const COMMIT: u32 = 0x454E_4F44;
/// An erased word.
pub const ERASED: u32 = 0xFFFF_FFFF;

const SEQ: usize = 1;
const HASH: usize = 2;
const LEN: usize = 3;
const VALUES: usize = 4;
const CRC: usize = VALUES + COUNT;
const COMMIT_AT: usize = CRC + 1;

/// A whole parameter set as found in flash.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Snapshot {
    pub sequence: u32,
    pub values: [f32; COUNT],
}

/// Where a snapshot was found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Location {
    pub sector: usize,
    pub slot: usize,
}

/// What a save must do, in this order: erase `erase` if set, then program `words` from word
/// `first_word` of `sector` one after the other (the commit word, last, last).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SavePlan {
    pub erase: Option<usize>,
    pub sector: usize,
    pub first_word: usize,
    pub words: [u32; RECORD_WORDS],
}

/// CRC-32 (IEEE 802.3, reflected, as zlib's) of `words`' little-endian bytes. A word at a
/// time, four bits a step from a 16-entry table: the reflected CRC takes a word's
/// little-endian bytes as its 32 bits from the lowest, so XORing the whole word in and
/// stepping 32 bits is the bytewise CRC. A bit a step, fcu-core's opt-level 3 unrolled the 32
/// steps (some 400 bytes); this is a fraction of that, with the 64-byte table. Out of line:
/// one copy for loading and saving.
#[inline(never)]
pub fn crc32(words: &[u32]) -> u32 {
    let mut crc = !0u32;
    for w in words {
        crc ^= w;
        for _ in 0..8 {
            crc = (crc >> 4) ^ CRC_NIBBLE.get((crc & 0xF) as usize).copied().unwrap_or(0);
        }
    }
    !crc
}

/// The reflected polynomial.
const CRC_POLY: u32 = 0xEDB8_8320;

/// What four bit steps of the reflected CRC XOR in, by the four bits shifted out.
const CRC_NIBBLE: [u32; 16] = crc_nibble_table();

// Evaluated by the compiler: an index out of bounds would fail the build.
#[allow(clippy::indexing_slicing)]
const fn crc_nibble_table() -> [u32; 16] {
    let mut t = [0u32; 16];
    let mut n = 0;
    while n < 16 {
        let mut c = n as u32;
        let mut bit = 0;
        while bit < 4 {
            c = (c >> 1) ^ (CRC_POLY & (c & 1).wrapping_neg());
            bit += 1;
        }
        t[n] = c;
        n += 1;
    }
    t
}

/// The words of a snapshot.
pub fn encode(sequence: u32, values: &[f32; COUNT]) -> [u32; RECORD_WORDS] {
    let mut w = [ERASED; RECORD_WORDS];
    let header = [MAGIC, sequence, LAYOUT_HASH, COUNT as u32];
    for (dst, src) in w.iter_mut().zip(header.iter().copied().chain(values.iter().map(|v| v.to_bits()))) {
        *dst = src;
    }
    let crc = crc32(w.get(..CRC).unwrap_or(&[]));
    if let Some(c) = w.get_mut(CRC) {
        *c = crc;
    }
    if let Some(c) = w.get_mut(COMMIT_AT) {
        *c = COMMIT;
    }
    w
}

/// The snapshot in `words` (one slot), if it is whole and this firmware's.
pub fn decode(words: &[u32]) -> Option<Snapshot> {
    let w = words.get(..RECORD_WORDS)?;
    let at = |i: usize| w.get(i).copied();
    let ours = at(0)? == MAGIC && at(HASH)? == LAYOUT_HASH && at(LEN)? == COUNT as u32;
    if !ours || at(COMMIT_AT)? != COMMIT || at(CRC)? != crc32(w.get(..CRC)?) {
        return None;
    }
    let mut values = [0.0; COUNT];
    for (v, bits) in values.iter_mut().zip(w.get(VALUES..CRC)?) {
        *v = f32::from_bits(*bits);
    }
    Some(Snapshot { sequence: at(SEQ)?, values })
}

fn slot(sector: &[u32], slot: usize) -> &[u32] {
    sector.get(slot * RECORD_WORDS..(slot + 1) * RECORD_WORDS).unwrap_or(&[])
}

/// The newest valid snapshot in the two sectors, and where it is.
pub fn newest(sectors: [&[u32]; 2]) -> Option<(Snapshot, Location)> {
    let mut best: Option<(Snapshot, Location)> = None;
    for (s, words) in sectors.iter().enumerate() {
        for k in 0..SLOTS {
            if let Some(snap) = decode(slot(words, k)) {
                if best.is_none_or(|(b, _)| snap.sequence > b.sequence) {
                    best = Some((snap, Location { sector: s, slot: k }));
                }
            }
        }
    }
    best
}

/// The newest valid snapshot (see [`newest`]).
pub fn load(sectors: [&[u32]; 2]) -> Option<Snapshot> {
    newest(sectors).map(|(s, _)| s)
}

/// Where the configuration at boot came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    /// The newest valid snapshot, with its sequence number.
    Snapshot { sequence: u32 },
    /// No valid snapshot of this firmware's table: the defaults.
    NoSnapshot,
    /// The newest snapshot's values do not make a valid configuration (the rule): the defaults.
    Refused(&'static str),
}

/// The configuration to boot with: `defaults` with the newest valid snapshot's values, or
/// `defaults` alone (and why), never a mix.
// Out of line: inlined into a firmware's `init` with constant defaults, opt-level 3 builds the
// defaults field by field once per way out (a kilobyte each) instead of copying them.
#[inline(never)]
pub fn load_config(sectors: [&[u32]; 2], defaults: &crate::Config) -> (crate::Config, Source) {
    match load(sectors) {
        None => (*defaults, Source::NoSnapshot),
        Some(s) => match super::with_values(defaults, &s.values) {
            Ok(cfg) => (cfg, Source::Snapshot { sequence: s.sequence }),
            Err(rule) => (*defaults, Source::Refused(rule)),
        },
    }
}

/// How to save `values` as the newest snapshot.
pub fn plan_save(sectors: [&[u32]; 2], values: &[f32; COUNT]) -> SavePlan {
    let found = newest(sectors);
    let sequence = found.map_or(1, |(s, _)| s.sequence.wrapping_add(1));
    let words = encode(sequence, values);
    // The slot after the last one written to in the newest snapshot's sector (a save cut
    // short leaves its slot used): everything after it is erased, the newest untouched.
    let (sector, next) = match found {
        Some((_, at)) => {
            let words = sectors.get(at.sector).copied().unwrap_or(&[]);
            let last_used = (0..SLOTS).rev().find(|&k| !erased(slot(words, k))).unwrap_or(at.slot);
            (at.sector, last_used + 1)
        }
        None => (0, SLOTS),
    };
    if next < SLOTS {
        return SavePlan { erase: None, sector, first_word: next * RECORD_WORDS, words };
    }
    // The sector is full (or there is no snapshot): the other one, erased unless it is.
    let other = if found.is_some() { sector ^ 1 } else { 0 };
    let other_words = sectors.get(other).copied().unwrap_or(&[]);
    let fresh = other_words.get(..SLOTS * RECORD_WORDS).is_some_and(erased);
    SavePlan { erase: (!fresh).then_some(other), sector: other, first_word: 0, words }
}

/// Words that are all erased flash (and at least one). Out of line: the save asks it of every
/// slot and of a whole sector, and at fcu-core's opt-level each copy would be unrolled.
#[inline(never)]
fn erased(words: &[u32]) -> bool {
    !words.is_empty() && words.iter().all(|&w| w == ERASED)
}

#[cfg(test)]
mod tests;
