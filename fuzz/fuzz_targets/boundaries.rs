//! The bench board (`fcu_testkit::bench_board`): the link task, the control loop and the
//! parameter flash composed as the firmware composes them, driven by a scenario decoded from
//! the input (`Scenario::from_bytes`: a flash history, ground-station frames, the pilot's
//! gestures, floods, power cuts at any flash word). A violated invariant is a crash.
//!
//! The booted board is cached by (flash history, seed), and the board part way through an
//! input's operations by the input's bytes up to there (`BootCache::run_bytes`), and cloned:
//! the bench is deterministic, so a clone runs on exactly as a fresh boot would, and most
//! inputs share their first bytes with one run before.
#![no_main]

use std::cell::RefCell;

use fcu_core::Config;
use fcu_testkit::bench_board::BootCache;
use libfuzzer_sys::fuzz_target;

static DEFAULTS: Config = Config::DEFAULT;

thread_local! {
    static BOOTS: RefCell<BootCache> = RefCell::new(BootCache::new(&DEFAULTS));
}

fuzz_target!(|data: &[u8]| {
    let bench = BOOTS.with(|boots| boots.borrow_mut().run_bytes(data));
    if let Some(v) = bench.checker.violations().first() {
        panic!("{v}");
    }
});
