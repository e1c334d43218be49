//! The emulated board as a [`FlightComputer`]: the seam fcu-testkit's simulated drone flies
//! through. Boot runs on its own (the drone sits level and still, the receiver is silent)
//! until the firmware starts its control timer: that instant is scenario time 0, so the
//! firmware's tick `k` falls on the simulation's tick `k`, as the in-process core's does.
//!
//! Each step then: the IMU model's words for the end of the period go into the LSM6DSL model,
//! the battery voltage onto PB1's divider, the period's capture edges onto PA0..PA3 at their
//! own times, and the machine runs to the period's end; TIM4's compare values in force then
//! drive the plant over the next period. So the firmware reads sensor words up to one tick
//! newer than the instant it reads them, and its motor writes reach the plant up to one tick
//! later than they happen (plus TIM4's own preload, up to a PWM period): together the same
//! loop delay as the in-process core, bounded by a tick either way.

use fcu_core::baro::{COUNTS_PER_DEG_C, PA_PER_COUNT};
use fcu_core::imu::RawImu;
use fcu_core::supervisor::Blocker;
use fcu_core::telemetry::{CalibrationReport, StatusFields};
use fcu_testkit::sim::baro_model::BaroModel;
use fcu_testkit::sim::radio_model::TimedEdge;
use fcu_testkit::sim::{ComputerView, FlightComputer, SimError};

use crate::board::Board;
use crate::elf::Image;
use crate::machine::{Fault, Machine};
use crate::periph::sensors::ISA_SEA_LEVEL_PA;
use crate::periph::{time_from_s, time_to_s, Time};
use crate::telemetry::{self, Line, LineSplitter};
use crate::timing::TimingProfile;

/// The control tick the firmware runs (TIM9 at exactly 800 Hz, `Config::default()`).
pub const TICK_HZ: f64 = 800.0;

/// What to do to the board before or during the flight (fault injection).
#[derive(Clone, Debug, Default)]
pub struct BoardSetup {
    /// WHO_AM_I answers replaced, per sensor (LSM6DSL, LIS2MDL, LPS22HB).
    pub who_am_i_override: [Option<u8>; 3],
    /// Boot waits at most this long for the control timer (default 5 s).
    pub boot_timeout_s: Option<f64>,
    /// The drone's battery voltage during boot.
    pub boot_battery_v: f64,
    /// The HSE crystal never starts (a cracked crystal).
    pub hse_dead: bool,
    /// The PLL never locks.
    pub pll_dead: bool,
    /// The LSI's frequency, Hz (`None`: its nominal 32 kHz; DS9716 allows 17–47 kHz).
    pub lsi_hz: Option<u64>,
    /// VDD, volts (`None`: the board's 3.3 V regulator).
    pub vdd_volts: Option<f64>,
    /// How the emulator prices time ([`crate::timing`]); `None`: `FCU_PIL_TIMING` from the
    /// environment, optimistic if it is not set (a value that names no profile is an error).
    pub timing: Option<TimingProfile>,
    /// Measure interrupt masking against this exception, and every interrupt's wait from its
    /// line to its entry, from the end of boot ([`Machine::measure_masking_against`]).
    pub measure_masking_against: Option<usize>,
    /// The flash memory's contents at power-on (a saved image); the ELF's sectors replace theirs.
    /// `None`: no saved image, and what the parameter sectors hold is [`BoardSetup::mavlink_from_boot`]'s.
    pub flash_contents: Option<Vec<u8>>,
    /// With no `flash_contents`: the board as shipped, its parameter sectors erased, so its UART
    /// speaks MAVLink from boot (`LINK_PROTOCOL`'s default) and the harness leaves it
    /// unparsed. `false`, the default: the product's defaults saved with `LINK_PROTOCOL` 0, as
    /// `cargo pil fly --params` saves them, so the UART carries the text lines the harness reads
    /// the board's state from.
    pub mavlink_from_boot: bool,
    /// Add up the time spent in these code ranges from the end of boot
    /// ([`Machine::measure_time_in`]).
    pub measure_time_in: Option<Vec<(u32, u32)>>,
    /// Parameters set by name over the saved set (`flash_contents`', or the product's
    /// defaults) before power-on, as a ground station would have set and saved them: a
    /// scenario's settings (`ALT_MODE` for altitude hold). Saved with `LINK_PROTOCOL` 0, so the
    /// harness reads the text lines; a name or value the parameter table refuses fails the
    /// boot, naming it (as does asking for them with [`BoardSetup::mavlink_from_boot`]).
    pub settings: Vec<(String, f32)>,
}

