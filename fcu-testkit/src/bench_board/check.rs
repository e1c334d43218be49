//! The bench's invariants, checked from outside the board: what the ground station sent and
//! read back, what the flash holds, what the control loop shows and what the pilot did.
//!
//! The ground station's view of the parameters (`model`) starts from what the board loaded and
//! changes only by what the board confirmed: a PARAM_VALUE carrying a value a PARAM_SET asked
//! for (applied to the model with fcu-core's table rules, so a set that moves another
//! parameter moves it there too), and a PREFLIGHT_STORAGE reset acknowledged as accepted. The
//! board takes sets in the order they came, by the rules in force when its link task received
//! them (armed or not): a set confirmed means the sets before it were taken or refused first.
//! Each report shows the board where the one before it did or later, and the model goes no
//! further through the pending sets than a report needs. An
//! answer the transmit queue dropped, or owed and folded into a later one, is caught up with
//! when the value shows up later (a report, a save, a load).

use std::collections::VecDeque;

use fcu_core::Config;
use fcu_params::snapshot::{self, SavePlan, RECORD_WORDS};
use fcu_params::{self as parameters, COUNT};

use super::board::TICK_US;
use super::flash::Flash;
use super::gcs::{cmd, Answer, GcsFrame};

/// The rules the bench holds the board to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Invariant {
    /// No reset, flash erase or program, calibration or motor test starts while armed
    /// (arming, armed or the failsafe's level stage).
    NothingStartsArmed,
    /// The board arms only after the pilot held the arm gesture for the hold time.
    ArmedOnlyByGesture,
    /// A value the board accepted (echoed for a PARAM_SET) is the value it reports, saves and
    /// loads after a reboot; the board's output is whole frames.
    AcceptedIsReportedSavedLoaded,
    /// After a power cut the loaded set is one that was in force as a whole at some point.
    PowerCutLoadsAWholeSet,
    /// A saved set that a rule refuses falls back to the newest saved set still valid.
    RefusedSnapshotFallsBack,
    /// No save or erase raises a sensor fault or makes the loop miss its data.
    SavesKeepTheLoopRunning,
}

/// A broken invariant: which, when (bench time), and what was seen.
#[derive(Clone, Debug, PartialEq)]
pub struct Violation {
    pub invariant: Invariant,
    pub at_ms: u64,
    pub what: String,
}

impl std::fmt::Display for Violation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:?} at {} ms: {}", self.invariant, self.at_ms, self.what)
    }
}

/// Why the board booted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BootKind {
    First,
    /// A reset the firmware decided (a reboot command).
    Reset,
    PowerCut,
}

/// A snapshot written whole, in the order written.
#[derive(Clone, Debug)]
struct Written {
    sector: usize,
    first_word: usize,
    words: [u32; RECORD_WORDS],
    values: [f32; COUNT],
    /// Saved by the board on the bench (not found in flash at the start).
    by_board: bool,
}

fn bits(values: &[f32; COUNT]) -> [u32; COUNT] {
    values.map(f32::to_bits)
}

fn name(i: usize) -> &'static str {
    parameters::name(i).unwrap_or("?")
}

/// The first parameter that differs between two sets, for a message.
fn first_difference(a: &[f32; COUNT], b: &[f32; COUNT]) -> String {
    match (0..COUNT).find(|&i| a[i].to_bits() != b[i].to_bits()) {
        Some(i) => format!("{} = {} against {}", name(i), a[i], b[i]),
        None => "no difference".into(),
    }
}

/// Control ticks as milliseconds of bench time.
pub(crate) fn ms(ticks: u64) -> u64 {
    ticks * u64::from(TICK_US) / 1000
}

/// A frame the ground station sent, for a trace.
fn describe(frame: &GcsFrame) -> String {
    match frame {
        GcsFrame::ParamSet { name: n, value } => match parameters::index_of(n) {
            Some(i) => format!("PARAM_SET {} = {value}", name(i)),
            None => format!("PARAM_SET (unknown) = {value}"),
        },
        other => format!("{other:?}"),
    }
}

/// A PARAM_SET the ground station sent and has not seen confirmed yet.
#[derive(Clone, Copy, Debug)]
struct PendingSet {
    index: usize,
    value: f32,
    /// Where its frame starts and ends in the bytes sent.
    start: u64,
    end: u64,
    /// Whether changes were restricted (armed) when the board's link task received the whole
    /// frame; `None` while it has not.
    restricted: Option<bool>,
}

impl PendingSet {
    /// `cfg` as the board leaves it taking this set, or `None` when the table refuses it.
    fn taken(&self, cfg: &Config) -> Option<Config> {
        let mut next = *cfg;
        parameters::set(&mut next, self.index, self.value, self.restricted.unwrap_or(false)).ok().map(|_| next)
    }

