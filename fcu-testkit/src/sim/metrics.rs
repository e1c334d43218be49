//! Control-quality numbers of `docs/simulation.md#metrics` and the scenario pass criteria, both
//! computed from a [`FlightLog`] only (so they can be recomputed from any recorded flight).

use super::scenario::{describe, Axis, Criterion, Scenario};
use super::{FlightLog, LogRow, VerticalMode};

/// Within this many degrees of level counts as "level" after a link loss.
pub const LEVEL_TOLERANCE_DEG: f64 = 3.0;

/// The metrics of one flight (`docs/simulation.md#metrics`). `None` where the scenario does not
/// exercise it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Metrics {
    /// RMS of (true − target) roll and pitch over the scenario's hover window, degrees.
    pub hover_rms_deg: Option<f64>,
    /// Worst 10→90 % rise time over the scenario's 20° steps, s (`None` if never reached 90 %).
    pub step_rise_s: Option<f64>,
    /// Worst overshoot over the steps, % of the step.
    pub step_overshoot_pct: Option<f64>,
    /// From the link loss to within 3° of level, s.
    pub level_after_link_loss_s: Option<f64>,
    /// RMS of (commanded − true) yaw rate over the yaw window, °/s.
    pub yaw_rate_rms_dps: Option<f64>,
    /// Largest tilt from level while armed, degrees.
    pub max_tilt_armed_deg: Option<f64>,
    /// RMS of the compare values' change from one tick to the next over the hover window,
    /// counts: the noise the controller puts on the motors (the derivative's low-pass is the
    /// main knob).
    pub motor_jitter_counts: Option<f64>,
    /// RMS of (true height − the hold's target) over the hold window, m.
    pub height_rms_m: Option<f64>,
    /// Its two parts: the mean of (true height − target), the height estimate's offset from
    /// the truth once the hold has settled, and the RMS about that mean, the hold's unsteadiness.
    pub height_offset_m: Option<f64>,
    pub height_rms_about_offset_m: Option<f64>,
    /// The true height's change over the hold window (its last second's mean minus its first
    /// second's), m.
    pub height_drift_m: Option<f64>,
    /// Downward speed at the first touchdown after the landing began, m/s.
    pub touchdown_speed_m_s: Option<f64>,
    /// How far the drone sank below its height at a barometer fault once the hold let go, m.
    pub height_lost_leaving_hold_m: Option<f64>,
    /// From the touchdown to disarmed, s.
    pub disarmed_after_touchdown_s: Option<f64>,
    /// RMS of the collective motor command in the 1–5 Hz band over the hold window (the
    /// hover window where there is none), counts.
    pub throttle_oscillation_counts: Option<f64>,
}

fn window(log: &FlightLog, from_s: f64, to_s: f64) -> impl Iterator<Item = &LogRow> {
    log.rows.iter().filter(move |r| r.t_s >= from_s && r.t_s < to_s)
}

fn tilt_deg(r: &LogRow) -> f64 {
    // Tilt of the body z axis from vertical: cos(tilt) = cos(pitch)·cos(roll) for this Euler pair.
    let c = r.pitch_deg.to_radians().cos() * r.roll_deg.to_radians().cos();
    c.clamp(-1.0, 1.0).acos().to_degrees()
}

pub fn attitude_rms_deg(log: &FlightLog, from_s: f64, to_s: f64) -> Option<f64> {
    let (sum, n) = window(log, from_s, to_s).fold((0.0, 0usize), |(s, n), r| {
        let er = r.roll_deg - r.roll_target_deg;
        let ep = r.pitch_deg - r.pitch_target_deg;
        (s + er * er + ep * ep, n + 1)
    });
    (n > 0).then(|| (sum / (2 * n) as f64).sqrt())
}

pub fn max_tilt_deg(log: &FlightLog, from_s: f64, to_s: f64) -> Option<f64> {
    window(log, from_s, to_s).map(tilt_deg).reduce(f64::max)
}

