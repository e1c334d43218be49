//! The cascade: an outer angle loop (P, optional I) at the estimator rate produces rate
//! demands; an inner rate loop (PID) every tick produces the torque commands for the mixer.
//!
//! Axis order everywhere is `[x, y, z]` = `[pitch, roll, yaw]` (the reference's naming:
//! pitch is the rotation about body X).

use crate::math::{above, within};
use crate::mixer::Saturation;

/// Gains and limits of one axis of the cascade.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisGains {
    /// Outer (angle) loop: rate demand = kp·e + ki·∫e, rad/s per rad.
    pub outer_kp: f32,
    pub outer_ki: f32,
    pub outer_i_limit: f32,
    /// Inner (rate) loop, compare counts per rad/s.
    pub inner_kp: f32,
    pub inner_ki: f32,
    pub inner_kd: f32,
    pub inner_i_limit: f32,
    /// Clamp of the inner output (the reference's MAX_ADJ_AMOUNT, ±800 counts).
    pub output_limit: f32,
    /// Low-pass the derivative (the reference does on pitch and roll, not on yaw; the default
    /// profile on every axis).
    pub d_lowpass: bool,
}

impl AxisGains {
    fn is_valid(&self) -> bool {
        let v = [
            self.outer_kp,
            self.outer_ki,
            self.outer_i_limit,
            self.inner_kp,
            self.inner_ki,
            self.inner_kd,
            self.inner_i_limit,
            self.output_limit,
        ];
        v.iter().all(|&g| within(g, 0.0, f32::MAX))
    }
}

/// Where the derivative term looks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Derivative {
    /// d/dt of the rate error: a step in the demand kicks the output (reference).
    OnError,
    /// d/dt of the negated measured rate: no kick on demand steps.
    OnMeasurement,
}

/// The whole cascade's tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlConfig {
    pub pitch: AxisGains,
    pub roll: AxisGains,
    pub yaw: AxisGains,
    /// EMA factor of the derivative low-pass (0.025 at 800 Hz ≈ 3.2 Hz).
    pub d_filter_k: f32,
    pub derivative: Derivative,
    /// Inner-loop step, s (the reference's `pid.ts`, 0.00125 though it ticks at 807.69 Hz).
    pub inner_dt_s: f32,
    /// Step of the outer integrator, s: the reference uses the inner `ts`, the default
    /// profile the real outer period.
    pub outer_integrator_dt_s: f32,
    /// Stop integrating in the direction the mixer saturates (the reference's integrators wind
    /// up against a saturated motor).
    pub anti_windup: bool,
    /// Fraction of the yaw stick's commanded rate fed straight into the yaw rate demand
    /// (a feedforward). 0 in the reference: the rate comes only from the heading loop, as
    /// `outer_kp` × the heading error, so a turn lags its stick by a heading error of
    /// rate / `outer_kp` and the rate loop sees the demand only as that error builds up.
    pub yaw_rate_feedforward: f32,
    /// Shape the stick's yaw rate into one the airframe can follow, and lead the yaw rate
    /// demand by the shaped rate's acceleration; `None` in the reference, whose heading
    /// target moves at the stick's rate from one outer step to the next.
    pub yaw_shaping: Option<YawShaping>,
    /// Scale the rate loop's output and the throttle map with the battery voltage;
    /// `None` in the reference, whose gains weaken as the battery sags.
    pub battery: Option<BatteryCompensation>,
    /// Scale the rate loop with the motors' thrust curve at the throttle flown; `None`
    /// in the reference, whose corrections make less thrust the higher the throttle.
    pub thrust_curve: Option<ThrustCurve>,
}

/// The motors' static thrust against duty, for the rate loop's gain.
///
/// A brushed motor's thrust is not linear in its duty: the STEVAL-DRONE01's 8520 motors give
/// `quad·d² + lin·d` of their full thrust at duty `d` (−0.33 d² + 1.32 d), so a correction of
/// one compare count makes 1.32 − 0.66 d of thrust: a third less at full throttle than at zero.
/// The rate loop's gains are tuned at `reference_duty`; at the duty the throttle asks for, they
/// are multiplied by `slope(reference_duty) / slope(d)`, so a rate error asks for the same
/// torque at any throttle and the loop keeps the crossover and margins it was tuned for.
/// This linearises the corrections around the throttle flown, the part the loop depends on,
/// with no work on the 800 Hz path (the outer step works out the gain; the tick is rescaled
/// only when it moves a step of 1/256); the throttle stick itself keeps the reference's map.
/// On another airframe, measure its curve and set these three numbers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThrustCurve {
    /// Thrust fraction = `quad·d² + lin·d`.
    pub quad: f32,
    pub lin: f32,
    /// The duty the rate loop's gains were tuned at (the nominal drone's hover), 0..1.
    pub reference_duty: f32,
}