    fn asks(&self, i: usize, value: f32) -> bool {
        self.index == i && self.value.to_bits() == value.to_bits()
    }
}

/// A PREFLIGHT_STORAGE command sent and not acknowledged yet.
#[derive(Clone, Copy, Debug)]
struct PendingStorage {
    param1: f32,
    /// Where its frame starts and ends in what the ground station sent.
    start: u64,
    end: u64,
    /// A reset already seen done (in a save ahead of its acknowledgement).
    seen_done: bool,
    /// Whether changes were restricted when the board received it (`None`: not yet received).
    restricted: Option<bool>,
    /// A command sent after it was answered: the board answers in the order it received, so
    /// this one's answer was dropped (the transmit queue had no room) and no later answer is
    /// its. A reset stays pending for what it may explain (its frame may also have been lost
    /// in a receive ring that overflowed, so it is not taken at once).
    answer_dropped: bool,
}

/// A command other than PREFLIGHT_STORAGE sent and not acknowledged yet: where its frame starts.
#[derive(Clone, Copy, Debug)]
struct PendingCommand {
    command: u16,
    start: u64,
}

impl PendingStorage {
    fn is_reset(&self) -> bool {
        self.param1 == 2.0
    }

    /// Whether the board's answer to it can have this result: MAV_RESULT_UNSUPPORTED for a
    /// param1 other than save (1) and reset (2); for those, TEMPORARILY_REJECTED while changes
    /// are restricted, else ACCEPTED (or a failure).
    fn can_answer(&self, result: u8) -> bool {
        const ACCEPTED: u8 = 0;
        const TEMPORARILY_REJECTED: u8 = 1;
        const UNSUPPORTED: u8 = 3;
        let known = self.param1 == 1.0 || self.param1 == 2.0;
        match result {
            UNSUPPORTED => !known,
            ACCEPTED => known && self.restricted != Some(true),
            TEMPORARILY_REJECTED => known && self.restricted != Some(false),
            _ => known,
        }
    }
}

/// Keeps at most this many violations of each invariant.
const KEEP: usize = 4;

#[derive(Clone)]
pub struct Checker {
    defaults: &'static Config,
    model: Config,
    /// PARAM_SETs sent and not confirmed yet, in the order sent.
    pending_sets: Vec<PendingSet>,
    /// PREFLIGHT_STORAGE commands sent and not acknowledged yet, in the order sent.
    pending_storage: VecDeque<PendingStorage>,
    /// The other commands sent and not acknowledged yet, in the order sent: their answers
    /// tell which storage answers were dropped.
    pending_commands: VecDeque<PendingCommand>,
    /// Bytes the ground station sent.
    sent_bytes: u64,
    /// Values replaced by a set seen in a save or a load before its answer: (index, bits).
    stale: Vec<(usize, u32)>,
    /// Every set that was in force as a whole, as bits.
    history: Vec<[u32; COUNT]>,
    written: Vec<Written>,
    violations: Vec<Violation>,
    /// Sets the board confirmed.
    pub accepted_sets: u32,
    /// Prints every event the checker sees, and its model's verdicts, to stderr (for replaying
    /// a fuzz input: `cargo run -p fcu-testkit --example boundaries_replay`).
    pub trace: bool,
}

impl Checker {
    pub fn new(defaults: &'static Config) -> Checker {
        Checker {
            defaults,
            model: *defaults,
            pending_sets: Vec::new(),
            pending_storage: VecDeque::new(),
            pending_commands: VecDeque::new(),
            sent_bytes: 0,
            stale: Vec::new(),
            history: vec![bits(&parameters::values(defaults))],
            written: Vec::new(),
            violations: Vec::new(),
            accepted_sets: 0,
            trace: false,
        }
    }

    pub fn violations(&self) -> &[Violation] {
        &self.violations
    }

    /// The first violation of `invariant`.
    pub fn first(&self, invariant: Invariant) -> Option<&Violation> {
        self.violations.iter().find(|v| v.invariant == invariant)
    }

    pub fn violate(&mut self, invariant: Invariant, at_ticks: u64, what: String) {
        if self.trace {
            eprintln!("{:>6} ms VIOLATION {invariant:?}: {what}", ms(at_ticks));
        }
        if self.violations.iter().filter(|v| v.invariant == invariant).count() < KEEP {
            self.violations.push(Violation { invariant, at_ms: ms(at_ticks), what });
        }
    }

    fn remember(&mut self, values: &[f32; COUNT]) {
        let b = bits(values);
        if self.history.last() != Some(&b) && !self.history.contains(&b) {
            self.history.push(b);
        }
    }

