//! Loop identification: the open-loop frequency response of the attitude control, measured in
//! closed loop on the simulated drone, and its gain and phase margins.
//!
//! The loop is broken where the airframe sees it, at the motors: a multisine `d` (one axis's
//! pattern of the mixer, [`fcu_core::mixer::MIX`]) is added to the compare values the flight
//! computer returns before the plant gets them. With `u` the computer's own command on that
//! axis (recovered from its four compare values) and `e = u + d` what the plant receives, the
//! loop transfer at the plant input is `L(jω) = −U(jω) / E(jω)`: the rate loop, the angle loop
//! above it, the estimator, the filters, the delays and the airframe, all as they fly.
//!
//! The multisine's tones sit on exact DFT bins of its period, and the response is read over a
//! whole number of periods after one period of settling, so there is no leakage; noise and the
//! pilot's height keeping average out over the periods. Each period is also read on its own:
//! how well they agree (the coherence of `u` and `e`) says where the reading is the loop's
//! and where it is the sensor noise's.

use std::f64::consts::{PI, TAU};

use fcu_core::mixer::MIX;

/// A periodic sum of sines, the excitation: tones on multiples of `1 / period_s`.
#[derive(Clone, Debug, PartialEq)]
pub struct Multisine {
    /// Axis the excitation goes into: 0 pitch (about X), 1 roll (about Y), 2 yaw.
    pub axis: usize,
    /// When the excitation starts, s of scenario time.
    pub start_s: f64,
    pub period_s: f64,
    /// `(frequency Hz, amplitude compare counts, phase rad)` of each tone.
    pub tones: Vec<(f64, f64, f64)>,
}

impl Multisine {
    /// `count` tones log-spaced from `from_hz` to `to_hz` (each on a bin of `period_s`, no
    /// bin twice), `amplitude_counts` each, with Schroeder phases (a low crest factor: the sum
    /// stays near its RMS rather than piling up into one large kick).
    pub fn log_spaced(
        axis: usize,
        start_s: f64,
        period_s: f64,
        from_hz: f64,
        to_hz: f64,
        count: usize,
        amplitude_counts: f64,
    ) -> Multisine {
        let bin_hz = 1.0 / period_s;
        let mut bins: Vec<u64> = Vec::with_capacity(count);
        for k in 0..count {
            let f = from_hz * (to_hz / from_hz).powf(k as f64 / (count.max(2) - 1) as f64);
            let bin = ((f / bin_hz).round() as u64).max(1);
            if bins.last().is_none_or(|&b| bin > b) {
                bins.push(bin);
            }
        }
        let n = bins.len() as f64;
        let tones = bins
            .iter()
            .enumerate()
            .map(|(k, &b)| {
                let k = k as f64 + 1.0;
                (b as f64 * bin_hz, amplitude_counts, -PI * k * (k - 1.0) / n)
            })
            .collect();
        Multisine { axis, start_s, period_s, tones }
    }

    /// The excitation at scenario time `t_s`, compare counts (0 before it starts).
    pub fn value(&self, t_s: f64) -> f64 {
        if t_s < self.start_s {
            return 0.0;
        }
        let t = t_s - self.start_s;
        self.tones.iter().map(|&(f, a, ph)| a * (TAU * f * t + ph).sin()).sum()
    }

    /// The four compare values the plant gets: the computer's, plus this excitation in its
    /// axis's mixer pattern, kept inside the 16-bit compare register.
    pub fn add_to(&self, compare: [u16; 4], t_s: f64) -> [u16; 4] {
        let d = self.value(t_s);
        let mut out = compare;
        for (m, c) in out.iter_mut().enumerate() {
            let sign = f64::from(MIX[m][self.axis.min(2)]);
            *c = (f64::from(*c) + sign * d).round().clamp(0.0, f64::from(u16::MAX)) as u16;
        }
        out
    }
}

/// The command on `axis` in four compare values: the mixer's columns are orthogonal ±1, so
/// the projection on one column, over four, is that axis's share.
pub fn axis_command(compare: [u16; 4], axis: usize) -> f64 {
    compare.iter().enumerate().map(|(m, &c)| f64::from(MIX[m][axis.min(2)]) * f64::from(c)).sum::<f64>() / 4.0
}