impl ThrustCurve {
    /// The 8520 motors of the STEVAL-DRONE01 (the DC build), gains tuned at the nominal hover.
    pub const MOTOR_8520: ThrustCurve = ThrustCurve { quad: -0.33, lin: 1.32, reference_duty: 0.45 };

    /// The gain stays within `[1 / MAX_GAIN, MAX_GAIN]`.
    pub const MAX_GAIN: f32 = 2.0;

    /// Thrust per unit of duty at `duty`.
    pub fn slope(&self, duty: f32) -> f32 {
        2.0 * self.quad * duty + self.lin
    }

    /// A curve whose thrust rises with the duty over the whole range, tuned inside it.
    pub fn is_valid(&self) -> bool {
        let finite = within(self.quad, f32::MIN, f32::MAX) && within(self.lin, f32::MIN, f32::MAX);
        // Between 0 and 1, so finite.
        finite && self.slope(0.0) > 0.0 && self.slope(1.0) > 0.0 && self.reference_duty > 0.0 && self.reference_duty < 1.0
    }

    /// The rate loop's gain factor at `duty`, in steps of 1/256 so that the tick is rescaled
    /// only when it moves a step.
    pub fn gain_at(&self, duty: f32) -> f32 {
        let d = if duty.is_finite() { duty.clamp(0.0, 1.0) } else { self.reference_duty };
        let g = self.slope(self.reference_duty) / self.slope(d);
        if g.is_finite() {
            libm::roundf(g.clamp(1.0 / Self::MAX_GAIN, Self::MAX_GAIN) * 256.0) / 256.0
        } else {
            1.0
        }
    }
}

/// Thrust compensation for the battery. A brushed motor's speed at a given duty is
/// proportional to the voltage and its thrust to the speed squared, so at `v` the same duty
/// gives `(v / nominal)²` of the thrust it gave at `nominal`: the rate loop's gains, its output
/// limit and the throttle map are multiplied by `(nominal / v)²` (the thrust gain), so the
/// loop and the throttle stick feel the same from a full battery to an empty one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BatteryCompensation {
    /// The voltage the gains and the throttle map are tuned for, mV.
    pub nominal_mv: u32,
    /// Readings below this are not a battery (unplugged, USB power): ignored, mV.
    pub min_valid_mv: u32,
    /// The thrust gain stays within `[1 / max_gain, max_gain]`: a nearly empty battery is not
    /// chased into motors that cannot deliver anyway.
    pub max_gain: f32,
    /// Time constant of the reading's low-pass, s. The sag follows the current within
    /// milliseconds; compensating it that fast would turn more throttle into more sag into
    /// more throttle, so the gain follows the battery's charge, not each burst of current.
    pub filter_s: f32,
}

impl BatteryCompensation {
    /// A 1S LiPo: tuned at 4.0 V (a charged cell hovering), ignored under 2.5 V, at most
    /// ×1.5, 2 s low-pass.
    pub const LIPO_1S: BatteryCompensation = BatteryCompensation { nominal_mv: 4000, min_valid_mv: 2500, max_gain: 1.5, filter_s: 2.0 };

    pub fn is_valid(&self) -> bool {
        self.nominal_mv > 0 && self.min_valid_mv > 0 && within(self.max_gain, 1.0, 4.0) && above(self.filter_s, 0.0, f32::MAX)
    }

    /// The thrust gain for a (filtered) battery voltage.
    pub fn thrust_gain(&self, battery_mv: f32) -> f32 {
        let ratio = self.nominal_mv as f32 / battery_mv;
        let g = ratio * ratio;
        if g.is_finite() {
            crate::math::limit(g, 1.0 / self.max_gain, self.max_gain)
        } else {
            1.0
        }
    }
}