    /// The snapshots already in flash at the start, oldest first (by sequence: a history
    /// planted on the bench has no wrap), were each in force on the board that saved them.
    pub fn on_flash_history(&mut self, flash: &Flash) {
        let mut found = Vec::new();
        for (s, words) in flash.sectors().iter().enumerate() {
            for k in 0..snapshot::SLOTS {
                let at = k * RECORD_WORDS;
                if let Some(snap) = snapshot::decode(&words[at..at + RECORD_WORDS]) {
                    let mut w = [0u32; RECORD_WORDS];
                    w.copy_from_slice(&words[at..at + RECORD_WORDS]);
                    found.push((snap.sequence, Written { sector: s, first_word: at, words: w, values: snap.values, by_board: false }));
                }
            }
        }
        found.sort_by_key(|(seq, _)| *seq);
        for (_, w) in found {
            self.remember(&w.values);
            self.written.push(w);
        }
    }

    /// A frame the ground station sent, `bytes` long.
    pub fn on_sent(&mut self, frame: &GcsFrame, bytes: usize) {
        let at = self.sent_bytes;
        self.sent_bytes += bytes as u64;
        if self.trace && !matches!(frame, GcsFrame::ParamRead { .. }) {
            eprintln!("          sent @{at}: {}", describe(frame));
        }
        match *frame {
            GcsFrame::ParamSet { name, value } => {
                if let Some(i) = parameters::index_of(&name) {
                    self.pending_sets.push(PendingSet { index: i, value, start: at, end: self.sent_bytes, restricted: None });
                }
            }
            GcsFrame::Command { command: cmd::PREFLIGHT_STORAGE, params, .. } => self.pending_storage.push_back(PendingStorage {
                param1: params[0],
                start: at,
                end: self.sent_bytes,
                seen_done: false,
                restricted: None,
                answer_dropped: false,
            }),
            GcsFrame::Command { command, .. } => self.pending_commands.push_back(PendingCommand { command, start: at }),
            _ => {}
        }
    }

    /// The board's link task received the first `delivered` bytes the ground station sent,
    /// with changes restricted or not (armed, as the status it last observed says): it took or
    /// refused every PARAM_SET among them by the rules in force then.
    pub fn on_received(&mut self, delivered: u64, restricted: bool) {
        for cmd in self.pending_storage.iter_mut().filter(|c| c.end <= delivered && c.restricted.is_none()) {
            cmd.restricted = Some(restricted);
        }
        for set in self.pending_sets.iter_mut().filter(|s| s.end <= delivered && s.restricted.is_none()) {
            set.restricted = Some(restricted);
            if self.trace {
                eprintln!("          received @{}: PARAM_SET {} = {}, restricted {restricted}", set.start, name(set.index), set.value);
            }
        }
    }

    /// The board confirmed the pending set at `pos` (its answer, a value only it explains, a
    /// save or a load showing it). It took the sets before it first, in the order they came,
    /// each changing the parameters as the table has it (a refused one nothing): their side
    /// effects stand (an RCMAP set swaps another channel, which a later set does not undo), and
    /// their answers went out or were folded into later ones (an answer the transmit queue has
    /// no room for is owed, and carries the value in force when it goes). `ahead` when this
    /// showed in a save or a load before the answers queued ahead of it went out (the link goes
    /// quiet before a save or a reboot): those may still report any value it replaced on the way.
    /// False when the table refuses the set at `pos` (a violation).
    fn take_through(&mut self, pos: usize, ahead: bool, at: u64) -> bool {
        self.pass(pos, ahead);
        if self.pending_sets.is_empty() {
            return true;
        }
        let last = self.pending_sets.remove(0);
        self.reset_before(last.start, ahead);
        let taken = match last.taken(&self.model) {
            Some(next) => {
                self.step_to(next, ahead);
                true
            }
            None => {
                // The reason, as the table gives it.
                let mut next = self.model;
                let rule =
                    parameters::set(&mut next, last.index, last.value, last.restricted.unwrap_or(false)).err().map_or("", |r| r.rule);
                self.violate(
                    Invariant::AcceptedIsReportedSavedLoaded,
                    at,
                    format!("the board took {} = {}, which the table refuses in the set it reported: {rule}", name(last.index), last.value),
                );
                false
            }
        };
        self.accepted_sets += 1;
        taken
    }

    /// The first `count` pending sets, as the board took them: each changes the model when the
    /// table takes it; `ahead` as in [`Checker::take_through`].
    fn pass(&mut self, count: usize, ahead: bool) {
        let end = count.min(self.pending_sets.len());
        let passed: Vec<PendingSet> = self.pending_sets.drain(..end).collect();
        for set in passed {
            self.reset_before(set.start, ahead);
            if let Some(next) = set.taken(&self.model) {
                self.step_to(next, ahead);
            }
        }
    }