impl BoardSetup {
    /// The timing profile this setup asks for.
    pub fn timing_profile(&self) -> Result<TimingProfile, String> {
        self.timing.map_or_else(TimingProfile::from_env, Ok)
    }
}

/// `settings` as a parameter file (`NAME VALUE` lines, fcu-params' format).
fn settings_file(settings: &[(String, f32)]) -> String {
    settings.iter().map(|(name, value)| format!("{name} {value}\n")).collect()
}

/// A parsed UART line with the time its last byte left the UART.
#[derive(Clone, Debug)]
pub struct TimedLine {
    pub at: Time,
    pub text: String,
    pub line: Line,
}

/// The release firmware in the emulated STM32F401.
pub struct EmulatedBoard {
    pub machine: Machine<Board>,
    /// Emulated time of scenario time 0 (the control timer's start), if it started.
    t0: Option<Time>,
    splitter: LineSplitter,
    uart_read: usize,
    pub lines: Vec<TimedLine>,
    /// Every STATUS line, in order.
    pub statuses: Vec<(Time, StatusFields)>,
    view: ComputerView,
    /// First problem with a UART line (format errors are failures of the image).
    pub line_errors: Vec<String>,
    /// A HardFault or a lockup fails the flight ([`FlightComputer::step`]) unless this is set:
    /// a test that injects one sets it to watch what follows.
    pub faults_expected: bool,
    /// The UART carries something other than the firmware's text lines (a binary protocol):
    /// its bytes are not parsed as lines.
    pub raw_uart: bool,
    /// Lines a reset cut short, with the time of the first byte after it (not parsed).
    pub cut_lines: Vec<(Time, String)>,
    /// When the last UART byte the harness split into lines left the UART.
    last_uart_at: Option<Time>,
    /// The simulator's barometer part has made a sample: from then on its words are the
    /// pressure at the emulated LPS22HB ([`FlightComputer::step_with_baro`]).
    sim_baro_sampled: bool,
}