/// Rise time (10→90 %) and overshoot (%) of the true angle after a stick step from level to
/// `target_deg` at `t_s`, over the next 1.0 s (while the stick is held). Fractions are of the
/// commanded step (0 → target), as a step response is read.
pub fn step_response(log: &FlightLog, axis: Axis, t_s: f64, target_deg: f64) -> (Option<f64>, Option<f64>) {
    let angle = |r: &LogRow| match axis {
        Axis::Roll => r.roll_deg,
        Axis::Pitch => r.pitch_deg,
    };
    let start = 0.0;
    let span = target_deg - start;
    if span.abs() < 1e-6 {
        return (None, None);
    }
    let mut t10 = None;
    let mut t90 = None;
    let mut peak = 0.0f64;
    for r in window(log, t_s, t_s + 1.0) {
        let frac = (angle(r) - start) / span;
        if t10.is_none() && frac >= 0.1 {
            t10 = Some(r.t_s);
        }
        if t90.is_none() && frac >= 0.9 {
            t90 = Some(r.t_s);
        }
        peak = peak.max(frac);
    }
    let rise = t10.zip(t90).map(|(a, b)| b - a);
    (rise, Some(((peak - 1.0) * 100.0).max(0.0)))
}

/// Time from the link loss at `t_s` until roll and pitch are within 3° of level, checked
/// while the supervisor levels the drone (the first 1 s, stage 1).
pub fn level_after_link_loss_s(log: &FlightLog, t_s: f64) -> Option<f64> {
    window(log, t_s, t_s + 1.0)
        .find(|r| r.roll_deg.abs() < LEVEL_TOLERANCE_DEG && r.pitch_deg.abs() < LEVEL_TOLERANCE_DEG)
        .map(|r| r.t_s - t_s)
}

/// RMS of the commanded yaw rate minus the true yaw rate, each averaged over the same 0.1 s,
/// °/s. The commanded rate is what the pilot's stick asks for (`LogRow::yaw_rate_cmd_dps`,
/// which the harness works out from the frames it sends, [`super::stick_rate`]), not the
/// core's own heading target, so that a controller which smooths or delays its target is
/// measured against the stick all the same.
pub fn yaw_rate_rms_dps(log: &FlightLog, from_s: f64, to_s: f64) -> Option<f64> {
    let w: Vec<&LogRow> = window(log, from_s, to_s).collect();
    let lag = (0.1 * log.tick_hz).round().max(1.0) as usize;
    // Sums of the stick's rate up to each row: a window's mean is a difference of two.
    let mut cmd_sums = Vec::with_capacity(w.len() + 1);
    cmd_sums.push(0.0);
    for r in &w {
        let last = cmd_sums.last().copied().unwrap_or(0.0);
        cmd_sums.push(last + r.yaw_rate_cmd_dps);
    }
    let mut sum = 0.0;
    let mut n = 0usize;
    for (i, (a, b)) in w.iter().zip(w.iter().skip(lag)).enumerate() {
        let dt = b.t_s - a.t_s;
        if dt <= 0.0 {
            continue;
        }
        // The rate asked for over the ticks after `a` up to `b`: what moves the heading from
        // a's to b's.
        let cmd = (cmd_sums[i + lag + 1] - cmd_sums[i + 1]) / lag as f64;
        let mut dyaw = b.yaw_deg - a.yaw_deg;
        // The true heading wraps at ±180°.
        while dyaw > 180.0 {
            dyaw -= 360.0;
        }
        while dyaw < -180.0 {
            dyaw += 360.0;
        }
        let e = cmd - dyaw / dt;
        sum += e * e;
        n += 1;
    }
    (n > 0).then(|| (sum / n as f64).sqrt())
}

