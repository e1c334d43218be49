//! The bench board (`fcu_testkit::bench_board`): the link task, the control loop and the
//! parameter flash composed as the firmware composes them, driven by a scenario decoded from
//! the input (`Scenario::from_bytes`: a flash history, ground-station frames, the pilot's
//! gestures, floods, power cuts at any flash word). A violated invariant is a crash.
//!
//! `FCU_FUZZ_ALL_INVARIANTS=1` checks every invariant; without it, those the code of today
//! breaks (each pinned by a named test in `fcu-testkit/tests/boundaries.rs`) are left out so the
//! smoke run in CI looks for new failures (see `PENDING`).
#![no_main]

use std::sync::OnceLock;

use fcu_core::Config;
use fcu_testkit::bench_board::{Invariant, Scenario};
use libfuzzer_sys::fuzz_target;

static DEFAULTS: Config = Config::DEFAULT;

/// Broken today, checked once their fixes land: the saved set the load refuses or loses
/// (ANGLE_MAX 60, the sequence number's wrap), the fallback to the defaults past a valid older
/// set.
const PENDING: [Invariant; 2] = [Invariant::AcceptedIsReportedSavedLoaded, Invariant::RefusedSnapshotFallsBack];

fn all() -> bool {
    static ALL: OnceLock<bool> = OnceLock::new();
    *ALL.get_or_init(|| std::env::var_os("FCU_FUZZ_ALL_INVARIANTS").is_some_and(|v| v == "1"))
}

fuzz_target!(|data: &[u8]| {
    let bench = Scenario::from_bytes(data).run(&DEFAULTS);
    if let Some(v) = bench.checker.violations().iter().find(|v| all() || !PENDING.contains(&v.invariant)) {
        panic!("{v}");
    }
});
