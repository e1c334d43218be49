//! Against an in-RAM model of two 16 KB sectors, with power cuts at every word.

use super::*;
use std::vec::Vec;

/// Two sectors of flash: programming clears bits, erasing sets them.
#[derive(Clone, Debug, PartialEq)]
struct Flash {
    sectors: [Vec<u32>; 2],
}

/// Where the power goes: after `steps` whole words (erase words first, then programmed
/// ones), with the next word left partly done: `partial` are the bits of the change that
/// did happen (a word being programmed has only these of its zeros cleared, a word being
/// erased only these of its zeros set).
#[derive(Clone, Copy, Debug)]
struct Cut {
    steps: usize,
    partial: u32,
}

impl Flash {
    fn erased() -> Flash {
        Flash { sectors: [std::vec![ERASED; SECTOR_WORDS], std::vec![ERASED; SECTOR_WORDS]] }
    }

    fn view(&self) -> [&[u32]; 2] {
        [&self.sectors[0], &self.sectors[1]]
    }

    /// Carry out `plan`, up to `cut` if given. Returns whether it ran to the end.
    fn run(&mut self, plan: &SavePlan, cut: Option<Cut>) -> bool {
        let mut steps = 0;
        let mut budget = |word: &mut u32, target: u32| -> bool {
            match cut {
                Some(c) if steps == c.steps => {
                    // Only the bits that were to change, and of those only `partial`.
                    let changing = *word ^ target;
                    *word ^= changing & c.partial;
                    false
                }
                _ => {
                    *word = target;
                    steps += 1;
                    true
                }
            }
        };
        if let Some(s) = plan.erase {
            for w in self.sectors[s].iter_mut() {
                let old = *w;
                if !budget(w, ERASED) {
                    return false;
                }
                debug_assert!(old | *w == ERASED);
            }
        }
        for (i, &t) in plan.words.iter().enumerate() {
            let w = &mut self.sectors[plan.sector][plan.first_word + i];
            // Programming can only clear bits: the plan must target erased words.
            assert_eq!(*w, ERASED, "programming a word that is not erased");
            if !budget(w, t) {
                return false;
            }
        }
        true
    }

    fn save(&mut self, values: &[f32; COUNT]) -> SavePlan {
        let plan = plan_save(self.view(), values);
        assert!(self.run(&plan, None));
        plan
    }

    fn steps(plan: &SavePlan) -> usize {
        plan.erase.map_or(0, |_| SECTOR_WORDS) + RECORD_WORDS
    }
}

/// A parameter set that differs from `values(n - 1)` in every value.
fn values(n: u32) -> [f32; COUNT] {
    core::array::from_fn(|i| n as f32 * 1000.0 + i as f32)
}

#[test]
fn a_snapshot_reads_back_and_its_crc_is_zlibs() {
    // The check value of CRC-32/ISO-HDLC: "123456789" -> 0xCBF43926 (as words: "1234",
    // "5678" and then only whole words, so check the 8-byte prefix against a known value).
    assert_eq!(crc32(&[]), 0);
    assert_eq!(crc32(&[u32::from_le_bytes(*b"1234"), u32::from_le_bytes(*b"5678")]), 0x9AE0_DAAF);
    let w = encode(7, &values(3));
    assert_eq!(decode(&w), Some(Snapshot { sequence: 7, values: values(3) }));
    assert_eq!(w[0], MAGIC);
    assert_eq!(w[RECORD_WORDS - 1], COMMIT);
    // Tens of saves per erase of a sector (62 with the 60 parameters).
    const { assert!(SLOTS >= 60) };
}

#[test]
fn a_snapshot_with_any_word_wrong_is_not_read() {
    let good = encode(7, &values(3));
    for i in 0..RECORD_WORDS {
        for flip in [1u32, 0x8000_0000, 0x0001_0000] {
            let mut w = good;
            w[i] ^= flip;
            assert_eq!(decode(&w), None, "word {i} flipped by {flip:#x}");
        }
    }
    // Another table: same words, another layout hash (with a CRC that matches it).
    let mut other = good;
    other[2] ^= 1;
    other[RECORD_WORDS - 2] = crc32(&other[..RECORD_WORDS - 2]);
    assert_eq!(decode(&other), None);
    let mut fixed = good;
    fixed[RECORD_WORDS - 2] = crc32(&fixed[..RECORD_WORDS - 2]);
    assert!(decode(&fixed).is_some());
    assert_eq!(decode(&good[..RECORD_WORDS - 1]), None);
}

