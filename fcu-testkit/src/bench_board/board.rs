//! [`Bench`]: the board on a bench, deterministic to the tick: the control loop at 800 Hz, the
//! link task every 5 ms, the UART both ways at 115200 baud, the parameter flash, the pilot's
//! transmitter and the ground station's wire, with the checks of [`super::check`] watching.

use std::collections::VecDeque;

use fcu_core::flight::{ControlTick, FlightController, OuterStep, Status};
use fcu_core::imu::CalibrationPhase;
use fcu_core::rc::{CaptureEdge, EdgeDecoder, Sticks};
use fcu_core::supervisor::{FlightState, SupervisorConfig};
use fcu_core::Config;
use fcu_gcs::Due;
use fcu_gcs::{Observed, Service, ToControl};
use fcu_link::LinkConfig;
use fcu_params::snapshot;

use super::check::{ms, BootKind, Checker, Invariant};
use super::flash::{Flash, PowerCut};
use super::gcs::{AnswerReader, GcsFrame};
use crate::safety::{sticks, LevelImu, PwmReceiver, RadioFrame};

/// The link's transmit queue, bytes (the firmware's `LINK_TX_BYTES`).
pub const LINK_TX_BYTES: usize = 512;
/// Control ticks per link period (800 Hz, 5 ms).
pub const TICKS_PER_PERIOD: u32 = 4;
/// Microseconds per control tick.
pub const TICK_US: u32 = 1250;
/// UART bytes per control tick at 115200 baud, 10 bits a byte: 11.52 bytes/ms.
pub const UART_BYTES_PER_TICK: f64 = 11.52 * 1.25;
/// The firmware's UART transmit queue, bytes.
pub const UART_QUEUE_BYTES: usize = 1024;
/// The link task's buffer between the link and the UART: it moves chunks of this each period
/// until the UART queue is full or the link has nothing left.
pub const UART_CHUNK_BYTES: usize = 128;
/// The firmware's receive ring (DMA), bytes: what arrives while nothing reads it beyond that
/// overwrites the oldest.
pub const RX_RING_BYTES: usize = 6 * 1024;
/// How late the board may see the pilot's sticks, control ticks: a channel's pulse ends up to a
/// receiver frame (20 ms at 50 Hz) after the sticks move, and the next frame's may be the first
/// the decoder hands over; two frames, 40 ms. The arming checks allow the board's view of a
/// gesture to lag the pilot's by this much.
pub const RADIO_LAG_TICKS: u32 = 32;
/// The battery the bench supply holds, mV.
pub const BATTERY_MV: u32 = 3900;

/// What the pilot does with the transmitter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pilot {
    /// Sticks centred, throttle low.
    Neutral,
    /// The arm gesture (yaw right, throttle low) held.
    Arm,
    /// Level flight at a mid throttle.
    Fly,
    /// The disarm gesture (yaw left, throttle low) held.
    Disarm,
    /// The transmitter off.
    Off,
}

impl Pilot {
    fn sticks(self) -> Option<Sticks> {
        match self {
            Pilot::Neutral => Some(sticks::NEUTRAL),
            Pilot::Arm => Some(sticks::ARM),
            Pilot::Fly => Some(sticks::FLY),
            Pilot::Disarm => Some(sticks::DISARM),
            Pilot::Off => None,
        }
    }
}

/// One thing that happens on the bench.
#[derive(Clone, Debug, PartialEq)]
pub enum Op {
    /// The ground station sends a frame (it goes out at the line's rate, after what it sent
    /// before).
    Send(GcsFrame),
    /// The pilot's sticks from now on.
    Pilot(Pilot),
    /// Time passes.
    Wait { ms: u32 },
    /// For `ms`, the ground station keeps the uplink full of PARAM_REQUEST_READs, each
    /// answered with a PARAM_VALUE: more than the downlink carries, so the board's transmit
    /// queues fill.
    Flood { ms: u32 },
    /// The power goes off at a flash word operation to come (see [`PowerCut`]).
    CutAtWord(PowerCut),
    /// The power goes off now, and comes back.
    CutNow,
    /// How long erases take from now on, ms (250..=500 on the F401; clamped there).
    EraseMs(u32),
}

