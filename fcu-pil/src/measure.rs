//! What the image costs, measured on the image: instructions per control interrupt (with its
//! SPI read), the time from the TIM9 update to the last motor write, CPU load, stack use, the
//! radio capture's worst latency while the control task runs, the longest stretch with the
//! capture interrupt masked, and the harness's own speed.
//! Numbers in instructions are exact for the emulated core under either timing profile; times
//! are the profile's ([`crate::timing`]): under the optimistic one, those instructions at
//! 84 MHz; under the pessimistic one, as slow as the board can be.

use std::fmt;

use crate::machine::SRAM_BASE;
use crate::periph::{self, time_to_s, Time};
use crate::rig;
use crate::timing::TimingProfile;

/// TIM1_BRK_TIM9 is external interrupt 24: exception 40.
const CONTROL_EXCEPTION: usize = 16 + periph::irq::TIM1_BRK_TIM9 as usize;
/// The radio capture, TIM2, is external interrupt 28: exception 44.
const CAPTURE_EXCEPTION: usize = 16 + periph::irq::TIM2 as usize;

#[derive(Clone, Debug, Default)]
pub struct Report {
    pub scenario: String,
    /// The timing profile the figures were measured under.
    pub timing: TimingProfile,
    pub emulated_s: f64,
    pub wall_s: f64,
    pub control_interrupts: usize,
    pub control_instructions_median: u64,
    pub control_instructions_max: u64,
    /// From the control interrupt's entry to its return (nested interrupts included).
    pub control_duration_us_median: f64,
    pub control_duration_us_max: f64,
    pub tick_to_last_ccr_us_median: f64,
    pub tick_to_last_ccr_us_max: f64,
    pub cpu_load_pct: f64,
    /// The ground-station link's share of the CPU after boot ([`link_ranges`]); `None` for an
    /// image without the link.
    pub link_cpu_pct: Option<f64>,
    pub stack_used_bytes: u32,
    pub stack_size_bytes: u32,
    pub capture_latency_us_median: f64,
    pub capture_latency_us_max: f64,
    pub capture_latency_during_control_us_max: f64,
    /// What ran when the slowest capture was latched: the innermost exception handler active
    /// then, or `thread` (idle or the tasks RTIC runs from thread mode).
    pub capture_latency_worst_in: String,
    /// The longest interval after boot during which the capture interrupt could not be taken
    /// because of the masks (PRIMASK, or BASEPRI at or above its priority), and where it began:
    /// the block that set the mask and its function.
    pub masked_us_max: f64,
    pub masked_from_pc: Option<u32>,
    pub masked_from_function: Option<String>,
    /// Masked intervals after boot, and the share of the flight they covered.
    pub masked_intervals: u64,
    pub masked_pct: f64,
    /// The longest wait of the capture interrupt from its line rising (a capture, or the
    /// counter's update) to its entry.
    pub capture_pending_us_max: f64,
    pub flash_bytes: u32,
    pub ram_bytes: u32,
    /// Exception entries, and how many stacked the extended (FP) frame.
    pub exception_entries: u64,
    pub fp_frames: u64,
}

/// What of an image is the ground-station link, as the ELF's function names tell (LTO inlines
/// the protocol crate into the link's task): the task (`fcu_firmware::link_task`) and what it
/// calls of its own (`fcu_link`, `fcu_gcs`, the receive ring, the flash store, fcu-core's parameter
/// table and the configuration checks a change runs), and the USART1 and DMA2 stream 2
/// interrupts.
pub fn link_ranges(image: &crate::elf::Image) -> Vec<(u32, u32)> {
    const PARTS: [&str; 11] = [
        "fcu_firmware::link_task::",
        "fcu_link::",
        "fcu_gcs::",
        "fcu_firmware::uart_rx::",
        "fcu_firmware::param_flash::",
        "fcu_params::",
        "fcu_core::flight::ControlTick::take_config",
        "Config::validate",
        "::is_valid",
        "USART1",
        "DMA2_STREAM2",
    ];
    image
        .functions
        .iter()
        .filter(|(_, _, name)| {
            let name = crate::elf::demangle(name);
            PARTS.iter().any(|p| name.contains(p))
        })
        .map(|&(a, size, _)| (a & !1, (a & !1) + size))
        .collect()
}