impl EmulatedBoard {
    /// Powers the board on with `image` and runs its boot until the control timer starts (or
    /// the timeout passes: a board that never starts it can still be inspected).
    pub fn boot(image: Image, setup: &BoardSetup, imu_at_rest: RawImu) -> Result<EmulatedBoard, Fault> {
        let mut board = Board::new();
        for (i, o) in setup.who_am_i_override.iter().enumerate() {
            board.spi2.sensors_mut().set_who_am_i_override(i, *o);
        }
        board.spi2.sensors_mut().lsm6dsl.set_output(imu_at_rest.gyro, imu_at_rest.accel);
        board.set_battery_volts(if setup.boot_battery_v > 0.0 { setup.boot_battery_v } else { 4.0 });
        board.rcc.set_hse_dead(setup.hse_dead);
        board.rcc.set_pll_dead(setup.pll_dead);
        if let Some(hz) = setup.lsi_hz {
            board.iwdg.set_lsi_hz(hz);
        }
        if let Some(volts) = setup.vdd_volts {
            board.pwr.set_vdd_volts(volts);
        }
        let text_lines;
        let contents = match (&setup.flash_contents, setup.mavlink_from_boot, setup.settings.is_empty()) {
            (Some(contents), _, true) => Some(contents),
            (None, true, true) => None,
            (_, true, false) => {
                return Err(Fault::Setup(
                    "parameter settings are saved with LINK_PROTOCOL 0 (text lines): not with mavlink_from_boot".into(),
                ))
            }
            (saved, false, _) => {
                let file = settings_file(&setup.settings);
                let text = (!file.is_empty()).then_some(file.as_str());
                text_lines = crate::serve::flash_for_flight(saved.clone().unwrap_or_default(), text)
                    .map_err(|e| Fault::Setup(format!("parameter settings {:?}: {e:?}", setup.settings)))?;
                Some(&text_lines)
            }
        };
        if let Some(contents) = contents {
            board.flash.load_memory(contents);
        }
        // With no saved parameters the image speaks MAVLink from boot: its UART is binary, not
        // lines (a frame's bytes may happen to look like a debug line).
        let speaks_mavlink = contents.is_none();
        let machine = Machine::new(image, board, setup.timing_profile().map_err(Fault::Setup)?)?;
        let mut b = EmulatedBoard {
            machine,
            t0: None,
            splitter: LineSplitter::default(),
            uart_read: 0,
            lines: Vec::new(),
            statuses: Vec::new(),
            view: ComputerView::default(),
            line_errors: Vec::new(),
            faults_expected: false,
            raw_uart: speaks_mavlink,
            cut_lines: Vec::new(),
            last_uart_at: None,
            sim_baro_sampled: false,
        };
        let timeout = time_from_s(setup.boot_timeout_s.unwrap_or(5.0));
        let slice = time_from_s(0.001);
        while b.machine.now() < timeout {
            let next = b.machine.now() + slice;
            b.machine.run_until(next)?;
            b.drain_uart();
            if let Some(&t) = b.machine.board().records.tick_timer_starts.first() {
                b.t0 = Some(t);
                // From the end of the boot slice: the first control tick is a period after
                // the timer's start, later than the slice's end.
                if let Some(exc) = setup.measure_masking_against {
                    b.machine.measure_masking_against(exc);
                }
                if let Some(ranges) = &setup.measure_time_in {
                    b.machine.measure_time_in(ranges.clone());
                }
                break;
            }
        }
        Ok(b)
    }

    /// Hangs the control task: runs until its interrupt (TIM9) is the active exception, then
    /// makes it call the image's endless loop (`DefaultHandler_`), as a stalled control task
    /// would. For the watchdog's tests.
    pub fn hang_control_task(&mut self) -> Result<(), Fault> {
        let control = 16 + crate::periph::irq::TIM1_BRK_TIM9 as usize;
        let endless = self
            .machine
            .image()
            .symbol("DefaultHandler_")
            .ok_or_else(|| Fault::Setup("no DefaultHandler_ (an endless loop) in the image".into()))?;
        let mut t = self.machine.now();
        while self.machine.current_exception() != control {
            t += time_from_s(2e-6);
            self.machine.run_until(t)?;
        }
        self.machine.inject_call(endless, 0)
    }

    /// Whether the firmware started its control timer at boot.
    pub fn flying(&self) -> bool {
        self.t0.is_some()
    }

    /// Where a boot that never started the control timer is stuck: the PC, its function, and
    /// the register the code last read (a polling loop's register), with its value.
    pub fn boot_stall(&self) -> String {
        let pc = self.machine.pc();
        let function = self.machine.image().function_at(pc).unwrap_or_else(|| "an unnamed function".into());
        let register = match self.machine.board().records.last_read {
            Some((at, addr, value)) => {
                format!("last register read {} = {value:#010x} at {:.6} s", crate::board::register_name(addr), time_to_s(at))
            }
            None => "no register read".into(),
        };
        let faults = self.fault_report().map_or(String::new(), |f| format!("; {f}"));
        format!(
            "the firmware never started its control timer: at {:.3} s the CPU is at PC {pc:#010x} in {function}; {register}{faults}",
            time_to_s(self.machine.now())
        )
    }