/// Counts of what happened, for tests that want to know their cases reach something.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    pub ticks: u64,
    pub saves: u32,
    pub erases: u32,
    pub reboots: u32,
    pub power_cuts: u32,
    pub cuts_in_flash: u32,
    pub arms: u32,
    pub accepted_sets: u32,
}

/// One power-on of the board: what a reset starts again.
#[derive(Clone)]
struct Boot {
    tick: ControlTick,
    outer: OuterStep,
    decoder: EdgeDecoder,
    task: Service<LINK_TX_BYTES>,
    /// MAVLink is on the UART (from boot, or since a frame was heard on a board set to text).
    mavlink_on: bool,
    /// The configuration the control loop last took (the boot's, at first).
    cfg: Config,
    /// Ticks since power-on.
    ticks: u32,
    /// Taken by the control loop before its next tick.
    to_control: ToControl,
    /// The received bytes not read yet (the DMA ring).
    rx: VecDeque<u8>,
    /// Bytes in the UART's transmit queue.
    uart_queued: usize,
    status: Status,
    /// The pilot's arm gesture as the sticks sent it: ticks held in the current (or last)
    /// hold, ticks since it ended (0 while held), and ticks of those with the sticks at rest
    /// (arming completes once every stick is back in a safe place, however long after).
    arm_held_ticks: u32,
    arm_released_ticks: u32,
    arm_rest_ticks: u32,
    /// Ticks the transmitter has been off in a row.
    off_ticks: u32,
    /// Ticks since the pilot's sticks last allowed the board to complete arming (held the hold
    /// time, back at rest a moment ago at most).
    arm_ok_ago: u32,
    /// The pilot held the arm gesture the hold time and the board has been arming since: it
    /// completes once every stick is back in a safe place, whatever the sticks do meanwhile.
    full_hold: bool,
    /// A motor test's output was seen on the last tick.
    testing: bool,
    /// A radio calibration ran on the last tick.
    radio_calibration: bool,
}

impl Boot {
    /// How long the arm gesture must be held, control ticks (at once with the reference).
    fn arm_hold_ticks(&self) -> u32 {
        match self.cfg.supervisor {
            SupervisorConfig::Safe(s) => s.arm_hold_ticks,
            SupervisorConfig::Reference => 1,
        }
    }

    fn new(cfg: Config, source: snapshot::Source, defaults: &'static Config) -> Result<Boot, String> {
        let fc = FlightController::new(&cfg).map_err(|e| e.to_string())?;
        let decoder = fc.edge_decoder();
        let status = fc.status();
        let (tick, mut outer) = fc.into_parts();
        outer.set_battery_mv(BATTERY_MV);
        Ok(Boot {
            tick,
            outer,
            decoder,
            task: Service::new(cfg, defaults, source, LinkConfig::DEFAULT),
            mavlink_on: false,
            cfg,
            ticks: 0,
            to_control: ToControl::default(),
            rx: VecDeque::new(),
            uart_queued: 0,
            status,
            arm_held_ticks: 0,
            arm_released_ticks: u32::MAX,
            arm_rest_ticks: u32::MAX,
            off_ticks: 0,
            arm_ok_ago: u32::MAX,
            full_hold: false,
            testing: false,
            radio_calibration: false,
        })
    }

    fn now_ms(&self) -> u32 {
        ms(u64::from(self.ticks)) as u32
    }
}

/// The board, its flash, the pilot and the ground station. `Clone` is a deep copy: a clone
/// runs on exactly as the original would (the boot cache, [`super::BootCache`], relies on it).
#[derive(Clone)]
pub struct Bench {
    pub flash: Flash,
    defaults: &'static Config,
    boot: Boot,
    radio: PwmReceiver,
    imu: LevelImu,
    pilot: Pilot,
    /// The pilot's sticks as the last radio frame carried them: a frame takes the sticks at its
    /// start, 20 ms apart, so a movement shorter than that may never be sent. The arming checks
    /// judge the gesture the board was sent.
    sent: Pilot,
    edges: Vec<CaptureEdge>,
    /// Bytes the ground station sent that are still on the wire.
    uplink: VecDeque<u8>,
    uplink_credit: f64,
    /// Bytes the ground station sent that reached the board's receive ring.
    uplink_delivered: u64,
    uart_credit: f64,
    gcs_sequence: u8,
    flood_ticks: u32,
    flood_index: u16,
    erase_ms: u32,
    answers: AnswerReader,
    pub checker: Checker,
    pub counts: Counts,
    /// Bench time, ticks since the bench was switched on (stalls and power cuts included).
    time_ticks: u64,
    /// Every byte the board sent, folded into an FNV-1a hash: two benches that answered
    /// alike have the same.
    downlink_hash: u64,
}