#[test]
fn saves_rotate_through_both_sectors_and_the_newest_loads() {
    let mut f = Flash::erased();
    assert_eq!(load(f.view()), None);
    let mut erases = 0;
    for n in 1..=(3 * SLOTS as u32 + 5) {
        let plan = f.save(&values(n));
        erases += usize::from(plan.erase.is_some());
        let got = load(f.view()).expect("a snapshot");
        assert_eq!(got, Snapshot { sequence: n, values: values(n) });
        // The sector only changes when one is full: an erase every SLOTS saves, the first
        // two sectors found erased.
        let k = n as usize - 1;
        assert_eq!(plan.sector, (k / SLOTS) % 2, "save {n}");
        assert_eq!(plan.first_word, (k % SLOTS) * RECORD_WORDS);
    }
    assert_eq!(erases, 2);
}

#[test]
fn a_sector_holding_old_code_is_erased_before_the_first_save() {
    let mut f = Flash::erased();
    for (i, w) in f.sectors[0].iter_mut().enumerate() {
        *w = (i as u32).wrapping_mul(0x9E37_79B9);
    }
    assert_eq!(load(f.view()), None);
    let plan = f.save(&values(1));
    assert_eq!((plan.erase, plan.sector, plan.first_word), (Some(0), 0, 0));
    assert_eq!(load(f.view()).map(|s| s.values), Some(values(1)));
}

/// Partly done words: a few patterns of which of a word's changing bits happened.
const PARTIALS: [u32; 4] = [0, 0x0000_FFFF, 0xFFFF_0000, 0x5A5A_A5A5];

/// Cut the save of `values(n)` on `before` at every word, with every partial pattern: the
/// loaded set is the old or the new one, and a save after the cut loads.
fn every_cut(before: &Flash, n: u32) {
    let old = load(before.view());
    let plan = plan_save(before.view(), &values(n));
    let total = Flash::steps(&plan);
    let erase_steps = total - RECORD_WORDS;
    let mut cuts = 0;
    for steps in 0..total {
        // Every pattern in the program; two in the erase (its words outnumber the program's 70 to 1).
        let partials = if steps < erase_steps { &PARTIALS[..2] } else { &PARTIALS[..] };
        for &partial in partials {
            let mut f = before.clone();
            assert!(!f.run(&plan, Some(Cut { steps, partial })));
            let got = load(f.view());
            let new = Some(Snapshot { sequence: old.map_or(1, |s| s.sequence + 1), values: values(n) });
            let commit_done = steps + 1 == total && f.sectors[plan.sector][plan.first_word + RECORD_WORDS - 1] == COMMIT;
            if commit_done {
                assert_eq!(got, new);
            } else {
                // The commit word not complete: the old set, never a mix.
                assert_eq!(got, old, "cut at step {steps} of {total}, partial {partial:#x}");
            }
            // The next save after the cut goes through and loads.
            f.save(&values(n + 1));
            assert_eq!(load(f.view()).map(|s| s.values), Some(values(n + 1)), "after cut at {steps}");
            cuts += 1;
        }
    }
    assert!(cuts >= RECORD_WORDS * PARTIALS.len() + erase_steps * 2);
}

#[test]
fn a_power_cut_at_any_word_of_a_save_leaves_the_old_set() {
    // A save within a sector.
    let mut f = Flash::erased();
    for n in 1..=3 {
        f.save(&values(n));
    }
    every_cut(&f, 4);
    // The very first save.
    every_cut(&Flash::erased(), 1);
}

#[test]
fn a_power_cut_at_any_word_of_the_erase_that_rotates_leaves_the_old_set() {
    // The first sector full and the second holding an older generation: the next save
    // erases the first. Cut at every word of the erase and of the program that follows.
    let mut f = Flash::erased();
    for n in 1..=(2 * SLOTS as u32) {
        f.save(&values(n));
    }
    let plan = plan_save(f.view(), &values(0));
    assert_eq!((plan.erase, plan.sector), (Some(0), 0));
    every_cut(&f, 2 * SLOTS as u32 + 1);
}

#[test]
fn the_commit_word_completes_the_snapshot() {
    // The last step of a save: with the commit word whole, the new set; cut inside it (any
    // of its bits still set), the old.
    let mut f = Flash::erased();
    f.save(&values(1));
    let plan = plan_save(f.view(), &values(2));
    let mut whole = f.clone();
    assert!(whole.run(&plan, None));
    assert_eq!(load(whole.view()).map(|s| s.values), Some(values(2)));
    for bit in (0..32).filter(|b| COMMIT & (1 << b) == 0) {
        let mut g = f.clone();
        // Every changing bit done but one.
        g.run(&plan, Some(Cut { steps: RECORD_WORDS - 1, partial: !(1 << bit) }));
        assert_eq!(load(g.view()).map(|s| s.values), Some(values(1)), "bit {bit}");
    }
}