    /// The first HardFault and the first lockup, if any, in words.
    pub fn fault_report(&self) -> Option<String> {
        let st = self.machine.state();
        let hard_fault = st.hard_faults.first().map(|hf| {
            let function = self.machine.image().function_at(hf.pc).unwrap_or_else(|| "an unnamed function".into());
            format!("HardFault at PC {:#010x} in {function}, {:.6} s: {}", hf.pc, time_to_s(hf.at), hf.cause)
        });
        let lockup = st.lockups.first().map(|l| {
            let function = self.machine.image().function_at(l.pc).unwrap_or_else(|| "an unnamed function".into());
            format!("lockup at PC {:#010x} in {function}, {:.6} s: {}", l.pc, time_to_s(l.at), l.cause)
        });
        match (hard_fault, lockup) {
            (Some(h), Some(l)) => Some(format!("{h}; then {l}")),
            (h, l) => h.or(l),
        }
    }

    /// Emulated time of a scenario time.
    pub fn time_of(&self, t_s: f64) -> Time {
        self.t0.unwrap_or(0) + time_from_s(t_s)
    }

    /// Scenario time of an emulated time.
    pub fn scenario_s(&self, t: Time) -> f64 {
        time_to_s(t) - time_to_s(self.t0.unwrap_or(0))
    }

    /// Runs until scenario time `t_s` with nothing new from the outside.
    pub fn run_to(&mut self, t_s: f64) -> Result<(), Fault> {
        let target = self.time_of(t_s);
        self.machine.run_until(target)?;
        self.drain_uart();
        Ok(())
    }

    /// Everything the UART sent so far, as text.
    pub fn uart_text(&self) -> String {
        let bytes: Vec<u8> = self.machine.board().records.uart.iter().map(|&(_, b)| b).collect();
        String::from_utf8_lossy(&bytes).into_owned()
    }

    fn drain_uart(&mut self) {
        let uart = &self.machine.board().records.uart;
        let new: Vec<(Time, u8)> = uart.get(self.uart_read..).map(<[_]>::to_vec).unwrap_or_default();
        self.uart_read = uart.len();
        if self.raw_uart {
            return;
        }
        let resets: Vec<Time> = self.machine.state().resets.iter().map(|&(t, _)| t).collect();
        for (at, byte) in new {
            // A reset (the watchdog's, after a fault) cuts the line being sent: its start is
            // not the start of the next line, and not a malformed line of the image.
            if resets.iter().any(|&r| self.last_uart_at.is_some_and(|last| last < r) && r <= at) {
                if let Some(text) = self.splitter.cut() {
                    self.cut_lines.push((at, text));
                }
            }
            self.last_uart_at = Some(at);
            if let Some(text) = self.splitter.push(byte) {
                match telemetry::parse(&text) {
                    Ok(line) => {
                        self.apply(at, &line);
                        self.lines.push(TimedLine { at, text, line });
                    }
                    Err(e) => self.line_errors.push(e),
                }
            }
        }
    }

    fn apply(&mut self, at: Time, line: &Line) {
        match line {
            Line::Status(s) => {
                self.view.state = s.state;
                self.view.armed = s.armed();
                self.view.link = !s.blockers.contains(Blocker::LinkNotGood) && s.failsafe_stage().is_none();
                self.view.calibrating = s.calibration.in_progress();
                if s.calibration == CalibrationReport::Passed {
                    self.view.calibrated = true;
                }
                self.statuses.push((at, *s));
            }
            Line::Debug(d) => {
                self.view.est_pitch_deg = d.pitch_deg * DEG_PER_PRINTED_DEG;
                self.view.est_roll_deg = d.roll_deg * DEG_PER_PRINTED_DEG;
                self.view.pitch_target_deg = d.pitch_target_deg * DEG_PER_PRINTED_DEG;
                self.view.roll_target_deg = d.roll_target_deg * DEG_PER_PRINTED_DEG;
            }
            Line::Fatal(_) | Line::Other(_) => {}
        }
    }
}