/// FNV-1a's offset basis.
const FNV_OFFSET: u64 = 0xCBF2_9CE4_8422_2325;

impl Bench {
    /// A board with `flash` as it is, switched on; `seed` sets the radio's frame phase and
    /// the IMU's noise.
    pub fn new(flash: Flash, defaults: &'static Config, seed: u64) -> Bench {
        let mut checker = Checker::new(defaults);
        checker.on_flash_history(&flash);
        let boot = Self::power_on(&flash, defaults, &mut checker, BootKind::First, 0, 0);
        Bench {
            flash,
            defaults,
            boot,
            radio: PwmReceiver::new(seed),
            imu: LevelImu::new(seed),
            pilot: Pilot::Neutral,
            sent: Pilot::Neutral,
            edges: Vec::new(),
            uplink: VecDeque::new(),
            uplink_credit: 0.0,
            uplink_delivered: 0,
            uart_credit: 0.0,
            gcs_sequence: 0,
            flood_ticks: 0,
            flood_index: 0,
            erase_ms: 250,
            answers: AnswerReader::default(),
            checker,
            counts: Counts::default(),
            time_ticks: 0,
            downlink_hash: FNV_OFFSET,
        }
    }

    /// Loads the parameters from flash and boots the board with them. A configuration that
    /// cannot build a controller (a check fails) boots the defaults, so the bench runs on.
    fn power_on(
        flash: &Flash,
        defaults: &'static Config,
        checker: &mut Checker,
        kind: BootKind,
        delivered_bytes: u64,
        time_ticks: u64,
    ) -> Boot {
        let (cfg, source) = snapshot::load_config(flash.sectors(), defaults);
        checker.on_boot(&cfg, source, flash, kind, delivered_bytes, time_ticks);
        match Boot::new(cfg, source, defaults) {
            Ok(b) => b,
            Err(e) => {
                checker.violate(
                    Invariant::AcceptedIsReportedSavedLoaded,
                    time_ticks,
                    format!("the loaded configuration builds no controller: {e}"),
                );
                match Boot::new(*defaults, snapshot::Source::NoSnapshot, defaults) {
                    Ok(b) => b,
                    Err(e) => panic!("the defaults build no controller: {e}"),
                }
            }
        }
    }

    /// What the control loop shows now.
    pub fn status(&self) -> Status {
        self.boot.status
    }

    /// The configuration the control loop runs with.
    pub fn config(&self) -> &Config {
        &self.boot.cfg
    }

    /// A hash (FNV-1a) of every byte the board sent since switched on.
    pub fn downlink_hash(&self) -> u64 {
        self.downlink_hash
    }

    /// Bench time, ms since switched on.
    pub fn time_ms(&self) -> u64 {
        ms(self.time_ticks)
    }

    /// Runs the operations in order.
    pub fn run(&mut self, ops: &[Op]) {
        for op in ops {
            self.apply(op);
        }
    }

    pub fn apply(&mut self, op: &Op) {
        match *op {
            Op::Send(frame) => {
                let bytes = frame.encode(self.gcs_sequence);
                self.gcs_sequence = self.gcs_sequence.wrapping_add(1);
                self.checker.on_sent(&frame, bytes.len());
                self.uplink.extend(bytes);
            }
            Op::Pilot(p) => self.pilot = p,
            Op::Wait { ms } => self.run_ms(ms),
            Op::Flood { ms } => {
                self.flood_ticks = ms_to_ticks(ms);
                self.run_ms(ms);
                self.flood_ticks = 0;
            }
            Op::CutAtWord(cut) => self.flash.arm_cut(cut),
            Op::CutNow => self.power_cut(),
            Op::EraseMs(ms) => self.erase_ms = ms.clamp(250, 500),
        }
    }

    /// Runs the bench for `ms` (whole ticks).
    pub fn run_ms(&mut self, ms: u32) {
        for _ in 0..ms_to_ticks(ms) {
            self.tick();
        }
    }