    /// A set sent from byte `start` is being taken: the board takes the frames in the order
    /// they came, so a reset of the parameters sent before it was taken first, whatever its
    /// acknowledgement has not shown yet (the sets before the reset were taken before this
    /// one). Without it, a save that shows the set, and that the set alone explains (the model
    /// at the defaults already), left the reset pending, and its acknowledgement wiped the set.
    fn reset_before(&mut self, start: u64, ahead: bool) {
        self.take_resets(|e| e.start < start, ahead);
    }

    /// Every set the board received so far, taken in order with each reset among them where
    /// it came, and a reset received after the last of them (taken disarmed): what the board's
    /// link periods did before it saved or rebooted, each taking every frame received. A
    /// reset's acknowledgement may have died with the reboot.
    fn take_every_received(&mut self) {
        let received = self.pending_sets.iter().take_while(|s| s.restricted.is_some()).count();
        self.pass(received, true);
        self.take_resets(|e| e.restricted == Some(false), true);
    }

    /// The pending resets of the parameters `which` picks, not seen done yet, as the board
    /// took them: the model at the defaults.
    fn take_resets(&mut self, which: impl Fn(&PendingStorage) -> bool, ahead: bool) {
        let mut reset = false;
        for entry in self.pending_storage.iter_mut().filter(|e| e.is_reset() && !e.seen_done && which(e)) {
            entry.seen_done = true;
            reset = true;
        }
        if reset {
            let defaults = *self.defaults;
            self.step_to(defaults, ahead);
        }
    }

    /// The model moves to `next`, a set the board had in force; `ahead` as in
    /// [`Checker::take_through`].
    fn step_to(&mut self, next: Config, ahead: bool) {
        let (old, new) = (parameters::values(&self.model), parameters::values(&next));
        if ahead {
            for (j, (o, n)) in old.iter().zip(new.iter()).enumerate() {
                if o.to_bits() != n.to_bits() {
                    self.stale.push((j, o.to_bits()));
                }
            }
        }
        self.model = next;
        self.remember(&new);
    }

    /// Where the board may have been when it reported parameter `i` at `value`: how many of the
    /// pending sets it had taken, the fewest that explain it (0: the model as it is). The
    /// answers leave in the order they were queued, each with the value in force then, so a
    /// report shows the board where the one before it did or later; the board takes the sets
    /// in the order they came (only those it received), and an answer it has no room for is
    /// owed and goes later, in index order, with the value then in force. Two sets of one
    /// RCMAP, say, each a swap, move a third channel where neither alone would, and that
    /// channel's report comes first. Committing to no more than the fewest sets keeps a report
    /// that matches several points (a swap undone before its answers went out shows the map as
    /// it was) from skipping sets that a later report needs.
    fn matched_after(&self, i: usize, value: f32) -> Option<usize> {
        let matches = |cfg: &Config| parameters::value(cfg, i).is_some_and(|x| x.to_bits() == value.to_bits());
        if matches(&self.model) {
            return Some(0);
        }
        let mut cfg = self.model;
        for (k, set) in self.pending_sets.iter().enumerate() {
            set.restricted?;
            if let Some(next) = set.taken(&cfg) {
                cfg = next;
                if matches(&cfg) {
                    return Some(k + 1);
                }
            }
        }
        None
    }

    /// A PREFLIGHT_STORAGE acknowledgement. It carries the command's number and the result,
    /// not which of the commands sent it answers: the board answers them in the order it got
    /// them, but an answer the full transmit queue has no room for is dropped. So it answers
    /// the first pending command that can have this result (an unsupported param1, a save or
    /// reset refused while changes were restricted, or taken), and the ones before it had
    /// their answers dropped: a reset among those, taken (changes were not restricted when it
    /// came), wiped the sets before it, as its acknowledgement would have said.
    fn on_storage_ack(&mut self, result: u8) {
        let Some(k) = self.pending_storage.iter().position(|c| !c.answer_dropped && c.can_answer(result)) else {
            // No command this answer fits: the oldest's, as the board answers in order.
            let _oldest = self.pending_storage.pop_front();
            return;
        };
        let dropped: Vec<PendingStorage> = self.pending_storage.drain(..k).collect();
        let answered = self.pending_storage.pop_front();
        if let Some(start) = answered.map(|c| c.start) {
            // The commands sent before it were answered before it, or their answers dropped.
            self.pending_commands.retain(|c| c.start > start);
        }
        let reset_taken = |c: &PendingStorage| c.is_reset() && !c.seen_done && c.restricted == Some(false);
        let resets =
            dropped.iter().filter(|c| reset_taken(c)).chain(answered.iter().filter(|c| result == 0 && !c.seen_done && c.is_reset()));
        let last_reset = resets.map(|c| c.start).next_back();
        if let Some(start) = last_reset {
            // The sets before the reset were taken and wiped by it.
            self.pending_sets.retain(|s| s.start > start);
            self.model = *self.defaults;
            let v = parameters::values(&self.model);
            self.remember(&v);
        }
    }