/// The debug line prints angles as the reference does, radians × 57.3; true degrees are
/// radians × 180/π.
const DEG_PER_PRINTED_DEG: f64 = 180.0 / std::f64::consts::PI / 57.3;

impl FlightComputer for EmulatedBoard {
    fn tick_hz(&self) -> f64 {
        TICK_HZ
    }

    fn step(&mut self, t_end_s: f64, edges: &[TimedEdge], imu: RawImu, battery_v: f64) -> Result<[u16; 4], SimError> {
        let t0 = self.t0.ok_or_else(|| SimError::Computer(format!("{} (see uart.log)", self.boot_stall())))?;
        {
            let board = self.machine.board_mut();
            board.spi2.sensors_mut().lsm6dsl.set_output(imu.gyro, imu.accel);
            board.set_battery_volts(battery_v);
            for e in edges {
                board.schedule_edge(t0 + time_from_s(e.t_s), e.edge.channel, e.edge.level_high);
            }
        }
        let target = t0 + time_from_s(t_end_s);
        self.machine.run_until(target).map_err(|f| SimError::Computer(format!("firmware image: {f}")))?;
        if !self.faults_expected {
            if let Some(report) = self.fault_report() {
                return Err(SimError::Computer(format!("firmware image: {report} (times since power-on)")));
            }
        }
        self.drain_uart();
        if let Some(e) = self.line_errors.first() {
            return Err(SimError::Computer(format!("firmware image: malformed UART line: {e}")));
        }
        let now = self.machine.now();
        Ok(self.machine.board_mut().motor_compares(now))
    }

    /// The barometer reads the ISA pressure at the drone's height, the take-off level at
    /// standard sea-level pressure.
    fn air(&mut self, height_m: f64) -> Result<(), SimError> {
        let baro = &mut self.machine.board_mut().spi2.sensors_mut().lps22hb;
        baro.set_height_m(height_m, ISA_SEA_LEVEL_PA)
            .map_err(|e| SimError::Computer(format!("barometer input at height {height_m} m: {e:?}")))
    }

    /// The scenario's barometer part (its noise, offset, warm-up, prop wash, ground effect,
    /// gust pressure and a freeze, sampled at its rate) sets the pressure and temperature at
    /// the emulated LPS22HB, in place of [`FlightComputer::air`]'s ISA height: so the image
    /// sees the air the in-process core sees, through the emulated part's own filter and
    /// sampling on top (`docs/fcu-pil.md`). Before the part's first sample, the ISA height.
    fn step_with_baro(
        &mut self,
        t_end_s: f64,
        edges: &[TimedEdge],
        imu: RawImu,
        battery_v: f64,
        baro: &mut BaroModel,
    ) -> Result<[u16; 4], SimError> {
        // Nothing else reads the simulated part in this flight: reading it (clearing its P_DA)
        // only tells a new sample.
        let raw = baro.read();
        self.sim_baro_sampled |= raw.pressure_fresh();
        if self.sim_baro_sampled {
            let pressure_pa = f64::from(raw.pressure_counts) * f64::from(PA_PER_COUNT);
            let temperature_c = f64::from(raw.temperature_counts) / f64::from(COUNTS_PER_DEG_C);
            let part = &mut self.machine.board_mut().spi2.sensors_mut().lps22hb;
            part.set_pressure_pa(pressure_pa)
                .and_then(|()| part.set_temperature_c(temperature_c))
                .map_err(|e| SimError::Computer(format!("barometer input {pressure_pa} Pa, {temperature_c} °C: {e:?}")))?;
        }
        self.step(t_end_s, edges, imu, battery_v)
    }

    fn view(&self) -> ComputerView {
        self.view.clone()
    }
}