#[test]
fn a_snapshot_of_another_table_is_not_loaded() {
    let mut f = Flash::erased();
    f.save(&values(1));
    // Rewrite the newest as another firmware would: another layout hash, a valid CRC.
    let mut w = encode(2, &values(2));
    w[2] = LAYOUT_HASH ^ 0x100;
    w[RECORD_WORDS - 2] = crc32(&w[..RECORD_WORDS - 2]);
    f.sectors[0][RECORD_WORDS..2 * RECORD_WORDS].copy_from_slice(&w);
    assert_eq!(load(f.view()).map(|s| s.sequence), Some(1));
}

#[test]
fn boot_takes_the_newest_set_or_the_defaults_and_says_which() {
    let defaults = fcu_core::Config::default();
    let mut f = Flash::erased();
    assert_eq!(load_config(f.view(), &defaults), (defaults, Source::NoSnapshot));
    // A tune saved: it comes back whole.
    let mut tuned = defaults;
    let i = crate::index_of(b"RATE_RLL_P").unwrap();
    crate::set(&mut tuned, i, 250.0, false).unwrap();
    f.save(&crate::values(&tuned));
    assert_eq!(load_config(f.view(), &defaults), (tuned, Source::Snapshot { sequence: 1, passed_over: None }));
    // A set whose values are this table's but do not validate: the defaults, and the rule.
    let mut bad = crate::values(&defaults);
    bad[crate::index_of(b"RC1_TRIM").unwrap()] = 2400.0;
    f.save(&bad);
    let (cfg, source) = load_config(f.view(), &defaults);
    // The newer set is refused: the older one loads, and the refusal is named in full.
    let passed_over = Some(PassedOver { sequence: 2, why: Why::Rule { parameter: None, rule: "RCn: need MIN <= TRIM <= MAX" } });
    assert_eq!((cfg, source), (tuned, Source::Snapshot { sequence: 1, passed_over }));
    // With no older one, the defaults and the rule.
    let mut only_bad = Flash::erased();
    only_bad.save(&bad);
    assert_eq!(load_config(only_bad.view(), &defaults), (defaults, Source::Refused("RCn: need MIN <= TRIM <= MAX")));
}

/// `defaults`' values with `name` set to `v`, unchecked.
fn values_with(name: &str, v: f32) -> [f32; COUNT] {
    let mut values = crate::values(&fcu_core::Config::default());
    values[crate::index_of(name.as_bytes()).unwrap()] = v;
    values
}

fn describe(source: &Source) -> std::string::String {
    let mut line = fcu_core::telemetry::LineBuf::<{ DESCRIBE_LEN }>::new();
    source.describe(&mut line);
    assert!(!line.is_truncated());
    line.as_str().into()
}

#[test]
fn a_newest_snapshot_refused_falls_back_to_the_older_one_and_says_why() {
    let defaults = fcu_core::Config::default();
    let tuned = values_with("RATE_RLL_P", 250.0);
    let tuned_cfg = crate::with_values(&defaults, &tuned).unwrap();
    // A value above its maximum (as ANGLE_MAX 60 read back as 60.000004 was saved).
    let mut f = Flash::erased();
    f.save(&tuned);
    f.save(&values_with("ANGLE_MAX", 60.000_004));
    let (cfg, source) = load_config(f.view(), &defaults);
    assert_eq!(cfg, tuned_cfg);
    assert_eq!(describe(&source), "parameters loaded from flash (snapshot 1); newer snapshot 2 refused: ANGLE_MAX: above the maximum");
    // A radio map that is no permutation: refused, not loaded rearranged.
    let mut f = Flash::erased();
    f.save(&tuned);
    f.save(&values_with("RCMAP_ROLL", 2.0));
    let (cfg, source) = load_config(f.view(), &defaults);
    assert_eq!(cfg, tuned_cfg);
    assert_eq!(
        describe(&source),
        "parameters loaded from flash (snapshot 1); newer snapshot 2 refused: RCMAP_PITCH: RCMAP: each input once"
    );
    // A newer firmware's snapshot (another table, whole): passed over, and the next save
    // numbered after it.
    let mut f = Flash::erased();
    f.save(&tuned);
    let mut w = encode(2, &values(2));
    w[2] = LAYOUT_HASH ^ 0x100;
    w[RECORD_WORDS - 2] = crc32(&w[..RECORD_WORDS - 2]);
    f.sectors[0][RECORD_WORDS..2 * RECORD_WORDS].copy_from_slice(&w);
    let (cfg, source) = load_config(f.view(), &defaults);
    assert_eq!(cfg, tuned_cfg);
    assert_eq!(
        describe(&source),
        "parameters loaded from flash (snapshot 1); newer snapshot 2 refused: saved by a firmware with another parameter table"
    );
    assert_eq!(decode(&f.save(&tuned).words).map(|s| s.sequence), Some(3));
    assert_eq!(load_config(f.view(), &defaults).1, Source::Snapshot { sequence: 3, passed_over: None });
    // The other sources' texts.
    assert_eq!(describe(&Source::NoSnapshot), "no saved parameters: defaults");
    assert_eq!(describe(&Source::Refused("RCMAP: each input once")), "saved parameters refused (RCMAP: each input once): defaults");
}