/// The battery voltage as the compensation sees it: the low-passed valid readings, and the
/// thrust gain they give (1 until the first valid reading).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BatteryFilter {
    filtered_mv: Option<f32>,
    latest_mv: u32,
}

impl BatteryFilter {
    /// The latest reading (the firmware's ADC gives one every 100 ms).
    pub fn set_reading(&mut self, battery_mv: u32) {
        self.latest_mv = battery_mv;
    }

    /// One outer step of `dt_s`: the filter follows the latest valid reading; the thrust gain.
    pub fn update(&mut self, cfg: &BatteryCompensation, dt_s: f32) -> f32 {
        if self.latest_mv >= cfg.min_valid_mv {
            let v = self.latest_mv as f32;
            let alpha = (dt_s / cfg.filter_s).min(1.0);
            self.filtered_mv = Some(match self.filtered_mv {
                Some(f) => f + alpha * (v - f),
                // The first reading: no start-up ramp from nothing.
                None => v,
            });
        }
        // In steps of 1/512 (0.2 %): the rate loop is rescaled only when the gain moves a
        // step, a few hundred times a flight at most, not on every outer step.
        self.filtered_mv.map_or(1.0, |mv| libm::roundf(cfg.thrust_gain(mv) * 512.0) / 512.0)
    }
}

/// The scaling the outer step works out at run time ([`GainSchedule`]): the throttle map's gain
/// (the battery compensation's thrust gain) and the rate loop's (the thrust gain times the
/// thrust curve's factor at the throttle flown). Both 1 without either.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gains {
    /// The throttle map's: [`BatteryCompensation`].
    pub thrust: f32,
    /// The rate loop's: the thrust gain times [`ThrustCurve::gain_at`].
    pub rate: f32,
}

impl Gains {
    /// The configuration as given.
    pub const UNITY: Gains = Gains { thrust: 1.0, rate: 1.0 };
}

/// Where the [`Gains`] come from, once per outer step: the battery's filtered voltage (battery
/// compensation) and the duty the throttle stick flies at (the thrust curve).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GainSchedule {
    battery: Option<BatteryCompensation>,
    filter: BatteryFilter,
    /// The thrust curve, with the throttle map and PWM period its operating point (a duty) is
    /// read through: the configuration's, not the scaled map the tick flies.
    thrust_curve: Option<(ThrustCurve, crate::mixer::MixerConfig)>,
    /// The outer step's period, s.
    dt_s: f32,
}

impl GainSchedule {
    /// For outer steps at `outer_hz`; unity until the first valid battery reading.
    pub fn new(control: &ControlConfig, mixer: &crate::mixer::MixerConfig, outer_hz: f32) -> GainSchedule {
        GainSchedule {
            battery: control.battery,
            filter: BatteryFilter::default(),
            thrust_curve: control.thrust_curve.map(|c| (c, *mixer)),
            dt_s: 1.0 / outer_hz,
        }
    }

    /// The latest battery reading, mV (ignored without a battery compensation).
    pub fn set_battery_mv(&mut self, battery_mv: u32) {
        self.filter.set_reading(battery_mv);
    }

    /// One outer step with the throttle stick at `throttle`.
    pub fn update(&mut self, throttle: crate::rc::StickCounts) -> Gains {
        let thrust = match self.battery {
            Some(b) => self.filter.update(&b, self.dt_s),
            None => 1.0,
        };
        let rate = match self.thrust_curve {
            Some((curve, mixer)) => {
                // The duty the throttle stick flies at, through the map in force.
                let counts = f32::from(mixer.throttle_counts(throttle).0) * thrust;
                thrust * curve.gain_at(counts / mixer.period_counts())
            }
            None => thrust,
        };
        Gains { thrust, rate }
    }
}

impl ControlConfig {
    /// This configuration's rate loop for a thrust gain `g` (see [`BatteryCompensation`]).
    pub fn scaled_rate_loop(&self, g: f32) -> ControlConfig {
        let scale = |a: AxisGains| AxisGains {
            inner_kp: a.inner_kp * g,
            inner_ki: a.inner_ki * g,
            inner_kd: a.inner_kd * g,
            output_limit: a.output_limit * g,
            ..a
        };
        ControlConfig { pitch: scale(self.pitch), roll: scale(self.roll), yaw: scale(self.yaw), ..*self }
    }
}

