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
//! Loading takes the newest valid snapshot, sequence numbers compared in serial-number
//! arithmetic ([`is_newer`]: after 0xFFFF_FFFF comes 0); one whose values are refused (a rule
//! they break, or another firmware's table) gives way to the one before it, and [`Source`]
//! says so.
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
/// stepping 32 bits is the bytewise CRC.
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
    match inspect(words)? {
        Record::Ours(s) => Some(s),
        Record::OtherTable { .. } => None,
    }
}

/// A whole record found in a slot.
// Only ever one or two on the stack while a sector is read at boot, and there is no heap to
// box the values in: the size difference costs nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq)]
enum Record {
    /// This firmware's.
    Ours(Snapshot),
    /// Whole (magic, CRC and commit word right) but saved with another table: another
    /// firmware's, never read into this one's parameters.
    OtherTable { sequence: u32 },
}

impl Record {
    fn sequence(&self) -> u32 {
        match self {
            Record::Ours(s) => s.sequence,
            Record::OtherTable { sequence } => *sequence,
        }
    }
}

/// The whole record starting at `words`, of this table or another (with its own length, if
/// it fits), or `None`.
fn inspect(words: &[u32]) -> Option<Record> {
    let at = |i: usize| words.get(i).copied();
    if at(0)? != MAGIC {
        return None;
    }
    let len = usize::try_from(at(LEN)?).ok()?;
    let crc_at = VALUES.checked_add(len)?;
    if at(crc_at.checked_add(1)?)? != COMMIT || at(crc_at)? != crc32(words.get(..crc_at)?) {
        return None;
    }
    let sequence = at(SEQ)?;
    if at(HASH)? != LAYOUT_HASH || len != COUNT {
        return Some(Record::OtherTable { sequence });
    }
    let mut values = [0.0; COUNT];
    for (v, bits) in values.iter_mut().zip(words.get(VALUES..CRC)?) {
        *v = f32::from_bits(*bits);
    }
    Some(Record::Ours(Snapshot { sequence, values }))
}

fn slot(sector: &[u32], slot: usize) -> &[u32] {
    sector.get(slot * RECORD_WORDS..(slot + 1) * RECORD_WORDS).unwrap_or(&[])
}

/// The record from slot `k` of `sector` on (to the sector's end: another table's record may
/// be longer than a slot).
fn from_slot(sector: &[u32], k: usize) -> &[u32] {
    sector.get(k * RECORD_WORDS..).unwrap_or(&[])
}

/// Sequence number `a` is newer than `b`, in serial-number arithmetic (RFC 1982): `a` is
/// less than 2^31 saves after `b`, across the wrap from 0xFFFF_FFFF to 0. The two sectors
/// hold at most `2 · SLOTS` consecutive numbers, so any two are comparable.
pub fn is_newer(a: u32, b: u32) -> bool {
    (a.wrapping_sub(b) as i32) > 0
}

/// The newest whole record older than `before` (all if `None`), with where it is; `ours_only`
/// skips other tables' records. Of two with the same sequence number, the one in the lower
/// sector and slot. Whole records are at most `2 · SLOTS` consecutive numbers apart (every save
/// numbers its snapshot after the newest whole record), so "newest" is an order among them.
fn newest_record(sectors: [&[u32]; 2], before: Option<u32>, ours_only: bool) -> Option<(Record, Location)> {
    // The CRC of every slot is the cost of a boot and of a save's plan, so the record with the
    // newest number among those that begin with the magic word is checked first: when it is
    // whole, as it nearly always is, no other record can win and none costs a CRC below.
    let mut likely: Option<(u32, usize, usize)> = None;
    for (s, words) in sectors.iter().enumerate() {
        for k in 0..SLOTS {
            if let [MAGIC, seq, ..] = *slot(words, k) {
                if before.is_none_or(|b| is_newer(b, seq)) && likely.is_none_or(|(l, _, _)| is_newer(seq, l)) {
                    likely = Some((seq, s, k));
                }
            }
        }
    }
    // Then every slot, the likely one first (0: it, if any; n > 0: slot n - 1 in order).
    let mut best: Option<(Record, Location)> = None;
    for n in 0..=2 * SLOTS {
        let (s, k) = match (n, likely) {
            (0, Some((_, s, k))) => (s, k),
            (0, None) => continue,
            _ => ((n - 1) / SLOTS, (n - 1) % SLOTS),
        };
        let words = sectors.get(s).copied().unwrap_or(&[]);
        // The sequence word first: a record that could not win costs no CRC. Of two with one
        // number, the lower place wins.
        let Some(&seq) = slot(words, k).get(SEQ) else { continue };
        let wins =
            best.as_ref().is_none_or(|(r, at)| is_newer(seq, r.sequence()) || (seq == r.sequence() && (s, k) < (at.sector, at.slot)));
        if !(before.is_none_or(|b| is_newer(b, seq)) && wins) {
            continue;
        }
        match inspect(from_slot(words, k)) {
            Some(Record::OtherTable { .. }) if ours_only => {}
            Some(r) => best = Some((r, Location { sector: s, slot: k })),
            None => {}
        }
    }
    best
}

