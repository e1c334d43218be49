//! [`Rig`]: a flight controller wired to the test inputs and a [`SafetyMonitor`].

use fcu_core::config::{Config, ConfigError};
use fcu_core::flight::{FlightController, TickOutput};
use fcu_core::imu::{CalibrationOutcome, CalibrationPhase, RawImu};
use fcu_core::rc::{CaptureEdge, EdgeDecoder, Sticks};
use fcu_core::supervisor::{FlightState, SupervisorConfig};

use super::inputs::{sticks, LevelImu, PwmReceiver, RadioFrame};
use super::{Observation, SafetyMonitor, Violation};

/// A controller wired to an edge decoder, a receiver, a level IMU and a monitor.
#[derive(Clone, Debug)]
pub struct Rig {
    pub fc: FlightController,
    pub monitor: SafetyMonitor,
    pub decoder: EdgeDecoder,
    pub radio: PwmReceiver,
    pub imu: LevelImu,
    edges: Vec<CaptureEdge>,
}

impl Rig {
    pub fn new(cfg: Config, seed: u64) -> Result<Rig, ConfigError> {
        let fc = FlightController::new(&cfg)?;
        Ok(Rig {
            monitor: SafetyMonitor::new(&cfg),
            decoder: fc.edge_decoder(),
            fc,
            radio: PwmReceiver::new(seed),
            imu: LevelImu::new(seed),
            edges: Vec::new(),
        })
    }

    pub fn state(&self) -> FlightState {
        self.fc.status().state
    }

    /// One tick from given edges and sensor words ([`crate::harness::tick`]), then the
    /// monitor.
    pub fn tick_with(&mut self, imu: RawImu, edges: &[CaptureEdge]) -> Result<TickOutput, Violation> {
        let ticked = crate::harness::tick(&mut self.fc, &mut self.decoder, imu, edges.iter().copied());
        let status = self.fc.status();
        let (out, batch) = (ticked.out, ticked.pulses);
        self.monitor.check(&Observation { imu: Some(imu), batch: Some(&batch), edges: Some(edges), out: &out, status: &status })?;
        Ok(out)
    }

    /// One tick of the receiver sending `frame` (plus `glitches` spikes per frame), with
    /// the given sensor words.
    pub fn tick_frame_imu(&mut self, frame: &RadioFrame, glitches: u8, imu: RawImu) -> Result<TickOutput, Violation> {
        let mut edges = core::mem::take(&mut self.edges);
        edges.clear();
        self.radio.tick(frame, glitches, &mut edges);
        let r = self.tick_with(imu, &edges);
        self.edges = edges;
        r
    }

    /// One tick of the receiver sending `frame`, with the level IMU.
    pub fn tick_frame(&mut self, frame: &RadioFrame, glitches: u8) -> Result<TickOutput, Violation> {
        let imu = self.imu.sample();
        self.tick_frame_imu(frame, glitches, imu)
    }

    /// `ticks` ticks of `frame` with the level IMU.
    pub fn run(&mut self, frame: &RadioFrame, ticks: u32, glitches: u8) -> Result<(), Violation> {
        for _ in 0..ticks {
            self.tick_frame(frame, glitches)?;
        }
        Ok(())
    }

    /// `ticks` ticks of the sticks `s` on a clean link.
    pub fn sticks(&mut self, s: Sticks, ticks: u32) -> Result<(), Violation> {
        let frame = RadioFrame::from_sticks(&self.fc.config().rc, s);
        self.run(&frame, ticks, 0)
    }

    /// Boot with neutral sticks on a clean link until the start-up calibration has passed
    /// and the boot settling is over (the default profile is then Disarmed, released).
    pub fn booted(cfg: Config, seed: u64) -> Result<Rig, String> {
        let mut rig = Rig::new(cfg, seed).map_err(|e| e.to_string())?;
        let settle = match cfg.supervisor {
            SupervisorConfig::Safe(s) => s.boot_settle_ticks,
            SupervisorConfig::Reference => 0,
        };
        let limit = cfg.calibration.settle_ticks + cfg.calibration.samples + settle + 100;
        for _ in 0..limit {
            rig.sticks(sticks::NEUTRAL, 1).map_err(|v| v.to_string())?;
            let st = rig.fc.status();
            if matches!(st.calibration, CalibrationPhase::Idle { last: Some(CalibrationOutcome::Passed) })
                && rig.monitor.ticks() > u64::from(settle) + 1
                && st.link
            {
                return Ok(rig);
            }
        }
        Err(format!("not booted after {limit} ticks: {:?}", rig.fc.status().state))
    }

    /// Arm with the gesture (hold `arm_hold_ticks` + 16, release to neutral) on a clean link.
    pub fn arm(&mut self) -> Result<(), String> {
        let hold = match self.fc.config().supervisor {
            SupervisorConfig::Safe(s) => s.arm_hold_ticks,
            SupervisorConfig::Reference => 1,
        };
        self.sticks(sticks::ARM, hold + 16).map_err(|v| v.to_string())?;
        for _ in 0..64 {
            self.sticks(sticks::NEUTRAL, 1).map_err(|v| v.to_string())?;
            if self.state() == FlightState::Armed {
                return Ok(());
            }
        }
        Err(format!("not armed: {:?}", self.fc.status().blockers))
    }
}