impl ControlConfig {
    pub const REFERENCE: ControlConfig = ControlConfig {
        pitch: AxisGains {
            outer_kp: 3.0,
            outer_ki: 0.0,
            outer_i_limit: 2.0,
            inner_kp: 100.0,
            inner_ki: 100.0,
            inner_kd: 10.0,
            inner_i_limit: 20.0,
            output_limit: 800.0,
            d_lowpass: true,
        },
        roll: AxisGains {
            outer_kp: 3.0,
            outer_ki: 0.0,
            outer_i_limit: 2.0,
            inner_kp: 100.0,
            inner_ki: 100.0,
            inner_kd: 10.0,
            inner_i_limit: 20.0,
            output_limit: 800.0,
            d_lowpass: true,
        },
        yaw: AxisGains {
            outer_kp: 4.0,
            outer_ki: 0.0,
            outer_i_limit: 2.0,
            inner_kp: 1000.0,
            inner_ki: 0.0,
            inner_kd: 0.0,
            inner_i_limit: 2.0,
            output_limit: 800.0,
            d_lowpass: false,
        },
        d_filter_k: 0.025,
        derivative: Derivative::OnError,
        inner_dt_s: 0.00125,
        outer_integrator_dt_s: 0.00125,
        anti_windup: false,
        yaw_rate_feedforward: 0.0,
        yaw_shaping: None,
        battery: None,
        thrust_curve: None,
    };

    pub fn axes(&self) -> [&AxisGains; 3] {
        [&self.pitch, &self.roll, &self.yaw]
    }

    pub fn is_valid(&self) -> bool {
        let dt_ok = |dt: f32| above(dt, 0.0, f32::MAX);
        self.axes().iter().all(|a| a.is_valid())
            && above(self.d_filter_k, 0.0, 1.0)
            && dt_ok(self.inner_dt_s)
            && dt_ok(self.outer_integrator_dt_s)
            && within(self.yaw_rate_feedforward, 0.0, 1.5)
            && self.yaw_shaping.is_none_or(|y| y.is_valid())
            && self.battery.is_none_or(|b| b.is_valid())
            && self.thrust_curve.is_none_or(|c| c.is_valid())
    }
}

/// Yaw turns shaped to what the airframe can follow.
///
/// A stick step asks for a new yaw rate at once, which no airframe can give: the motors take
/// tens of milliseconds to change their torque, and a quad's yaw torque is small against its
/// yaw inertia (a full-stick turn takes about 0.1 s of full braking to stop on a weak ±30 %
/// airframe). So the stick's rate passes through two first-order stages of `stage_s` each
/// (critically damped: no overshoot, the turn's total heading unchanged) and the heading
/// target moves at the shaped rate. The yaw rate demand then leads the shaped rate by
/// `lead_s` times its acceleration: the rate loop's P term turns that into the torque the
/// acceleration needs (the inertia's, and what the derivative term on the measurement takes away
/// while the rate changes) before a rate error has to build up to ask for it. Both happen in
/// the outer step; the tick sees only its rate demand.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct YawShaping {
    /// Time constant of each of the two stages, s.
    pub stage_s: f32,
    /// How far the yaw rate demand leads the shaped rate, s (demand += lead × acceleration).
    pub lead_s: f32,
}

impl YawShaping {
    /// Stages from 1 ms (the acceleration is divided by it) to 1 s, a lead of at most 0.5 s.
    pub fn is_valid(&self) -> bool {
        within(self.stage_s, 0.001, 1.0) && within(self.lead_s, 0.0, 0.5)
    }
}

/// One outer step of the shaped yaw rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShapedYaw {
    /// The rate the heading target moves at, rad/s.
    pub rate_rad_s: f32,
    /// What the rate demand adds ahead of it: `lead_s` × the shaped acceleration, rad/s.
    pub lead_rad_s: f32,
}

/// The two stages of [`YawShaping`], stepped once per outer step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct YawRateShaper {
    cfg: YawShaping,
    /// Each stage's step towards its input per outer step: 1 − e^(−dt / stage_s).
    alpha: f32,
    first: f32,
    rate: f32,
}

impl YawRateShaper {
    /// At rest, for steps of `dt_s`.
    pub fn new(cfg: &YawShaping, dt_s: f32) -> YawRateShaper {
        YawRateShaper { cfg: *cfg, alpha: 1.0 - libm::expf(-dt_s / cfg.stage_s), first: 0.0, rate: 0.0 }
    }