/// Re-dates the log's state columns from the STATUS lines' tick stamps: the line leaves the
/// UART some milliseconds after the change, but says at which control tick it was taken.
/// The vertical columns the line carries (who sets the thrust, the mode chosen, the hold's
/// target to the millimetre, the barometer's fault) are filled from it the same way; the
/// height estimate and its climb rate are on no line and stay empty.
pub fn retime_states(log: &mut fcu_testkit::sim::FlightLog, statuses: &[(Time, StatusFields)]) {
    let tick_s = 1.0 / log.tick_hz;
    let mut changes: Vec<(f64, &StatusFields)> = statuses.iter().map(|(_, s)| (f64::from(s.tick) * tick_s, s)).collect();
    changes.sort_by(|a, b| a.0.total_cmp(&b.0));
    if changes.is_empty() {
        return;
    }
    let mut i = 0;
    let mut current: Option<&StatusFields> = None;
    let mut calibrated = false;
    for row in &mut log.rows {
        while i < changes.len() && changes[i].0 <= row.t_s + 1e-9 {
            current = Some(changes[i].1);
            i += 1;
        }
        if let Some(s) = current {
            row.state = s.state;
            row.armed = s.armed();
            row.calibrating = s.calibration.in_progress();
            calibrated |= s.calibration == CalibrationReport::Passed;
            row.calibrated = calibrated;
            let v = &s.vertical;
            row.vertical.mode = Some(v.mode);
            row.vertical.mode_chosen = Some(v.chosen);
            row.vertical.alt_target_m = v.target_m().map_or(f64::NAN, f64::from);
            row.vertical.baro_fault = v.baro_fault;
        }
    }
}

/// `setup` with `scenario`'s parameter settings after its own (a name in both: the scenario's
/// value, set last).
pub fn with_scenario_settings(setup: &BoardSetup, scenario: &fcu_testkit::sim::scenario::Scenario) -> BoardSetup {
    let mut setup = setup.clone();
    setup.settings.extend(scenario.settings.iter().map(|&(name, value)| (name.to_string(), value)));
    setup
}

/// A flight of the image, with what the harness saw.
pub struct Flight {
    pub log: fcu_testkit::sim::FlightLog,
    /// Every byte the UART sent, boot included.
    pub uart_log: Vec<u8>,
    pub board: EmulatedBoard,
    /// Emulated seconds since power-on, and the host's wall-clock seconds for them.
    pub emulated_s: f64,
    pub wall_s: f64,
    pub instructions: u64,
}

/// The IMU's words with the drone level and still on the ground (what it reads during boot).
pub fn imu_at_rest(seed: u64) -> RawImu {
    use fcu_testkit::sim::imu_model::{ImuModel, ImuModelParams, Vibration};
    use fcu_testkit::sim::plant::{Plant, PlantParams};
    let plant = Plant::new(PlantParams::default());
    let mut imu = ImuModel::new(ImuModelParams::default(), seed);
    for _ in 0..20 {
        imu.step(0.00025, &plant.kinematics(), Vibration::NONE);
    }
    imu.read()
}

/// Boots the image and flies `scenario` with it through the simulation's seam, timed as
/// `FCU_PIL_TIMING` says ([`BoardSetup::timing`]).
pub fn fly(
    elf: &std::path::Path,
    scenario: &fcu_testkit::sim::scenario::Scenario,
    opts: &fcu_testkit::sim::RunOptions,
) -> Result<Flight, String> {
    fly_with(elf, scenario, opts, &BoardSetup::default())
}