    /// The acknowledgement of a command other than PREFLIGHT_STORAGE. It answers the first such
    /// command pending, or a later one if that one's answer was dropped: either way the board
    /// had answered every command sent before the first, so a storage command among them that
    /// is still pending had its answer dropped, and no acknowledgement to come is its.
    fn on_command_ack(&mut self, command: u16) {
        let Some(k) = self.pending_commands.iter().position(|c| c.command == command) else {
            return;
        };
        let start = self.pending_commands.get(k).map_or(0, |c| c.start);
        self.pending_commands.drain(..=k);
        // A save or an unknown command settled: its answer would only mislead the matching.
        // A reset not yet seen done stays, for what it may explain.
        self.pending_storage.retain(|e| e.start > start || (e.is_reset() && !e.seen_done));
        for e in self.pending_storage.iter_mut().filter(|e| e.start < start) {
            e.answer_dropped = true;
        }
    }

    /// A report of parameter `i` at `value` that only a pending reset of the parameters
    /// explains, its acknowledgement dropped (the transmit queue drops an answer it has no
    /// room for) or still queued: the model takes the sets before the reset, the reset, and as
    /// many sets after it as the report needs. False, and nothing changed, when the reset does
    /// not explain it either.
    fn reset_explains(&mut self, i: usize, value: f32, at: u64) -> bool {
        let Some(k) = self.pending_storage.iter().position(|e| e.is_reset() && !e.seen_done) else {
            return false;
        };
        let reset_at = self.pending_storage.get(k).map_or(0, |e| e.start);
        let before = self.clone();
        let before_reset = self.pending_sets.iter().filter(|s| s.start < reset_at).count();
        self.pass(before_reset, false);
        let defaults = *self.defaults;
        self.step_to(defaults, false);
        if let Some(entry) = self.pending_storage.get_mut(k) {
            entry.seen_done = true;
        }
        match self.matched_after(i, value) {
            Some(0) => {}
            Some(m) => {
                self.take_through(m - 1, false, at);
            }
            None => {
                *self = before;
                return false;
            }
        }
        true
    }

    /// Catches up with sets whose answer was dropped: where `values` differ from the model by
    /// a value a PARAM_SET sent from byte `from` on, and received, asked for, the board took it. Taking a set
    /// takes the ones before it, whose side effects (an RCMAP swap) may move a parameter
    /// already looked at, so the parameters are looked at again until no set is taken (each
    /// pass that takes one leaves fewer pending).
    fn reconcile(&mut self, values: &[f32; COUNT], from: u64, at: u64) {
        loop {
            let pending = self.pending_sets.len();
            for (i, v) in values.iter().enumerate() {
                let differs = parameters::value(&self.model, i).is_some_and(|m| m.to_bits() != v.to_bits());
                if !differs {
                    continue;
                }
                // The earliest set that asks for the value and that the board took: one it
                // refused (an RC endpoint set while armed, say, its echo the value in force)
                // leaves the value to a later set of it. When the table refuses every one, none
                // explains the value: a reset taken on the way to another parameter's set may
                // (a ground-only set refused while arming asks for the default), and what is
                // left unexplained is the caller's violation.
                // Only a set the board received: one still on the wire (behind a backlog of
                // frames) explains nothing it saved or loaded, and taking it would take every
                // set before it, which a later save or answer may still show as to come.
                let taken = (0..self.pending_sets.len())
                    .filter(|&k| self.pending_sets.get(k).is_some_and(|s| s.restricted.is_some() && s.start >= from && s.asks(i, *v)))
                    .find_map(|pos| {
                        let mut trial = self.clone();
                        // A refusal found on trial is no finding.
                        trial.trace = false;
                        trial.take_through(pos, true, at).then_some(Checker { trace: self.trace, ..trial })
                    });
                if let Some(trial) = taken {
                    *self = trial;
                }
            }
            if self.pending_sets.len() == pending {
                return;
            }
        }
    }

    /// For a message: the first parameter where `values` differ from the model, when a pending
    /// set asks for its value there and the table refuses that set by the rules in force when
    /// the board received it (a ground-only change while armed, say): the board took a change
    /// it must refuse.
    fn refused_asking(&self, values: &[f32; COUNT]) -> String {
        let Some(i) = (0..COUNT)
            .find(|&i| parameters::value(&self.model, i).is_some_and(|m| values.get(i).is_some_and(|v| m.to_bits() != v.to_bits())))
        else {
            return String::new();
        };
        let refusal = self.pending_sets.iter().filter(|s| values.get(i).is_some_and(|v| s.asks(i, *v))).find_map(|s| {
            let mut next = self.model;
            parameters::set(&mut next, s.index, s.value, s.restricted.unwrap_or(false)).err().map(|r| r.rule)
        });
        refusal.map_or(String::new(), |rule| {
            format!(" (the board took {} = {}, which the table refuses: {rule})", name(i), values.get(i).copied().unwrap_or(f32::NAN))
        })
    }

