//! The simulated PWM receiver and the TIM2 capture unit behind it (`docs/reference.md#radio`).
//!
//! Every 20 ms frame the receiver drives its four outputs one after the other (AIL, ELE, THR,
//! RUD: each channel rises when the previous one falls), each pulse 800..2200 µs wide. The MCU
//! timestamps every edge with TIM2 counting at 4 MHz (0.25 µs) and wrapping every 32768 counts
//! (8.192 ms), so a 2 ms pulse spans a quarter of the counter and the wrap is hit every frame.
//! Edges carry jitter; optionally whole frames drop out and short spurious spikes appear.
//!
//! The pilot's sticks arrive as the reference's transmitter (a Devo 7E) sends them. A scenario
//! can fly another [`Transmitter`]: each stick's travel re-encoded with that transmitter's
//! endpoints and sense, on the receiver output it uses.

use std::collections::VecDeque;

use fcu_core::rc::{CaptureEdge, CAPTURE_WRAP, CHANNELS, COUNTS_PER_US};

use super::rng::Rng;

/// TIM2 counts per second (84 MHz / (PSC 20 + 1)).
pub const CAPTURE_COUNTS_PER_S: f64 = COUNTS_PER_US as f64 * 1e6;

/// What the transmitter sends in one frame: pulse widths in µs and whether the link is up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TxFrame {
    pub width_us: [f64; CHANNELS],
    /// False: the receiver outputs nothing (signal lost, receiver without failsafe pulses).
    pub link: bool,
}

#[derive(Clone, Debug, PartialEq)]
pub struct RadioParams {
    /// The transmitter behind the receiver; `None`: the reference's Devo 7E, whose widths the
    /// pilot's sticks already are.
    pub transmitter: Option<Transmitter>,
    pub frame_period_s: f64,
    /// Edge timing jitter, µs rms (receiver clock and interrupt latency).
    pub jitter_us: f64,
    /// Probability that a whole frame is missing (a brief radio fade).
    pub frame_dropout_probability: f64,
    /// Probability per frame of one spurious short spike on a random channel.
    pub glitch_probability: f64,
}

impl Default for RadioParams {
    fn default() -> Self {
        RadioParams { transmitter: None, frame_period_s: 0.020, jitter_us: 0.5, frame_dropout_probability: 0.0, glitch_probability: 0.0 }
    }
}

impl RadioParams {
    /// A noisy receiver: a frame in fifty missing and a spike every ten frames.
    pub fn noisy() -> Self {
        RadioParams { jitter_us: 2.0, frame_dropout_probability: 0.02, glitch_probability: 0.1, ..Self::default() }
    }
}

/// A transmitter that is not the reference's: which receiver output each stick comes out on,
/// which sticks it reverses, and each stick's pulse width at the bottom, centre and top of its
/// travel. The flight core flies it once its parameters say the same (`RCMAP_*`, `RCn_MIN`,
/// `RCn_TRIM`, `RCn_MAX`, `RCn_REV`); with the Devo's, it reads the wrong sticks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transmitter {
    pub name: &'static str,
    /// The receiver output (capture input, 0-based) of each stick, in the core's order: roll
    /// (AIL), pitch (ELE), throttle (THR), yaw (RUD).
    pub output_of: [usize; CHANNELS],
    /// The stick's pulse gets shorter as the stick goes up or right.
    pub reversed: [bool; CHANNELS],
    /// Each stick's width at the bottom, the centre and the top of its travel, µs (the
    /// throttle is flown from its bottom to its top; its centre is not read).
    pub endpoints_us: [[f64; 3]; CHANNELS],
}

impl Transmitter {
    /// A transmitter in the common "TAER" order (throttle on the first output, then roll,
    /// pitch, yaw), its pitch reversed, every stick from 1000 to 2000 µs, centred at 1500.
    /// Its parameters: `fcu-testkit/data/other-transmitter.parm`.
    pub const OTHER: Transmitter = Transmitter {
        name: "TAER, pitch reversed, 1000..2000 µs",
        output_of: [1, 2, 0, 3],
        reversed: [false, true, false, false],
        endpoints_us: [[1000.0, 1500.0, 2000.0], [1000.0, 1500.0, 2000.0], [1000.0, 1500.0, 2000.0], [1000.0, 1500.0, 2000.0]],
    };