    fn radio_frame(&self) -> RadioFrame {
        self.pilot.sticks().map_or(RadioFrame::OFF, |s| RadioFrame::from_sticks(&self.boot.cfg.rc, s))
    }

    /// One control tick, then the link's period when one is due, then a reset when one is.
    fn tick(&mut self) {
        self.time_ticks += 1;
        self.counts.ticks += 1;
        self.wires();
        let frame = self.radio_frame();
        let b = &mut self.boot;
        // The control task takes what the link task left before it ticks.
        // The outer step takes only what the tick took (a ground-only change is refused once
        // armed).
        if let Some(change) = b.to_control.config.take() {
            if b.tick.take_config(&change).is_ok() {
                b.outer.take_config(&change.cfg);
                b.cfg = change.cfg;
            }
        }
        if let Some(g) = b.to_control.gcs.take() {
            b.tick.take_gcs(&g);
        }
        self.edges.clear();
        if self.radio.frame_starts_next_tick() {
            self.sent = self.pilot;
        }
        self.radio.tick(&frame, 0, &mut self.edges);
        for e in &self.edges {
            b.decoder.on_edge(*e);
        }
        let pulses = b.decoder.take();
        let was = b.status;
        let out = b.tick.tick(self.imu.sample(), &pulses);
        if let Some(job) = &out.outer_job {
            let r = b.outer.run(job);
            b.tick.apply_outer(&r);
        }
        b.status = b.tick.status();
        b.ticks = b.ticks.wrapping_add(1);
        let sent = self.sent;
        b.off_ticks = if sent == Pilot::Off { b.off_ticks.saturating_add(1) } else { 0 };
        // The link is lost only a timeout after the last pulse, and until then the last pulses
        // stand: a transmitter off for less than that leaves the arm gesture held, as far as the
        // board can tell (as `docs/safety.md` has it, and the safety monitor's radio model).
        let gap = sent == Pilot::Off && b.arm_released_ticks == 0 && b.off_ticks < b.cfg.rc.link_timeout_ticks;
        if sent == Pilot::Arm || gap {
            b.arm_held_ticks = if b.arm_released_ticks == 0 { b.arm_held_ticks + 1 } else { 1 };
            b.arm_released_ticks = 0;
            b.arm_rest_ticks = 0;
        } else {
            b.arm_released_ticks = b.arm_released_ticks.saturating_add(1);
            if sent == Pilot::Neutral {
                b.arm_rest_ticks = b.arm_rest_ticks.saturating_add(1);
            }
        }
        // The gesture arms once released (or at once with the reference): held at least the
        // hold time, the sticks back at rest a moment ago at most; as the board sees the sticks,
        // which may lag the pilot's by a frame or two at either end of the hold.
        let held_full = b.arm_held_ticks.saturating_add(RADIO_LAG_TICKS) >= b.arm_hold_ticks();
        let ok = b.arm_rest_ticks <= 200 && (held_full || b.full_hold);
        b.arm_ok_ago = if ok { 0 } else { b.arm_ok_ago.saturating_add(1) };
        b.full_hold = held_full || (b.full_hold && b.status.state == FlightState::Arming);
        self.after_tick(was);
        if self.boot.ticks % TICKS_PER_PERIOD == 0 {
            self.period();
        }
    }

