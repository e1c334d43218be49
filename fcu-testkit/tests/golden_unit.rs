//! Unit-level golden vectors (`data/golden/unit/`, produced by the reference's own C code):
//! each algorithm of `Config::reference()` against them, bit for bit.

use fcu_core::ahrs::{Mahony, MahonyConfig};
use fcu_core::control::{AngleLoop, ControlConfig, RateLoop};
use fcu_core::filter::{Biquad, BiquadCoeffs};
use fcu_core::math::{inv_sqrt_fast, quat_to_tilt, Quat};
use fcu_core::mixer::MixerConfig;
use fcu_core::mixer::Saturation;
use fcu_core::rc::{RcConfig, StickCounts, Sticks};

fn rows(name: &str) -> Vec<Vec<String>> {
    let path = format!("{}/data/golden/unit/{name}", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    text.lines().skip(1).map(|l| l.split(',').map(str::to_string).collect()).collect()
}

fn f(s: &str) -> f32 {
    s.parse().unwrap_or_else(|_| panic!("bad float {s}"))
}

fn same(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

#[test]
fn gyro_iir_is_bit_exact() {
    let mut bq = Biquad::new(BiquadCoeffs::REFERENCE_GYRO);
    let data = rows("iir.csv");
    assert_eq!(data.len(), 2000);
    for r in data {
        let x: i32 = r[1].parse().unwrap();
        let y = bq.update(x as f32);
        assert!(same(y, f(&r[2])), "step {}: {y} vs {}", r[0], r[2]);
    }
}

#[test]
fn fast_inverse_square_root_is_bit_exact() {
    let data = rows("invsqrt.csv");
    assert_eq!(data.len(), 2000);
    for r in data {
        let y = inv_sqrt_fast(f(&r[0]));
        assert!(same(y, f(&r[1])), "x {}: {y} vs {}", r[0], r[1]);
    }
}

#[test]
fn mahony_update_and_euler_are_bit_exact() {
    let data = rows("ahrs.csv");
    assert_eq!(data.len(), 2000);
    let mut seq = String::new();
    let mut m = Mahony::new(MahonyConfig::REFERENCE);
    for r in data {
        if r[0] != seq {
            seq = r[0].clone();
            m = Mahony::new(MahonyConfig::REFERENCE);
        }
        let gthr: i32 = r[2].parse().unwrap();
        m.update([f(&r[3]), f(&r[4]), f(&r[5])], [f(&r[6]), f(&r[7]), f(&r[8])], gthr < 200);
        let q = m.quat();
        let want = Quat::new(f(&r[9]), f(&r[10]), f(&r[11]), f(&r[12]));
        for (a, b) in [(q.w, want.w), (q.x, want.x), (q.y, want.y), (q.z, want.z)] {
            assert!(same(a, b), "seq {} step {}: q {q:?} vs {want:?}", r[0], r[1]);
        }
        let e = quat_to_tilt(q);
        assert!(same(e.pitch_rad, f(&r[13])) && same(e.roll_rad, f(&r[14])), "seq {} step {}: euler", r[0], r[1]);
    }
}

#[test]
fn quaternion_to_euler_is_bit_exact_except_where_the_asin_argument_is_clamped() {
    let data = rows("quat2euler.csv");
    assert_eq!(data.len(), 2000);
    let mut clamped = 0;
    for r in &data {
        let e = quat_to_tilt(Quat::new(f(&r[0]), f(&r[1]), f(&r[2]), f(&r[3])));
        assert!(same(e.pitch_rad, f(&r[4])), "{r:?}: pitch {}", e.pitch_rad);
        let want_roll = f(&r[5]);
        if want_roll.is_nan() {
            // The reference's asin of an argument beyond ±1 is NaN; ours clamps to ±π/2.
            assert!((e.roll_rad.abs() - core::f32::consts::FRAC_PI_2).abs() < 1e-6, "{r:?}");
            clamped += 1;
        } else {
            assert!(same(e.roll_rad, want_roll), "{r:?}: roll {}", e.roll_rad);
        }
    }
    assert_eq!(clamped, 6, "exactly the last six rows have |asin argument| > 1");
}

#[test]
fn stick_targets_and_yaw_accumulation_are_bit_exact() {
    let cfg = RcConfig::REFERENCE;
    let data = rows("rc_targets.csv");
    assert_eq!(data.len(), 2000);
    let mut seq = String::new();
    let mut yaw = 0.0f32;
    for r in data {
        if r[0] != seq {
            seq = r[0].clone();
            yaw = 0.0;
        }
        let n = |i: usize| -> i16 { r[i].parse().unwrap() };
        let s = Sticks::new(n(2), n(3), n(5), n(4));
        let (pitch, roll) = cfg.tilt_targets(&s);
        let step = cfg.yaw_step(&s, fcu_core::Config::reference().timing.outer_hz());
        if step != 0.0 {
            yaw += step;
        }
        if cfg.throttle_low(&s) {
            yaw = 0.0;
        }
        assert!(same(pitch, f(&r[6])) && same(roll, f(&r[7])), "seq {} step {}: {pitch} {roll}", r[0], r[1]);
        assert!(same(yaw, f(&r[8])), "seq {} step {}: yaw {yaw} vs {}", r[0], r[1], r[8]);
    }
}

#[test]
fn pulse_width_to_stick_is_exact() {
    let cfg = RcConfig::REFERENCE;
    let data = rows("rc_decode.csv");
    assert_eq!(data.len(), 2000);
    for r in data {
        let ch: usize = r[0].parse().unwrap();
        let width: u16 = r[1].parse().unwrap();
        let want: i16 = r[2].parse().unwrap();
        assert_eq!(cfg.stick_from_width(ch, width), StickCounts(want), "{r:?}");
    }
}

#[test]
fn cascade_mixer_and_clamp_are_bit_exact() {
    let ctrl = ControlConfig::REFERENCE;
    let mixer = MixerConfig::REFERENCE_DC;
    let data = rows("pid.csv");
    assert_eq!(data.len(), 2000);
    let mut outer = AngleLoop::default();
    let mut inner = RateLoop::default();
    let mut s1 = [0.0f32; 3];
    let mut saw_integrator_clamp = false;
    for r in data {
        let gthr: i16 = r[1].parse().unwrap();
        let low = gthr < 200;
        if r[8] == "1" {
            let target = [f(&r[2]), f(&r[3]), f(&r[4])];
            let est = [f(&r[5]), f(&r[6]), f(&r[7])];
            s1 = outer.rate_demands(&ctrl, target, est, low);
        }
        for (a, i) in s1.iter().zip(12..) {
            assert!(same(*a, f(&r[i])), "step {}: s1 {s1:?}", r[0]);
        }
        let s2 = inner.commands(&ctrl, s1, [f(&r[9]), f(&r[10]), f(&r[11])], low, Saturation::NONE);
        for (a, i) in s2.iter().zip(15..) {
            assert!(same(*a, f(&r[i])), "step {}: s2 {s2:?} vs {:?}", r[0], &r[15..18]);
        }
        let (m, _) = mixer.mix(mixer.throttle_counts(StickCounts(gthr)), s2);
        for ((a, i), j) in m.iter().zip(18..).zip(22..) {
            assert!(same(*a, f(&r[i])), "step {}: motor {m:?}", r[0]);
            let ccr: u16 = r[j].parse().unwrap();
            assert_eq!(mixer.to_compare(*a), ccr, "step {}", r[0]);
        }
        saw_integrator_clamp |= inner.integrators()[0].abs() == 20.0;
    }
    assert!(saw_integrator_clamp, "the vectors drive integ2 into its ±20 clamp");
}
