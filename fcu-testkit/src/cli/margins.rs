//! `fcu-sim margins`: the attitude loops' frequency response, measured on the simulated drone
//! in hover, with their gain and phase margins and a Bode plot (see `sim::loop_id`).
//!
//! Exit codes: 0 every axis has at least [`MIN_GAIN_MARGIN_DB`] and [`MIN_PHASE_MARGIN_DEG`],
//! 1 one does not, 2 bad usage.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use super::fly::{check_spread, OutputDir};
use super::CliError;
use crate::sim::loop_id::{self, AxisLoop, Plan, AXES};
use crate::sim::{InProcess, Profile, RunOptions};

/// The margins a loop must keep (classical robustness figures).
pub const MIN_GAIN_MARGIN_DB: f64 = 6.0;
pub const MIN_PHASE_MARGIN_DEG: f64 = 45.0;
/// More delay than this is not a robustness question any more.
pub const MAX_EXTRA_DELAY_TICKS: u32 = 40;

#[derive(clap::Args, Debug)]
pub struct MarginsArgs {
    /// Flight-controller profile: `default` (the product) or `reference` (ST's firmware).
    #[arg(long, default_value = "default")]
    pub profile: String,
    // `allow_negative_numbers`: `--seed -1` is a bad value of --seed (refused naming it), not
    // an unknown flag `-1`; the same for --spread and --extra-delay-ticks.
    /// Seed for sensor noise and (with --spread) the airframe.
    #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
    pub seed: u64,
    /// Randomise every airframe parameter by ±this fraction from the seed (0 = nominal drone).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub spread: f64,
    /// Extra control ticks between the computer's compare values and the motors (0..=40;
    /// one is the robustness requirement).
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    pub extra_delay_ticks: u32,
    /// Directory for margins.csv (per tone: freq_hz, then per axis gain_db, phase_deg and
    /// coherence) and margins.svg (its Bode plot, margins marked).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// All three axes measured with `opts`.
pub fn measure(profile: Profile, opts: &RunOptions) -> Result<Vec<AxisLoop>, CliError> {
    (0..AXES.len())
        .map(|axis| {
            let mut computer = InProcess::new(profile.config()).map_err(|e| CliError(e.to_string()))?;
            loop_id::measure_axis(&mut computer, profile, axis, &Plan::DEFAULT, opts).map_err(|e| CliError(e.to_string()))
        })
        .collect()
}

/// Whether every axis keeps the required margins.
pub fn all_meet(loops: &[AxisLoop]) -> bool {
    loops.iter().all(|l| l.meets(MIN_GAIN_MARGIN_DB, MIN_PHASE_MARGIN_DEG, Plan::DEFAULT.to_hz))
}

pub fn run(a: &MarginsArgs) -> Result<ExitCode, CliError> {
    let profile = Profile::parse(&a.profile)
        .ok_or_else(|| CliError(format!("--profile: unknown profile `{}`; known: default, reference", a.profile)))?;
    let spread = check_spread(a.spread)?;
    if a.extra_delay_ticks > MAX_EXTRA_DELAY_TICKS {
        return Err(CliError(format!("--extra-delay-ticks: {} is more than {MAX_EXTRA_DELAY_TICKS}", a.extra_delay_ticks)));
    }
    let out = a.out.as_deref().map(OutputDir::prepare).transpose().map_err(CliError)?;
    let opts = RunOptions { seed: a.seed, plant_spread: spread, extra_delay_ticks: a.extra_delay_ticks, ..RunOptions::default() };
    let abandon = |e: CliError| match &out {
        Some(o) => o.abandon(e),
        None => e,
    };
    let loops = measure(profile, &opts).map_err(abandon)?;

    println!(
        "fcu-sim margins: profile {}, seed {}, spread ±{:.0} %, {} extra tick(s) of delay; loop broken at the motors",
        profile.name(),
        a.seed,
        spread * 100.0,
        a.extra_delay_ticks
    );
    println!(
        "{:<6} {:>12} {:>14} {:>14} {:>16} {:>14} {:>10}",
        "axis", "crossover", "phase margin", "gain margin", "phase crossover", "coherence", "max tilt"
    );
    let show = |v: Option<f64>, unit: &str, prec: usize| v.map_or("—".to_string(), |v| format!("{v:.prec$} {unit}"));
    for l in &loops {
        let m = &l.margins;
        // No phase crossover above the crossover inside the band: the gain margin is more
        // than the band shows (`Margins::meets` accepts that only for a band 5× the crossover).
        let gm = match (m.gain_margin_db, m.crossover_hz) {
            (Some(g), _) => format!("{g:.1} dB"),
            (None, Some(_)) => "none ≤ band".to_string(),
            (None, None) => "—".to_string(),
        };
        println!(
            "{:<6} {:>12} {:>14} {:>14} {:>16} {:>14} {:>10}",
            AXES[l.axis],
            show(m.crossover_hz, "Hz", 2),
            show(m.phase_margin_deg, "°", 1),
            gm,
            m.phase_crossover_hz.map_or(format!("> {:.0} Hz", Plan::DEFAULT.to_hz), |f| format!("{f:.1} Hz")),
            coherence(l),
            format!("{:.1}°", l.max_tilt_deg),
        );
        if let Some(why) = &l.hover_lost {
            println!("  the drone did not hover throughout, so this is not the hovering loop: {why}");
        }
    }
    let passed = all_meet(&loops);
    println!(
        "requirement: at least {MIN_PHASE_MARGIN_DEG}° and {MIN_GAIN_MARGIN_DB} dB on every axis: {}",
        if passed { "PASS" } else { "FAIL" }
    );
    if let (Some(dir), Some(o)) = (a.out.as_deref(), &out) {
        let title = format!(
            "fcu-sim margins: {} profile, seed {}, ±{:.0} %, +{} tick(s)",
            profile.name(),
            a.seed,
            spread * 100.0,
            a.extra_delay_ticks
        );
        write_outputs(dir, &title, &loops).map_err(|e| o.abandon(e))?;
        println!("wrote {} and {}", dir.join("margins.csv").display(), dir.join("margins.svg").display());
    }
    Ok(if passed { ExitCode::SUCCESS } else { ExitCode::from(1) })
}

/// The coherence where the two margins were read (`a / b`: at the crossover, at the phase
/// crossover), so a margin read in noise shows as one.
fn coherence(l: &AxisLoop) -> String {
    let at = |f: Option<f64>| f.and_then(|f| l.coherence_at(f)).map_or("—".to_string(), |c| format!("{c:.2}"));
    format!("{} / {}", at(l.margins.crossover_hz), at(l.margins.phase_crossover_hz))
}

fn write_outputs(dir: &Path, title: &str, loops: &[AxisLoop]) -> Result<(), CliError> {
    let mut csv = String::from("freq_hz");
    for l in loops {
        let name = AXES[l.axis];
        csv.push_str(&format!(",{name}_gain_db,{name}_phase_deg,{name}_coherence"));
    }
    csv.push('\n');
    let n = loops.iter().map(|l| l.response.len()).min().unwrap_or(0);
    for k in 0..n {
        csv.push_str(&format!("{:.3}", loops[0].response[k].freq_hz));
        for l in loops {
            let p = l.response[k];
            csv.push_str(&format!(",{:.3},{:.2},{:.4}", p.gain_db, p.phase_deg, p.coherence));
        }
        csv.push('\n');
    }
    let svg_tmp = dir.join(".margins.svg.partial");
    if let Err(e) = bode_svg(&svg_tmp, title, loops) {
        let _ = std::fs::remove_file(&svg_tmp);
        return Err(CliError(e));
    }
    super::write_output(Some(&dir.join("margins.csv")), csv.as_bytes())?;
    std::fs::rename(&svg_tmp, dir.join("margins.svg")).map_err(|e| {
        let _ = std::fs::remove_file(&svg_tmp);
        CliError(format!("writing {}: {e}", dir.join("margins.svg").display()))
    })
}

/// A plotting error as text (the caller names the file).
fn text(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// A frequency axis's label: log10 Hz shown as Hz.
fn hz_label(x: &f64) -> String {
    let f = 10f64.powf(*x);
    if f < 10.0 {
        format!("{f:.1}")
    } else {
        format!("{f:.0}")
    }
}

/// One panel of the Bode plot.
type Chart<'a, 'b> = ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A panel over log frequency `x` (log10 Hz) and `y`, its mesh drawn (with plotters' own
/// number of y labels unless `y_labels` says).
fn bode_panel<'a, 'b>(
    area: &'a DrawingArea<SVGBackend<'b>, plotters::coord::Shift>,
    caption: (&str, u32),
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
    y_labels: Option<usize>,
) -> Result<Chart<'a, 'b>, String> {
    let mut chart = ChartBuilder::on(area)
        .caption(caption.0, ("sans-serif", caption.1))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(50)
        .build_cartesian_2d(x, y)
        .map_err(text)?;
    let mut mesh = chart.configure_mesh();
    mesh.x_desc("Hz").x_label_formatter(&hz_label);
    if let Some(n) = y_labels {
        mesh.y_labels(n);
    }
    mesh.draw().map_err(text)?;
    Ok(chart)
}

/// The three panels and the gain's and phase's ranges, dB and °.
struct Bode<'a, 'b> {
    gain: Chart<'a, 'b>,
    phase: Chart<'a, 'b>,
    coherence: Chart<'a, 'b>,
    g: (f64, f64),
    p: (f64, f64),
}

/// Gain, phase and coherence against log frequency, one curve per axis; 0 dB and −180°
/// drawn; at each axis's crossover the phase margin is a bar from −180° up to the phase, at
/// its phase crossover the gain margin a bar from the gain up to 0 dB (both with faint
/// vertical guides through every panel).
fn bode_svg(path: &Path, title: &str, loops: &[AxisLoop]) -> Result<(), String> {
    bode_page(path, title, loops).map_err(|e| format!("plotting {}: {e}", path.display()))
}

fn bode_page(path: &Path, title: &str, loops: &[AxisLoop]) -> Result<(), String> {
    let root = SVGBackend::new(path, (1000, 1050)).into_drawing_area();
    root.fill(&WHITE).map_err(text)?;
    let (top, body) = root.split_vertically(40);
    top.titled(title, ("sans-serif", 20)).map_err(text)?;
    let (gain_area, rest) = body.split_vertically(430);
    let (phase_area, coherence_area) = rest.split_vertically(400);
    let colors = [RGBColor(31, 119, 180), RGBColor(214, 39, 40), RGBColor(44, 160, 44)];
    let (lo, hi) = (Plan::DEFAULT.from_hz.log10(), Plan::DEFAULT.to_hz.log10());
    let finite = |v: f64| v.is_finite();
    let gains: Vec<f64> = loops.iter().flat_map(|l| l.response.iter().map(|p| p.gain_db)).filter(|v| finite(*v)).collect();
    let (g_lo, g_hi) = (gains.iter().copied().fold(-20.0f64, f64::min).max(-60.0), gains.iter().copied().fold(20.0f64, f64::max).min(60.0));
    let phases: Vec<f64> = loops.iter().flat_map(|l| l.response.iter().map(|p| p.phase_deg)).filter(|v| finite(*v)).collect();
    let (p_lo, p_hi) =
        (phases.iter().copied().fold(-200.0f64, f64::min).max(-540.0), phases.iter().copied().fold(-90.0f64, f64::max).min(180.0));

    let mut gain = bode_panel(&gain_area, ("|L| (dB)", 16), lo..hi, g_lo..g_hi, None)?;
    gain.draw_series(LineSeries::new([(lo, 0.0), (hi, 0.0)], BLACK.stroke_width(1))).map_err(text)?;
    let mut phase = bode_panel(&phase_area, ("arg L (°)", 16), lo..hi, p_lo..p_hi, None)?;
    phase.draw_series(LineSeries::new([(lo, -180.0), (hi, -180.0)], BLACK.stroke_width(1))).map_err(text)?;
    let coherence = bode_panel(&coherence_area, ("coherence of u and e over the periods", 14), lo..hi, 0.0..1.05, Some(3))?;
    let mut bode = Bode { gain, phase, coherence, g: (g_lo, g_hi), p: (p_lo, p_hi) };
    for (l, color) in loops.iter().zip(colors) {
        bode.draw_loop(l, color)?;
    }
    bode.gain.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw().map_err(text)?;
    root.present().map_err(text)
}

impl Bode<'_, '_> {
    /// One axis's curves, its guides and its margins.
    fn draw_loop(&mut self, l: &AxisLoop, color: RGBColor) -> Result<(), String> {
        let ((g_lo, g_hi), (p_lo, p_hi)) = (self.g, self.p);
        // Values outside a panel's range are drawn at its edge rather than off the picture.
        let clip = |v: f64, lo: f64, hi: f64| v.clamp(lo, hi);
        let pts = |pick: fn(&loop_id::ResponsePoint) -> f64| -> Vec<(f64, f64)> {
            l.response.iter().filter(|p| pick(p).is_finite() && p.freq_hz > 0.0).map(|p| (p.freq_hz.log10(), pick(p))).collect()
        };
        let m = l.margins;
        let label = format!(
            "{}: crossover {}, PM {}, GM {}",
            AXES[l.axis],
            m.crossover_hz.map_or("—".into(), |v| format!("{v:.1} Hz")),
            m.phase_margin_deg.map_or("—".into(), |v| format!("{v:.0}°")),
            m.gain_margin_db.map_or("—".into(), |v| format!("{v:.1} dB"))
        );
        let (gain, phase, coherence) = (&mut self.gain, &mut self.phase, &mut self.coherence);
        gain.draw_series(LineSeries::new(pts(|p| p.gain_db), color.stroke_width(2)))
            .map_err(text)?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
        phase.draw_series(LineSeries::new(pts(|p| p.phase_deg), color.stroke_width(2))).map_err(text)?;
        coherence.draw_series(LineSeries::new(pts(|p| p.coherence), color.stroke_width(2))).map_err(text)?;
        for f in [m.crossover_hz, m.phase_crossover_hz].into_iter().flatten().filter(|f| *f > 0.0) {
            let x = f.log10();
            gain.draw_series(LineSeries::new([(x, g_lo), (x, g_hi)], color.mix(0.3).stroke_width(1))).map_err(text)?;
            phase.draw_series(LineSeries::new([(x, p_lo), (x, p_hi)], color.mix(0.3).stroke_width(1))).map_err(text)?;
            coherence.draw_series(LineSeries::new([(x, 0.0), (x, 1.05)], color.mix(0.3).stroke_width(1))).map_err(text)?;
        }
        // The margins themselves: the phase margin is the distance from −180° at the
        // crossover, the gain margin the distance below 0 dB at the phase crossover.
        if let (Some(fc), Some(pm)) = (m.crossover_hz.filter(|f| *f > 0.0), m.phase_margin_deg) {
            let (x, ph) = (fc.log10(), clip(pm - 180.0, p_lo, p_hi));
            phase.draw_series(LineSeries::new([(x, clip(-180.0, p_lo, p_hi)), (x, ph)], color.stroke_width(4))).map_err(text)?;
            phase.draw_series(std::iter::once(Circle::new((x, ph), 5, color.filled()))).map_err(text)?;
            gain.draw_series(std::iter::once(Circle::new((x, clip(0.0, g_lo, g_hi)), 5, color.filled()))).map_err(text)?;
        }
        if let (Some(f180), Some(gm)) = (m.phase_crossover_hz.filter(|f| *f > 0.0), m.gain_margin_db) {
            let (x, g) = (f180.log10(), clip(-gm, g_lo, g_hi));
            gain.draw_series(LineSeries::new([(x, clip(0.0, g_lo, g_hi)), (x, g)], color.stroke_width(4))).map_err(text)?;
            gain.draw_series(std::iter::once(Circle::new((x, g), 5, color.filled()))).map_err(text)?;
            phase.draw_series(std::iter::once(Circle::new((x, clip(-180.0, p_lo, p_hi)), 5, color.filled()))).map_err(text)?;
        }
        Ok(())
    }
}