/// One frequency of a measured loop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResponsePoint {
    pub freq_hz: f64,
    /// |L|, dB.
    pub gain_db: f64,
    /// arg L, degrees, unwrapped from the lowest frequency.
    pub phase_deg: f64,
    /// Magnitude-squared coherence of `u` and `e` over the record's segments, 0..1: 1 when
    /// every segment tells the same story (the response is the excitation's), lower as noise,
    /// turbulence or a non-linearity take a share. 1 by definition from a single segment.
    pub coherence: f64,
}

/// The DFT of `x` at `freq_hz`, summed over the samples `range` of it (sample `k` taken at
/// `k·dt_s`): `Σ x·e^{−jωt}`, as (re, im). The exponent runs on the whole record's time, not
/// the segment's, so every segment of a periodic signal gives the same phase.
fn dft_at(x: &[f64], range: std::ops::Range<usize>, dt_s: f64, freq_hz: f64) -> (f64, f64) {
    let w = TAU * freq_hz * dt_s;
    let start = range.start;
    x.get(range).unwrap_or(&[]).iter().enumerate().fold((0.0, 0.0), |(re, im), (k, &v)| {
        let a = w * (start + k) as f64;
        (re + v * a.cos(), im - v * a.sin())
    })
}

/// `L = −U/E` at each of `freqs_hz` from the samples `u` (the computer's command) and `e`
/// (what the plant got), taken every `dt_s` over a whole number of the excitation's periods.
///
/// The record is cut into `segments` equal parts (one per period of the excitation: each is
/// then leakage-free at the tones, like a Welch average with rectangular windows and no
/// overlap). `L` is `−ΣU/ΣE` over the segments, which is the DFT of the whole record: the
/// average of the periods, where what is not periodic (noise, the pilot's throttle) cancels.
/// The coherence compares the segments: `|ΣU·E*|² / (Σ|U|²·Σ|E|²)`.
pub fn loop_response(u: &[f64], e: &[f64], dt_s: f64, freqs_hz: &[f64], segments: usize) -> Vec<ResponsePoint> {
    let n = u.len().min(e.len());
    let segments = segments.clamp(1, n.max(1));
    let seg_len = n / segments;
    let mut out: Vec<ResponsePoint> = Vec::with_capacity(freqs_hz.len());
    for &f in freqs_hz {
        // Sums over the segments: U, E, |U|², |E|², U·conj(E).
        let (mut su, mut se) = ((0.0, 0.0), (0.0, 0.0));
        let (mut suu, mut see, mut sue) = (0.0, 0.0, (0.0, 0.0));
        for p in 0..segments {
            let range = p * seg_len..(p + 1) * seg_len;
            let (ur, ui) = dft_at(u, range.clone(), dt_s, f);
            let (er, ei) = dft_at(e, range, dt_s, f);
            su = (su.0 + ur, su.1 + ui);
            se = (se.0 + er, se.1 + ei);
            suu += ur * ur + ui * ui;
            see += er * er + ei * ei;
            sue = (sue.0 + ur * er + ui * ei, sue.1 + ui * er - ur * ei);
        }
        // Samples past the last whole segment (a period that is not a whole number of ticks,
        // as at the reference's 807.69 Hz) still belong to the record's DFT.
        let (ur, ui) = dft_at(u, segments * seg_len..n, dt_s, f);
        let (er, ei) = dft_at(e, segments * seg_len..n, dt_s, f);
        su = (su.0 + ur, su.1 + ui);
        se = (se.0 + er, se.1 + ei);
        let ((ur, ui), (er, ei)) = (su, se);
        let den = er * er + ei * ei;
        // −U/E = −(U·conj E)/|E|².
        let (lr, li) = if den > 0.0 { (-(ur * er + ui * ei) / den, -(ui * er - ur * ei) / den) } else { (f64::NAN, f64::NAN) };
        let gain_db = 20.0 * (lr * lr + li * li).sqrt().log10();
        let coherence = if suu > 0.0 && see > 0.0 { ((sue.0 * sue.0 + sue.1 * sue.1) / (suu * see)).clamp(0.0, 1.0) } else { f64::NAN };
        let mut phase_deg = li.atan2(lr).to_degrees();
        if let Some(prev) = out.iter().rev().find(|p| p.phase_deg.is_finite()) {
            // Unwrapped: the step from the last point is the one within ±180°.
            phase_deg -= 360.0 * ((phase_deg - prev.phase_deg) / 360.0).round();
        } else if phase_deg > 0.0 {
            // A loop with integral action starts near −90° (or below): a first point just
            // above +90° is the same angle a turn lower.
            phase_deg -= 360.0;
        }
        out.push(ResponsePoint { freq_hz: f, gain_db, phase_deg, coherence });
    }
    out
}

