//! The bench board (`fcu_testkit::bench_board`): the link task, the control loop and the
//! parameter flash composed as the firmware composes them, driven by a scenario decoded from
//! the input (`Scenario::from_bytes`: a flash history, ground-station frames, the pilot's
//! gestures, floods, power cuts at any flash word). A violated invariant is a crash.
#![no_main]

use fcu_core::Config;
use fcu_testkit::bench_board::Scenario;
use libfuzzer_sys::fuzz_target;

static DEFAULTS: Config = Config::DEFAULT;

fuzz_target!(|data: &[u8]| {
    let bench = Scenario::from_bytes(data).run(&DEFAULTS);
    if let Some(v) = bench.checker.violations().first() {
        panic!("{v}");
    }
});