/// [`fly`] with the board set up as `setup` says. The scenario's parameter settings
/// (`Scenario::settings`, such as `ALT_MODE` 1) are saved over `setup`'s before power-on, as
/// the in-process flight configures its core with them.
pub fn fly_with(
    elf: &std::path::Path,
    scenario: &fcu_testkit::sim::scenario::Scenario,
    opts: &fcu_testkit::sim::RunOptions,
    setup: &BoardSetup,
) -> Result<Flight, String> {
    let started = std::time::Instant::now();
    let image = Image::load(elf)?;
    let setup = with_scenario_settings(setup, scenario);
    let mut board = EmulatedBoard::boot(image, &setup, imu_at_rest(opts.seed)).map_err(|e| format!("boot: {e}"))?;
    if !board.flying() {
        return Err(format!("{} (within the boot timeout); its UART said:\n{}", board.boot_stall(), board.uart_text()));
    }
    let mut log = fcu_testkit::sim::run_with(&mut board, scenario, fcu_testkit::Profile::Default, opts).map_err(|e| e.to_string())?;
    // Tick stamps count from the firmware's boot: after a reset they start again, so only the
    // lines of the first boot are re-dated.
    let first_reset = board.machine.state().resets.first().map_or(Time::MAX, |&(t, _)| t);
    let first_boot: Vec<(Time, StatusFields)> = board.statuses.iter().filter(|(at, _)| *at < first_reset).copied().collect();
    retime_states(&mut log, &first_boot);
    let uart_log: Vec<u8> = board.machine.board().records.uart.iter().map(|&(_, b)| b).collect();
    let emulated_s = time_to_s(board.machine.now());
    let instructions = board.machine.state().instructions;
    Ok(Flight { log, uart_log, board, emulated_s, wall_s: started.elapsed().as_secs_f64(), instructions })
}

#[cfg(test)]
mod tests {
    use super::*;
    use fcu_core::altitude::AltMode;
    use fcu_core::baro::BaroFault;
    use fcu_core::telemetry::{parse_status_line, VerticalMode};
    use fcu_testkit::sim::{scenario, RunOptions, Vertical};

    fn status(tick: u32, vertical: &str) -> (Time, StatusFields) {
        let line = format!(
            "STATUS state=armed armed=1 blockers=none cal=passed failsafe=none fault=none {vertical} vbat=3.900V overruns=0 \
             bus_errors=0 uart_dropped=0 rc_muted=0 tick={tick}"
        );
        (0, parse_status_line(&line).unwrap())
    }

    #[test]
    fn status_lines_fill_the_vertical_columns_from_their_tick() {
        let sc = scenario::by_name("althold-hover").unwrap();
        let opts = RunOptions { duration_s: Some(0.02), ..RunOptions::default() };
        let mut log = fcu_testkit::sim::run(&sc, fcu_testkit::Profile::Default, &opts).unwrap();
        for r in &mut log.rows {
            r.vertical = Vertical { climb_m_s: 0.0, ..Vertical::ABSENT };
        }
        let statuses =
            [status(8, "vmode=hold alt_mode=1 target=1.250 baro=stuck"), status(0, "vmode=manual alt_mode=1 target=none baro=ok")];
        retime_states(&mut log, &statuses);
        for r in &log.rows {
            let v = &r.vertical;
            if r.t_s < 0.01 - 1e-9 {
                assert_eq!((v.mode, v.mode_chosen, v.baro_fault), (Some(VerticalMode::Manual), Some(AltMode::Hold), None), "{}", r.t_s);
                assert!(v.alt_target_m.is_nan());
            } else {
                assert_eq!((v.mode, v.baro_fault), (Some(VerticalMode::Hold), Some(BaroFault::Stuck)), "{}", r.t_s);
                assert!((v.alt_target_m - 1.25).abs() < 1e-6, "{}", v.alt_target_m);
            }
            assert!(v.est_alt_m.is_nan(), "the estimate is on no line");
        }
    }

    #[test]
    fn the_scenarios_settings_are_saved_after_the_setups() {
        let sc = scenario::by_name("althold-hover").unwrap();
        let setup = BoardSetup { settings: vec![("ALT_MODE".into(), 0.0), ("CLIMB_RATE_MAX".into(), 0.5)], ..BoardSetup::default() };
        let with = with_scenario_settings(&setup, &sc);
        assert_eq!(with.settings.first(), Some(&("ALT_MODE".to_string(), 0.0)));
        assert_eq!(with.settings.last(), Some(&("ALT_MODE".to_string(), 1.0)), "the scenario's value, set last");
        assert_eq!(with_scenario_settings(&BoardSetup::default(), &scenario::by_name("hover").unwrap()).settings, []);
    }
}
