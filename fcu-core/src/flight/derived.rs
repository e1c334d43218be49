//! What a configuration comes to for the two halves of the pipeline, worked out in one place:
//! [`Derived::new`], at boot (and again when a run-time parameter changes). The configuration
//! itself is never changed; the scaling that moves in flight is a separate [`Gains`] value,
//! which only the tick's rate loop and throttle map follow: the tick's values are a function of
//! the configuration and the gains ([`TickParams::new`]), whatever gains came before.

use crate::config::Config;
use crate::control::{ControlConfig, Gains};
use crate::imu::Decoder;
use crate::mixer::{CompareRange, MixerConfig};
use crate::rc::RcConfig;
use crate::supervisor::SupervisorConfig;

/// Both halves' values: each half keeps its own, as they may run in different tasks.
#[derive(Clone, Debug)]
pub(crate) struct Derived {
    pub(crate) tick: TickParams,
    pub(crate) outer: OuterParams,
}

impl Derived {
    /// The one place where a configuration becomes the values the pipeline works with, at
    /// unity gains.
    pub(crate) fn new(cfg: &Config) -> Derived {
        let tick = TickParams::new(cfg, Gains::UNITY);
        // Both halves read the sensor's words the same way: one decoder, made once.
        let outer = OuterParams::new(cfg, tick.decoder);
        Derived { tick, outer }
    }
}

/// What the control tick works with: the configuration's values it reads every tick, prepared
/// once (sensor words to units, the compare range in counts, `f64` values rounded), and its rate
/// loop and throttle map scaled by the [`Gains`] in force.
#[derive(Clone, Debug)]
pub struct TickParams {
    pub(crate) rc: RcConfig,
    /// Sensor words to body axes and physical units (mount, sensitivities).
    pub(crate) decoder: Decoder,
    /// Evaluate the reference's double-precision expressions in `f64`: read it through
    /// [`reference_arithmetic`](Self::reference_arithmetic).
    reference_arithmetic: bool,
    /// The dt the heading integration assumes, s, as the reference's double (read through
    /// [`reference_dt_s`](Self::reference_dt_s)) and in f32.
    #[cfg(feature = "reference")]
    tick_dt_s_f64: f64,
    pub(crate) tick_dt_s: f32,
    /// Outer steps per second (for the yaw rate the stick asks for, in `Status`).
    pub(crate) outer_hz: f32,
    /// The configuration's control gains, the rate loop's scaled by the rate gain in force.
    pub(crate) rate_loop: ControlConfig,
    /// The configuration's mixer, the throttle map scaled by the thrust gain in force.
    pub(crate) mixer: MixerConfig,
    /// The compare clamp in whole counts.
    pub(crate) compare_range: CompareRange,
    /// The compare value with the motors off.
    pub(crate) off_compare: u16,
}

/// The configuration's control gains and mixer, unscaled: what [`TickParams::set_gains`]
/// scales. Kept beside the tick's values, not among them: the tick reads these only when the
/// gains move (docs/performance.md, «unscaled apart»).
#[derive(Clone, Debug)]
pub(crate) struct Unscaled {
    control: ControlConfig,
    mixer: MixerConfig,
}

impl Unscaled {
    pub(crate) fn new(cfg: &Config) -> Unscaled {
        Unscaled { control: cfg.control, mixer: cfg.mixer }
    }
}

impl TickParams {
    /// What `cfg` comes to for the tick with `gains` in force: its rate loop and throttle map
    /// scaled by them (at unity, `x · 1.0` is `x` bit for bit: the configuration's).
    pub(crate) fn new(cfg: &Config, gains: Gains) -> TickParams {
        TickParams {
            rc: cfg.rc,
            decoder: Decoder::new(&cfg.imu),
            reference_arithmetic: cfg.reference_arithmetic,
            #[cfg(feature = "reference")]
            tick_dt_s_f64: cfg.timing.tick_dt_s_f64(),
            tick_dt_s: cfg.timing.tick_dt_s(),
            outer_hz: cfg.timing.outer_hz(),
            rate_loop: cfg.control.scaled_rate_loop(gains.rate),
            mixer: cfg.mixer.scaled_throttle(gains.thrust),
            compare_range: cfg.mixer.compare_range(),
            off_compare: cfg.mixer.off_compare(),
        }
    }

    /// The gains in force are now `gains`: the rate loop and the throttle map are the
    /// configuration's (`unscaled`) scaled by them, as [`new`](Self::new) makes them.
    pub(crate) fn set_gains(&mut self, unscaled: &Unscaled, gains: Gains) {
        self.rate_loop = unscaled.control.scaled_rate_loop(gains.rate);
        self.mixer = unscaled.mixer.scaled_throttle(gains.thrust);
    }

    /// Evaluate the reference's double-precision expressions in `f64`. A constant `false`
    /// without the `reference` feature, so its `f64` branches are not compiled into the image
    /// (`Config::validate` refuses the flag there).
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    pub(crate) fn reference_arithmetic(&self) -> bool {
        cfg!(feature = "reference") && self.reference_arithmetic
    }

    /// The reference's double dt when its arithmetic is on; always `None` without the
    /// `reference` feature.
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    pub(crate) fn reference_dt_s(&self) -> Option<f64> {
        #[cfg(feature = "reference")]
        if self.reference_arithmetic {
            return Some(self.tick_dt_s_f64);
        }
        None
    }

    /// The control gains in force: the configuration's, the rate loop scaled by the rate gain.
    pub fn rate_loop(&self) -> &ControlConfig {
        &self.rate_loop
    }

    /// The mixer in force: the configuration's, the throttle map scaled by the thrust gain.
    pub fn mixer(&self) -> &MixerConfig {
        &self.mixer
    }
}

/// What the outer step works with, from the configuration.
#[derive(Clone, Debug)]
pub(crate) struct OuterParams {
    /// The accelerometer words of a job to body mg.
    pub(crate) decoder: Decoder,
    /// Sticks to attitude targets and heading steps.
    pub(crate) rc: RcConfig,
    /// The angle loop's gains and the yaw feedforward (the configuration's: the outer step is
    /// not scaled).
    pub(crate) control: ControlConfig,
    /// Read through [`reference_arithmetic`](Self::reference_arithmetic).
    reference_arithmetic: bool,
    pub(crate) outer_hz: f32,
    /// The supervisor checks the tilt from level before arming: the outer step works it out.
    pub(crate) arming_tilt: bool,
}

impl OuterParams {
    /// `decoder`: the tick's, made from the same configuration ([`Derived::new`]).
    pub(crate) fn new(cfg: &Config, decoder: Decoder) -> OuterParams {
        OuterParams {
            decoder,
            rc: cfg.rc,
            control: cfg.control,
            reference_arithmetic: cfg.reference_arithmetic,
            outer_hz: cfg.timing.outer_hz(),
            arming_tilt: matches!(cfg.supervisor, SupervisorConfig::Safe(_)),
        }
    }

    /// As [`TickParams::reference_arithmetic`]: a constant `false` without the `reference`
    /// feature.
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    pub(crate) fn reference_arithmetic(&self) -> bool {
        cfg!(feature = "reference") && self.reference_arithmetic
    }
}