/// The newest valid snapshot in the two sectors, and where it is.
pub fn newest(sectors: [&[u32]; 2]) -> Option<(Snapshot, Location)> {
    match newest_record(sectors, None, true)? {
        (Record::Ours(s), at) => Some((s, at)),
        (Record::OtherTable { .. }, _) => None,
    }
}

/// The newest valid snapshot (see [`newest`]).
pub fn load(sectors: [&[u32]; 2]) -> Option<Snapshot> {
    newest(sectors).map(|(s, _)| s)
}

/// Why a whole snapshot was not loaded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Why {
    /// Its values break a rule: `parameter` when one value (off its bounds or step, or a
    /// radio map entry another already has) is at fault, else the whole set's rule.
    Rule { parameter: Option<&'static str>, rule: &'static str },
    /// Saved by a firmware with another parameter table.
    OtherTable,
}

/// A snapshot passed over at boot: its sequence number and why.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PassedOver {
    pub sequence: u32,
    pub why: Why,
}

/// Where the configuration at boot came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    /// The snapshot with this sequence number: the newest whole one that makes a valid
    /// configuration. `passed_over`: the newest of the newer ones refused, and why.
    Snapshot { sequence: u32, passed_over: Option<PassedOver> },
    /// No whole snapshot of this firmware's table: the defaults.
    NoSnapshot,
    /// Every snapshot of this table refused (the newest's rule): the defaults.
    Refused(&'static str),
}

/// The longest text [`Source::describe`] writes, bytes.
pub const DESCRIBE_LEN: usize = 150;

impl Source {
    /// Where the parameters in force came from, for a `STATUSTEXT` (at most [`DESCRIBE_LEN`]
    /// bytes: longer than one message's 50, the link sends it in chunks), e.g. `parameters
    /// loaded from flash (snapshot 12); newer snapshot 13 refused: RC1_TRIM: above the
    /// maximum`.
    pub fn describe<const N: usize>(&self, out: &mut fcu_core::telemetry::LineBuf<N>) {
        match self {
            Source::Snapshot { sequence, passed_over } => {
                out.push_str("parameters loaded from flash (snapshot ");
                out.push_uint(*sequence);
                out.push_str(")");
                if let Some(p) = passed_over {
                    out.push_str("; newer snapshot ");
                    out.push_uint(p.sequence);
                    out.push_str(" refused: ");
                    match p.why {
                        Why::Rule { parameter, rule } => {
                            if let Some(name) = parameter {
                                out.push_str(name);
                                out.push_str(": ");
                            }
                            out.push_str(rule);
                        }
                        Why::OtherTable => out.push_str("saved by a firmware with another parameter table"),
                    }
                }
            }
            Source::NoSnapshot => out.push_str("no saved parameters: defaults"),
            Source::Refused(rule) => {
                out.push_str("saved parameters refused (");
                out.push_str(rule);
                out.push_str("): defaults");
            }
        }
    }
}

/// The configuration to boot with: `defaults` with the newest whole snapshot's values that
/// make a valid configuration, or `defaults` alone (and why), never a mix. A newer snapshot
/// refused (its values break a rule, or another firmware's table) falls back to the older
/// one, and [`Source`] names the refused one.
pub fn load_config(sectors: [&[u32]; 2], defaults: &fcu_core::Config) -> (fcu_core::Config, Source) {
    let mut before = None;
    let mut passed_over: Option<PassedOver> = None;
    let mut newest_rule = None;
    // Each round passes over one record: at most every slot of both sectors.
    for _ in 0..=2 * SLOTS {
        let Some((record, _)) = newest_record(sectors, before, false) else { break };
        let sequence = record.sequence();
        before = Some(sequence);
        let why = match record {
            Record::Ours(s) => match super::with_values_at(defaults, &s.values) {
                Ok(cfg) => return (cfg, Source::Snapshot { sequence, passed_over }),
                Err((index, rule)) => {
                    newest_rule.get_or_insert(rule);
                    Why::Rule { parameter: index.and_then(super::name), rule }
                }
            },
            Record::OtherTable { .. } => Why::OtherTable,
        };
        passed_over.get_or_insert(PassedOver { sequence, why });
    }
    match newest_rule {
        Some(rule) => (*defaults, Source::Refused(rule)),
        None => (*defaults, Source::NoSnapshot),
    }
}

/// How to save `values` as the newest snapshot.
pub fn plan_save(sectors: [&[u32]; 2], values: &[f32; COUNT]) -> SavePlan {
    let found = newest(sectors);
    // After the newest whole record of any table: a snapshot another firmware saved later
    // stays older than this one.
    let sequence = newest_record(sectors, None, false).map_or(1, |(r, _)| r.sequence().wrapping_add(1));
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

/// Words that are all erased flash (and at least one).
fn erased(words: &[u32]) -> bool {
    !words.is_empty() && words.iter().all(|&w| w == ERASED)
}

#[cfg(test)]
mod tests;
