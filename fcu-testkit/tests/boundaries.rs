//! The invariants where the link, the parameter flash and the flight state meet, on the bench
//! board (`fcu_testkit::bench_board`): any interleaving of ground-station frames, the pilot's
//! gestures and flight, a flooded or silent link, and power cuts at any flash word.
//!
//! Each invariant is its own proptest over the same operations (a shrunk counterexample names
//! the operations that break it), and each finding that broke one has a plain test with its
//! scenario written out.

use fcu_core::supervisor::FlightState;
use fcu_core::Config;
use fcu_params::{self as parameters, snapshot, COUNT};
use fcu_testkit::bench_board::{
    cmd, command_for, gesture, param_set, value_for, Bench, GcsFrame, Invariant, Op, Pilot, Planted, PowerCut, Scenario,
};
use proptest::prelude::*;

static DEFAULTS: Config = Config::DEFAULT;

fn index(name: &str) -> usize {
    parameters::index_of(name.as_bytes()).unwrap_or_else(|| panic!("no parameter {name}"))
}

/// Parameters the findings were about, picked more often than the rest.
fn interesting() -> Vec<usize> {
    ["ANGLE_MAX", "YAW_RATE_MAX", "RCMAP_ROLL", "RCMAP_YAW", "RCMAP_THROTTLE", "ARM_HOLD_MS", "LINK_ATT_HZ", "RATE_RLL_P"]
        .iter()
        .filter_map(|n| parameters::index_of(n.as_bytes()))
        .collect()
}

fn param_index() -> impl Strategy<Value = usize> {
    prop_oneof![2 => prop::sample::select(interesting()), 1 => 0..=COUNT]
}

