//! End-to-end golden replay: `Config::reference()` against the reference firmware's own
//! output, tick for tick, and the `fcu-sim replay` command line.

use std::io::Read;
use std::process::Command;

use fcu_core::Config;
use fcu_testkit::replay;

fn golden(name: &str) -> String {
    let path = format!("{}/data/golden/replay/{name}.gz", env!("CARGO_MANIFEST_DIR"));
    let file = std::fs::File::open(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let mut s = String::new();
    flate2::read::GzDecoder::new(file).read_to_string(&mut s).unwrap();
    s
}

fn check_scenario(n: u32) {
    let input = replay::parse_input(&golden(&format!("scenario_{n}.in.csv"))).unwrap();
    let want_text = golden(&format!("scenario_{n}.out.csv"));
    let want = replay::parse_output(&want_text).unwrap();
    let got = replay::run(Config::reference(), &input).unwrap();
    let c = replay::compare(&got, &want);
    assert_eq!(c.rows, 8000);
    assert!(c.out_of_tolerance.is_empty(), "scenario {n}: {:?}", &c.out_of_tolerance[..c.out_of_tolerance.len().min(10)]);
    assert_eq!((c.inexact_ccr, c.inexact_floats), (0, 0), "scenario {n} is not bit-exact");
    // The text itself is byte-identical (same %.9g formatting).
    assert_eq!(replay::format_output(&got), want_text, "scenario {n}: output text differs");
}

#[test]
fn scenario_1_is_bit_exact() {
    check_scenario(1);
}

#[test]
fn scenario_2_is_bit_exact() {
    check_scenario(2);
}

#[test]
fn scenario_3_is_bit_exact() {
    check_scenario(3);
}

#[test]
fn the_first_outer_step_follows_tick_1604_and_motors_start_no_earlier_than_1600() {
    let input = replay::parse_input(&golden("scenario_3.in.csv")).unwrap();
    let got = replay::run(Config::reference(), &input).unwrap();
    let first_q = got.iter().position(|r| r.q != [1.0, 0.0, 0.0, 0.0]).unwrap();
    assert_eq!(got[first_q].tick, 1604);
    let first_motor = got.iter().position(|r| r.ccr != [0; 4]).unwrap();
    assert_eq!(got[first_motor].tick, 1600, "scenario 3 is armed with throttle up before calibration ends");
}

fn write_tmp(name: &str, text: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("fcu-replay-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn cli_replay_reproduces_a_scenario_on_stdout() {
    let input = write_tmp("s2.in.csv", &golden("scenario_2.in.csv"));
    let out = Command::new(env!("CARGO_BIN_EXE_fcu-sim")).args(["replay", "--profile", "reference"]).arg(&input).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(String::from_utf8(out.stdout).unwrap(), golden("scenario_2.out.csv"));
}

#[test]
fn cli_replay_names_the_line_of_a_letter_in_a_number_column() {
    let mut text = golden("scenario_1.in.csv");
    text = text.replacen("\n5,", "\n5x,", 1);
    let input = write_tmp("bad_letter.in.csv", &text);
    let out = Command::new(env!("CARGO_BIN_EXE_fcu-sim")).arg("replay").arg(&input).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("line 6") && err.contains("`tick`") && err.contains("5x"), "{err}");
}

#[test]
fn cli_replay_names_the_line_of_a_missing_column() {
    let text = "tick,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z,ail_width,ele_width,thr_width,rud_width,link,armed,cal_request\n\
                1,0,0,8197,0,0,0,6000,6000,4400,6000,0,0,0\n\
                2,0,0,8197,0,0,0,6000,6000,4400,6000,0,0\n";
    let input = write_tmp("missing.in.csv", text);
    let out = Command::new(env!("CARGO_BIN_EXE_fcu-sim")).arg("replay").arg(&input).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("line 3") && err.contains("expected 14 columns, found 13"), "{err}");
}

#[test]
fn cli_replay_reports_a_missing_file() {
    let out = Command::new(env!("CARGO_BIN_EXE_fcu-sim")).args(["replay", "/nonexistent/x.csv"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot read /nonexistent/x.csv"));
}

/// Replay scenario 1 with `cal_request` raised on `ticks`, and return the first tick whose
/// output row differs from the unmodified replay.
fn first_difference_with_calibration_request(ticks: std::ops::RangeInclusive<u32>) -> Option<u32> {
    let input = replay::parse_input(&golden("scenario_1.in.csv")).unwrap();
    let plain = replay::run(Config::reference(), &input).unwrap();
    let mut requested = input.clone();
    for row in requested.iter_mut().filter(|r| ticks.contains(&r.tick)) {
        row.radio.cal_request = true;
    }
    let recal = replay::run(Config::reference(), &requested).unwrap();
    plain.iter().zip(&recal).find(|(a, b)| a != b).map(|(a, _)| a.tick)
}

#[test]
fn a_recalibration_request_takes_effect_on_its_800th_sample() {
    // golden README §4.4: a request at tick t averages ticks t..t+799; the new offsets are
    // computed at t+799 and that tick's own sample already uses them (scenario 4: 4541 → 5340).
    // Flying at that point, the new gyro offsets move the yaw estimate on that very tick.
    assert_eq!(first_difference_with_calibration_request(4541..=4751), Some(5340));
}

#[test]
fn a_calibration_request_during_start_up_runs_from_tick_1600_to_2399() {
    // golden README §4.4 (scenario 6): a request during the start-up calibration starts its
    // average at tick 1600, right after the start-up offsets, and completes at 2399; the
    // outer step that follows tick 2399 already averages a sample with the new offsets.
    assert_eq!(first_difference_with_calibration_request(1019..=1229), Some(2399));
}