    /// An answer of the board, as it left the link.
    pub fn on_answer(&mut self, answer: &Answer, at: u64) {
        if self.trace {
            eprintln!("{:>6} ms answer {answer:?} (pending {})", ms(at), self.pending_sets.len());
        }
        match answer {
            Answer::ParamValue { name: reported, value, index } => {
                let i = usize::from(*index);
                let Some(current) = parameters::value(&self.model, i) else {
                    return self.violate(
                        Invariant::AcceptedIsReportedSavedLoaded,
                        at,
                        format!("PARAM_VALUE of index {i}, which does not exist"),
                    );
                };
                if parameters::name(i) != Some(reported.as_str()) {
                    self.violate(
                        Invariant::AcceptedIsReportedSavedLoaded,
                        at,
                        format!("PARAM_VALUE {reported} with the index of {}", name(i)),
                    );
                }
                if let Some(k) = self.stale.iter().position(|&(j, b)| j == i && b == value.to_bits()) {
                    // Queued before a save or a load showed the value that replaced it. The
                    // answers leave in the order queued, each with the value in force when it
                    // was queued: this parameter's values before this one are past, this one may
                    // be reported again (several sets of one value, each answered). The value in
                    // force now may have been in force before too (A, B, A taken together): the
                    // earliest match commits to the least.
                    let mut n = 0;
                    self.stale.retain(|&(j, _)| {
                        n += 1;
                        j != i || n > k
                    });
                    return;
                }
                match self.matched_after(i, *value) {
                    Some(0) => {
                        // Answered in order: what was queued before the value in force is out.
                        self.stale.retain(|&(j, _)| j != i);
                    }
                    Some(k) => {
                        self.take_through(k - 1, false, at);
                    }
                    None if self.reset_explains(i, *value, at) => {}
                    None => match self.pending_sets.iter().find(|s| s.index == i).map(|s| s.value) {
                        Some(asked) => self.violate(
                            Invariant::AcceptedIsReportedSavedLoaded,
                            at,
                            format!(
                                "a PARAM_SET of {} = {asked} answered with {value}: neither the value asked for nor the one in force ({current})",
                                name(i)
                            ),
                        ),
                        None => self.violate(
                            Invariant::AcceptedIsReportedSavedLoaded,
                            at,
                            format!("the board reports {} = {value}; the value it accepted is {current}", name(i)),
                        ),
                    },
                }
            }
            Answer::CommandAck { command: cmd::PREFLIGHT_STORAGE, result } => self.on_storage_ack(*result),
            Answer::CommandAck { command, .. } => self.on_command_ack(*command),
            _ => {}
        }
    }

    /// The board resets the parameters when it takes the command, and a save it owed may write
    /// the result before the reset's acknowledgement reaches the ground station (the answers
    /// queue behind each other). A save that the defaults, and the sets asked for since, explain
    /// is that reset seen early: the model takes it then, and not again at its acknowledgement.
    fn reset_seen_in(&mut self, saved: &[f32; COUNT], at: u64) {
        let Some(k) = self.pending_storage.iter().position(|e| e.is_reset() && !e.seen_done) else {
            return;
        };
        let reset_at = self.pending_storage.get(k).map_or(0, |e| e.start);
        // Tried: kept only when the save shows it.
        let before = self.clone();
        // The sets before the reset were taken, then wiped by it; the answers still queued for
        // them may report what they set, or what the model had before.
        let before_reset = self.pending_sets.iter().filter(|s| s.start < reset_at).count();
        self.pass(before_reset, true);
        let defaults = *self.defaults;
        self.step_to(defaults, true);
        if let Some(entry) = self.pending_storage.get_mut(k) {
            entry.seen_done = true;
        }
        self.reconcile(saved, reset_at, at);
        if bits(saved) == bits(&parameters::values(&self.model)) {
            let v = parameters::values(&self.model);
            self.remember(&v);
        } else {
            *self = before;
        }
    }