pub fn compute(log: &FlightLog, s: &Scenario) -> Metrics {
    let mut m = Metrics::default();
    if let Some((a, b)) = s.hover_window_s {
        m.hover_rms_deg = attitude_rms_deg(log, a, b);
    }
    let mut rises = Vec::new();
    let mut overs = Vec::new();
    let mut missed = false;
    for &(axis, t_s, target) in &s.steps {
        let (r, o) = step_response(log, axis, t_s, target);
        match r {
            Some(r) => rises.push(r),
            None => missed = true,
        }
        overs.extend(o);
    }
    if !s.steps.is_empty() {
        m.step_rise_s = if missed { None } else { rises.into_iter().reduce(f64::max) };
        m.step_overshoot_pct = overs.into_iter().reduce(f64::max);
    }
    if let Some(t) = s.link_loss_s {
        m.level_after_link_loss_s = level_after_link_loss_s(log, t);
    }
    if let Some((a, b)) = s.yaw_window_s {
        m.yaw_rate_rms_dps = yaw_rate_rms_dps(log, a, b);
    }
    m.max_tilt_armed_deg = log.rows.iter().filter(|r| r.armed && r.alt_m > 0.05).map(tilt_deg).reduce(f64::max);
    if let Some((a, b)) = s.hover_window_s {
        m.motor_jitter_counts = motor_jitter_counts(log, a, b);
    }
    if let Some((a, b)) = s.hold_window_s {
        m.height_rms_m = height_rms_m(log, a, b);
        m.height_offset_m = height_offset_m(log, a, b);
        m.height_rms_about_offset_m = m.height_rms_m.zip(m.height_offset_m).map(|(r, o)| (r * r - o * o).max(0.0).sqrt());
        m.height_drift_m = height_drift_m(log, a, b);
    }
    if let Some(t) = s.landing_s {
        let touchdown = touchdown(log, t);
        m.touchdown_speed_m_s = touchdown.map(|(_, v)| v);
        m.disarmed_after_touchdown_s = touchdown.and_then(|(t, _)| disarmed_after_s(log, t));
    }
    if let Some(t) = s.baro_freeze_s {
        m.height_lost_leaving_hold_m = height_lost_leaving_hold_m(log, t);
    }
    if let Some((a, b)) = s.hold_window_s.or(s.hover_window_s) {
        m.throttle_oscillation_counts = collective_band_rms_counts(log, a, b, OSCILLATION_BAND_HZ);
    }
    m
}

/// Rows with a finite hold target in the window: the hold in force.
fn holding(log: &FlightLog, from_s: f64, to_s: f64) -> impl Iterator<Item = &LogRow> {
    window(log, from_s, to_s).filter(|r| r.vertical.alt_target_m.is_finite())
}

/// RMS of (true height − the hold's target) over the rows of the window where the hold has a
/// target, m (`None` if it never has one there).
pub fn height_rms_m(log: &FlightLog, from_s: f64, to_s: f64) -> Option<f64> {
    let (sum, n) = holding(log, from_s, to_s).fold((0.0, 0usize), |(s, n), r| {
        let e = r.alt_m - r.vertical.alt_target_m;
        (s + e * e, n + 1)
    });
    (n > 0).then(|| (sum / n as f64).sqrt())
}

/// The mean of (true height − the hold's target) where the hold has a target, m.
pub fn height_offset_m(log: &FlightLog, from_s: f64, to_s: f64) -> Option<f64> {
    let (sum, n) = holding(log, from_s, to_s).fold((0.0, 0usize), |(s, n), r| (s + r.alt_m - r.vertical.alt_target_m, n + 1));
    (n > 0).then(|| sum / n as f64)
}

fn mean_height_m(log: &FlightLog, from_s: f64, to_s: f64) -> Option<f64> {
    let (sum, n) = window(log, from_s, to_s).fold((0.0, 0usize), |(s, n), r| (s + r.alt_m, n + 1));
    (n > 0).then(|| sum / n as f64)
}

/// The true height's mean over the window's last second minus its mean over the first, m:
/// the slow wander of a hold (the barometer's drift followed faithfully), the noise averaged.
pub fn height_drift_m(log: &FlightLog, from_s: f64, to_s: f64) -> Option<f64> {
    if to_s - from_s < 2.0 {
        return None;
    }
    Some(mean_height_m(log, to_s - 1.0, to_s)? - mean_height_m(log, from_s, from_s + 1.0)?)
}

/// Within this of the floor a descent is a touchdown, m.
const TOUCHDOWN_ZONE_M: f64 = 0.01;

