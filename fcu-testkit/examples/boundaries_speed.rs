//! How fast the `boundaries` fuzz target's sessions run (docs/fuzzing.md): a fixed set of
//! inputs, made by a seeded generator the way libFuzzer grows them (random bytes of random
//! length), decoded with `Scenario::from_bytes` and run as the target runs them, checks and
//! all, once booting each session afresh (`Scenario::run`) and once from a boot cache
//! (`Scenario::run_cached`, as the fuzz target runs them). Prints sessions per second, CPU and
//! bench time per session, and the cache's hit rate; the two must find the same.
//!
//! `cargo run --release -p fcu-testkit --example boundaries_speed [inputs] [max_len]`
//!
//! The inputs share their first bytes the way a fuzzer's do: each is a previous one with a
//! few bytes changed, appended or cut, now and then a fresh random one.

use std::time::Instant;

use fcu_core::Config;
use fcu_testkit::bench_board::{plant, Bench, BootCache, Flash, Scenario, BOOT_MS};

static DEFAULTS: Config = Config::DEFAULT;

fn main() {
    let mut args = std::env::args().skip(1);
    let inputs: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(2000);
    let max_len: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(200);
    // xorshift64*: the same inputs on every run and every machine.
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        state.wrapping_mul(0x2545_F491_4F6C_DD1D)
    };
    let mut data: Vec<Vec<u8>> = Vec::with_capacity(inputs);
    for _ in 0..inputs {
        let fresh = data.is_empty() || next() % 8 == 0;
        let mut d: Vec<u8> = if fresh {
            let len = (next() as usize) % (max_len + 1);
            (0..len).map(|_| next() as u8).collect()
        } else {
            data[(next() as usize) % data.len()].clone()
        };
        if !fresh {
            for _ in 0..1 + next() % 3 {
                let at = (next() as usize) % (d.len() + 1);
                match next() % 3 {
                    0 if at < d.len() => d[at] = next() as u8,
                    1 if d.len() < max_len => d.insert(at, next() as u8),
                    _ => d.truncate(at.max(1)),
                }
            }
        }
        data.push(d);
    }
    let before = measure("as before (every save planned, every input booted)", &data, max_len, |d| {
        let scenario = Scenario::from_bytes(d);
        let mut flash = Flash::new();
        for p in &scenario.history {
            plant(&mut flash, p.sequence, &p.values(&DEFAULTS));
        }
        let mut bench = Bench::new(flash, &DEFAULTS, scenario.seed);
        bench.run_ms(BOOT_MS);
        bench.run(&scenario.ops);
        bench
    });
    let fresh = measure("every input booted (Scenario::run)", &data, max_len, |d| Scenario::from_bytes(d).run(&DEFAULTS));
    println!("  {:.1}x the sessions per second", before.0 / fresh.0);
    let mut boots = BootCache::new(&DEFAULTS);
    let cached = measure("boot cache", &data, max_len, |d| Scenario::from_bytes(d).run_cached(&mut boots));
    println!("  {} boots cached, {} run; {:.1}x the sessions per second", boots.hits, boots.misses, before.0 / cached.0);
    let mut cache = BootCache::new(&DEFAULTS);
    let prefixed = measure("boot and prefix cache (the fuzz target)", &data, max_len, |d| cache.run_bytes(d));
    println!(
        "  {} inputs from a cached prefix, {} boots cached, {} run; {:.1}x the sessions per second",
        cache.prefix_hits,
        cache.hits,
        cache.misses,
        before.0 / prefixed.0
    );
    for other in [fresh, cached, prefixed] {
        assert_eq!((before.1, before.2), (other.1, other.2), "a session ran otherwise than as before");
    }
}

/// Runs every input as a session; prints the rates; returns the seconds taken, the bench time
/// (ms) and the violations found, summed.
fn measure(how: &str, data: &[Vec<u8>], max_len: usize, mut run: impl FnMut(&[u8]) -> Bench) -> (f64, u64, usize) {
    let start = Instant::now();
    let (mut bench_ms, mut violations) = (0u64, 0usize);
    for d in data {
        let bench = run(d);
        bench_ms += bench.time_ms();
        violations += bench.checker.violations().len();
    }
    let s = start.elapsed().as_secs_f64();
    let n = data.len() as f64;
    println!(
        "{how}: {} inputs of 0..={max_len} bytes in {s:.2} s: {:.0} sessions/s, {:.2} ms of CPU and {:.1} s of bench time per session, {violations} violations",
        data.len(),
        n / s,
        1000.0 * s / n,
        bench_ms as f64 / 1000.0 / n
    );
    (s, bench_ms, violations)
}