/// The innermost exception handler active at `t` (the one entered last among those whose
/// activation spans `t`), named by its vector; `thread` when none is.
fn running_at(stats: &std::collections::HashMap<usize, crate::machine::ExceptionStats>, t: Time, image: &crate::elf::Image) -> String {
    let innermost = stats
        .iter()
        .filter_map(|(&number, s)| {
            let i = s.spans.partition_point(|&(entered, _)| entered <= t).checked_sub(1)?;
            let &(entered, returned) = s.spans.get(i)?;
            (t <= returned).then_some((entered, number))
        })
        .max();
    match innermost {
        Some((_, number)) => image.handler_name(number).unwrap_or_else(|| format!("exception {number}")),
        None => "thread".to_string(),
    }
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn us(t: Time) -> f64 {
    time_to_s(t) * 1e6
}

/// Flies `scenario` with the image on a board set up as `setup` says (its timing profile
/// included) and measures it over the flight (boot excluded).
pub fn measure(
    elf: &std::path::Path,
    scenario: &fcu_testkit::sim::scenario::Scenario,
    opts: &fcu_testkit::sim::RunOptions,
    setup: &rig::BoardSetup,
) -> Result<Report, String> {
    let timing = setup.timing_profile()?;
    let link = link_ranges(&crate::elf::Image::load(elf)?);
    let flight = rig::fly_with(
        elf,
        scenario,
        opts,
        &rig::BoardSetup {
            timing: Some(timing),
            measure_masking_against: Some(CAPTURE_EXCEPTION),
            measure_time_in: (!link.is_empty()).then_some(link),
            // What the image costs as shipped: MAVLink from boot, not the harness's text lines.
            mavlink_from_boot: true,
            ..setup.clone()
        },
    )?;
    let m = &flight.board.machine;
    let st = m.state();
    let board = m.board();
    let t0 = board.records.tick_timer_starts.first().copied().unwrap_or(0);
    let control = st.exception_stats.get(&CONTROL_EXCEPTION).cloned().unwrap_or_default();
    let c = ControlFigures::of(&control, &board.records.ccr_writes, t0);
    let capture = CaptureFigures::of(&board.records.capture_reads, &control.spans, &st.exception_stats, m.image());

    let flown = m.now().saturating_sub(t0);
    let share_pct = |t: Time| 100.0 * time_to_s(t) / time_to_s(flown).max(1e-9);
    let masking = st.masking.clone().unwrap_or_default();
    let masked = masking.longest;
    Ok(Report {
        scenario: scenario.name.clone(),
        timing,
        emulated_s: flight.emulated_s,
        wall_s: flight.wall_s,
        control_interrupts: control.instructions.len(),
        control_instructions_median: c.instructions_median,
        control_instructions_max: c.instructions_max,
        control_duration_us_median: c.duration_us_median,
        control_duration_us_max: c.duration_us_max,
        tick_to_last_ccr_us_median: c.tick_to_last_ccr_us_median,
        tick_to_last_ccr_us_max: c.tick_to_last_ccr_us_max,
        // Idle time after boot: the boot's busy waits count as busy.
        cpu_load_pct: 100.0 - share_pct(st.idle_time.min(flown)),
        link_cpu_pct: st.region.as_ref().map(|&(_, t)| share_pct(t)),
        stack_used_bytes: m.stack_high_water().map_or(0, |low| m.stack_top - low),
        stack_size_bytes: m.stack_top - SRAM_BASE,
        capture_latency_us_median: capture.median_us,
        capture_latency_us_max: capture.max_us,
        capture_latency_during_control_us_max: capture.during_control_max_us,
        capture_latency_worst_in: capture.worst_in,
        masked_us_max: masked.map_or(0.0, |i| us(i.to - i.from)),
        masked_from_pc: masked.map(|i| i.pc),
        masked_from_function: masked.and_then(|i| m.image().function_at(i.pc)),
        masked_intervals: masking.intervals,
        masked_pct: share_pct(masking.total),
        capture_pending_us_max: st
            .exception_stats
            .get(&CAPTURE_EXCEPTION)
            .and_then(|s| s.longest_pending)
            .map_or(0.0, |(wait, _)| us(wait)),
        flash_bytes: m.image().flash_bytes,
        ram_bytes: m.image().ram_bytes,
        exception_entries: st.exception_stats.values().map(|e| e.entries).sum(),
        fp_frames: st.fp_frames,
    })
}

/// The control interrupt's own figures over a flight.
struct ControlFigures {
    instructions_median: u64,
    instructions_max: u64,
    duration_us_median: f64,
    duration_us_max: f64,
    tick_to_last_ccr_us_median: f64,
    tick_to_last_ccr_us_max: f64,
}

impl ControlFigures {
    /// From its activations, the TIM4 compare writes `(instant, channel, value)` and the
    /// tick timer's start `t0`.
    fn of(control: &crate::machine::ExceptionStats, ccr_writes: &[(Time, usize, u32)], t0: Time) -> ControlFigures {
        let mut instr: Vec<u64> = control.instructions.clone();
        instr.sort_unstable();
        let mut durations: Vec<f64> = control.spans.iter().map(|&(entered, returned)| us(returned - entered)).collect();
        let mut latencies = tick_to_last_ccr_us(&control.spans, ccr_writes, t0);
        ControlFigures {
            instructions_median: instr.get(instr.len() / 2).copied().unwrap_or(0),
            instructions_max: instr.last().copied().unwrap_or(0),
            duration_us_max: durations.iter().copied().fold(0.0, f64::max),
            duration_us_median: median(&mut durations),
            tick_to_last_ccr_us_max: latencies.iter().copied().fold(0.0, f64::max),
            tick_to_last_ccr_us_median: median(&mut latencies),
        }
    }
}

/// Per control interrupt that wrote a compare, µs from the TIM9 update that started it (the
/// last update at or before its entry: they come every 1.25 ms from the timer's start `t0`)
/// to its last TIM4 compare write.
fn tick_to_last_ccr_us(spans: &[(Time, Time)], writes: &[(Time, usize, u32)], t0: Time) -> Vec<f64> {
    let period = periph::time_from_s(1.0 / rig::TICK_HZ);
    let mut latencies = Vec::new();
    let mut w = 0;
    for &(entered, returned) in spans {
        let update = t0 + (entered.saturating_sub(t0) / period) * period;
        while w < writes.len() && writes[w].0 < entered {
            w += 1;
        }
        let mut last = None;
        while w < writes.len() && writes[w].0 <= returned {
            last = Some(writes[w].0);
            w += 1;
        }
        if let Some(last) = last {
            latencies.push(us(last - update));
        }
    }
    latencies
}

/// The radio capture's latency, from each TIM2 capture to its register read.
struct CaptureFigures {
    median_us: f64,
    max_us: f64,
    /// The longest of those that landed while the control interrupt ran.
    during_control_max_us: f64,
    /// What ran when the longest one was captured.
    worst_in: String,
}

impl CaptureFigures {
    /// From the (capture, read) instants, the control interrupt's activations (in time order)
    /// and every exception's.
    fn of(
        reads: &[(Time, Time)],
        control_spans: &[(Time, Time)],
        stats: &std::collections::HashMap<usize, crate::machine::ExceptionStats>,
        image: &crate::elf::Image,
    ) -> CaptureFigures {
        let mut lat: Vec<f64> = reads.iter().map(|&(c, r)| us(r - c)).collect();
        let during_control_max_us = reads
            .iter()
            .filter(|&&(c, _)| {
                // Spans are in time order: the last one starting at or before the capture.
                let i = control_spans.partition_point(|&(a, _)| a <= c);
                i > 0 && c <= control_spans[i - 1].1
            })
            .map(|&(c, r)| us(r - c))
            .fold(0.0, f64::max);
        let worst_in = reads.iter().max_by_key(|&&(c, r)| r - c).map_or_else(String::new, |&(c, _)| running_at(stats, c, image));
        CaptureFigures { max_us: lat.iter().copied().fold(0.0, f64::max), median_us: median(&mut lat), during_control_max_us, worst_in }
    }
}

/// The control interrupt's latency targets on the board, which the image must meet under
/// either timing profile: (what, measured, limit), limits in µs.
pub const TARGETS: [Target; 3] = [
    ("TIM9 update to the last TIM4 compare write, median", |r| r.tick_to_last_ccr_us_median, 25.0),
    ("TIM2 capture to its read, max", |r| r.capture_latency_us_max, 5.0),
    ("longest interval with TIM2 masked, after boot", |r| r.masked_us_max, 5.0),
];

/// A latency target: what it bounds, how to read it from a report, its limit in µs.
pub type Target = (&'static str, fn(&Report) -> f64, f64);

impl Report {
    /// The targets the report misses, each as a line naming the figure, its value and its limit.
    pub fn missed_targets(&self) -> Vec<String> {
        TARGETS
            .iter()
            .filter_map(|&(what, value, limit_us)| {
                let v = value(self);
                (v.is_nan() || v > limit_us).then(|| format!("{what}: {v:.1} µs, over its target of {limit_us:.0} µs"))
            })
            .collect()
    }
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "firmware image measured over `{}` ({:.1} s emulated, boot included), {} timing profile",
            self.scenario, self.emulated_s, self.timing
        )?;
        writeln!(
            f,
            "  control interrupt (TIM9, SPI read included), instructions: median {} max {} over {} ticks",
            self.control_instructions_median, self.control_instructions_max, self.control_interrupts
        )?;
        writeln!(
            f,
            "  control interrupt, entry to return: median {:.1} µs, max {:.1} µs",
            self.control_duration_us_median, self.control_duration_us_max
        )?;
        writeln!(
            f,
            "  TIM9 update to the last TIM4 compare write: median {:.1} µs, max {:.1} µs",
            self.tick_to_last_ccr_us_median, self.tick_to_last_ccr_us_max
        )?;
        writeln!(f, "  CPU load after boot: {:.1} %", self.cpu_load_pct)?;
        if let Some(link) = self.link_cpu_pct {
            writeln!(
                f,
                "  of which the ground-station link's own code (its task, protocol, receive, flash store, parameter checks; shared helpers such as memcpy not counted): {link:.2} %"
            )?;
        }
        writeln!(f, "  stack: {} of {} bytes used (high-water mark of the painted stack)", self.stack_used_bytes, self.stack_size_bytes)?;
        writeln!(
            f,
            "  TIM2 capture to its read: median {:.1} µs, max {:.1} µs (latched while {} ran); max {:.1} µs while the control task runs",
            self.capture_latency_us_median,
            self.capture_latency_us_max,
            self.capture_latency_worst_in,
            self.capture_latency_during_control_us_max
        )?;
        match self.masked_from_pc {
            Some(pc) => writeln!(
                f,
                "  TIM2 masked (PRIMASK, or BASEPRI at or above its priority): longest {:.1} µs, from PC {pc:#010x} in {}; {} intervals, {:.2} % of the time",
                self.masked_us_max,
                self.masked_from_function.as_deref().unwrap_or("an unnamed function"),
                self.masked_intervals,
                self.masked_pct
            )?,
            None => writeln!(f, "  TIM2 masked (PRIMASK, or BASEPRI at or above its priority): never after boot")?,
        }
        writeln!(
            f,
            "  TIM2 interrupt pending, from its line rising (a capture or the counter's update) to its entry: max {:.1} µs",
            self.capture_pending_us_max
        )?;
        writeln!(f, "  image: flash {} B, static RAM {} B", self.flash_bytes, self.ram_bytes)?;
        writeln!(f, "  exceptions taken: {} ({} with the extended FP frame)", self.exception_entries, self.fp_frames)?;
        writeln!(
            f,
            "  harness: {:.1} s emulated in {:.1} s of wall time ({:.1}× real time)",
            self.emulated_s,
            self.wall_s,
            self.emulated_s / self.wall_s.max(1e-9)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image_with(functions: &[(u32, u32, &str)]) -> crate::elf::Image {
        crate::elf::Image {
            path: std::path::PathBuf::from("test.elf"),
            segments: Vec::new(),
            initial_sp: 0,
            symbols: std::collections::HashMap::new(),
            symbol_sizes: std::collections::HashMap::new(),
            functions: functions.iter().map(|&(a, n, name)| (a, n, name.to_string())).collect(),
            flash_bytes: 0,
            ram_bytes: 0,
        }
    }

    #[test]
    fn the_link_is_its_task_and_what_it_calls_of_its_own() {
        let with = image_with(&[
            (0x0800_c001, 0x100, "TIM1_BRK_TIM9"),
            (0x0800_d000, 0x2000, "fcu_firmware::link_task::run::{{closure}}"),
            (0x0800_f001, 0x40, "fcu_params::snapshot::crc32"),
            (0x0800_f100, 0x80, "fcu_core::flight::ControlTick::tick_with"),
            (0x0800_f200, 0x20, "USART1"),
        ]);
        assert_eq!(link_ranges(&with), vec![(0x0800_d000, 0x0800_f000), (0x0800_f000, 0x0800_f040), (0x0800_f200, 0x0800_f220)]);
    }

    fn within_targets() -> Report {
        Report { tick_to_last_ccr_us_median: 24.9, capture_latency_us_max: 4.9, masked_us_max: 4.9, ..Report::default() }
    }

    #[test]
    fn a_report_within_every_target_misses_none() {
        assert!(within_targets().missed_targets().is_empty());
    }

    #[test]
    fn each_target_missed_is_named_with_its_value() {
        let late = Report { capture_latency_us_max: 5.6, ..within_targets() };
        assert_eq!(late.missed_targets(), vec!["TIM2 capture to its read, max: 5.6 µs, over its target of 5 µs".to_string()]);
        let slow = Report { tick_to_last_ccr_us_median: 25.1, masked_us_max: f64::NAN, ..within_targets() };
        assert_eq!(slow.missed_targets().len(), 2);
    }
}