/// The first touchdown after `after_s`: where the drone, having come within 1 cm of the
/// floor, stops or bounces (its true climb rate no longer downward, or on the floor), and its
/// fastest downward speed from the last row above that centimetre to there, m/s. Not the
/// first row at height 0: a drone that bounces off the floor within a control tick (its
/// thrust and ground effect lift it again) shows no such row.
pub fn touchdown(log: &FlightLog, after_s: f64) -> Option<(f64, f64)> {
    let rows: Vec<&LogRow> = window(log, after_s, f64::INFINITY).collect();
    let entry = rows.windows(2).position(|w| w[0].alt_m > TOUCHDOWN_ZONE_M && w[1].alt_m <= TOUCHDOWN_ZONE_M)?;
    let approach = rows.get(entry..)?;
    let contact = approach.iter().skip(1).position(|r| r.alt_m <= 0.0 || r.vertical.climb_m_s >= 0.0)? + 1;
    let speed = approach.get(..contact)?.iter().map(|r| -r.vertical.climb_m_s).fold(0.0, f64::max);
    Some((approach.get(contact)?.t_s, speed))
}

/// From `touchdown_s` to the first row disarmed (motors not allowed to run), s.
pub fn disarmed_after_s(log: &FlightLog, touchdown_s: f64) -> Option<f64> {
    window(log, touchdown_s, f64::INFINITY).find(|r| !r.armed).map(|r| r.t_s - touchdown_s)
}

/// The height lost when a barometer fault at `fault_s` ends the hold: the mean true height
/// over the 0.5 s before the fault minus the lowest true height over the 5 s after it (not
/// below zero), m. `None` if the log does not reach past the fault.
pub fn height_lost_leaving_hold_m(log: &FlightLog, fault_s: f64) -> Option<f64> {
    let before = mean_height_m(log, fault_s - 0.5, fault_s)?;
    let lowest = window(log, fault_s, fault_s + 5.0).map(|r| r.alt_m).reduce(f64::min)?;
    Some((before - lowest).max(0.0))
}

/// The throttle-oscillation band, Hz: faster than a hold's own corrections and slower than
/// the attitude loops, where a height loop fighting the barometer's noise and the pilot's
/// corrections show.
pub const OSCILLATION_BAND_HZ: (f64, f64) = (1.0, 5.0);

/// RMS of the collective motor command (the mean of the four compare values) over
/// `[from_s, to_s)` in the band `band_hz`, counts: the window's mean taken off, then the
/// power of its discrete Fourier transform's bins in the band (Parseval). Averaged to 100 Hz
/// first (what lies above the band's top is of no interest here).
pub fn collective_band_rms_counts(log: &FlightLog, from_s: f64, to_s: f64, band_hz: (f64, f64)) -> Option<f64> {
    let per = (log.tick_hz / 100.0).round().max(1.0) as usize;
    let collective: Vec<f64> = window(log, from_s, to_s).map(|r| r.motors.iter().map(|&m| f64::from(m)).sum::<f64>() / 4.0).collect();
    let x: Vec<f64> = collective.chunks_exact(per).map(|c| c.iter().sum::<f64>() / per as f64).collect();
    let n = x.len();
    if n < 16 {
        return None;
    }
    let dt = per as f64 / log.tick_hz;
    let mean = x.iter().sum::<f64>() / n as f64;
    let df = 1.0 / (n as f64 * dt);
    let (k_lo, k_hi) = ((band_hz.0 / df).ceil() as usize, ((band_hz.1 / df).floor() as usize).min((n - 1) / 2));
    let mut power = 0.0;
    for k in k_lo.max(1)..=k_hi {
        let w = std::f64::consts::TAU * k as f64 / n as f64;
        let (mut re, mut im) = (0.0, 0.0);
        for (i, v) in x.iter().enumerate() {
            let (sin, cos) = (w * i as f64).sin_cos();
            re += (v - mean) * cos;
            im -= (v - mean) * sin;
        }
        // A one-sided bin carries twice its two-sided power.
        power += 2.0 * (re * re + im * im) / (n as f64 * n as f64);
    }
    Some(power.sqrt())
}

