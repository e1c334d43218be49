//! Control-quality numbers of `docs/simulation.md#metrics` and the scenario pass criteria, both
//! computed from a [`FlightLog`] only (so they can be recomputed from any recorded flight).

use super::scenario::{describe, Axis, Criterion, Scenario};
use super::{FlightLog, LogRow};

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
    m
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
    };
    Verdict { criterion: describe(c), passed, detail }
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
    ]
}