    /// A save's words were all programmed.
    pub fn on_saved(&mut self, plan: &SavePlan, at: u64) {
        let Some(snap) = snapshot::decode(&plan.words) else {
            return self.violate(Invariant::AcceptedIsReportedSavedLoaded, at, "a save wrote a snapshot that does not decode".into());
        };
        if self.trace {
            let d = first_difference(&snap.values, &parameters::values(&self.model));
            eprintln!("{:>6} ms saved (sequence {:#x}); first difference from the model: {d}", ms(at), snap.sequence);
        }
        let before = self.clone();
        self.reconcile(&snap.values, 0, at);
        if bits(&snap.values) != bits(&parameters::values(&self.model)) {
            // Tried from before the catching up: sets sent after a reset must not be taken on the
            // set it wiped.
            let reconciled = std::mem::replace(self, before.clone());
            self.reset_seen_in(&snap.values, at);
            if bits(&snap.values) != bits(&parameters::values(&self.model)) {
                // The board saves between link periods, each of which takes every frame
                // received: every set received so far, each reset among them where it came.
                // Catching up set by set takes the earliest set of a value, which a reset
                // after it may have wiped (the value set again after the reset is the one in
                // the save); the sets all taken in order are what the board did.
                *self = before;
                self.take_every_received();
                if bits(&snap.values) != bits(&parameters::values(&self.model)) {
                    *self = reconciled;
                }
            }
        }
        let model = parameters::values(&self.model);
        if bits(&snap.values) != bits(&model) {
            let d = first_difference(&snap.values, &model);
            let refused = self.refused_asking(&snap.values);
            self.violate(
                Invariant::AcceptedIsReportedSavedLoaded,
                at,
                format!("saved a set other than the one accepted: {d} accepted{refused}"),
            );
        }
        self.written.push(Written {
            sector: plan.sector,
            first_word: plan.first_word,
            words: plan.words,
            values: snap.values,
            by_board: true,
        });
    }

    /// A power cut fell in the middle of programming a save's words. Only the last word cut
    /// with every bit it clears cleared leaves the record whole (the commit word is written
    /// last): then the board made the save, and the loader may find it, so it is judged and
    /// kept as one. A record cut anywhere else is not whole, and a boot must pass over it.
    pub fn on_save_cut(&mut self, plan: &SavePlan, flash: &Flash, at: u64) {
        let whole =
            flash.sectors().get(plan.sector).and_then(|s| s.get(plan.first_word..plan.first_word + RECORD_WORDS)) == Some(&plan.words[..]);
        if self.trace {
            eprintln!("{:>6} ms a power cut in a save's words; the record whole: {whole}", ms(at));
        }
        if whole {
            self.on_saved(plan, at);
        }
    }