    /// The flight core's radio parameters for this transmitter, in MAVProxy's `param save`
    /// format: `RCMAP_*` from its outputs, `RCn_MIN/TRIM/MAX/REV` from each output's
    /// endpoints and sense (the throttle's trim at its bottom, as ground stations set it).
    pub fn parameters(&self) -> String {
        use std::fmt::Write as _;
        let mut text = String::new();
        for (stick, name) in ["RCMAP_ROLL", "RCMAP_PITCH", "RCMAP_THROTTLE", "RCMAP_YAW"].iter().enumerate() {
            let _ = writeln!(text, "{name} {}", self.output_of[stick] + 1);
        }
        for (stick, &output) in self.output_of.iter().enumerate() {
            let [lo, mid, hi] = self.endpoints_us[stick];
            let trim = if stick == fcu_core::rc::THR { lo } else { mid };
            let n = output + 1;
            let rev = if self.reversed[stick] { -1 } else { 1 };
            let _ = writeln!(text, "RC{n}_MIN {lo}\nRC{n}_TRIM {trim}\nRC{n}_MAX {hi}\nRC{n}_REV {rev}");
        }
        text
    }

    /// The widths this transmitter sends, by receiver output, for the sticks the Devo 7E
    /// sends as `devo_us` (AIL, ELE, THR, RUD): each stick's travel from its centre, as a
    /// fraction of the Devo's, placed on this transmitter's endpoints; the throttle's from its
    /// bottom to its top, resting on its bottom where the Devo's rests below its own. A width
    /// that is not a number stays one (a broken script, as for the Devo).
    pub fn widths_us(&self, devo_us: [f64; CHANNELS]) -> [f64; CHANNELS] {
        let devo = fcu_core::rc::RcConfig::REFERENCE;
        let us = |counts: u16| f64::from(counts) / COUNTS_PER_US as f64;
        let mut out = [0.0; CHANNELS];
        for (stick, &w) in devo_us.iter().enumerate() {
            let d = devo.inputs[stick];
            let (d_lo, d_mid, d_hi) = (us(d.min_counts), us(d.trim_counts), us(d.max_counts));
            let [lo, mid, hi] = self.endpoints_us[stick];
            let width = if stick == fcu_core::rc::THR {
                let up = ((w - d_lo) / (d_hi - d_lo)).max(0.0);
                if self.reversed[stick] {
                    hi - up * (hi - lo)
                } else {
                    lo + up * (hi - lo)
                }
            } else {
                // -1 at the bottom, 0 at the centre, +1 at the top.
                let travel = if w >= d_mid { (w - d_mid) / (d_hi - d_mid) } else { (w - d_mid) / (d_mid - d_lo) };
                let travel = if self.reversed[stick] { -travel } else { travel };
                if travel >= 0.0 {
                    mid + travel * (hi - mid)
                } else {
                    mid + travel * (mid - lo)
                }
            };
            if let Some(slot) = out.get_mut(self.output_of[stick]) {
                *slot = width;
            }
        }
        out
    }
}

/// A capture edge and the simulation time it happens at (the core never sees the time; it
/// orders the edges, and an emulated board changes its pin then).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimedEdge {
    pub t_s: f64,
    pub edge: CaptureEdge,
}

#[derive(Clone, Debug)]
pub struct RadioModel {
    params: RadioParams,
    rng: Rng,
    next_frame_s: f64,
    /// Edges scheduled but not yet delivered, in time order.
    pending: VecDeque<TimedEdge>,
    frames_sent: u64,
}

/// TIM2 value at simulation time `t_s` (the timer starts with the simulation).
pub fn capture_counts_at(t_s: f64) -> u16 {
    let counts = (t_s.max(0.0) * CAPTURE_COUNTS_PER_S).floor() as u64;
    (counts % u64::from(CAPTURE_WRAP)) as u16
}

impl RadioModel {
    /// `first_frame_s` sets the receiver's phase relative to the control ticks.
    pub fn new(params: RadioParams, seed: u64) -> Self {
        let mut rng = Rng::fork(seed, 0x0052_4144_494F);
        let first_frame_s = params.frame_period_s * rng.uniform();
        RadioModel { params, rng, next_frame_s: first_frame_s, pending: VecDeque::new(), frames_sent: 0 }
    }

    pub fn frames_sent(&self) -> u64 {
        self.frames_sent
    }