/// RMS over the four motors of the compare value's change between consecutive ticks in
/// `[from_s, to_s)`, counts.
pub fn motor_jitter_counts(log: &FlightLog, from_s: f64, to_s: f64) -> Option<f64> {
    let rows: Vec<&LogRow> = window(log, from_s, to_s).collect();
    let (mut sum, mut n) = (0.0, 0usize);
    for w in rows.windows(2) {
        for (a, b) in w[0].motors.iter().zip(&w[1].motors) {
            let d = f64::from(*b) - f64::from(*a);
            sum += d * d;
            n += 1;
        }
    }
    (n > 0).then(|| (sum / n as f64).sqrt())
}

/// The verdict on one criterion.
#[derive(Clone, Debug, PartialEq)]
pub struct Verdict {
    pub criterion: String,
    pub passed: bool,
    pub detail: String,
}

fn fmt_opt(v: Option<f64>, unit: &str) -> String {
    v.map_or_else(|| "n/a".to_string(), |x| format!("{x:.3}{unit}"))
}

pub fn check(log: &FlightLog, c: &Criterion) -> Verdict {
    let end_s = log.rows.last().map_or(0.0, |r| r.t_s);
    let (passed, detail) = match *c {
        Criterion::ArmedBy { t_s } => {
            let first = log.rows.iter().find(|r| r.armed).map(|r| r.t_s);
            (first.is_some_and(|f| f <= t_s), format!("first armed at {}", fmt_opt(first, " s")))
        }
        Criterion::NeverArmedBefore { t_s } => {
            let first = log.rows.iter().find(|r| r.armed).map(|r| r.t_s);
            (first.is_none_or(|f| f >= t_s), format!("first armed at {}", fmt_opt(first, " s")))
        }
        Criterion::AttitudeRmsBelow { from_s, to_s, max_deg } => {
            let v = attitude_rms_deg(log, from_s, to_s);
            (v.is_some_and(|v| v < max_deg), format!("RMS {}", fmt_opt(v, "°")))
        }
        Criterion::TiltBelow { from_s, to_s, max_deg } => {
            let v = max_tilt_deg(log, from_s, to_s);
            (v.is_some_and(|v| v < max_deg), format!("max tilt {}", fmt_opt(v, "°")))
        }
        Criterion::AltitudeAbove { from_s, to_s, min_m } => {
            let v = window(log, from_s, to_s).map(|r| r.alt_m).reduce(f64::min);
            (v.is_some_and(|v| v > min_m), format!("lowest {}", fmt_opt(v, " m")))
        }
        Criterion::Step { axis, t_s, target_deg, rise_max_s, overshoot_max_pct } => {
            let (rise, over) = step_response(log, axis, t_s, target_deg);
            let ok = rise.is_some_and(|r| r < rise_max_s) && over.is_some_and(|o| o < overshoot_max_pct);
            (ok, format!("rise {}, overshoot {}", fmt_opt(rise, " s"), fmt_opt(over, " %")))
        }
        Criterion::StateSeen { from_s, to_s, state } => {
            let seen = window(log, from_s, to_s).any(|r| r.state == state);
            (seen, if seen { "seen".into() } else { "not seen".into() })
        }
        Criterion::StateHolds { from_s, to_s, state } => {
            let other = window(log, from_s, to_s).find(|r| r.state != state);
            (other.is_none(), other.map_or_else(|| "held".into(), |r| format!("`{}` at {:.3} s", r.state.name(), r.t_s)))
        }
        Criterion::MotorsOffDisarmedFrom { t_s } => {
            let bad = window(log, t_s, f64::INFINITY).find(|r| r.armed || r.motors.iter().any(|&m| m != 0));
            let reached = end_s >= t_s;
            (
                reached && bad.is_none(),
                match bad {
                    Some(r) => format!("at {:.3} s: state `{}`, motors {:?}", r.t_s, r.state.name(), r.motors),
                    None if reached => "motors 0, disarmed".into(),
                    None => format!("flight ended at {end_s:.1} s"),
                },
            )
        }
        Criterion::LevelAfterLinkLoss { t_s, max_s } => {
            let v = level_after_link_loss_s(log, t_s);
            (v.is_some_and(|v| v <= max_s), format!("level after {}", fmt_opt(v, " s")))
        }
        Criterion::YawRateRmsBelow { from_s, to_s, max_dps } => {
            let v = yaw_rate_rms_dps(log, from_s, to_s);
            (v.is_some_and(|v| v < max_dps), format!("RMS {}", fmt_opt(v, " °/s")))
        }
        Criterion::CalibrationNotDoneAt { t_s } => {
            let r = window(log, 0.0, t_s).last();
            let restarts = window(log, 0.0, t_s).map(|r| r.calibration_restarts).max().unwrap_or(0);
            (
                r.is_some_and(|r| !r.calibrated),
                format!("calibrated: {}, motion restarts seen: {restarts}", r.map_or("n/a".into(), |r| r.calibrated.to_string())),
            )
        }
        Criterion::CalibratedBy { t_s } => {
            let first = log.rows.iter().find(|r| r.calibrated).map(|r| r.t_s);
            (first.is_some_and(|f| f <= t_s), format!("calibrated at {}", fmt_opt(first, " s")))
        }
        Criterion::HeightRmsBelow { .. }
        | Criterion::HeightDriftBelow { .. }
        | Criterion::HeightNear { .. }
        | Criterion::TouchdownSpeedBelow { .. }
        | Criterion::DisarmedAfterTouchdownWithin { .. }
        | Criterion::MotorsOffOnlyBelow { .. }
        | Criterion::HeightLostLeavingHoldBelow { .. }
        | Criterion::BaroFaultReportedWithin { .. }
        | Criterion::VerticalModeHolds { .. }
        | Criterion::VerticalModeSeen { .. } => check_vertical(log, c),
    };
    Verdict { criterion: describe(c), passed, detail }
}