    /// The checks of one tick: arming, what may start only disarmed, faults.
    fn after_tick(&mut self, was: Status) {
        let b = &mut self.boot;
        let now = b.status;
        let t = self.time_ticks;
        if self.checker.trace && now.state != was.state {
            eprintln!("{:>6} ms {:?} -> {:?}", ms(t), was.state, now.state);
        }
        let recent = b.arm_released_ticks <= 200;
        if now.state == FlightState::Arming && was.state != FlightState::Arming && !recent {
            self.checker.violate(
                Invariant::ArmedOnlyByGesture,
                t,
                format!("{:?} -> Arming without the pilot's arm gesture (released {} ticks ago)", was.state, b.arm_released_ticks),
            );
        }
        if now.state == FlightState::Armed && !matches!(was.state, FlightState::Armed | FlightState::FailsafeLevel) {
            self.counts.arms += 1;
            if b.arm_ok_ago > RADIO_LAG_TICKS {
                self.checker.violate(
                    Invariant::ArmedOnlyByGesture,
                    t,
                    format!(
                        "{:?} -> Armed with the pilot's arm gesture held {} ticks (hold {}), released {} ticks ago, at rest for {}",
                        was.state,
                        b.arm_held_ticks,
                        b.arm_hold_ticks(),
                        b.arm_released_ticks,
                        b.arm_rest_ticks
                    ),
                );
            }
        }
        let idle = |c: CalibrationPhase| matches!(c, CalibrationPhase::Idle { .. });
        if was.state.changes_restricted() && idle(was.calibration) && !idle(now.calibration) {
            self.checker.violate(Invariant::NothingStartsArmed, t, format!("an IMU calibration started in {:?}", was.state));
        }
        // A motor test drives one motor on the ground: disarmed, the compare values differ.
        let testing = now.state == FlightState::Disarmed && now.compare.iter().any(|&c| c != now.compare[0]);
        if testing && !b.testing && was.state.changes_restricted() {
            self.checker.violate(Invariant::NothingStartsArmed, t, format!("a motor test started in {:?}: {:?}", was.state, now.compare));
        }
        b.testing = testing;
        let radio_calibration = b.tick.radio_calibration();
        if radio_calibration && !b.radio_calibration && was.state.changes_restricted() {
            self.checker.violate(Invariant::NothingStartsArmed, t, format!("a radio calibration started in {:?}", was.state));
        }
        b.radio_calibration = radio_calibration;
        if now.fault.is_some() || now.state == FlightState::Fault {
            self.checker.violate(Invariant::SavesKeepTheLoopRunning, t, format!("{:?} {:?}", now.state, now.fault));
        }
    }

    /// Both directions of the UART for one tick: the ground station's bytes into the receive
    /// ring, the transmit queue out.
    fn wires(&mut self) {
        if self.flood_ticks > 0 {
            self.flood_ticks -= 1;
            if self.uplink.len() < 64 {
                let index = self.flood_index as i16;
                self.flood_index = (self.flood_index + 1) % fcu_params::count() as u16;
                self.apply(&Op::Send(GcsFrame::ParamRead { index, name: [0; 16] }));
            }
        }
        self.uplink_credit = (self.uplink_credit + UART_BYTES_PER_TICK).min(2.0 * UART_BYTES_PER_TICK);
        while self.uplink_credit >= 1.0 {
            let Some(byte) = self.uplink.pop_front() else { break };
            self.uplink_credit -= 1.0;
            self.uplink_delivered += 1;
            if self.boot.rx.len() == RX_RING_BYTES {
                self.boot.rx.pop_front();
            }
            self.boot.rx.push_back(byte);
        }
        self.uart_credit = (self.uart_credit + UART_BYTES_PER_TICK).min(2.0 * UART_BYTES_PER_TICK);
        let sent = (self.uart_credit as usize).min(self.boot.uart_queued);
        self.boot.uart_queued -= sent;
        self.uart_credit -= sent as f64;
    }

    /// One period of the link task, as the firmware's `gcs::step` runs it: the status,
    /// the bytes received, the period, the UART, and the flash or reset work due, done at once.
    fn period(&mut self) {
        let observed = Observed { status: self.boot.status, battery_mv: BATTERY_MV, rc_widths_counts: self.radio_frame_widths() };
        let b = &mut self.boot;
        let now_ms = b.now_ms();
        b.task.observe(now_ms, &observed);
        let rx: Vec<u8> = b.rx.drain(..).collect();
        // The station takes or refuses a set by the status it observed just now.
        self.checker.on_received(self.uplink_delivered, self.boot.status.state.changes_restricted());
        let b = &mut self.boot;
        b.task.receive(now_ms, &rx);
        b.mavlink_on = b.mavlink_on || b.task.speaks_mavlink_from_boot() || b.task.heard();
        if !b.mavlink_on {
            return;
        }
        let to = b.task.period(now_ms);
        if to.config.is_some() {
            b.to_control.config = to.config;
        }
        if let Some(g) = to.gcs {
            b.to_control.gcs = Some(b.to_control.gcs.map_or(g, |older| older.then(g)));
        }
        // As the firmware's link task: everything the UART queue has room for, a chunk at a time.
        let mut moved = Vec::new();
        loop {
            let room = UART_QUEUE_BYTES.saturating_sub(b.uart_queued).min(UART_CHUNK_BYTES);
            let mut out = [0u8; UART_CHUNK_BYTES];
            let n = b.task.poll_tx(&mut out[..room]);
            if n == 0 {
                break;
            }
            b.uart_queued += n;
            moved.extend_from_slice(&out[..n]);
        }
        let out = moved;
        let n = out.len();
        for &byte in &out[..n] {
            self.downlink_hash = (self.downlink_hash ^ u64::from(byte)).wrapping_mul(0x0100_0000_01B3);
        }
        let idle = b.uart_queued == 0;
        let t = self.time_ticks;
        match self.answers.push(&out[..n]) {
            Ok(answers) => {
                for a in &answers {
                    self.checker.on_answer(a, t);
                }
            }
            Err(e) => self.checker.violate(
                Invariant::AcceptedIsReportedSavedLoaded,
                t,
                format!("the board's output is not whole frames: {}", e.0),
            ),
        }
        match self.boot.task.due(now_ms, idle, true) {
            Due::Nothing => {}
            Due::Save => self.save(),
            Due::Reboot => self.reset(),
        }
    }