    /// Schedule every frame that starts before `t_end_s` (with the transmitter state `tx`
    /// given by `tx_at(frame_start_s)`), then move the edges that happen before `t_end_s`
    /// into `out`, oldest first.
    pub fn advance(&mut self, t_end_s: f64, mut tx_at: impl FnMut(f64) -> TxFrame, out: &mut Vec<TimedEdge>) {
        while self.next_frame_s < t_end_s {
            let start = self.next_frame_s;
            self.next_frame_s += self.params.frame_period_s.max(1e-3);
            let tx = tx_at(start);
            if !tx.link || self.rng.chance(self.params.frame_dropout_probability) {
                continue;
            }
            self.schedule_frame(start, &tx);
        }
        while let Some(e) = self.pending.front() {
            if e.t_s >= t_end_s {
                break;
            }
            if let Some(e) = self.pending.pop_front() {
                out.push(e);
            }
        }
    }

    fn schedule_frame(&mut self, start_s: f64, tx: &TxFrame) {
        self.frames_sent += 1;
        let mut new = Vec::with_capacity(2 * CHANNELS + 2);
        let mut rise_s = start_s;
        let widths_us = self.params.transmitter.map_or(tx.width_us, |t| t.widths_us(tx.width_us));
        for (ch, &w_us) in widths_us.iter().enumerate() {
            // A width that is not a number is what a broken transmitter script would give;
            // the receiver then holds the line low for that channel.
            let w_s = if w_us.is_finite() { w_us.clamp(0.0, 19_000.0) * 1e-6 } else { 0.0 };
            let fall_s = rise_s + w_s;
            if w_s > 0.0 {
                let j1 = self.jitter_s();
                let j2 = self.jitter_s();
                new.push(self.edge(rise_s + j1, ch, true));
                new.push(self.edge(fall_s + j2, ch, false));
            }
            rise_s = fall_s;
        }
        if self.rng.chance(self.params.glitch_probability) {
            let ch = (self.rng.next_u64() % CHANNELS as u64) as usize;
            // A spike somewhere in the frame, a few µs long.
            let at = start_s + self.params.frame_period_s * self.rng.uniform();
            let len = (2.0 + 20.0 * self.rng.uniform()) * 1e-6;
            new.push(self.edge(at, ch, true));
            new.push(self.edge(at + len, ch, false));
        }
        self.pending.extend(new);
        // Jitter and glitches can reorder neighbouring edges: deliver them in time order.
        self.pending.make_contiguous().sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    }

    fn jitter_s(&mut self) -> f64 {
        self.params.jitter_us * 1e-6 * self.rng.gaussian()
    }

    fn edge(&self, t_s: f64, channel: usize, level_high: bool) -> TimedEdge {
        TimedEdge { t_s, edge: CaptureEdge { channel, capture_counts: capture_counts_at(t_s), level_high } }
    }
}