/// The criteria on the height, the landing and the vertical mode ([`check`]'s other half).
fn check_vertical(log: &FlightLog, c: &Criterion) -> (bool, String) {
    match *c {
        Criterion::HeightRmsBelow { from_s, to_s, max_m } => {
            let v = height_rms_m(log, from_s, to_s);
            (v.is_some_and(|v| v <= max_m), format!("RMS {}", fmt_opt(v, " m")))
        }
        Criterion::HeightDriftBelow { from_s, to_s, max_m } => {
            let v = height_drift_m(log, from_s, to_s);
            (v.is_some_and(|v| v.abs() <= max_m), format!("drift {}", fmt_opt(v, " m")))
        }
        Criterion::HeightNear { from_s, to_s, target_m, tolerance_m } => {
            let (lo, hi) =
                window(log, from_s, to_s).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), r| (lo.min(r.alt_m), hi.max(r.alt_m)));
            let ok = lo.is_finite() && (lo - target_m).abs() <= tolerance_m && (hi - target_m).abs() <= tolerance_m;
            (ok, if lo.is_finite() { format!("between {lo:.3} and {hi:.3} m") } else { "no rows".into() })
        }
        Criterion::TouchdownSpeedBelow { after_s, max_m_s } => {
            let v = touchdown(log, after_s);
            (v.is_some_and(|(_, v)| v <= max_m_s), v.map_or("no touchdown".into(), |(t, v)| format!("{v:.3} m/s at {t:.3} s")))
        }
        Criterion::DisarmedAfterTouchdownWithin { after_s, max_s } => {
            let v = touchdown(log, after_s).and_then(|(t, _)| disarmed_after_s(log, t));
            (v.is_some_and(|v| v <= max_s), format!("disarmed {} after the touchdown", fmt_opt(v, " s")))
        }
        Criterion::MotorsOffOnlyBelow { from_s, max_m } => {
            let bad = window(log, from_s, f64::INFINITY).find(|r| r.motors == [0; 4] && r.alt_m > max_m);
            (bad.is_none(), bad.map_or("never off in the air".into(), |r| format!("motors off at {:.3} m at {:.3} s", r.alt_m, r.t_s)))
        }
        Criterion::HeightLostLeavingHoldBelow { t_s, max_m } => {
            let v = height_lost_leaving_hold_m(log, t_s);
            (v.is_some_and(|v| v <= max_m), format!("lost {}", fmt_opt(v, " m")))
        }
        Criterion::BaroFaultReportedWithin { t_s, max_s } => {
            let first = window(log, t_s, f64::INFINITY).find(|r| r.vertical.baro_fault.is_some()).map(|r| r.t_s - t_s);
            (first.is_some_and(|f| f <= max_s), format!("reported {} after", fmt_opt(first, " s")))
        }
        Criterion::VerticalModeHolds { from_s, to_s, mode } => {
            let other = window(log, from_s, to_s).find(|r| r.vertical.mode != Some(mode));
            (
                other.is_none(),
                other.map_or_else(
                    || "held".into(),
                    |r| format!("`{}` at {:.3} s", r.vertical.mode.map_or("none", VerticalMode::name), r.t_s),
                ),
            )
        }
        Criterion::VerticalModeSeen { from_s, to_s, mode } => {
            let seen = window(log, from_s, to_s).any(|r| r.vertical.mode == Some(mode));
            (seen, if seen { "seen".into() } else { "not seen".into() })
        }
        _ => (false, format!("{} is not a criterion on the height", describe(c))),
    }
}

