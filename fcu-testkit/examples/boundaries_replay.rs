//! Replays `boundaries` fuzz inputs on the bench board and prints the violations each one
//! finds; with `--trace`, the scenario's operations and everything the checker saw (frames
//! sent, answers, saves, boots, state changes) as the bench ran it.
//!
//! ```sh
//! cargo run -p fcu-testkit --example boundaries_replay -- [--trace] <input file>...
//! ```
//!
//! Runs each input as the fuzz target does (`BootCache::run_bytes`); exits 1 when any input
//! breaks an invariant.

use fcu_core::Config;
use fcu_testkit::bench_board::{BootCache, Scenario};

static DEFAULTS: Config = Config::DEFAULT;

fn main() {
    let mut trace = false;
    let mut failed = 0;
    for arg in std::env::args().skip(1) {
        if arg == "--trace" {
            trace = true;
            continue;
        }
        let bytes = match std::fs::read(&arg) {
            Ok(b) => b,
            Err(e) => {
                eprintln!("{arg}: {e}");
                failed += 1;
                continue;
            }
        };
        let bench = if trace {
            let scenario = Scenario::from_bytes(&bytes);
            eprintln!("{arg}: history {:?}, seed {}", scenario.history, scenario.seed);
            let mut cache = BootCache::new(&DEFAULTS);
            let mut bench = cache.booted(&scenario);
            bench.checker.trace = true;
            for op in &scenario.ops {
                eprintln!("{:>6} ms op {op:?}", bench.time_ms());
                bench.apply(op);
            }
            bench
        } else {
            BootCache::new(&DEFAULTS).run_bytes(&bytes)
        };
        let violations = bench.checker.violations();
        if violations.is_empty() {
            println!("{arg}: no violation ({:?})", bench.counts);
        } else {
            failed += 1;
            for v in violations {
                println!("{arg}: {v}");
            }
        }
    }
    std::process::exit(i32::from(failed > 0));
}