/// Gain and phase margins of a loop response.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Margins {
    /// Where |L| first falls through 0 dB, Hz (`None`: never within the measured band).
    pub crossover_hz: Option<f64>,
    /// 180° + arg L at the crossover, degrees.
    pub phase_margin_deg: Option<f64>,
    /// Where arg L first falls through −180° above the crossover, Hz.
    pub phase_crossover_hz: Option<f64>,
    /// −|L| in dB there (`None` when the phase never reaches −180° in the band: no finite
    /// gain margin was measured, which [`Margins::meets`] counts as enough).
    pub gain_margin_db: Option<f64>,
}

impl Margins {
    /// Whether these margins are at least `gain_db` and `phase_deg`. A loop without a
    /// crossover in the band fails (nothing was shown); a phase that never reaches −180°
    /// above the crossover within the band counts as an infinite gain margin only if the band
    /// reaches well past the crossover (5×).
    pub fn meets(&self, gain_db: f64, phase_deg: f64, band_top_hz: f64) -> bool {
        let (Some(fc), Some(pm)) = (self.crossover_hz, self.phase_margin_deg) else {
            return false;
        };
        let gm_ok = match self.gain_margin_db {
            Some(gm) => gm >= gain_db,
            None => band_top_hz >= 5.0 * fc,
        };
        pm >= phase_deg && gm_ok
    }
}

/// Margins from a response, interpolating linearly in log-frequency between points.
pub fn margins(points: &[ResponsePoint]) -> Margins {
    let lerp = |a: &ResponsePoint, b: &ResponsePoint, t: f64| {
        let f = (a.freq_hz.ln() + t * (b.freq_hz.ln() - a.freq_hz.ln())).exp();
        (f, a.gain_db + t * (b.gain_db - a.gain_db), a.phase_deg + t * (b.phase_deg - a.phase_deg))
    };
    let mut m = Margins { crossover_hz: None, phase_margin_deg: None, phase_crossover_hz: None, gain_margin_db: None };
    let mut crossover_at = 0;
    for (k, w) in points.windows(2).enumerate() {
        let (a, b) = (&w[0], &w[1]);
        if a.gain_db >= 0.0 && b.gain_db < 0.0 {
            let t = a.gain_db / (a.gain_db - b.gain_db);
            let (f, _, ph) = lerp(a, b, t);
            m.crossover_hz = Some(f);
            m.phase_margin_deg = Some(180.0 + ph);
            crossover_at = k;
            break;
        }
    }
    if m.crossover_hz.is_none() {
        return m;
    }
    for w in points[crossover_at..].windows(2) {
        let (a, b) = (&w[0], &w[1]);
        if a.phase_deg > -180.0 && b.phase_deg <= -180.0 {
            let t = (a.phase_deg + 180.0) / (a.phase_deg - b.phase_deg);
            let (f, g, _) = lerp(a, b, t);
            m.phase_crossover_hz = Some(f);
            m.gain_margin_db = Some(-g);
            break;
        }
    }
    m
}