    /// One step towards the stick's rate. The acceleration is the second stage's own
    /// derivative, (first − rate) / stage_s: exact, not a difference of two steps.
    pub fn shape(&mut self, stick_rate_rad_s: f32) -> ShapedYaw {
        self.first += self.alpha * (stick_rate_rad_s - self.first);
        self.rate += self.alpha * (self.first - self.rate);
        if !(self.first.is_finite() && self.rate.is_finite()) {
            self.reset();
        }
        let accel_rad_s2 = (self.first - self.rate) / self.cfg.stage_s;
        ShapedYaw { rate_rad_s: self.rate, lead_rad_s: self.cfg.lead_s * accel_rad_s2 }
    }

    /// Back at rest (throttle low).
    pub fn reset(&mut self) {
        self.first = 0.0;
        self.rate = 0.0;
    }
}

/// The outer (angle) loop: rate demand = kp·(target − estimate) + ki·∫(target − estimate), per
/// axis.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AngleLoop {
    integ: [f32; 3],
}

impl AngleLoop {
    /// One outer step. `throttle_low` resets the integrators first, as the reference.
    pub fn rate_demands(&mut self, cfg: &ControlConfig, target_rad: [f32; 3], estimate_rad: [f32; 3], throttle_low: bool) -> [f32; 3] {
        if throttle_low {
            self.integ = [0.0; 3];
        }
        let ts = cfg.outer_integrator_dt_s;
        let mut demand_rad_s = [0.0f32; 3];
        for (((s, integ), gains), (t, e_est)) in
            demand_rad_s.iter_mut().zip(self.integ.iter_mut()).zip(cfg.axes()).zip(target_rad.iter().zip(estimate_rad))
        {
            let e = t - e_est;
            *integ = clamp_symmetric(*integ + e * ts, gains.outer_i_limit);
            *s = gains.outer_kp * e + gains.outer_ki * *integ;
        }
        demand_rad_s
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct RateAxis {
    integ: f32,
    prev_error: f32,
    prev_rate: f32,
    d: f32,
}

impl RateAxis {
    /// One axis, one tick, for a finite error `e = demand − rate`, with the derivative on the
    /// measurement or on the error and with or without anti-windup.
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    #[allow(clippy::too_many_arguments)] // the per-tick values of one axis, kept in registers
    fn command<const ON_MEASUREMENT: bool, const ANTI_WINDUP: bool>(
        &mut self,
        cfg: &ControlConfig,
        g: &AxisGains,
        e: f32,
        rate: f32,
        saturated_dirs: u8,
        ts: f32,
        dt_recip: f32,
    ) -> f32 {
        let raw_d = if ON_MEASUREMENT { (self.prev_rate - rate) * dt_recip } else { (e - self.prev_error) * dt_recip };
        self.prev_error = e;
        self.prev_rate = rate;
        let d = if g.d_lowpass {
            self.d = self.d + (raw_d - self.d) * cfg.d_filter_k;
            self.d
        } else {
            raw_d
        };
        let integ = clamp_symmetric(self.integ + e * ts, g.inner_i_limit);
        let unclamped = g.inner_kp * e + g.inner_ki * integ + g.inner_kd * d;
        // `over` is the output clamp's own test, shared with the anti-windup: in steady flight
        // neither the clamp nor the mixer holds anything back, and one comparison says so.
        let over = unclamped.abs() > g.output_limit;
        if ANTI_WINDUP && (over || saturated_dirs != 0) && winds_up(e, saturated_dirs, unclamped, over) {
            // Keep the integrator where it was and say what that gives.
            let held = g.inner_kp * e + g.inner_ki * self.integ + g.inner_kd * d;
            return clamp_symmetric(held, g.output_limit);
        }
        self.integ = integ;
        if over {
            clamp_symmetric(unclamped, g.output_limit)
        } else {
            unclamped
        }
    }
}

/// The inner (rate) loop: PID per axis on the filtered gyro, every tick.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RateLoop {
    axes: [RateAxis; 3],
}

impl RateLoop {
    /// One tick: the angle loop's rate demands and the measured rates (rad/s) in, clamped
    /// commands out.
    /// `saturation` is the mixer's verdict of the previous tick (used only with anti-windup).
    pub fn commands(
        &mut self,
        cfg: &ControlConfig,
        demand_rad_s: [f32; 3],
        rate_rad_s: [f32; 3],
        throttle_low: bool,
        saturation: Saturation,
    ) -> [f32; 3] {
        if throttle_low {
            for a in &mut self.axes {
                a.integ = 0.0;
            }
        }
        let [d0, d1, d2] = demand_rad_s;
        let [r0, r1, r2] = rate_rad_s;
        let errors = [d0 - r0, d1 - r1, d2 - r2];
        // The profile's two switches, decided once per tick rather than on every axis.
        match (cfg.derivative, cfg.anti_windup) {
            (Derivative::OnMeasurement, true) => self.commands_of_axes::<true, true>(cfg, errors, rate_rad_s, saturation),
            #[cfg(feature = "reference")]
            (Derivative::OnMeasurement, false) => self.commands_of_axes::<true, false>(cfg, errors, rate_rad_s, saturation),
            #[cfg(feature = "reference")]
            (Derivative::OnError, true) => self.commands_of_axes::<false, true>(cfg, errors, rate_rad_s, saturation),
            #[cfg(feature = "reference")]
            (Derivative::OnError, false) => self.commands_of_axes::<false, false>(cfg, errors, rate_rad_s, saturation),
            // Without the `reference` feature `Config::validate` refuses every other pair: each
            // would be three more inlined copies of the rate loop (a kilobyte or so each) in an
            // image that cannot fly them.
            #[cfg(not(feature = "reference"))]
            _ => self.commands_of_axes::<true, true>(cfg, errors, rate_rad_s, saturation),
        }
    }