    /// The board booted with `cfg`, found as `source` in `flash`; the first `delivered_bytes`
    /// the ground station sent had reached the board before (what they asked died with it,
    /// unless answered; the frames after them are still on the wire, for the new boot).
    pub fn on_boot(&mut self, cfg: &Config, source: snapshot::Source, flash: &Flash, kind: BootKind, delivered_bytes: u64, at: u64) {
        let loaded = parameters::values(cfg);
        if self.trace {
            eprintln!("{:>6} ms boot {kind:?} from {source:?}, {delivered_bytes} bytes delivered", ms(at));
        }
        let sectors = flash.sectors();
        let intact: Vec<&Written> = self
            .written
            .iter()
            .filter(|w| sectors[w.sector].get(w.first_word..w.first_word + RECORD_WORDS) == Some(&w.words[..]))
            .collect();
        let mut found = Vec::new();
        if let Some(newest) = intact.last() {
            let seq = newest.words[1];
            if newest.by_board && bits(&newest.values) != bits(&loaded) {
                let d = first_difference(&loaded, &newest.values);
                found.push((
                    Invariant::AcceptedIsReportedSavedLoaded,
                    format!("{kind:?}: loaded ({source:?}) other than the newest save (sequence {seq:#x}): {d} saved"),
                ));
            }
            if let Err(rule) = parameters::with_values(self.defaults, &newest.values) {
                let fallback = intact.iter().rev().find(|w| parameters::with_values(self.defaults, &w.values).is_ok());
                let expected = fallback.map_or_else(|| parameters::values(self.defaults), |w| w.values);
                if bits(&expected) != bits(&loaded) {
                    let d = first_difference(&loaded, &expected);
                    let from = fallback.map_or("the defaults".to_string(), |w| format!("the set saved at sequence {:#x}", w.words[1]));
                    found.push((
                        Invariant::RefusedSnapshotFallsBack,
                        format!("the newest set (sequence {seq:#x}) is refused ({rule}); loaded {source:?}, not {from}: {d}"),
                    ));
                }
            }
        }
        if kind == BootKind::Reset {
            let before = self.clone();
            self.reconcile(&loaded, 0, at);
            if bits(&loaded) != bits(&parameters::values(&self.model)) {
                // A reboot comes in a link period, after the board took every frame it had
                // received and saved what they changed: every set received so far, each reset
                // among them where it came. Catching up set by set may have committed to an
                // explanation of an earlier save or answer that stopped short (a set of the
                // default rather than the reset the board took after it, its acknowledgement
                // dropped), which a later answer then moved past.
                let reconciled = std::mem::replace(self, before);
                self.take_every_received();
                if bits(&loaded) != bits(&parameters::values(&self.model)) {
                    *self = reconciled;
                }
            }
            let model = parameters::values(&self.model);
            if bits(&model) != bits(&loaded) {
                let d = first_difference(&loaded, &model);
                let refused = self.refused_asking(&loaded);
                found.push((
                    Invariant::AcceptedIsReportedSavedLoaded,
                    format!("after a reboot command loaded ({source:?}) {d} accepted{refused}"),
                ));
            }
        }
        if kind == BootKind::PowerCut && !self.history.contains(&bits(&loaded)) {
            found.push((Invariant::PowerCutLoadsAWholeSet, format!("loaded ({source:?}) a set never in force: {:?}", loaded)));
        }
        for (invariant, what) in found {
            self.violate(invariant, at, what);
        }
        self.model = *cfg;
        self.pending_sets.retain(|s| s.start >= delivered_bytes);
        self.stale.clear();
        self.pending_storage.retain(|e| e.start >= delivered_bytes);
        self.pending_commands.retain(|c| c.start >= delivered_bytes);
        self.remember(&loaded);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench_board::gcs::name16;

    static DEFAULTS: Config = Config::DEFAULT;

    fn index(name: &str) -> usize {
        parameters::index_of(name.as_bytes()).unwrap()
    }

    #[test]
    fn a_loaded_mix_of_two_sets_in_force_is_a_violation() {
        let mut c = Checker::new(&DEFAULTS);
        let (roll, angle) = (index("RATE_RLL_P"), index("ANGLE_MAX"));
        for (k, (i, v)) in [(roll, 100.0), (angle, 30.0)].into_iter().enumerate() {
            c.on_sent(&GcsFrame::ParamSet { name: name16(parameters::name(i).unwrap()), value: v }, 35);
            // The board received the frame (disarmed) before it answered.
            c.on_received(35 * (k as u64 + 1), false);
            c.on_answer(&Answer::ParamValue { name: parameters::name(i).unwrap().into(), value: v, index: i as u16 }, 1);
        }
        assert_eq!(c.accepted_sets, 2);
        assert!(c.violations().is_empty(), "{:?}", c.violations());
        // In force: defaults, then RATE_RLL_P 100, then both. ANGLE_MAX 30 alone never was.
        let mut mix = DEFAULTS;
        parameters::set(&mut mix, angle, 30.0, false).unwrap();
        c.on_boot(&mix, snapshot::Source::NoSnapshot, &Flash::new(), BootKind::PowerCut, 70, 2);
        assert_eq!(c.first(Invariant::PowerCutLoadsAWholeSet).map(|v| v.invariant), Some(Invariant::PowerCutLoadsAWholeSet));
    }

    #[test]
    fn a_value_reported_that_no_set_asked_for_is_a_violation() {
        let mut c = Checker::new(&DEFAULTS);
        let angle = index("ANGLE_MAX");
        c.on_answer(&Answer::ParamValue { name: "ANGLE_MAX".into(), value: 33.0, index: angle as u16 }, 1);
        assert!(c.first(Invariant::AcceptedIsReportedSavedLoaded).is_some());
    }

    /// The board taking a ground-only set it refused while arming is still a violation, and
    /// says so, when nothing else (a reset) explains the value it then shows.
    #[test]
    fn a_ground_only_set_the_board_refused_and_then_shows_is_a_violation() {
        let mut c = Checker::new(&DEFAULTS);
        let rev = index("RC2_REV");
        let send = |c: &mut Checker, v: f32, restricted: bool, at: u64| {
            c.on_sent(&GcsFrame::ParamSet { name: name16("RC2_REV"), value: v }, 35);
            c.on_received(c.sent_bytes, restricted);
            c.on_answer(&Answer::ParamValue { name: "RC2_REV".into(), value: -1.0, index: rev as u16 }, at);
        };
        send(&mut c, -1.0, false, 1);
        // Refused while arming: the echo is the value in force.
        send(&mut c, 1.0, true, 2);
        assert!(c.violations().is_empty(), "{:?}", c.violations());
        let mut shown = c.model;
        parameters::set(&mut shown, rev, 1.0, false).unwrap();
        c.on_boot(&shown, snapshot::Source::NoSnapshot, &Flash::new(), BootKind::Reset, c.sent_bytes, 3);
        let v = c.first(Invariant::AcceptedIsReportedSavedLoaded).expect("a violation");
        assert!(v.what.contains("which the table refuses: only while disarmed"), "{v}");
    }
}