/// What one identification flies: the excitation's shape and when.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plan {
    /// Excitation starts (the drone hovers at 1 m from about 6 s), s.
    pub start_s: f64,
    /// Period of the multisine (its frequency resolution is 1 / period), s.
    pub period_s: f64,
    /// Periods read after the first (settling) one.
    pub periods: u32,
    pub from_hz: f64,
    pub to_hz: f64,
    pub tones: usize,
    /// Per tone and axis (pitch, roll, yaw), compare counts: small enough to stay linear,
    /// large enough to stand over the sensor noise. On pitch and roll 6 counts tilt the drone
    /// by about 1.5° and the response stays coherent to 80 Hz. Yaw needs four times that: the
    /// motors' reaction torque is weak against the yaw inertia, so above ~30 Hz the gyro's
    /// noise through the yaw loop's D term outweighed 6 counts (coherence 0.3–0.5 where the
    /// phase crosses −180°, 0.9 at 24); a yaw excitation tilts nothing and, two motors up and
    /// two down, moves the total thrust only through the thrust curve's square term.
    pub amplitude_counts: [f64; 3],
}

impl Plan {
    pub const DEFAULT: Plan =
        Plan { start_s: 7.0, period_s: 4.0, periods: 4, from_hz: 0.5, to_hz: 80.0, tones: 40, amplitude_counts: [6.0, 6.0, 24.0] };

    /// Whether this plan can be flown at `tick_hz`: the excitation starts once the hover
    /// scenario is airborne, its band lies below the tick's Nyquist frequency, and there is
    /// at least one period to read.
    pub fn check(&self, tick_hz: f64) -> Result<(), String> {
        let ok = self.start_s.is_finite()
            && self.start_s >= MIN_START_S
            && self.period_s.is_finite()
            && (1.0..=60.0).contains(&self.period_s)
            && (1..=64).contains(&self.periods)
            && self.from_hz.is_finite()
            && self.from_hz >= 1.0 / self.period_s
            && self.to_hz.is_finite()
            && self.to_hz > self.from_hz
            && self.to_hz < 0.5 * tick_hz
            && (1..=1000).contains(&self.tones)
            && self.amplitude_counts.iter().all(|a| a.is_finite() && (0.0..=100.0).contains(a) && *a > 0.0);
        if ok {
            Ok(())
        } else {
            Err(format!("identification plan out of range: {self:?} at {tick_hz:.2} Hz"))
        }
    }
}

/// The hover scenario has taken off (4.5 s) and climbed to 1 m by here, s.
pub const MIN_START_S: f64 = 6.5;

/// A measurement describes the hovering loop only if the drone hovered throughout: armed,
/// off the floor, and within this tilt (the excitation should move it by a degree or two;
/// beyond this the loop is no longer the small-signal one, or not stable).
pub const MAX_HOVER_TILT_DEG: f64 = 15.0;
/// Off the floor: above this height (the pilot holds 1 m), m.
pub const MIN_HOVER_ALT_M: f64 = 0.3;

/// The names of the axes, in `MIX`'s column order.
pub const AXES: [&str; 3] = ["pitch", "roll", "yaw"];

/// One axis's measured loop.
#[derive(Clone, Debug)]
pub struct AxisLoop {
    pub axis: usize,
    pub response: Vec<ResponsePoint>,
    pub margins: Margins,
    /// Largest roll or pitch while the response was read, degrees.
    pub max_tilt_deg: f64,
    /// Why the drone did not hover throughout the reading, if it did not: then the response
    /// is not the hovering loop's, and the loop fails whatever its margins read.
    pub hover_lost: Option<String>,
}

impl AxisLoop {
    /// The drone hovered throughout and the margins are at least `gain_db` and `phase_deg`
    /// (see [`Margins::meets`]).
    pub fn meets(&self, gain_db: f64, phase_deg: f64, band_top_hz: f64) -> bool {
        self.hover_lost.is_none() && self.margins.meets(gain_db, phase_deg, band_top_hz)
    }

    /// The coherence at `freq_hz` (the lower of the two tones around it): how far a margin
    /// read there can be trusted. `None` outside the measured band.
    pub fn coherence_at(&self, freq_hz: f64) -> Option<f64> {
        let k = self.response.iter().position(|p| p.freq_hz >= freq_hz)?;
        let above = self.response.get(k)?.coherence;
        let below = k.checked_sub(1).and_then(|i| self.response.get(i)).map_or(above, |p| p.coherence);
        Some(above.min(below))
    }
}