    #[inline(always)] // docs/performance.md, «inlined into the tick».
    fn commands_of_axes<const ON_MEASUREMENT: bool, const ANTI_WINDUP: bool>(
        &mut self,
        cfg: &ControlConfig,
        errors: [f32; 3],
        rate_rad_s: [f32; 3],
        saturation: Saturation,
    ) -> [f32; 3] {
        let ts = cfg.inner_dt_s;
        let dt_recip = 1.0 / ts;
        let [e0, e1, e2] = errors;
        let mut out = [0.0f32; 3];
        let sat = [0, 1, 2].map(|axis| saturation.axis_bits(axis));
        let per_axis = self.axes.iter_mut().zip(cfg.axes()).zip(errors.into_iter().zip(rate_rad_s)).zip(sat);
        // A non-finite demand or rate makes its error, and so the sum of the three, non-finite:
        // one test covers the three axes on every ordinary tick. (Three finite errors can only
        // overflow the sum to infinity, which just sends the tick down the careful loop.)
        if (e0 + e1 + e2).is_finite() {
            for (o, (((st, g), (e, rate)), sat)) in out.iter_mut().zip(per_axis) {
                *o = st.command::<ON_MEASUREMENT, ANTI_WINDUP>(cfg, g, e, rate, sat, ts, dt_recip);
            }
        } else {
            for (o, (((st, g), (e, rate)), sat)) in out.iter_mut().zip(per_axis) {
                // A non-finite error must not enter the state: no correction on this axis this
                // tick, the state holds.
                *o = if e.is_finite() { st.command::<ON_MEASUREMENT, ANTI_WINDUP>(cfg, g, e, rate, sat, ts, dt_recip) } else { 0.0 };
            }
        }
        out
    }

