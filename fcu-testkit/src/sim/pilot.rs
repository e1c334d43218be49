//! The pilot's side of the radio: the scenario's stick timeline, with the throttle held by a
//! simulated pilot where the timeline says so, sent through the receiver model.

use fcu_core::Config;

use super::plant::{self, Plant};
use super::radio_model::{RadioModel, TimedEdge, TxFrame};
use super::scenario::{self, Scenario, Throttle, Timeline};
use super::stick_rate::StickRate;

/// The transmitter in the pilot's hands and the receiver's output, tick by tick.
pub(super) struct Transmitter<'s> {
    timeline: &'s Timeline,
    cfg: Config,
    radio: RadioModel,
    pilot: Pilot,
    stick: StickRate,
    /// The throttle pulse of the last frame sent, µs.
    pub(super) last_thr_us: f64,
}

impl<'s> Transmitter<'s> {
    pub(super) fn new(scenario: &'s Scenario, cfg: Config, seed: u64) -> Self {
        Transmitter {
            timeline: &scenario.timeline,
            cfg,
            radio: RadioModel::new(scenario.radio.clone(), seed),
            pilot: Pilot::default(),
            // The sticks as a core set up for the scenario's transmitter reads them: what the
            // pilot asks for, whatever the flight computer makes of it.
            stick: StickRate::new(
                &scenario.radio.transmitter.map_or(cfg, |t| fcu_params::apply_file(&cfg, &t.parameters()).unwrap_or(cfg)),
            ),
            last_thr_us: scenario::THR_LOW_US,
        }
    }

    /// The capture edges of the tick ending at `t_end_s` into `edges` (cleared first): each
    /// frame carries the sticks at the frame's start, the pilot's throttle worked out from
    /// `plant` as it is now. Returns the yaw rate those edges' stick asks for, °/s.
    pub(super) fn send(&mut self, t_end_s: f64, plant: &Plant, edges: &mut Vec<TimedEdge>) -> f64 {
        edges.clear();
        self.radio.advance(
            t_end_s,
            |tf| {
                let row = self.timeline.at(tf);
                let thr_us = match row.thr {
                    Throttle::Us(u) => u,
                    Throttle::HoldAltitude { alt_m } => self.pilot.throttle_us(alt_m, plant, &self.cfg, 0.02),
                    Throttle::Stick(f) => stick_us(&self.cfg, f),
                    Throttle::ClimbTo { alt_m, stick, release_m } => {
                        stick_us(&self.cfg, self.pilot.climb_stick(row.t_s, alt_m, stick, release_m, plant))
                    }
                };
                self.last_thr_us = thr_us;
                TxFrame { width_us: [row.ail_us, row.ele_us, thr_us, row.rud_us], link: row.link }
            },
            edges,
        );
        self.stick.yaw_rate_dps(edges.iter().map(|e| e.edge))
    }
}

/// The throttle pulse of the stick at `fraction` of its half travel from the centre (−1 the
/// bottom, +1 the top) with `cfg`'s throttle endpoints, µs.
fn stick_us(cfg: &Config, fraction: f64) -> f64 {
    let e = cfg.rc.input_for(fcu_core::rc::Function::Throttle);
    let (lo, hi) = (f64::from(e.min_counts), f64::from(e.max_counts));
    let f = if fraction.is_finite() { fraction.clamp(-1.0, 1.0) } else { 0.0 };
    (0.5 * (lo + hi) + f * 0.5 * (hi - lo)) / 4.0
}

/// The simulated pilot on the throttle stick: knows roughly where hover is and holds a height.
#[derive(Clone, Debug, Default)]
struct Pilot {
    integral: f64,
    /// The climb row (by its start time) whose height has been reached: the stick stays
    /// centred until the next row.
    released_row_s: Option<f64>,
}

impl Pilot {
    /// The stick of a [`Throttle::ClimbTo`] row starting at `row_s`: `stick` towards `alt_m`
    /// until within `release_m`, then centred (a pilot lets go of the stick at the height and
    /// the hold keeps it).
    fn climb_stick(&mut self, row_s: f64, alt_m: f64, stick: f64, release_m: f64, plant: &Plant) -> f64 {
        if self.released_row_s == Some(row_s) {
            return 0.0;
        }
        let err = alt_m - plant.state.pos_earth_m[2];
        if err.abs() <= release_m {
            self.released_row_s = Some(row_s);
            return 0.0;
        }
        stick.abs() * err.signum()
    }

    /// Throttle pulse (µs) to hold `alt_m`, from what a pilot sees (height, climb rate, tilt).
    fn throttle_us(&mut self, alt_target_m: f64, plant: &Plant, cfg: &Config, dt_s: f64) -> f64 {
        let p = &plant.params;
        let s = &plant.state;
        let alt_err = alt_target_m - s.pos_earth_m[2];
        let vz_wanted = (1.2 * alt_err).clamp(-0.4, 0.6);
        let vz_err = vz_wanted - s.vel_earth_m_s[2];
        if !s.on_ground {
            self.integral = (self.integral + 0.3 * alt_err * dt_s).clamp(-0.2, 0.2);
        }
        let factor = (1.0 + 0.6 * vz_err + self.integral).clamp(0.5, 1.5);
        let up = plant::quat_rotate(s.quat, [0.0, 0.0, 1.0])[2].max(0.5);
        let frac = p.hover_fraction(s.battery_v) * factor / up;
        let ccr = p.duty_for_fraction(frac) * p.pwm_full_scale_counts;
        let m = &cfg.mixer;
        let g_thr = if m.throttle_slope > 0.0 { (ccr - f64::from(m.throttle_offset)) / f64::from(m.throttle_slope) } else { 0.0 };
        // Never below MIN_THR + margin: below it the core cuts the motors (a pilot flying
        // knows not to pull the stick to the bottom).
        let g_thr = g_thr.max(f64::from(cfg.rc.min_throttle.get()) + 40.0);
        (f64::from(cfg.rc.input_for(fcu_core::rc::Function::Throttle).min_counts) + g_thr) / 4.0
    }
}
