//! The airframe and what acts on it over a control tick: the plant with the motors held, its
//! IMU and barometer following every substep, the air (turbulence and gusts) or a hand
//! rocking it.

use super::baro_model::{BaroInputs, BaroModel, BaroModelParams};
use super::imu_model::{ImuModel, ImuModelParams, Vibration};
use super::plant::{Disturbance, Plant, PlantParams};
use super::rng;
use super::scenario::{self, Gust, HandMotion};

/// The simulated drone in its world.
pub(super) struct World {
    pub(super) plant: Plant,
    pub(super) imu: ImuModel,
    /// The LPS22HB, read by the flight computer at its outer steps.
    pub(super) baro: BaroModel,
    /// When the barometer sticks (the scenario's fault), s.
    baro_freeze_s: Option<f64>,
    air: Air,
    hand: Option<HandMotion>,
    gusts: Vec<Gust>,
    vibration: Vibration,
    /// Plant RK4 steps per control tick.
    substeps: u32,
}

impl World {
    pub(super) fn new(scenario: &scenario::Scenario, params: &PlantParams, seed: u64, substeps: u32) -> Self {
        World {
            plant: Plant::new(params.clone()),
            imu: ImuModel::new(ImuModelParams::default(), seed),
            baro: BaroModel::new(BaroModelParams::default(), seed),
            baro_freeze_s: scenario.baro_freeze_s,
            air: Air::new(scenario.turbulence, seed),
            hand: scenario.hand,
            gusts: scenario.gusts.clone(),
            vibration: Vibration { amplitude_g_at_full_speed: params.vibration_accel_g, full_speed_hz: params.motor_full_speed_hz },
            substeps: substeps.clamp(1, 100),
        }
    }

    /// The tick from `t0_s`, `tick_s` long, with the compare values the plant holds (a
    /// zero-order hold, like TIM4): the plant, the IMU and the barometer substep by substep,
    /// then the air.
    pub(super) fn advance(&mut self, t0_s: f64, tick_s: f64) {
        let sub_s = tick_s / f64::from(self.substeps);
        for j in 0..self.substeps {
            let t = t0_s + f64::from(j) * sub_s;
            let wind_earth_m_s = match self.hand.filter(|h| t >= h.start_s && t < h.end_s) {
                Some(h) => {
                    let ph = std::f64::consts::TAU * h.freq_hz * (t - h.start_s);
                    self.plant.carry(sub_s, [h.peak_rate_rad_s * ph.sin(), 0.5 * h.peak_rate_rad_s * ph.cos(), 0.0]);
                    [0.0; 3]
                }
                None => {
                    let dist = self.disturbance_at(t);
                    self.plant.step(sub_s, &dist);
                    dist.wind_earth_m_s
                }
            };
            self.imu.step(sub_s, &self.plant.kinematics(), self.vibration);
            if self.baro_freeze_s.is_some_and(|f| t >= f) {
                self.baro.freeze();
            }
            self.baro.step(sub_s, &self.baro_inputs(wind_earth_m_s));
        }
        self.air.advance(tick_s);
    }

    /// What the barometer is exposed to now: the plant's height, its collective thrust and
    /// the air's speed relative to the drone with `wind_earth_m_s` blowing.
    fn baro_inputs(&self, wind_earth_m_s: [f64; 3]) -> BaroInputs {
        let s = &self.plant.state;
        let rel: f64 = s.vel_earth_m_s.iter().zip(wind_earth_m_s).map(|(v, w)| (v - w) * (v - w)).sum();
        BaroInputs { height_m: s.pos_earth_m[2], thrust_fraction: self.plant.collective_thrust_fraction(), airspeed_m_s: rel.sqrt() }
    }

    /// The turbulence in force and every gust blowing at `t_s`.
    fn disturbance_at(&self, t_s: f64) -> Disturbance {
        let mut dist = self.air.disturbance();
        for g in self.gusts.iter().filter(|g| t_s >= g.start_s && t_s < g.start_s + g.duration_s) {
            for i in 0..3 {
                dist.wind_earth_m_s[i] += g.push.wind_earth_m_s[i];
                dist.force_earth_n[i] += g.push.force_earth_n[i];
                dist.torque_body_nm[i] += g.push.torque_body_nm[i];
            }
        }
        dist
    }
}

/// The scenario's turbulence as it evolves: first-order Gauss–Markov processes, advanced once
/// per control tick (their correlation time is hundreds of ticks).
struct Air {
    turbulence: Option<scenario::Turbulence>,
    rng: rng::Rng,
    /// Wind east, north; torque about body X, Y (unit-variance states, scaled on use).
    state: [f64; 4],
}

impl Air {
    fn new(turbulence: Option<scenario::Turbulence>, seed: u64) -> Air {
        Air { turbulence, rng: rng::Rng::fork(seed, 0x7475_7262), state: [0.0; 4] }
    }

    fn advance(&mut self, dt_s: f64) {
        if let Some(t) = self.turbulence {
            let a = (-dt_s / t.correlation_s).exp();
            let b = (1.0 - a * a).sqrt();
            for x in &mut self.state {
                *x = a * *x + b * self.rng.gaussian();
            }
        }
    }

    fn disturbance(&self) -> Disturbance {
        let Some(t) = self.turbulence else {
            return Disturbance::default();
        };
        let [we, wn, tx, ty] = self.state;
        Disturbance {
            wind_earth_m_s: [t.wind_rms_m_s * we, t.wind_rms_m_s * wn, 0.0],
            force_earth_n: [0.0; 3],
            torque_body_nm: [t.torque_rms_nm * tx, t.torque_rms_nm * ty, 0.0],
        }
    }
}