    /// The integrator of each axis (for tests and telemetry).
    pub fn integrators(&self) -> [f32; 3] {
        self.axes.map(|a| a.integ)
    }
}

/// Anti-windup: integrating `e` would push further in a direction that is already
/// saturated, either in the mixer on the last tick (`sat`) or by this output's own clamp
/// (`over`: conditional integration, since what the clamp holds back would only have to be
/// unwound later). Compared by sign bits (docs/performance.md, «sign bits»): with `e = ±0`
/// the integrator cannot move, so which way a zero counts does not matter.
#[inline(always)] // docs/performance.md, «inlined into the tick».
fn winds_up(e: f32, saturated_dirs: u8, unclamped: f32, over: bool) -> bool {
    let e_negative = e.is_sign_negative();
    let mixer_blocks = saturated_dirs & if e_negative { 2 } else { 1 } != 0;
    mixer_blocks || (over && unclamped.is_sign_negative() == e_negative)
}

/// The reference's clamp: `if v > lim {lim} else if v < −lim {−lim} else {v}`, for the
/// validated `lim ≥ 0`, as one magnitude test (docs/performance.md): the same result for
/// every `v`, NaN included (it passes through, as in C; the mixer's final clamp catches it).
#[inline(always)] // docs/performance.md, «inlined into the tick».
fn clamp_symmetric(v: f32, lim: f32) -> f32 {
    if v.abs() > lim {
        if v > 0.0 {
            lim
        } else {
            -lim
        }
    } else {
        v
    }
}

/// The battery voltage from the ADC with a divider ratio that can be set (the parameter
/// `BATT_VOLT_MULT`): a board whose resistors differ from the schematic's reads true.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BatterySense {
    /// Battery volts per volt at the ADC pin (1.5 with the board's 10 k / 20 k divider).
    pub volt_mult: f32,
}

impl BatterySense {
    /// The board's divider.
    pub const BOARD: BatterySense = BatterySense { volt_mult: BATTERY_DIVIDER_NUM as f32 / BATTERY_DIVIDER_DEN as f32 };

    pub fn is_valid(&self) -> bool {
        self.volt_mult.is_finite() && self.volt_mult >= 1.0 && self.volt_mult <= 10.0
    }

    /// Battery millivolts from a 12-bit reading, rounded (the board's divider gives what
    /// [`battery_mv`](crate::telemetry::battery_mv) gives).
    pub fn mv(&self, adc_counts: u16) -> u32 {
        let counts = u32::from(adc_counts).min(BATTERY_ADC_FULL_SCALE);
        let pin_mv = (counts * BATTERY_ADC_REF_MV) as f32 / BATTERY_ADC_FULL_SCALE as f32;
        // Non-negative and at most 3300 × 10: the cast neither wraps nor saturates.
        (pin_mv * self.volt_mult + 0.5) as u32
    }
}