/// Stick width (µs) for a stick value `g` in RC counts around a centre in counts
/// (`docs/reference.md#radio`).
pub fn width_us_for(centre_counts: f64, g_counts: f64) -> f64 {
    (centre_counts + g_counts) / 4.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tx(width_us: [f64; 4]) -> impl FnMut(f64) -> TxFrame {
        move |_| TxFrame { width_us, link: true }
    }

    /// Wrap-safe width, as the capture decoder computes it.
    fn width_counts(rise: u16, fall: u16) -> u32 {
        (u32::from(fall) + CAPTURE_WRAP - u32::from(rise)) % CAPTURE_WRAP
    }

    #[test]
    fn capture_counter_wraps_every_8_192_ms() {
        assert_eq!(capture_counts_at(0.0), 0);
        assert_eq!(capture_counts_at(0.001), 4000);
        assert_eq!(capture_counts_at(0.008_192), 0);
        assert_eq!(capture_counts_at(0.008_192 + 0.000_25), 1000);
    }

    #[test]
    fn frames_come_at_50_hz_with_widths_that_decode_through_the_wrap() {
        let widths = [1465.5, 1537.75, 1000.0, 1599.25];
        let mut r = RadioModel::new(RadioParams { jitter_us: 0.0, ..RadioParams::default() }, 1);
        let mut edges = Vec::new();
        let mut t = 0.0;
        while t < 1.0 {
            t += 0.00125;
            r.advance(t, tx(widths), &mut edges);
        }
        assert!((49..=51).contains(&r.frames_sent()), "{} frames", r.frames_sent());
        assert!(edges.windows(2).all(|w| w[0].t_s <= w[1].t_s), "edges out of order");
        let mut rise = [None; 4];
        let mut seen = 0;
        for e in edges.iter().map(|e| e.edge) {
            if e.level_high {
                rise[e.channel] = Some(e.capture_counts);
            } else if let Some(r0) = rise[e.channel] {
                let w = width_counts(r0, e.capture_counts);
                let want = (widths[e.channel] * 4.0) as u32;
                assert!(w.abs_diff(want) <= 1, "channel {} width {w} counts, want {want}", e.channel);
                seen += 1;
            }
        }
        assert!(seen >= 4 * 49);
    }

    #[test]
    fn edges_are_delivered_only_once_their_time_has_come() {
        let mut r = RadioModel::new(RadioParams::default(), 3);
        let mut t = 0.0;
        for _ in 0..2000 {
            let mut edges = Vec::new();
            let t0 = t;
            t += 0.00125;
            r.advance(t, tx([1500.0; 4]), &mut edges);
            assert!(edges.iter().all(|e| e.t_s < t && e.t_s >= t0 - 1e-5));
        }
    }

    #[test]
    fn no_link_means_no_edges() {
        let mut r = RadioModel::new(RadioParams::default(), 1);
        let mut edges = Vec::new();
        r.advance(1.0, |_| TxFrame { width_us: [1500.0; 4], link: false }, &mut edges);
        assert!(edges.is_empty());
    }

    #[test]
    fn dropouts_and_glitches_happen_at_their_rates() {
        let params = RadioParams { frame_dropout_probability: 0.2, glitch_probability: 0.5, ..RadioParams::default() };
        let mut r = RadioModel::new(params, 9);
        let mut edges = Vec::new();
        r.advance(20.0, tx([1500.0; 4]), &mut edges);
        let frames = r.frames_sent() as f64;
        assert!((700.0..900.0).contains(&frames), "{frames} of 1000 frames sent");
        let extra = edges.len() as f64 - 8.0 * frames;
        // Each glitch adds 2 edges; expected 0.5 per sent frame.
        assert!((extra / 2.0 / frames - 0.5).abs() < 0.1, "{extra} glitch edges");
    }

    #[test]
    fn the_other_transmitter_moves_each_stick_to_its_output_endpoints_and_sense() {
        let devo =
            fcu_core::rc::RcConfig::REFERENCE.inputs.map(|e| [e.min_counts, e.trim_counts, e.max_counts].map(|c| f64::from(c) / 4.0));
        let t = Transmitter::OTHER;
        // Sticks centred, throttle resting below the Devo's bottom: centres, the throttle on
        // its bottom, each on its output (throttle 0, roll 1, pitch 2, yaw 3).
        let rest = t.widths_us([devo[0][1], devo[1][1], 1000.0, devo[3][1]]);
        assert_eq!(rest, [1000.0, 1500.0, 1500.0, 1500.0]);
        // Every stick at its Devo top: the tops, but the reversed pitch at its bottom.
        let top = t.widths_us([devo[0][2], devo[1][2], devo[2][2], devo[3][2]]);
        assert_eq!(top, [2000.0, 2000.0, 1000.0, 2000.0]);
        // Half the roll stick's travel down: half this transmitter's.
        let half = t.widths_us([(devo[0][0] + devo[0][1]) / 2.0, devo[1][1], devo[2][0], devo[3][1]]);
        assert_eq!(half[1], 1250.0);
        assert!(t.widths_us([f64::NAN, devo[1][1], devo[2][0], devo[3][1]])[1].is_nan());
    }

    #[test]
    fn the_other_transmitters_parameters_are_its_file() {
        let file = fcu_params::apply_file(
            &fcu_core::Config::default(),
            include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/data/other-transmitter.parm")),
        );
        let made = fcu_params::apply_file(&fcu_core::Config::default(), &Transmitter::OTHER.parameters());
        assert_eq!(file.map(|c| c.rc), made.map(|c| c.rc));
        assert_ne!(made.map(|c| c.rc), Ok(fcu_core::Config::default().rc));
    }

    #[test]
    fn stick_widths_follow_the_reference_centres() {
        // Full right aileron (gAIL = −1800 around 5862 counts) is 1015.5 µs.
        assert_eq!(width_us_for(5862.0, -1800.0), 1015.5);
    }
}