#[test]
fn every_description_fits_its_length() {
    let mut longest = 0;
    for i in 0..COUNT {
        let name = crate::name(i).unwrap();
        let source = Source::Snapshot {
            sequence: u32::MAX,
            passed_over: Some(PassedOver { sequence: u32::MAX, why: Why::Rule { parameter: Some(name), rule: "x".repeat(32).leak() } }),
        };
        longest = longest.max(describe(&source).len());
    }
    assert!(longest <= DESCRIBE_LEN, "{longest}");
}

#[test]
fn sequence_numbers_wrap_across_both_sectors() {
    // From a snapshot numbered 0xFFFF_FFFF on, each save must load: the next is 0, which
    // compared as a plain number would lose to 0xFFFF_FFFF, and both saves be lost.
    let mut f = Flash::erased();
    let first = encode(u32::MAX, &values(1));
    f.sectors[0][..RECORD_WORDS].copy_from_slice(&first);
    for n in 2..=(2 * SLOTS as u32 + 3) {
        f.save(&values(n));
        let got = load(f.view()).expect("a snapshot");
        assert_eq!(got, Snapshot { sequence: n - 2, values: values(n) }, "save {n}");
    }
    // And with the wrap in the middle of the second sector.
    let mut f = Flash::erased();
    f.sectors[1][..RECORD_WORDS].copy_from_slice(&encode(u32::MAX - 10, &values(1)));
    for n in 2..=(SLOTS as u32 + 20) {
        f.save(&values(n));
        assert_eq!(load(f.view()).map(|s| s.values), Some(values(n)), "save {n}");
    }
    assert!(is_newer(0, u32::MAX) && !is_newer(u32::MAX, 0) && is_newer(5, 3) && !is_newer(3, 3));
}

/// The plain scan [`newest_record`] shortens: every slot in order, the CRC of every one that
/// could win, strictly newer to replace (so the lower place keeps a tie).
fn newest_record_by_plain_scan(sectors: [&[u32]; 2], before: Option<u32>, ours_only: bool) -> Option<(Record, Location)> {
    let mut best: Option<(Record, Location)> = None;
    for (s, words) in sectors.iter().enumerate() {
        for k in 0..SLOTS {
            let Some(&seq) = slot(words, k).get(SEQ) else { continue };
            if !(before.is_none_or(|b| is_newer(b, seq)) && best.is_none_or(|(r, _)| is_newer(seq, r.sequence()))) {
                continue;
            }
            match inspect(from_slot(words, k)) {
                Some(Record::OtherTable { .. }) if ours_only => {}
                Some(r) => best = Some((r, Location { sector: s, slot: k })),
                None => {}
            }
        }
    }
    best
}

/// The record with the newest number is checked first, to spare the CRC of every other slot
/// (a third of the bench's time went to those CRCs at every boot): over flashes holding whole,
/// torn, corrupted, repeated and other tables' records, numbered within a window of
/// consecutive numbers across the wrap as saves number them, the answer is the plain scan's.
#[test]
fn the_newest_record_is_the_plain_scans_on_any_flash() {
    let mut rng = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move |n: u64| {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        rng % n
    };
    for trial in 0..400 {
        let mut f = Flash::erased();
        let base = [0u32, u32::MAX - 40, 7_000][trial % 3];
        for _ in 0..next(2 * SLOTS as u64 + 1) {
            let seq = base.wrapping_add(next(2 * SLOTS as u64) as u32);
            let mut w = encode(seq, &values(seq % 50));
            match next(6) {
                0 => w[VALUES + 3] ^= 1,
                1 => w[COMMIT_AT] = ERASED,
                2 => {
                    w[HASH] = LAYOUT_HASH ^ 0x100;
                    w[CRC] = crc32(&w[..CRC]);
                }
                _ => {}
            }
            let (s, k) = (next(2) as usize, next(SLOTS as u64) as usize);
            f.sectors[s][k * RECORD_WORDS..(k + 1) * RECORD_WORDS].copy_from_slice(&w);
        }
        let view = f.view();
        for before in [None, Some(base.wrapping_add(next(2 * SLOTS as u64) as u32))] {
            for ours_only in [false, true] {
                assert_eq!(
                    newest_record(view, before, ours_only),
                    newest_record_by_plain_scan(view, before, ours_only),
                    "trial {trial}, before {before:?}, ours only {ours_only}"
                );
            }
        }
    }
}