/// Battery sense: ADC1 channel 9 on PB1, 12-bit, 3.3 V reference, 10 k / 20 k divider (×1.5).
pub const BATTERY_ADC_FULL_SCALE: u32 = 4095;
pub const BATTERY_ADC_REF_MV: u32 = 3300;
/// (R_top + R_bottom) / R_bottom = (10 + 20) / 20, as a fraction 3/2.
pub const BATTERY_DIVIDER_NUM: u32 = 3;
pub const BATTERY_DIVIDER_DEN: u32 = 2;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_gains_differ_in_any_one_field() {
        let a = ControlConfig::REFERENCE.pitch;
        assert_eq!(a, a);
        let changes: [fn(&mut AxisGains); 9] = [
            |g| g.outer_kp += 1.0,
            |g| g.outer_ki += 1.0,
            |g| g.outer_i_limit += 1.0,
            |g| g.inner_kp += 1.0,
            |g| g.inner_ki += 1.0,
            |g| g.inner_kd += 1.0,
            |g| g.inner_i_limit += 1.0,
            |g| g.output_limit += 1.0,
            |g| g.d_lowpass = !g.d_lowpass,
        ];
        for (i, change) in changes.iter().enumerate() {
            let mut b = a;
            change(&mut b);
            assert_ne!(a, b, "field {i}");
        }
        // As f32 compares: -0 equals 0, a NaN nothing.
        assert_eq!(AxisGains { outer_ki: -0.0, ..a }, AxisGains { outer_ki: 0.0, ..a });
        let nan = AxisGains { inner_kd: f32::NAN, ..a };
        assert_ne!(nan, nan);
    }

    // The reference's rate loop (derivative on error, winding up) is compiled in with the
    // `reference` feature only.
    #[cfg(feature = "reference")]
    mod reference_rate_loop {
        use super::*;

        #[test]
        fn inner_d_filter_matches_the_reference_worked_example() {
            // docs/reference.md#examples: error steps 0 → 0.1 rad/s: raw_d 80, d 2.0, KD·d 20.
            let cfg = ControlConfig::REFERENCE;
            let mut r = RateLoop::default();
            let none = Saturation::NONE;
            let out = r.commands(&cfg, [0.1, 0.0, 0.0], [0.0; 3], false, none);
            let p = 100.0 * 0.1;
            let i = 100.0 * 0.1 * 0.00125;
            assert!((out[0] - (p + i + 20.0)).abs() < 1e-3, "{}", out[0]);
            let out2 = r.commands(&cfg, [0.1, 0.0, 0.0], [0.0; 3], false, none);
            let i2 = 100.0 * 0.1 * 0.0025;
            assert!((out2[0] - (p + i2 + 19.5)).abs() < 1e-3, "{}", out2[0]);
        }

        #[test]
        fn derivative_on_measurement_has_no_kick_on_a_demand_step() {
            let mut cfg = ControlConfig::REFERENCE;
            cfg.derivative = Derivative::OnMeasurement;
            let none = Saturation::NONE;
            let mut on_meas = RateLoop::default();
            let mut on_err = RateLoop::default();
            let a = on_meas.commands(&cfg, [1.0, 0.0, 0.0], [0.0; 3], false, none)[0];
            let b = on_err.commands(&ControlConfig::REFERENCE, [1.0, 0.0, 0.0], [0.0; 3], false, none)[0];
            // P + I only, vs P + I + a 200-count derivative kick.
            assert!(a < 101.0, "{a}");
            assert!(b > 290.0, "{b}");
        }

        #[test]
        fn integrator_resets_while_throttle_is_low_and_is_clamped() {
            let cfg = ControlConfig::REFERENCE;
            let none = Saturation::NONE;
            let mut r = RateLoop::default();
            for _ in 0..100_000 {
                r.commands(&cfg, [35.0, -35.0, 0.0], [0.0; 3], false, none);
            }
            assert_eq!(r.integrators()[0], 20.0);
            assert_eq!(r.integrators()[1], -20.0);
            r.commands(&cfg, [35.0, -35.0, 0.0], [0.0; 3], true, none);
            assert_eq!(r.integrators()[0], 35.0 * 0.00125);
        }
    }

    #[test]
    fn anti_windup_freezes_the_saturated_direction_only() {
        let mut cfg = ControlConfig::REFERENCE;
        cfg.anti_windup = true;
        let sat = Saturation::NONE.with(0, true, false);
        let mut r = RateLoop::default();
        r.commands(&cfg, [1.0, 1.0, 0.0], [0.0; 3], false, sat);
        assert_eq!(r.integrators()[0], 0.0);
        assert!(r.integrators()[1] > 0.0);
        r.commands(&cfg, [-1.0, 0.0, 0.0], [0.0; 3], false, sat);
        assert!(r.integrators()[0] < 0.0);
    }

    #[test]
    fn outer_loop_is_proportional_with_the_reference_gains() {
        let cfg = ControlConfig::REFERENCE;
        let mut o = AngleLoop::default();
        let d = o.rate_demands(&cfg, [0.1, -0.2, 0.05], [0.0; 3], false);
        assert!((d[0] - 0.3).abs() < 1e-6 && (d[1] + 0.6).abs() < 1e-6 && (d[2] - 0.2).abs() < 1e-6);
    }

    #[test]
    fn saturation_keeps_each_axis_and_direction_apart() {
        let s = Saturation::NONE.with(0, true, false).with(2, false, true);
        assert!(s.positive(0) && !s.negative(0));
        assert!(!s.positive(1) && !s.negative(1));
        assert!(!s.positive(2) && s.negative(2));
        assert!(!s.positive(7));
        assert_eq!(Saturation::of_commands([3.0, 0.0, -1.0]), s);
    }

    proptest::proptest! {
        #[test]
        fn the_magnitude_clamp_is_the_references_clamp(v in proptest::num::f32::ANY, lim in 0.0f32..1e6) {
            let reference = if v > lim { lim } else if v < -lim { -lim } else { v };
            proptest::prop_assert_eq!(clamp_symmetric(v, lim).to_bits(), reference.to_bits());
        }
    }

    #[test]
    fn a_nan_rate_does_not_stay_in_the_state() {
        let cfg = ControlConfig::REFERENCE;
        let none = Saturation::NONE;
        let mut r = RateLoop::default();
        r.commands(&cfg, [0.0; 3], [f32::NAN, 0.0, 0.0], false, none);
        let out = r.commands(&cfg, [0.0; 3], [0.0; 3], false, none);
        assert!(out.iter().all(|v| v.is_finite()));
    }
}