pub fn check_all(log: &FlightLog, s: &Scenario) -> Vec<Verdict> {
    s.criteria.iter().map(|c| check(log, c)).collect()
}

/// The metrics as `name value` lines for a summary.
pub fn lines(m: &Metrics) -> Vec<(&'static str, String)> {
    vec![
        ("RMS attitude error while hovering", fmt_opt(m.hover_rms_deg, "°")),
        ("20° step rise time (10-90 %, worst)", fmt_opt(m.step_rise_s, " s")),
        ("20° step overshoot (worst)", fmt_opt(m.step_overshoot_pct, " %")),
        ("time to level after link loss", fmt_opt(m.level_after_link_loss_s, " s")),
        ("yaw rate RMS error", fmt_opt(m.yaw_rate_rms_dps, " °/s")),
        ("max tilt while armed and airborne", fmt_opt(m.max_tilt_armed_deg, "°")),
        ("motor jitter (tick to tick, RMS, hovering)", fmt_opt(m.motor_jitter_counts, " counts")),
        ("height RMS error while holding", fmt_opt(m.height_rms_m, " m")),
        ("  of which the estimate's offset (mean)", fmt_opt(m.height_offset_m, " m")),
        ("  and the hold's unsteadiness (RMS about it)", fmt_opt(m.height_rms_about_offset_m, " m")),
        ("height drift over the hold", fmt_opt(m.height_drift_m, " m")),
        ("touchdown speed", fmt_opt(m.touchdown_speed_m_s, " m/s")),
        ("height lost on leaving hold", fmt_opt(m.height_lost_leaving_hold_m, " m")),
        ("disarmed after touchdown", fmt_opt(m.disarmed_after_touchdown_s, " s")),
        ("throttle oscillation in hold", fmt_opt(m.throttle_oscillation_counts, " counts")),
    ]
}

#[cfg(test)]
mod tests {

    use super::*;
    use crate::sim::{plant::PlantParams, Profile, Vertical};

    const TICK_HZ: f64 = 800.0;

    /// A log of `secs` at 800 Hz, each row made by `f(t_s)` from an armed, level row.
    fn log_of(secs: f64, f: impl Fn(f64, &mut LogRow)) -> FlightLog {
        let rows = (1..=(secs * TICK_HZ).round() as usize)
            .map(|k| {
                let t_s = k as f64 / TICK_HZ;
                let mut r = LogRow { vertical: Vertical { climb_m_s: 0.0, ..Vertical::ABSENT }, ..LogRow::steady(t_s) };
                f(t_s, &mut r);
                r
            })
            .collect();
        FlightLog { scenario: "test".into(), profile: Profile::Default, seed: 1, tick_hz: TICK_HZ, plant: PlantParams::default(), rows }
    }