/// Hover (no turbulence) with `computer`, excite `axis` at the motors, and measure its loop.
pub fn measure_axis(
    computer: &mut dyn super::FlightComputer,
    profile: super::Profile,
    axis: usize,
    plan: &Plan,
    opts: &super::RunOptions,
) -> Result<AxisLoop, super::SimError> {
    let name = AXES.get(axis).ok_or_else(|| super::SimError::Config(format!("axis {axis}: there are three (0 pitch, 1 roll, 2 yaw)")))?;
    plan.check(computer.tick_hz()).map_err(super::SimError::Config)?;
    let mut sc = super::scenario::by_name("hover").ok_or_else(|| super::SimError::Config("no hover scenario".into()))?;
    // Armed and holding 1 m from take-off on, in still air: the excitation is all there is.
    sc.turbulence = None;
    sc.timeline.rows.retain(|r| r.t_s <= plan.start_s - 1.0);
    let excitation =
        Multisine::log_spaced(axis, plan.start_s, plan.period_s, plan.from_hz, plan.to_hz, plan.tones, plan.amplitude_counts[axis.min(2)]);
    // The first period lets the loop's response to the excitation's start die out.
    let read_from_s = plan.start_s + plan.period_s;
    let duration_s = read_from_s + plan.period_s * f64::from(plan.periods);
    let opts = super::RunOptions { duration_s: Some(duration_s), excitation: Some(excitation.clone()), ..opts.clone() };
    let log = super::run_with(computer, &sc, profile, &opts)?;
    let dt_s = 1.0 / log.tick_hz;
    // Exactly `periods` periods of rows.
    let n = (plan.period_s * f64::from(plan.periods) * log.tick_hz).round() as usize;
    let rows: Vec<&super::LogRow> = log.rows.iter().filter(|r| r.t_s > read_from_s).take(n).collect();
    let max_tilt_deg = rows.iter().map(|r| r.roll_deg.abs().max(r.pitch_deg.abs())).fold(0.0, f64::max);
    let hover_lost = if rows.len() < n {
        Some(format!("{name}: the flight ended {} ticks early", n - rows.len()))
    } else if let Some(r) = rows.iter().find(|r| !r.armed) {
        Some(format!("{name}: disarmed ({}) at {:.2} s", r.state.name(), r.t_s))
    } else if let Some(r) = rows.iter().find(|r| r.alt_m < MIN_HOVER_ALT_M) {
        Some(format!("{name}: down to {:.2} m at {:.2} s", r.alt_m, r.t_s))
    } else if max_tilt_deg > MAX_HOVER_TILT_DEG {
        Some(format!("{name}: tilted {max_tilt_deg:.0}° (more than {MAX_HOVER_TILT_DEG:.0}°)"))
    } else {
        None
    };
    let u: Vec<f64> = rows.iter().map(|r| axis_command(r.motors, axis)).collect();
    let e: Vec<f64> = rows.iter().zip(&u).map(|(r, u)| u + excitation.value(r.t_s)).collect();
    let freqs: Vec<f64> = excitation.tones.iter().map(|t| t.0).collect();
    let response = loop_response(&u, &e, dt_s, &freqs, plan.periods as usize);
    let margins = margins(&response);
    Ok(AxisLoop { axis, response, margins, max_tilt_deg, hover_lost })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// L(jω) = k·e^{−jωT}/(jω): crossover at ω = k, phase margin 90° − k·T (rad → °), phase
    /// crossover at ω = π/(2T), gain margin 20·log10(π/(2Tk)).
    fn delayed_integrator(k: f64, delay_s: f64, freqs: &[f64]) -> Vec<ResponsePoint> {
        let mut out: Vec<ResponsePoint> = Vec::new();
        for &f in freqs {
            let w = TAU * f;
            let (gain_db, phase_deg) = (20.0 * (k / w).log10(), -90.0 - (w * delay_s).to_degrees());
            out.push(ResponsePoint { freq_hz: f, gain_db, phase_deg, coherence: 1.0 });
        }
        out
    }

    #[test]
    fn margins_of_a_delayed_integrator_are_the_textbook_ones() {
        let (k, delay) = (2.0 * PI * 5.0, 0.02);
        let freqs: Vec<f64> = (0..400).map(|i| 0.5 * 1.015f64.powi(i)).collect();
        let m = margins(&delayed_integrator(k, delay, &freqs));
        let fc = m.crossover_hz.unwrap();
        assert!((fc - 5.0).abs() < 0.02, "{fc}");
        let pm = 90.0 - (k * delay).to_degrees();
        assert!((m.phase_margin_deg.unwrap() - pm).abs() < 0.2, "{m:?} vs {pm}");
        let w180 = PI / (2.0 * delay);
        assert!((m.phase_crossover_hz.unwrap() - w180 / TAU).abs() < 0.05, "{m:?}");
        let gm = 20.0 * (w180 / k).log10();
        assert!((m.gain_margin_db.unwrap() - gm).abs() < 0.05, "{m:?} vs {gm}");
        assert!(m.meets(6.0, 45.0, 100.0));
        assert!(!m.meets(gm + 0.5, 45.0, 100.0));
        assert!(!m.meets(6.0, pm + 0.5, 100.0));
    }

    /// A loop flown at 800 Hz: the plant integrates its input, the controller is a gain on
    /// the plant's output seen `delay_ticks` ticks late, `noise` (standard deviation, on the
    /// controller's output) stands for the sensor noise. Excited at the plant input as the
    /// drone is; returns `u` and `e` over `periods` periods after one of settling.
    fn fly_delayed_integrator(k: f64, delay_ticks: usize, ms: &Multisine, periods: u32, noise: f64) -> (Vec<f64>, Vec<f64>) {
        let dt = 1.0 / 800.0;
        let read_from = (ms.period_s / dt).round() as usize;
        let n = read_from + (f64::from(periods) * ms.period_s / dt).round() as usize;
        let mut rng = crate::sim::rng::Rng::new(7);
        let (mut y, mut history) = (0.0f64, vec![0.0f64; delay_ticks + 1]);
        let (mut u_log, mut e_log) = (Vec::new(), Vec::new());
        for i in 0..n {
            let t = i as f64 * dt;
            let u = -k * history[0] + noise * rng.gaussian();
            let e = u + ms.value(t);
            y += e * dt;
            history.remove(0);
            history.push(y);
            if i >= read_from {
                u_log.push(u);
                e_log.push(e);
            }
        }
        (u_log, e_log)
    }

    #[test]
    fn a_closed_loop_measured_through_the_excitation_gives_the_same_margins() {
        let dt = 1.0 / 800.0;
        let (k, delay_ticks) = (2.0 * PI * 4.0, 12usize);
        let ms = Multisine::log_spaced(1, 0.0, 4.0, 0.5, 60.0, 40, 1.0);
        let freqs: Vec<f64> = ms.tones.iter().map(|t| t.0).collect();
        let (u, e) = fly_delayed_integrator(k, delay_ticks, &ms, 2, 0.0);
        let response = loop_response(&u, &e, dt, &freqs, 2);
        let m = margins(&response);
        // The sampled loop: the output is seen `delay_ticks` ticks late, plus half a tick
        // for the hold.
        let delay = (delay_ticks as f64 + 0.5) * dt;
        let pm = 90.0 - (k * delay).to_degrees();
        let gm = 20.0 * ((PI / (2.0 * delay)) / k).log10();
        assert!((m.crossover_hz.unwrap() - 4.0).abs() < 0.15, "{m:?}");
        assert!((m.phase_margin_deg.unwrap() - pm).abs() < 3.0, "{m:?} vs {pm}");
        assert!((m.gain_margin_db.unwrap() - gm).abs() < 1.0, "{m:?} vs {gm}");
        // Without noise every period is the same: the coherence is 1.
        assert!(response.iter().all(|p| p.coherence > 0.999), "{response:?}");
    }

    #[test]
    fn noise_lowers_the_coherence_and_averages_out_of_the_margins() {
        // Noise on the controller's output as large as the whole excitation's RMS (40 tones
        // of 1): the periods disagree where the excitation is weak against it, and the
        // average over eight periods still finds the textbook margins.
        let dt = 1.0 / 800.0;
        let (k, delay_ticks) = (2.0 * PI * 4.0, 12usize);
        let ms = Multisine::log_spaced(1, 0.0, 2.0, 0.5, 60.0, 40, 1.0);
        let freqs: Vec<f64> = ms.tones.iter().map(|t| t.0).collect();
        let (u, e) = fly_delayed_integrator(k, delay_ticks, &ms, 8, 4.5);
        let response = loop_response(&u, &e, dt, &freqs, 8);
        let m = margins(&response);
        let delay = (delay_ticks as f64 + 0.5) * dt;
        let pm = 90.0 - (k * delay).to_degrees();
        let gm = 20.0 * ((PI / (2.0 * delay)) / k).log10();
        assert!((m.crossover_hz.unwrap() - 4.0).abs() < 0.3, "{m:?}");
        assert!((m.phase_margin_deg.unwrap() - pm).abs() < 5.0, "{m:?} vs {pm}");
        assert!((m.gain_margin_db.unwrap() - gm).abs() < 1.5, "{m:?} vs {gm}");
        let coherence: Vec<f64> = response.iter().map(|p| p.coherence).collect();
        assert!(coherence.iter().all(|c| (0.0..=1.0).contains(c)), "{coherence:?}");
        assert!(coherence.iter().any(|&c| c < 0.95), "noise left no mark: {coherence:?}");
        // With one segment there is nothing to compare: coherence 1 by definition.
        assert!(loop_response(&u, &e, dt, &freqs, 1).iter().all(|p| (p.coherence - 1.0).abs() < 1e-9));
    }

    #[test]
    fn degenerate_records_give_no_margins_and_no_panic() {
        let freqs = [1.0, 2.0, 4.0];
        for (u, e) in [(vec![], vec![]), (vec![1.0], vec![]), (vec![0.0; 100], vec![0.0; 100]), (vec![f64::NAN; 50], vec![1.0; 50])] {
            for segments in [0, 1, 3, 1000] {
                let r = loop_response(&u, &e, 1.0 / 800.0, &freqs, segments);
                assert_eq!(r.len(), freqs.len());
                let m = margins(&r);
                assert_eq!(m.crossover_hz, None, "{r:?}");
                assert!(!m.meets(6.0, 45.0, 100.0));
            }
        }
        assert_eq!(margins(&[]).crossover_hz, None);
    }

    #[test]
    fn plans_outside_what_can_be_flown_are_refused() {
        assert!(Plan::DEFAULT.check(800.0).is_ok());
        assert!(Plan::DEFAULT.check(807.69).is_ok());
        for bad in [
            Plan { period_s: 0.0, ..Plan::DEFAULT },
            Plan { periods: 0, ..Plan::DEFAULT },
            Plan { to_hz: 500.0, ..Plan::DEFAULT },
            Plan { from_hz: f64::NAN, ..Plan::DEFAULT },
            Plan { start_s: 1.0, ..Plan::DEFAULT },
            Plan { amplitude_counts: [6.0, -1.0, 6.0], ..Plan::DEFAULT },
            Plan { amplitude_counts: [6.0, 6.0, f64::INFINITY], ..Plan::DEFAULT },
            Plan { tones: 0, ..Plan::DEFAULT },
        ] {
            assert!(bad.check(800.0).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn the_excitation_goes_in_on_its_axis_only() {
        let ms = Multisine { axis: 2, start_s: 0.0, period_s: 1.0, tones: vec![(1.0, 100.0, PI / 2.0)] };
        let out = ms.add_to([1000; 4], 0.0);
        assert_eq!(out, [1100, 900, 1100, 900]);
        assert_eq!(axis_command(out, 2), 100.0);
        assert_eq!(axis_command(out, 0), 0.0);
        assert_eq!(axis_command(out, 1), 0.0);
        assert_eq!(ms.add_to([10, 65530, 0, 0], 0.0), [110, 65430, 100, 0]);
    }
}