    fn radio_frame_widths(&self) -> [u16; 4] {
        let f = self.radio_frame();
        [f.width_counts[0], f.width_counts[1], f.width_counts[2], f.width_counts[3]]
    }

    /// The flash work of a save, as the firmware does it: the plan, an erase if it says so
    /// (the CPU stalled meanwhile), the words one at a time.
    fn save(&mut self) {
        let t = self.time_ticks;
        let armed = self.boot.status.state.changes_restricted() || self.boot.tick.changes_restricted();
        let plan = self.boot.task.plan_save(self.flash.sectors());
        if armed {
            self.checker.violate(
                Invariant::NothingStartsArmed,
                t,
                format!("a save (erase {:?}) started in {:?}", plan.erase, self.boot.status.state),
            );
        }
        self.counts.saves += 1;
        if let Some(sector) = plan.erase {
            self.counts.erases += 1;
            self.stall(self.erase_ms);
            if self.flash.erase(sector).is_err() {
                self.counts.cuts_in_flash += 1;
                return self.power_cut();
            }
        }
        if self.flash.program(plan.sector, plan.first_word, &plan.words).is_err() {
            self.counts.cuts_in_flash += 1;
            self.checker.on_save_cut(&plan, &self.flash, self.time_ticks);
            return self.power_cut();
        }
        self.checker.on_saved(&plan, self.time_ticks);
        self.boot.task.saved(true);
    }

    /// The CPU stalls for `ms`: no tick, no link period, no UART interrupt; time, the radio
    /// and the ground station's bytes (the receive DMA) go on.
    fn stall(&mut self, ms: u32) {
        let ticks = ms_to_ticks(ms);
        let frame = self.radio_frame();
        for _ in 0..ticks {
            self.time_ticks += 1;
            self.boot.ticks = self.boot.ticks.wrapping_add(1);
            // The capture interrupt cannot run: edges are lost.
            self.edges.clear();
            self.radio.tick(&frame, 0, &mut self.edges);
            let queued = self.boot.uart_queued;
            self.wires();
            self.boot.uart_queued = queued;
        }
    }

    /// A reset decided by the firmware.
    fn reset(&mut self) {
        let t = self.time_ticks;
        if self.boot.tick.changes_restricted() || self.boot.status.state.changes_restricted() {
            self.checker.violate(Invariant::NothingStartsArmed, t, format!("a reset in {:?}", self.boot.status.state));
        }
        self.counts.reboots += 1;
        self.restart(BootKind::Reset);
    }

    /// The power goes off and on.
    fn power_cut(&mut self) {
        self.counts.power_cuts += 1;
        self.flash.disarm_cut();
        self.restart(BootKind::PowerCut);
    }

    fn restart(&mut self, kind: BootKind) {
        let boot = Self::power_on(&self.flash, self.defaults, &mut self.checker, kind, self.uplink_delivered, self.time_ticks);
        self.boot = boot;
        self.answers = AnswerReader::default();
    }
}

/// Whole ticks in `ms`.
pub fn ms_to_ticks(ms: u32) -> u32 {
    (u64::from(ms) * 1000 / u64::from(TICK_US)) as u32
}
