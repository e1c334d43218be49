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