fn reboot() -> Op {
    Op::Send(GcsFrame::Command { command: cmd::PREFLIGHT_REBOOT_SHUTDOWN, params: [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: false })
}

fn save() -> Op {
    Op::Send(GcsFrame::Command { command: cmd::PREFLIGHT_STORAGE, params: [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: false })
}

fn set(name: &str, value: f32) -> Op {
    Op::Send(param_set(index(name), value))
}

/// One step of a bench session: a few operations that belong together.
fn episode() -> impl Strategy<Value = Vec<Op>> {
    prop_oneof![
        3 => Just(gesture(Pilot::Arm).to_vec()),
        2 => Just(gesture(Pilot::Disarm).to_vec()),
        2 => (200u32..3000).prop_map(|ms| vec![Op::Pilot(Pilot::Fly), Op::Wait { ms }, Op::Pilot(Pilot::Neutral)]),
        1 => (100u32..1500).prop_map(|ms| vec![Op::Pilot(Pilot::Off), Op::Wait { ms }, Op::Pilot(Pilot::Neutral)]),
        4 => (param_index(), any::<u8>()).prop_map(|(i, sel)| vec![Op::Send(param_set(i, value_for(i, sel)))]),
        1 => (param_index(), any::<u8>(), 1u32..60).prop_map(|(i, sel, ms)| {
            vec![Op::Send(param_set(i, value_for(i, sel))), Op::Wait { ms }, Op::Send(param_set(i, value_for(i, sel.wrapping_add(1))))]
        }),
        3 => (any::<u8>(), any::<u8>(), any::<bool>()).prop_map(|(c, p, int)| vec![Op::Send(command_for(c, p, int))]),
        2 => Just(vec![reboot()]),
        2 => Just(vec![save()]),
        1 => (0u8..=255).prop_map(|i| vec![Op::Send(GcsFrame::ParamRead { index: i16::from(i), name: [0; 16] })]),
        1 => Just(vec![Op::Send(GcsFrame::ParamList)]),
        1 => Just(vec![Op::Send(GcsFrame::Heartbeat)]),
        2 => (200u32..3000).prop_map(|ms| vec![Op::Flood { ms }]),
        2 => (prop_oneof![0..snapshot::RECORD_WORDS as u32, 0..(snapshot::SECTOR_WORDS + snapshot::RECORD_WORDS) as u32], any::<u32>())
            .prop_map(|(at_word, partial_bits)| vec![Op::CutAtWord(PowerCut { at_word, partial_bits })]),
        1 => Just(vec![Op::CutNow]),
        1 => (250u32..=500).prop_map(|ms| vec![Op::EraseMs(ms)]),
        4 => (5u32..3000).prop_map(|ms| vec![Op::Wait { ms }]),
    ]
}

/// Snapshots an older firmware left: none to three, or both sectors full (the next save erases
/// the older), numbered from 1 or up to the wrap.
fn history() -> impl Strategy<Value = Vec<Planted>> {
    let changes = || prop::collection::vec((param_index(), any::<u8>()).prop_map(|(i, sel)| (i % COUNT, value_for(i % COUNT, sel))), 0..3);
    let sets = prop_oneof![
        4 => prop::collection::vec(changes(), 0..4),
        1 => changes().prop_map(|c| vec![c; 2 * snapshot::SLOTS]),
    ];
    let start = prop_oneof![Just(1u32), (0u32..4).prop_map(|k| u32::MAX - k)];
    (sets, start).prop_map(|(sets, start)| {
        let n = sets.len() as u32;
        let start = start.min(u32::MAX - n.saturating_sub(1));
        sets.into_iter().enumerate().map(|(k, changes)| Planted { sequence: start + k as u32, changes }).collect()
    })
}

fn scenario() -> impl Strategy<Value = Scenario> {
    (history(), any::<u64>(), prop::collection::vec(episode(), 1..14)).prop_map(|(history, seed, eps)| Scenario {
        history,
        seed,
        ops: eps.into_iter().flatten().collect(),
    })
}

/// Runs the scenario and fails with the first violation of `invariant`.
fn holds(invariant: Invariant, s: &Scenario) -> Result<(), TestCaseError> {
    let bench = s.run(&DEFAULTS);
    match bench.checker.first(invariant) {
        Some(v) => Err(TestCaseError::fail(v.to_string())),
        None => Ok(()),
    }
}

fn config() -> ProptestConfig {
    ProptestConfig { failure_persistence: None, ..ProptestConfig::default() }
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn nothing_starts_while_armed(s in scenario()) {
        holds(Invariant::NothingStartsArmed, &s)?;
    }

    #[test]
    fn arming_only_by_the_stick_gesture(s in scenario()) {
        holds(Invariant::ArmedOnlyByGesture, &s)?;
    }

    #[test]
    fn an_accepted_value_is_reported_saved_and_loaded(s in scenario()) {
        holds(Invariant::AcceptedIsReportedSavedLoaded, &s)?;
    }

    #[test]
    fn a_power_cut_loads_a_set_once_in_force_as_a_whole(s in scenario()) {
        holds(Invariant::PowerCutLoadsAWholeSet, &s)?;
    }

    #[test]
    fn a_refused_saved_set_falls_back_to_the_newest_valid_one(s in scenario()) {
        holds(Invariant::RefusedSnapshotFallsBack, &s)?;
    }

    #[test]
    fn saves_keep_the_control_loop_fed(s in scenario()) {
        holds(Invariant::SavesKeepTheLoopRunning, &s)?;
    }
}

/// The bench after `ops` on an empty flash.
fn bench(ops: Vec<Op>) -> Bench {
    Scenario { history: Vec::new(), seed: 1, ops }.run(&DEFAULTS)
}

fn assert_holds(bench: &Bench, invariant: Invariant) {
    if let Some(v) = bench.checker.first(invariant) {
        panic!("{v}");
    }
}

#[test]
fn the_bench_arms_flies_disarms_and_saves() {
    let mut ops = vec![set("ANGLE_MAX", 35.0), save(), Op::Wait { ms: 200 }];
    ops.extend(gesture(Pilot::Arm));
    ops.extend([Op::Pilot(Pilot::Fly), Op::Wait { ms: 1000 }, Op::Pilot(Pilot::Neutral), Op::Wait { ms: 100 }]);
    ops.extend(gesture(Pilot::Disarm));
    let b = bench(ops);
    assert!(b.counts.arms >= 1, "{:?}", b.counts);
    assert_eq!(b.status().state, FlightState::Disarmed);
    assert!(b.counts.saves >= 1, "{:?}", b.counts);
    assert!(b.checker.violations().is_empty(), "{:?}", b.checker.violations());
}

/// Finding: a reboot accepted disarmed was carried out later in flight, once the transmit
/// queue drained (the firmware never looked at the flight state again). Now the link goes quiet
/// for it, arming waits, and the reboot comes first.
#[test]
fn a_reboot_accepted_disarmed_is_not_carried_out_in_flight() {
    let mut ops = vec![Op::Flood { ms: 500 }, reboot()];
    // The uplink stays full while the pilot arms and takes off: the acknowledgement waits.
    ops.push(Op::Pilot(Pilot::Arm));
    ops.push(Op::Flood { ms: 1100 });
    ops.push(Op::Pilot(Pilot::Neutral));
    ops.push(Op::Flood { ms: 100 });
    ops.push(Op::Pilot(Pilot::Fly));
    ops.push(Op::Flood { ms: 500 });
    ops.push(Op::Wait { ms: 3000 });
    let b = bench(ops);
    assert_holds(&b, Invariant::NothingStartsArmed);
    assert_eq!(b.counts.reboots, 1, "{:?}", b.counts);
}

/// Finding: ANGLE_MAX 60, a legal value, saved and rebooted wiped every parameter.
#[test]
fn angle_max_60_saved_and_rebooted_is_loaded() {
    let b = bench(vec![set("RATE_RLL_P", 100.0), set("ANGLE_MAX", 60.0), save(), Op::Wait { ms: 500 }, reboot(), Op::Wait { ms: 500 }]);
    assert_eq!(b.counts.reboots, 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
}

/// Finding: a save after the sequence number wrapped was lost (the older snapshot, numbered
/// higher, loaded).
#[test]
fn a_save_after_the_sequence_number_wraps_is_loaded() {
    let history = vec![Planted { sequence: u32::MAX, changes: vec![] }];
    let ops = vec![set("ANGLE_MAX", 40.0), save(), Op::Wait { ms: 500 }, reboot(), Op::Wait { ms: 500 }];
    let b = Scenario { history, seed: 1, ops }.run(&DEFAULTS);
    assert_eq!(b.counts.reboots, 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
}

/// Finding: an RCMAP set made a map that is not a permutation; saved, it was refused at the
/// next boot.
#[test]
fn an_rcmap_set_saved_and_rebooted_is_loaded() {
    for (a, x, c, y) in
        [("RCMAP_ROLL", 3.0, "RCMAP_YAW", 1.0), ("RCMAP_ROLL", 2.0, "RCMAP_PITCH", 4.0), ("RCMAP_THROTTLE", 1.0, "RCMAP_YAW", 3.0)]
    {
        let b = bench(vec![set(a, x), set(c, y), save(), Op::Wait { ms: 500 }, reboot(), Op::Wait { ms: 500 }]);
        assert_eq!((b.counts.saves, b.counts.reboots), (1, 1), "{a} {x} {c} {y}");
        assert!(b.config().rc.map.is_permutation(), "{a} {x} {c} {y}: {:?}", b.config().rc.map);
        assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    }
}

/// A snapshot today's rules refuse, saved after a valid one: the valid one loads, not the
/// defaults.
#[test]
fn a_refused_newest_snapshot_falls_back_to_the_one_before() {
    let angle = index("ANGLE_MAX");
    let max = parameters::param(angle).map(|p| p.max).unwrap_or(60.0);
    let history = vec![
        Planted { sequence: 7, changes: vec![(index("RATE_RLL_P"), 100.0)] },
        Planted { sequence: 8, changes: vec![(angle, max + 10.0)] },
    ];
    let b = Scenario { history, seed: 1, ops: vec![Op::Wait { ms: 10 }] }.run(&DEFAULTS);
    assert_holds(&b, Invariant::RefusedSnapshotFallsBack);
}

/// A power cut at every word a save programs, and at every 61st word of the erase before it:
/// the set loaded is always one in force, and the erase's stall raises no fault.
#[test]
fn a_power_cut_at_any_word_of_an_erasing_save_loads_a_whole_set() {
    // Both sectors full: the next save erases sector 0 (4096 word operations), then programs.
    let slots = 2 * snapshot::SLOTS as u32;
    let history: Vec<Planted> =
        (1..=slots).map(|k| Planted { sequence: k, changes: vec![(index("RATE_RLL_P"), 50.0 + k as f32)] }).collect();
    let erase = snapshot::SECTOR_WORDS as u32;
    let words = (0..erase).step_by(61).chain([erase - 1]).chain(erase..erase + snapshot::RECORD_WORDS as u32);
    for at_word in words {
        let ops =
            vec![Op::CutAtWord(PowerCut { at_word, partial_bits: 0x0F0F_F0F0 }), set("ANGLE_MAX", 41.0), save(), Op::Wait { ms: 800 }];
        let b = Scenario { history: history.clone(), seed: 3, ops }.run(&DEFAULTS);
        assert_eq!((b.counts.erases, b.counts.cuts_in_flash), (1, 1), "cut at word {at_word}");
        assert_holds(&b, Invariant::PowerCutLoadsAWholeSet);
        assert_holds(&b, Invariant::SavesKeepTheLoopRunning);
    }
}

/// A power cut at every word of a save into an empty slot, whatever the partial word keeps.
#[test]
fn a_power_cut_at_any_word_of_a_save_loads_a_whole_set() {
    let history = vec![Planted { sequence: 1, changes: vec![(index("RATE_RLL_P"), 70.0)] }];
    for at_word in 0..snapshot::RECORD_WORDS as u32 {
        for partial_bits in [0, u32::MAX, 0x8000_0001] {
            let ops = vec![Op::CutAtWord(PowerCut { at_word, partial_bits }), set("ANGLE_MAX", 41.0), save(), Op::Wait { ms: 200 }];
            let b = Scenario { history: history.clone(), seed: 5, ops }.run(&DEFAULTS);
            assert_eq!(b.counts.cuts_in_flash, 1, "cut at word {at_word}");
            assert_holds(&b, Invariant::PowerCutLoadsAWholeSet);
        }
    }
}

#[test]
fn any_bytes_make_a_scenario_that_runs() {
    for seed in 0..8u8 {
        let bytes: Vec<u8> = (0..64u32).map(|k| (k * 37 + u32::from(seed) * 11) as u8).collect();
        let s = Scenario::from_bytes(&bytes);
        let _ = s.run(&DEFAULTS);
    }
    let _ = Scenario::from_bytes(&[]).run(&DEFAULTS);
}

/// The generated sessions reach what the invariants are about: flight, saves, erases, reboots,
/// power cuts inside flash work.
#[test]
fn the_generated_sessions_reach_flight_saves_erases_reboots_and_cuts() {
    use proptest::strategy::ValueTree;
    use proptest::test_runner::{Config as RunnerConfig, TestRunner};
    let mut runner = TestRunner::new(RunnerConfig { rng_seed: proptest::test_runner::RngSeed::Fixed(7), ..RunnerConfig::default() });
    let mut total = fcu_testkit::bench_board::Counts::default();
    for _ in 0..64 {
        let s = scenario().new_tree(&mut runner).unwrap().current();
        let c = s.run(&DEFAULTS).counts;
        total.arms += c.arms;
        total.saves += c.saves;
        total.erases += c.erases;
        total.reboots += c.reboots;
        total.power_cuts += c.power_cuts;
        total.cuts_in_flash += c.cuts_in_flash;
    }
    assert!(total.arms > 0 && total.saves > 0 && total.erases > 0 && total.reboots > 0 && total.cuts_in_flash > 0, "{total:?}");
}

/// Found by the fuzzer (its checker, not the board): saves asked for, then a reset to the
/// defaults. The board resets when it takes the command and its owed save writes the defaults,
/// ahead of the reset's acknowledgement in the answers' queue; the ground station's view must
/// take the reset when the save shows it, not only at the acknowledgement.
#[test]
fn a_save_owed_before_a_reset_writes_the_defaults_the_reset_left() {
    let history = vec![Planted { sequence: 1, changes: vec![(index("RATE_RLL_P"), 150.0)] }];
    let reset = Op::Send(GcsFrame::Command { command: cmd::PREFLIGHT_STORAGE, params: [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: true });
    let mut ops: Vec<Op> = (0..6).map(|_| save()).collect();
    ops.push(reset);
    ops.push(Op::Wait { ms: 3000 });
    let b = Scenario { history, seed: 1, ops }.run(&DEFAULTS);
    assert!(b.counts.saves >= 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(parameters::value(b.config(), index("RATE_RLL_P")), parameters::value(&DEFAULTS, index("RATE_RLL_P")));
}

/// Found by the fuzzer (its checker, not the board): a refused RCMAP_ROLL, then ROLL 4 (which
/// swaps it with YAW), then ROLL 1 (which swaps it back). The refusal's echo carries ROLL's value
/// in force, 1, the value the third set asks for: the checker took it as that set's answer and
/// then refused the real one. Sets of a parameter are answered in order.
#[test]
fn a_refusal_echo_is_not_the_answer_of_a_later_set_of_the_same_value() {
    let roll = index("RCMAP_ROLL");
    let ops = vec![set("RCMAP_ROLL", 3.3448277), set("RCMAP_ROLL", 4.0), set("RCMAP_ROLL", 1.0), Op::Wait { ms: 1200 }];
    let b = bench(ops);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(parameters::value(b.config(), roll), Some(1.0));
    assert_eq!(parameters::value(b.config(), index("RCMAP_YAW")), Some(4.0));
}

/// Found by the fuzzer (its checker, not the board): RCMAP_ROLL 3 (a swap with THROTTLE), then
/// RCMAP_ROLL 4 (a swap with YAW) under a flood that drops the first set's answers. The board took
/// both in order, so THROTTLE stays 1; the checker took only the second and expected 3.
#[test]
fn an_earlier_set_whose_answer_was_dropped_keeps_its_swap() {
    let ops = vec![
        Op::Flood { ms: 1200 },
        set("RCMAP_ROLL", 3.0),
        set("RCMAP_ROLL", 4.0),
        Op::Wait { ms: 64 },
        Op::Flood { ms: 800 },
        Op::Wait { ms: 1500 },
    ];
    let b = bench(ops);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    let map: Vec<Option<f32>> =
        ["RCMAP_ROLL", "RCMAP_PITCH", "RCMAP_THROTTLE", "RCMAP_YAW"].iter().map(|n| parameters::value(b.config(), index(n))).collect();
    assert_eq!(map, [Some(4.0), Some(2.0), Some(1.0), Some(3.0)]);
}

/// The RCMAP channels, in table order, as the board has them.
fn rc_map(b: &Bench) -> Vec<Option<f32>> {
    ["RCMAP_ROLL", "RCMAP_PITCH", "RCMAP_THROTTLE", "RCMAP_YAW"].iter().map(|n| parameters::value(b.config(), index(n))).collect()
}

/// Found by the fuzzer (its checker, not the board): under a flood, RCMAP_YAW 2 (a swap with
/// PITCH), then RCMAP_YAW 1 (a swap with ROLL, which gets YAW's 2). The transmit queue had no
/// room, so both sets' answers were owed and went out in index order with the values in force:
/// ROLL = 2 first, a value neither set alone makes. The checker tried each pending set alone
/// and took the report for a value nobody accepted; the board takes the sets in order.
#[test]
fn two_swaps_of_one_channel_are_reported_before_either_answer() {
    let ops = vec![
        Op::Flood { ms: 1000 },
        Op::Send(GcsFrame::ParamList),
        set("RCMAP_YAW", 2.0),
        set("RCMAP_YAW", 1.0),
        Op::Flood { ms: 1000 },
        Op::Wait { ms: 1500 },
    ];
    let b = bench(ops);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(rc_map(&b), [Some(2.0), Some(4.0), Some(3.0), Some(1.0)]);
}

/// The same model for sets of different channels: RCMAP_PITCH 4 (a swap with YAW), then
/// RCMAP_ROLL 4 (a swap with PITCH, which gets ROLL's 1), answered late under a flood. ROLL's
/// answer and PITCH = 1 are seen before PITCH's own: the board took PITCH's set first.
#[test]
fn an_earlier_set_of_another_channel_is_taken_before_the_one_answered() {
    let ops = vec![
        Op::Flood { ms: 1000 },
        Op::Send(GcsFrame::ParamList),
        set("RCMAP_PITCH", 4.0),
        set("RCMAP_ROLL", 4.0),
        Op::Flood { ms: 1000 },
        Op::Wait { ms: 1500 },
    ];
    let b = bench(ops);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(rc_map(&b), [Some(4.0), Some(1.0), Some(3.0), Some(2.0)]);
}

/// An RCMAP set that arrives while armed is refused (its echo carries the value in force, which
/// the table would not refuse disarmed); it is not taken when a later set of the same channel is
/// answered disarmed. The checker takes a set by the rules in force when the board received it.
#[test]
fn an_rcmap_set_refused_while_armed_is_not_taken_by_a_later_answer() {
    let mut ops = gesture(Pilot::Arm).to_vec();
    ops.extend([set("RCMAP_ROLL", 2.0), Op::Wait { ms: 300 }]);
    ops.extend(gesture(Pilot::Disarm));
    ops.extend([Op::Wait { ms: 200 }, set("RCMAP_ROLL", 3.0), Op::Wait { ms: 500 }]);
    let b = bench(ops);
    assert!(b.counts.arms >= 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(rc_map(&b), [Some(3.0), Some(2.0), Some(1.0), Some(4.0)]);
}

/// A set taken before a reset of the parameters is wiped by it: its answer, owed under a flood
/// and sent after the reset with the value then in force (the default), leaves no set of it
/// pending for a later answer to take again.
#[test]
fn a_set_taken_before_a_reset_is_not_taken_again_after_it() {
    let reset = Op::Send(GcsFrame::Command { command: cmd::PREFLIGHT_STORAGE, params: [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: false });
    let ops = vec![
        Op::Flood { ms: 1000 },
        Op::Send(GcsFrame::ParamList),
        set("RCMAP_ROLL", 2.0),
        reset,
        Op::Flood { ms: 1000 },
        Op::Wait { ms: 1000 },
        set("RCMAP_YAW", 3.0),
        Op::Wait { ms: 300 },
        Op::Send(GcsFrame::ParamRead { index: 0, name: [0; 16] }),
        Op::Wait { ms: 300 },
    ];
    let b = bench(ops);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(rc_map(&b), [Some(1.0), Some(2.0), Some(4.0), Some(3.0)]);
}

/// Found by the fuzzer (its checker, not the board): the arm gesture held 780 ms, the
/// transmitter off for 62 ms, the gesture again for 715 ms, then the sticks released. The
/// link is lost only 100 ms (`RC_TIMEOUT_MS`) after the first channel's last pulse; until then
/// the last pulses stand, so the board saw the gesture held on a good link for 1.5 s and armed,
/// as `docs/safety.md` has it. The checker counted the hold from the transmitter's return.
#[test]
fn a_transmitter_gap_shorter_than_the_link_timeout_does_not_break_the_arm_gesture() {
    let ops = vec![
        Op::Pilot(Pilot::Arm),
        Op::Wait { ms: 780 },
        Op::Pilot(Pilot::Off),
        Op::Wait { ms: 62 },
        Op::Pilot(Pilot::Arm),
        Op::Wait { ms: 715 },
        Op::Pilot(Pilot::Neutral),
        Op::Wait { ms: 200 },
    ];
    let b = bench(ops);
    assert_holds(&b, Invariant::ArmedOnlyByGesture);
    assert_eq!(b.counts.arms, 1, "{:?}", b.counts);
}

/// Past the link timeout the gap is a link loss: the gesture starts again, and 715 ms of it
/// do not arm.
#[test]
fn a_transmitter_gap_past_the_link_timeout_starts_the_arm_gesture_again() {
    let ops = vec![
        Op::Pilot(Pilot::Arm),
        Op::Wait { ms: 780 },
        Op::Pilot(Pilot::Off),
        Op::Wait { ms: 150 },
        Op::Pilot(Pilot::Arm),
        Op::Wait { ms: 715 },
        Op::Pilot(Pilot::Neutral),
        Op::Wait { ms: 200 },
    ];
    let b = bench(ops);
    assert_holds(&b, Invariant::ArmedOnlyByGesture);
    assert_eq!(b.counts.arms, 0, "{:?}", b.counts);
}

/// Found by the fuzzer (its checker, not the board): under a flood, RCMAP_YAW 2.517 (refused),
/// RCMAP_YAW 1 (a swap with ROLL), a set of another parameter, RCMAP_ROLL 1 (the swap undone).
/// The owed answers carry the map as it is again, ROLL = 1 and YAW = 4, the values in force on
/// the checker's copy too; it took them for the ROLL set's answer alone, left the YAW set
/// pending, and took it (its swap) when the other parameter's answer came. A report matches the
/// board at some point at or after the last one matched: the sets stay pending until a report
/// only a later point explains.
#[test]
fn a_swap_undone_before_its_answers_went_out_is_not_taken_later() {
    let other = index("LINK_ATT_HZ");
    let ops = vec![
        Op::Flood { ms: 1000 },
        Op::Send(param_set(index("RCMAP_YAW"), value_for(index("RCMAP_YAW"), 0x54))),
        set("RCMAP_YAW", 1.0),
        Op::Send(param_set(other, value_for(other, 0x24))),
        set("RCMAP_ROLL", 1.0),
        Op::Wait { ms: 64 },
        Op::Send(param_set(other, value_for(other, 0xC6))),
        Op::Flood { ms: 1000 },
        Op::Wait { ms: 500 },
    ];
    let b = Scenario { history: Vec::new(), seed: 0x98, ops }.run(&DEFAULTS);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(rc_map(&b), [Some(1.0), Some(2.0), Some(3.0), Some(4.0)]);
}

/// Found by the fuzzer (its checker, not the board): the arm gesture held 1.2 s, the sticks at
/// rest for 20 ms, then the gesture again; the board completed arming 2 ticks into the new
/// gesture. It sees the sticks up to a receiver frame late, so the 20 ms at rest reached it
/// just then; the checker judged by the pilot's sticks of that tick.
#[test]
fn arming_completes_on_a_rest_the_board_sees_a_frame_late() {
    let ops = vec![
        Op::Wait { ms: 40 },
        Op::Pilot(Pilot::Arm),
        Op::Wait { ms: 1206 },
        Op::Pilot(Pilot::Neutral),
        Op::Wait { ms: 20 },
        Op::Pilot(Pilot::Arm),
        Op::Wait { ms: 17 },
    ];
    let b = Scenario { history: Vec::new(), seed: 0, ops }.run(&DEFAULTS);
    assert_eq!(b.counts.arms, 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::ArmedOnlyByGesture);
}

/// Found by the fuzzer (its checker, not the board): a reboot accepted, then sets of
/// RATE_RLL_D (469, then 57.47) and YAW_FF, then a reset of the parameters. The board saved the
/// defaults before the answers queued ahead of the reset went out (the link goes quiet before
/// a save), and the checker took the reset then; RATE_RLL_D = 57.47, the second set's answer
/// still queued, then came out. The sets before a reset seen early are taken, as the board
/// took them, and their queued answers may report what they set.
#[test]
fn an_answer_queued_before_a_reset_seen_early_reports_the_set_it_answers() {
    let roll_d = index("RATE_RLL_D");
    let reboot_int =
        Op::Send(GcsFrame::Command { command: cmd::PREFLIGHT_REBOOT_SHUTDOWN, params: [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: true });
    let reset = Op::Send(GcsFrame::Command { command: cmd::PREFLIGHT_STORAGE, params: [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: false });
    let ops = vec![
        reboot_int,
        Op::Wait { ms: 29 },
        Op::Send(GcsFrame::ParamRead { index: 220, name: [0; 16] }),
        set("RATE_RLL_D", 469.0),
        set("YAW_FF", 0.0),
        Op::Send(GcsFrame::ParamRead { index: 220, name: [0; 16] }),
        Op::Send(param_set(roll_d, value_for(roll_d, 50))),
        reset,
        Op::Wait { ms: 1180 },
    ];
    let history = vec![Planted { sequence: 1, changes: vec![] }];
    let b = Scenario { history, seed: 0x4a, ops }.run(&DEFAULTS);
    assert_eq!(b.counts.reboots, 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(parameters::value(b.config(), roll_d), parameters::value(&DEFAULTS, roll_d));
}

/// Found by the fuzzer (its checker, not the board): the arm gesture held 1.6 s, the disarm
/// gesture 1 s, the arm gesture 40 ms, the disarm gesture 1.1 s, the sticks released: armed.
/// After a full hold the board waits in Arming until every stick is back in a safe place,
/// whatever the sticks do meanwhile (`docs/safety.md`); the checker counted only the last,
/// 40 ms hold.
#[test]
fn arming_completes_after_a_full_hold_whatever_the_sticks_did_before_the_rest() {
    let mut ops = vec![
        Op::Wait { ms: 2000 },
        Op::Pilot(Pilot::Arm),
        Op::Wait { ms: 1624 },
        Op::Pilot(Pilot::Disarm),
        Op::Wait { ms: 1060 },
        Op::Pilot(Pilot::Arm),
        Op::Wait { ms: 40 },
    ];
    ops.extend(gesture(Pilot::Disarm));
    let b = Scenario { history: Vec::new(), seed: 0x42, ops }.run(&DEFAULTS);
    assert_eq!(b.counts.arms, 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::ArmedOnlyByGesture);
}

/// Found by the fuzzer (its checker, not the board): ANG_YAW_P 0 and RATE_D_LPF_K 1 taken, then
/// under a flood a reset of the parameters, whose acknowledgement the full transmit queue
/// dropped (an answer without room is dropped and counted; the ground station asks again). The
/// board reported ANG_YAW_P = 2, its default: a report only the reset explains is the reset
/// taken.
#[test]
fn a_reset_whose_acknowledgement_was_dropped_shows_in_the_values_reported() {
    let reset = Op::Send(GcsFrame::Command { command: cmd::PREFLIGHT_STORAGE, params: [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: true });
    let ops = vec![
        Op::Wait { ms: 20 },
        set("RCMAP_ROLL", 1.0),
        set("ANG_YAW_P", 0.0),
        Op::Wait { ms: 900 },
        set("RATE_D_LPF_K", 1.0),
        Op::Wait { ms: 78 },
        Op::Flood { ms: 2000 },
        Op::Send(GcsFrame::ParamList),
        reset,
        Op::Wait { ms: 900 },
        set("RATE_D_LPF_K", 1.0),
        Op::Wait { ms: 20 },
    ];
    let history = vec![Planted { sequence: u32::MAX - 11, changes: vec![] }];
    let b = Scenario { history, seed: 0x21, ops }.run(&DEFAULTS);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
}

/// Found by the fuzzer (its checker, not the board): a reboot accepted, RCMAP_ROLL 3 and
/// RC1_REV 1 taken, then a reset of the parameters and sets of RC1_MIN and RC2_MIN. The board
/// saved the defaults with the two sets after the reset before the reset's acknowledgement went
/// out; the checker took the two sets on the map it had (ROLL 3) and then found no reset to
/// explain the save. A save is matched against the reset from the model before the sets after it.
#[test]
fn sets_after_a_reset_seen_early_are_not_taken_before_it() {
    let reboot_int =
        Op::Send(GcsFrame::Command { command: cmd::PREFLIGHT_REBOOT_SHUTDOWN, params: [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: true });
    let reset = Op::Send(GcsFrame::Command { command: cmd::PREFLIGHT_STORAGE, params: [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: true });
    let ops = vec![
        reboot_int,
        set("RCMAP_ROLL", 3.0),
        set("RC1_REV", 1.0),
        Op::Wait { ms: 20 },
        reset,
        set("RC1_MIN", 1004.0),
        set("RC2_MIN", 500.0),
        Op::Wait { ms: 300 },
    ];
    let b = Scenario { history: Vec::new(), seed: 0x23, ops }.run(&DEFAULTS);
    assert_eq!(b.counts.reboots, 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(rc_map(&b), [Some(1.0), Some(2.0), Some(3.0), Some(4.0)]);
}

fn command(command: u16, first: f32, fifth: f32) -> Op {
    Op::Send(GcsFrame::Command { command, params: [first, 0.0, 0.0, 0.0, fifth, 0.0, 0.0], int: false })
}

/// Found by the fuzzer (its checker, not the board): a reboot accepted, a reset of the
/// parameters, ALT_DEADBAND_US 255 (the board at its defaults). The board saved the defaults
/// with the set before the reset's acknowledgement went out; the set alone explained the save,
/// so the checker took it and left the reset pending, and the reset's acknowledgement then
/// wiped the set (the report of 255 and the load after the reboot were violations). The board
/// takes the frames in the order they came: taking a set sent after a reset takes the reset
/// first. The same cause, other inputs: RATE_RLL_P 984 and RATE_PIT_P 3218.39 after a reset,
/// LINK_RC_HZ answered with 32 after a reset.
#[test]
fn a_set_sent_after_a_reset_is_not_wiped_by_the_reset_acknowledgement() {
    let deadband = index("ALT_DEADBAND_US");
    let ops = vec![
        command(cmd::DO_MOTOR_TEST, 2.0, 1.0),
        command(cmd::PREFLIGHT_CALIBRATION, 21196.0, 0.0),
        reboot(),
        Op::Wait { ms: 40 },
        command(cmd::PREFLIGHT_CALIBRATION, 1.0, 1.0),
        command(cmd::PREFLIGHT_STORAGE, 2.0, 0.0),
        set("ALT_DEADBAND_US", 255.0),
        command(cmd::PREFLIGHT_CALIBRATION, 2.0, 1.0),
        Op::Wait { ms: 320 },
    ];
    let b = Scenario { history: Vec::new(), seed: 0x7a, ops }.run(&DEFAULTS);
    assert_eq!((b.counts.saves, b.counts.reboots), (1, 1), "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(parameters::value(b.config(), deadband), Some(255.0));
}

/// Found by the fuzzer (its checker, not the board): under a flood, RCMAP_THROTTLE 1 (a swap
/// with ROLL: ROLL 3), ALT_POS_P 6.78, a reboot accepted, then RCMAP_ROLL 1 (the swap undone),
/// which the board took before the reboot's save. The checker caught up with the save in
/// index order: ROLL matched, ALT_POS_P did not, and taking its set took the THROTTLE swap
/// before it, which moved ROLL (already looked at) to 3. It now looks again until no set is
/// taken, and the ROLL set undoes the swap as on the board. The same cause: RCMAP_ROLL 2 and
/// RCMAP_PITCH 2 around a reboot (`RCMAP_ROLL = 1 against 2 accepted`).
#[test]
fn a_swap_taken_while_catching_up_with_a_save_is_undone_by_a_later_set_in_it() {
    let ops = vec![
        Op::Flood { ms: 2000 },
        set("RCMAP_THROTTLE", 1.0),
        set("ALT_POS_P", 6.781609),
        Op::Send(GcsFrame::Command { command: cmd::PREFLIGHT_REBOOT_SHUTDOWN, params: [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: true }),
        Op::Wait { ms: 100 },
        set("RCMAP_ROLL", 1.0),
        Op::Wait { ms: 200 },
    ];
    let b = Scenario { history: Vec::new(), seed: 0x9c, ops }.run(&DEFAULTS);
    assert_eq!((b.counts.saves, b.counts.reboots), (1, 1), "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(rc_map(&b), [Some(1.0), Some(2.0), Some(3.0), Some(4.0)]);
}

/// Found by the fuzzer (its checker, not the board): the arm gesture held 720 ms, the sticks at
/// rest for 16 ms, the gesture again for 720 ms, then released; the board armed. A receiver frame
/// takes the sticks at its start, every 20 ms: no frame started in those 16 ms, so the board was
/// sent the gesture unbroken for 1.46 s. The checker judged the pilot's sticks, not the frames.
#[test]
fn a_release_shorter_than_a_radio_frame_that_no_frame_carried_does_not_break_the_gesture() {
    let ops = vec![
        Op::Pilot(Pilot::Arm),
        Op::Wait { ms: 720 },
        Op::Pilot(Pilot::Neutral),
        Op::Wait { ms: 16 },
        Op::Pilot(Pilot::Arm),
        Op::Wait { ms: 720 },
        Op::Pilot(Pilot::Neutral),
        Op::Wait { ms: 100 },
    ];
    let b = Scenario { history: Vec::new(), seed: 0x52, ops }.run(&DEFAULTS);
    assert_eq!(b.counts.arms, 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::ArmedOnlyByGesture);
}

/// The same release, long enough that a frame carries it: the gesture starts again, and two
/// holds of 720 ms do not arm.
#[test]
fn a_release_a_radio_frame_carried_starts_the_arm_gesture_again() {
    let ops = vec![
        Op::Pilot(Pilot::Arm),
        Op::Wait { ms: 720 },
        Op::Pilot(Pilot::Neutral),
        Op::Wait { ms: 60 },
        Op::Pilot(Pilot::Arm),
        Op::Wait { ms: 720 },
        Op::Pilot(Pilot::Neutral),
        Op::Wait { ms: 100 },
    ];
    let b = Scenario { history: Vec::new(), seed: 0x52, ops }.run(&DEFAULTS);
    assert_eq!(b.counts.arms, 0, "{:?}", b.counts);
    assert_holds(&b, Invariant::ArmedOnlyByGesture);
}

/// Found by the fuzzer (its checker, not the board): a save asked for, then RATE_RLL_I 3218.39,
/// 3735.63 and 3218.39 again. The board took all three and saved before their answers went
/// out (the link goes quiet before a save); the answers carry 3218.39, 3735.63, 3218.39, each
/// the value in force when it was queued. The first answer equals the value in force, and the
/// checker took it for an answer of the present, forgetting 3735.63 as a value still to come.
#[test]
fn a_value_set_back_before_a_save_is_reported_in_the_order_set() {
    let ops = vec![
        save(),
        Op::Wait { ms: 15 },
        set("RATE_RLL_I", 3218.3909),
        set("RATE_RLL_I", 3735.632),
        set("RATE_RLL_I", 3218.3909),
        set("RATE_PIT_I", 1772.0),
        Op::Wait { ms: 500 },
    ];
    let b = bench(ops);
    assert_eq!(b.counts.saves, 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(parameters::value(b.config(), index("RATE_RLL_I")), Some(3218.3909));
}

/// Found by the fuzzer (its checker, not the board): before a save, RATE_PIT_D 344.83, 459.77,
/// 344.83 twice, ANGLE_MAX, 459.77. Each set is answered, so 344.83 is reported twice in a
/// row before 459.77; the checker let each value it knew was past stand for one answer only.
#[test]
fn a_value_set_twice_in_a_row_before_a_save_is_reported_twice() {
    let ops = vec![
        save(),
        Op::Wait { ms: 15 },
        set("RATE_PIT_D", 344.82758),
        set("RATE_PIT_D", 459.7701),
        set("RATE_PIT_D", 344.82758),
        set("RATE_PIT_D", 344.82758),
        set("ANGLE_MAX", 42.931034),
        set("RATE_PIT_D", 459.7701),
        Op::Wait { ms: 500 },
    ];
    let b = bench(ops);
    assert_eq!(b.counts.saves, 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(parameters::value(b.config(), index("RATE_PIT_D")), Some(459.7701));
}

/// Found by the fuzzer (its checker, not the board): RC4_MAX 2500 sent while the board was
/// arming (refused: only while disarmed; the echo carries the value in force, so the set stays
/// pending), then, disarmed, a save and RC4_MAX 2500 again, taken while the link is quiet for
/// the save (its answer goes after it). The checker caught up with the save from the earliest
/// set of 2500, the refused one, and called it taken against the table.
#[test]
fn a_set_refused_while_arming_is_not_the_one_a_later_save_shows() {
    let ops = vec![
        Op::Pilot(Pilot::Arm),
        Op::Wait { ms: 300 },
        set("RC4_MAX", 2500.0),
        Op::Wait { ms: 100 },
        Op::Pilot(Pilot::Neutral),
        Op::Wait { ms: 300 },
        Op::Send(GcsFrame::ParamList),
        save(),
        Op::Wait { ms: 15 },
        set("RC4_MAX", 2500.0),
        Op::Wait { ms: 500 },
    ];
    let b = bench(ops);
    assert_eq!((b.counts.arms, b.counts.saves), (0, 1), "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(parameters::value(b.config(), index("RC4_MAX")), Some(2500.0));
}

/// Found by the fuzzer (its checker, not the board): after a flood, a reboot accepted (the link
/// goes quiet for the save before it, while the flood's answers drain), a reset, RATE_RLL_P,
/// RATE_PIT_D and RC4_MAX set, another reset, RATE_RLL_P and RC4_MAX set again. The board took
/// them in order and saved before rebooting: the defaults with RATE_RLL_P and RC4_MAX, RATE_PIT_D
/// wiped by the second reset. The checker caught up set by set from the earliest set of each
/// value, which took RATE_PIT_D on the way to the first RC4_MAX set, and found no explanation.
#[test]
fn a_set_wiped_by_a_second_reset_is_not_in_the_save_after_it() {
    let reboot_int =
        Op::Send(GcsFrame::Command { command: cmd::PREFLIGHT_REBOOT_SHUTDOWN, params: [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: true });
    let reset = || Op::Send(GcsFrame::Command { command: cmd::PREFLIGHT_STORAGE, params: [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: true });
    let ops = vec![
        Op::Flood { ms: 800 },
        reboot_int,
        Op::Wait { ms: 30 },
        reset(),
        set("RATE_RLL_P", 3150.0),
        set("RATE_PIT_D", 374.0),
        set("RC4_MAX", 2500.0),
        reset(),
        set("RATE_RLL_P", 3150.0),
        set("RC4_MAX", 2500.0),
        Op::Wait { ms: 300 },
    ];
    let b = bench(ops);
    assert!(b.counts.saves >= 1 && b.counts.reboots == 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(parameters::value(b.config(), index("RATE_PIT_D")), parameters::value(&DEFAULTS, index("RATE_PIT_D")));
    assert_eq!(parameters::value(b.config(), index("RC4_MAX")), Some(2500.0));
}

/// Found by the fuzzer on the board of 20de103 (fcu-link's reader, fixed since): a power cut in
/// the middle of a flood's request left the tail of a frame in the receive ring after the boot;
/// the reader took a false header in it and swallowed the command and the GESTURE_US set after
/// it, which were never answered, while a later set's answer made the checker take them.
#[test]
fn a_set_sent_after_a_power_cut_that_split_a_request_is_taken() {
    // The flood's requests and a heartbeat put the cut where it splits a request.
    let mut ops: Vec<Op> = (0..4).map(|_| Op::Flood { ms: 1400 }).collect();
    ops.extend([
        Op::Send(GcsFrame::Heartbeat),
        Op::Flood { ms: 1400 },
        Op::Send(GcsFrame::Command { command: 1106, params: [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: false }),
        set("GESTURE_US", 177.0),
        Op::CutNow,
        Op::Wait { ms: 3000 },
        set("RATE_YAW_I", 2126.0),
        Op::Wait { ms: 500 },
        Op::Send(GcsFrame::ParamRead { index: index("GESTURE_US") as i16, name: [0; 16] }),
        Op::Wait { ms: 100 },
    ]);
    let b = Scenario { history: Vec::new(), seed: 0x4a, ops }.run(&DEFAULTS);
    assert_eq!(b.counts.power_cuts, 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(parameters::value(b.config(), index("GESTURE_US")), Some(177.0));
}

/// Found by the fuzzer (its checker, not the board): RATE_PIT_D 472 taken, a flood, then in one
/// burst two storage commands the board does not support, twelve unknown commands and a reset
/// of the parameters. The transmit queue had no room for the reset's acknowledgement, and the
/// board, armed later, refused seven saves. The checker matched acknowledgements to storage
/// commands first come, first served, so the first refusal answered the reset, and RATE_PIT_D
/// reported at its default afterwards had no explanation. An acknowledgement answers the first
/// pending command that can have its result; a reset before it, taken disarmed, whose answer
/// was dropped, wiped the sets.
#[test]
fn a_reset_whose_acknowledgement_was_dropped_is_not_answered_by_a_later_refusal() {
    let storage = |first: f32, int: bool| {
        Op::Send(GcsFrame::Command { command: cmd::PREFLIGHT_STORAGE, params: [first, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int })
    };
    let mut ops = vec![Op::Wait { ms: 1_000 }, set("RATE_PIT_D", 472.0), Op::Wait { ms: 250 }, Op::Flood { ms: 1_800 }];
    ops.extend([storage(0.5, true), storage(-1.0, false)]);
    ops.extend((0..14).map(|_| command(882, -1.0, 0.0)));
    ops.extend([storage(2.0, false), Op::Pilot(Pilot::Disarm), Op::Wait { ms: 1_020 }]);
    ops.extend([Op::Pilot(Pilot::Arm), Op::Wait { ms: 1_100 }, Op::Pilot(Pilot::Neutral), Op::Wait { ms: 100 }]);
    ops.extend((0..7).map(|_| storage(1.0, true)));
    ops.extend([Op::Wait { ms: 1_500 }, Op::Send(GcsFrame::ParamList), Op::Wait { ms: 2_000 }]);
    let b = bench(ops);
    assert_eq!(b.counts.arms, 1, "{:?}", b.counts);
    assert_eq!(
        parameters::value(b.config(), index("RATE_PIT_D")),
        parameters::value(&DEFAULTS, index("RATE_PIT_D")),
        "the reset was not taken"
    );
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
}

/// Found by the fuzzer (its checker, not the board): RC2_REV -1 taken, then RC2_REV 1 sent while
/// the board was arming, refused (only while disarmed; its echo is -1, the value in force, so the
/// set stays pending). Disarmed again, a reboot accepted and a reset of the parameters: the board
/// saved the defaults, RC2_REV 1 among them, before the reset's acknowledgement went out. The
/// checker caught up with the save from the refused set, the only one asking for 1, and called
/// it taken against the table, before it looked at the reset that explains the save. The board
/// never took the set: RC2_REV stayed -1 until the reset.
#[test]
fn a_ground_only_set_refused_while_arming_is_not_the_reset_a_later_save_shows() {
    let reset = Op::Send(GcsFrame::Command { command: cmd::PREFLIGHT_STORAGE, params: [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: true });
    let rev = index("RC2_REV");
    let ops = vec![
        set("RC2_REV", -1.0),
        Op::Wait { ms: 100 },
        Op::Pilot(Pilot::Arm),
        Op::Wait { ms: 300 },
        set("RC2_REV", 1.0),
        Op::Wait { ms: 100 },
        Op::Pilot(Pilot::Neutral),
        Op::Wait { ms: 300 },
        Op::Flood { ms: 800 },
        reboot(),
        Op::Wait { ms: 30 },
        reset,
        set("RATE_RLL_P", 3150.0),
        Op::Wait { ms: 300 },
    ];
    let b = bench(ops);
    assert_eq!((b.counts.arms, b.counts.reboots), (0, 1), "{:?}", b.counts);
    assert!(b.counts.saves >= 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(parameters::value(b.config(), rev), parameters::value(&DEFAULTS, rev));
    assert_eq!(parameters::value(&DEFAULTS, rev), Some(1.0));
}

/// Found by the fuzzer (its checker, not the board): RATE_YAW_D 362.07 taken, a reboot accepted
/// (the board saves what is unsaved first, each time the link is quiet), then in one burst a
/// reset of the parameters, RATE_PIT_P, a second reset, RATE_YAW_D 362.07 nine times and
/// RATE_YAW_D 60, its default. The board saved the defaults after a reset, the frames after it
/// still on the wire, then saved RATE_YAW_D 362.07 after the second reset and the sets. The
/// checker caught up with the first save from the set of 60, the only one asking for the value
/// saved, which the board had not received yet; that took every set before it, and the second
/// save had nothing left to explain it. A set still on the wire explains nothing the board saved.
#[test]
fn a_set_still_on_the_wire_does_not_explain_a_save() {
    let reset = || Op::Send(GcsFrame::Command { command: cmd::PREFLIGHT_STORAGE, params: [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: true });
    let mut ops = vec![set("RATE_YAW_D", 362.06897), Op::Wait { ms: 100 }, reboot(), Op::Wait { ms: 20 }];
    ops.extend([reset(), set("RATE_PIT_P", 3218.3909), reset()]);
    ops.extend((0..9).map(|_| set("RATE_YAW_D", 362.06897)));
    ops.extend([set("RATE_YAW_D", 60.0), Op::Wait { ms: 500 }]);
    let b = bench(ops);
    assert!(b.counts.saves >= 2 && b.counts.reboots == 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(parameters::value(b.config(), index("RATE_YAW_D")), Some(60.0));
}

/// Found by the fuzzer (its checker, not the board): after a flood, RATE_PIT_P 4942.53 and
/// RATE_YAW_D 362.07 taken, a reboot accepted (the board saves what is unsaved first), RATE_RLL_I
/// 3218.39, RATE_YAW_D 60 (its default) and 362.07 again, an unknown command, more sets of
/// RATE_YAW_D, a reset of the parameters, and RATE_RLL_I and RATE_PIT_P set again. The board took
/// them all, the reset's acknowledgement not out before the reboot, and saved the defaults with RATE_RLL_I and
/// RATE_PIT_P before rebooting. The checker explained the save with the set of 60 alone, then
/// took the answer of the 362.07 after it, queued before the save; at the reboot nothing it had
/// left pending put RATE_YAW_D back at 60 (`after a reboot command loaded ... RATE_YAW_D = 60
/// against 362.06897`). A reboot comes after the board took every frame it received and saved
/// them: the load is matched against every set received taken in order, the reset among them.
#[test]
fn a_reboot_loads_the_reset_the_board_took_after_a_set_of_the_default() {
    let reset = Op::Send(GcsFrame::Command { command: cmd::PREFLIGHT_STORAGE, params: [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: true });
    // param1 0: no reboot (answered unsupported).
    let no_reboot = || command(cmd::PREFLIGHT_REBOOT_SHUTDOWN, 0.0, 0.0);
    let mut ops = vec![Op::Wait { ms: 35 }, Op::Flood { ms: 800 }, Op::Wait { ms: 40 }];
    ops.extend([set("RATE_PIT_P", 4942.529), set("ALT_DEADBAND_US", 289.65518)]);
    ops.extend((0..4).map(|_| set("RATE_YAW_D", 362.06897)));
    ops.extend([set("RC1_MAX", 1787.3563), set("RC1_MIN", 1787.3563), reboot(), set("RC1_MAX", 1787.3563), set("RC1_MIN", 1787.3563)]);
    ops.extend([no_reboot(), set("RATE_RLL_I", 3218.3909), Op::Wait { ms: 40 }]);
    ops.extend([no_reboot(), set("RATE_YAW_D", 60.0), set("RATE_YAW_D", 362.06897), reboot(), no_reboot(), Op::Wait { ms: 60 }]);
    ops.push(Op::Send(GcsFrame::Command { command: 721, params: [0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: true }));
    ops.extend((0..4).map(|_| set("RATE_YAW_D", 362.06897)));
    ops.extend([set("RATE_YAW_D", 494.25287), set("ALT_DEADBAND_US", 257.47125), reset]);
    ops.extend([set("RATE_RLL_I", 3218.3909), set("RATE_PIT_P", 4942.529), Op::Wait { ms: 140 }]);
    let b = Scenario { history: Vec::new(), seed: 12, ops }.run(&DEFAULTS);
    assert_eq!(b.counts.reboots, 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(parameters::value(b.config(), index("RATE_YAW_D")), Some(60.0));
    assert_eq!(parameters::value(b.config(), index("RATE_RLL_I")), Some(3218.3909));
}

/// Found by the fuzzer (its checker, not the board): the flash held a set the table refuses
/// (RC2_REV 0.264, not a whole number), so the board started from the defaults; RATE_PIT_I
/// 1436.78 taken and saved, and a power cut fell on the save's last word, the commit word, with
/// every bit it clears already cleared. The record was whole, and the board loaded it after the
/// cut; the bench told the checker nothing of a save cut short, which then expected the refused
/// set's fallback, the defaults (`RefusedSnapshotFallsBack`). The same cause:
/// `PowerCut: loaded (Snapshot 2) other than the newest save (sequence 0x1)`.
#[test]
fn a_save_cut_at_its_last_word_fully_programmed_is_loaded() {
    let pit_i = index("RATE_PIT_I");
    let history = vec![Planted { sequence: 1, changes: vec![(index("RC2_REV"), 0.26436782)] }];
    let ops = vec![
        set("RATE_PIT_I", 1436.7816),
        Op::CutAtWord(PowerCut { at_word: snapshot::RECORD_WORDS as u32 - 1, partial_bits: 0 }),
        save(),
        Op::Wait { ms: 300 },
    ];
    let b = Scenario { history, seed: 0x64, ops }.run(&DEFAULTS);
    assert_eq!((b.counts.cuts_in_flash, b.counts.power_cuts), (1, 1), "{:?}", b.counts);
    assert!(b.checker.violations().is_empty(), "{:?}", b.checker.violations());
    assert_eq!(parameters::value(b.config(), pit_i), Some(1436.7816));
}

/// Found by the fuzzer (its checker, not the board; run 19's input, kept whole): in one burst
/// sets, saves, a reboot and, last, a reset of the parameters. The board took every frame it had
/// received before it rebooted, the reset last, saved the defaults and loaded them; the reset's
/// acknowledgement never went out. Matching the load against every set received took the sets,
/// and no set came after the reset to take it on the way: a reset received after the last set,
/// taken disarmed, is taken too.
#[test]
fn a_reset_after_the_last_set_before_a_reboot_is_in_what_the_reboot_loads() {
    const INPUT: [u8; 109] = [
        111, 52, 157, 111, 52, 157, 111, 1, 0, 113, 113, 113, 113, 113, 113, 113, 16, 48, 144, 113, 113, 113, 113, 113, 113, 113, 113, 141,
        113, 113, 113, 113, 113, 113, 113, 48, 113, 113, 113, 113, 113, 113, 113, 113, 113, 113, 113, 113, 113, 113, 113, 113, 113, 113,
        113, 113, 35, 113, 113, 113, 0, 109, 113, 113, 113, 113, 35, 113, 113, 113, 113, 113, 113, 113, 113, 113, 113, 113, 113, 113, 113,
        113, 113, 113, 113, 113, 113, 113, 113, 65, 82, 77, 95, 72, 79, 76, 68, 95, 77, 83, 113, 113, 53, 112, 239, 111, 48, 112, 239,
    ];
    let scenario = Scenario::from_bytes(&INPUT);
    let b = scenario.run(&DEFAULTS);
    assert_eq!(b.counts.reboots, 1, "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
}

/// Found by the fuzzer (its checker, not the board; run 20's input, kept whole): a save and an
/// unknown storage command lost in a burst of motor tests (their answers never came), RATE_PIT_D
/// and RC1_MIN taken, then a storage command answered unsupported, a reset of the parameters
/// accepted, a motor test, and a save refused while it ran. The checker matched the reset's
/// acceptance to the lost save, the first pending command it fitted, and the refusal to the
/// reset: the defaults reported afterwards had no explanation. The board answers commands in
/// the order it received them: once a command sent later is answered, an earlier one still
/// pending will never be, and no answer to come is its.
#[test]
fn a_storage_command_whose_answer_never_came_is_not_answered_by_a_later_reset() {
    const INPUT: [u8; 448] = [
        174, 45, 113, 113, 113, 157, 113, 113, 49, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123,
        123, 123, 123, 123, 123, 123, 255, 255, 123, 123, 123, 123, 87, 124, 124, 124, 124, 125, 124, 124, 124, 124, 123, 123, 123, 123,
        123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 113, 157, 113, 113, 49, 123, 123, 123, 123, 123,
        123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123,
        123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 198, 123, 123, 123, 123, 123, 123,
        123, 123, 123, 216, 156, 153, 45, 217, 96, 100, 248, 151, 155, 100, 248, 156, 155, 120, 153, 123, 123, 123, 123, 123, 123, 123,
        123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123,
        123, 123, 123, 123, 123, 123, 113, 4, 113, 33, 138, 0, 0, 0, 0, 123, 123, 33, 11, 93, 45, 113, 113, 113, 157, 113, 113, 49, 33, 11,
        93, 45, 123, 113, 113, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 130, 132, 132, 132, 123, 123, 123,
        123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123,
        123, 123, 123, 123, 123, 123, 123, 123, 48, 59, 0, 125, 123, 211, 59, 0, 48, 123, 112, 123, 123, 123, 123, 123, 123, 123, 123, 123,
        123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123,
        113, 157, 37, 11, 93, 45, 113, 113, 113, 157, 113, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123,
        123, 123, 123, 115, 123, 123, 123, 123, 123, 123, 123, 123, 1, 0, 0, 0, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123,
        123, 123, 123, 123, 123, 123, 123, 33, 11, 93, 45, 113, 113, 113, 157, 113, 113, 49, 33, 11, 93, 45, 123, 8, 124, 113, 113, 123,
        123, 123, 123, 123, 123, 123, 123, 189, 189, 189, 189, 189, 189, 189, 189, 189, 189, 189, 189, 189, 189, 189, 189, 189, 189, 189,
        123, 123, 123, 123, 123, 123, 130, 132, 132, 132, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123, 123,
    ];
    let b = Scenario::from_bytes(&INPUT).run(&DEFAULTS);
    assert_eq!(b.counts.saves, 5, "{:?}", b.counts);
    assert_holds(&b, Invariant::AcceptedIsReportedSavedLoaded);
    assert_eq!(parameters::value(b.config(), index("RATE_PIT_D")), parameters::value(&DEFAULTS, index("RATE_PIT_D")));
}