    #[test]
    fn the_band_rms_keeps_a_sine_inside_the_band_and_drops_one_outside() {
        let amplitude = 40.0;
        for (freq_hz, inside) in [(2.0, true), (4.5, true), (0.3, false), (12.0, false)] {
            let log = log_of(10.0, |t, r| {
                let c = 900.0 + amplitude * (std::f64::consts::TAU * freq_hz * t).sin();
                r.motors = [c.round() as u16; 4];
            });
            let rms = collective_band_rms_counts(&log, 0.0, 10.0, OSCILLATION_BAND_HZ).unwrap_or(f64::NAN);
            let expected = if inside { amplitude / 2f64.sqrt() } else { 0.0 };
            assert!((rms - expected).abs() < 0.1 * amplitude, "{freq_hz} Hz: {rms:.2} counts, expected {expected:.2}");
        }
        assert_eq!(collective_band_rms_counts(&log_of(0.05, |_, _| {}), 0.0, 0.05, OSCILLATION_BAND_HZ), None);
    }

    #[test]
    fn the_touchdown_is_the_first_row_on_the_floor_with_the_speed_just_before_it() {
        // A fall at 0.4 m/s from 1 m from t = 1 s: on the floor at 3.5 s, disarmed 0.6 s later.
        let log = log_of(6.0, |t, r| {
            r.alt_m = if t < 1.0 { 1.0 } else { (1.0 - 0.4 * (t - 1.0)).max(0.0) };
            r.vertical.climb_m_s = if t < 1.0 || r.alt_m <= 0.0 { 0.0 } else { -0.4 };
            r.armed = t < 4.1;
        });
        let (at_s, speed) = touchdown(&log, 0.5).unwrap_or((f64::NAN, f64::NAN));
        assert!((at_s - 3.5).abs() < 0.01 && (speed - 0.4).abs() < 1e-9, "{at_s} s, {speed} m/s");
        let disarmed = disarmed_after_s(&log, at_s).unwrap_or(f64::NAN);
        assert!((disarmed - 0.6).abs() < 0.01, "{disarmed}");
        assert_eq!(touchdown(&log, 4.0), None, "no touchdown after it");
    }

    #[test]
    fn height_error_drift_and_loss_are_measured_on_the_true_height() {
        // Holding a 1 m target, 2 cm above it, drifting 5 cm over 20 s; a 0.15 m dip after 12 s.
        let log = log_of(20.0, |t, r| {
            r.vertical.alt_target_m = 1.0;
            r.alt_m = 1.02 + 0.05 * t / 20.0 - if (12.0..13.0).contains(&t) { 0.15 } else { 0.0 };
        });
        let rms = height_rms_m(&log, 0.0, 11.0).unwrap_or(f64::NAN);
        assert!((rms - 0.034).abs() < 0.005, "{rms}");
        let offset = height_offset_m(&log, 0.0, 11.0).unwrap_or(f64::NAN);
        assert!((offset - 0.034).abs() < 0.005, "{offset}: the error is almost all offset");
        let drift = height_drift_m(&log, 0.0, 11.0).unwrap_or(f64::NAN);
        assert!((drift - 0.05 * 10.0 / 20.0).abs() < 0.002, "{drift}");
        let lost = height_lost_leaving_hold_m(&log, 12.0).unwrap_or(f64::NAN);
        assert!((lost - 0.15).abs() < 0.01, "{lost}");
        assert_eq!(height_rms_m(&log_of(2.0, |_, _| {}), 0.0, 2.0), None, "no target, no hold");
    }

    #[test]
    fn motors_off_in_the_air_fails_its_criterion_and_on_the_floor_passes() {
        let log = log_of(4.0, |t, r| {
            r.alt_m = (1.0 - t / 2.0).max(0.0);
            r.motors = if r.alt_m < 0.2 { [0; 4] } else { [900; 4] };
        });
        assert!(check(&log, &Criterion::MotorsOffOnlyBelow { from_s: 0.0, max_m: 0.3 }).passed);
        assert!(!check(&log, &Criterion::MotorsOffOnlyBelow { from_s: 0.0, max_m: 0.1 }).passed);
    }
}
