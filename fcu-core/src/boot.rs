//! What the board does once its boot checks are done: fly, or stay on the ground with what
//! failed named on the LEDs and the UART, never a silent hang (`docs/safety.md#boot`). The
//! checks: every sensor's `WHO_AM_I`, the HSE crystal (the clock the radio's pulse widths and
//! the control tick are timed by), and the independent watchdog taking its timeout (its LSI
//! clock running). The firmware collects the answers and acts on the verdict; the rule is
//! here.

use crate::imu::registers::{first_missing, Sensor};
use crate::telemetry::{write_sensor_missing_line, LedPattern, LineBuf};

/// The decision after boot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BootVerdict {
    /// Every sensor answered: start the control tick and the watchdog.
    Fly,
    /// A sensor did not answer: the control tick never starts, so the motors stay at their
    /// off compare; the watchdog is not armed, so the code stays visible instead of a reset
    /// loop.
    StayOnGround { sensor: Sensor, who_am_i: u8 },
    /// A clock the flight depends on failed: the control tick never starts.
    ClockFault(ClockFault),
}

/// A clock that failed its boot check.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClockFault {
    /// The HSE crystal never became ready: the board runs on the internal HSI, whose ±1 %
    /// would skew every radio pulse width and the control rate.
    Crystal,
    /// The independent watchdog never took its timeout: its LSI clock is not running, so
    /// nothing would reset a stalled control loop.
    WatchdogClock,
    /// The PLL never locked: the board runs at its 16 MHz input, a fifth of the speed every
    /// timing of the control loop assumes.
    Pll,
}

impl ClockFault {
    /// LED blink count, after the three sensors' 1..3.
    pub fn blink_count(self) -> u8 {
        match self {
            ClockFault::Crystal => 4,
            ClockFault::WatchdogClock => 5,
            ClockFault::Pll => 6,
        }
    }

    fn description(self) -> &'static str {
        match self {
            ClockFault::Crystal => "HSE crystal did not start (running on HSI)",
            ClockFault::WatchdogClock => "watchdog did not take its timeout (LSI not running)",
            ClockFault::Pll => "PLL did not lock (running at 16 MHz)",
        }
    }
}

impl BootVerdict {
    /// `answers`: each sensor's `WHO_AM_I` answer in [`Sensor::ALL`] order (0x00, which no
    /// sensor answers, when its bus transfers failed).
    pub fn from_answers(answers: [u8; 3]) -> BootVerdict {
        match first_missing(answers) {
            None => BootVerdict::Fly,
            Some(sensor) => {
                let who_am_i = Sensor::ALL.into_iter().zip(answers).find(|&(s, _)| s == sensor).map_or(0, |(_, a)| a);
                BootVerdict::StayOnGround { sensor, who_am_i }
            }
        }
    }

    /// The verdict once the crystal has been checked: a board without its crystal stays on
    /// the ground whatever the sensors said (reported first: it is found first).
    pub fn with_crystal(self, crystal_ready: bool) -> BootVerdict {
        if crystal_ready {
            self
        } else {
            BootVerdict::ClockFault(ClockFault::Crystal)
        }
    }

    /// The verdict once the PLL has been tried: a board whose PLL does not lock stays on the
    /// ground whatever the sensors said; a crystal fault, found before, is the one reported.
    pub fn with_pll(self, locked: bool) -> BootVerdict {
        match self {
            _ if locked => self,
            BootVerdict::ClockFault(_) => self,
            _ => BootVerdict::ClockFault(ClockFault::Pll),
        }
    }

    /// The verdict once the watchdog's set-up has been tried (only on a board that may fly).
    pub fn with_watchdog(self, took_timeout: bool) -> BootVerdict {
        if took_timeout || !self.may_fly() {
            self
        } else {
            BootVerdict::ClockFault(ClockFault::WatchdogClock)
        }
    }

    pub fn may_fly(self) -> bool {
        self == BootVerdict::Fly
    }

    /// The LED code from boot on: nothing yet when flying (the flight status takes over),
    /// both on with the sensor's blink count when not.
    pub fn led_pattern(self) -> LedPattern {
        match self {
            BootVerdict::Fly => LedPattern::Off,
            BootVerdict::StayOnGround { sensor, .. } => LedPattern::SensorFault { blinks: sensor.blink_count() },
            BootVerdict::ClockFault(fault) => LedPattern::SensorFault { blinks: fault.blink_count() },
        }
    }

    /// The FATAL line to repeat on the UART, if the board stays on the ground.
    pub fn write_fatal_line<const N: usize>(self, out: &mut LineBuf<N>) -> bool {
        match self {
            BootVerdict::Fly => false,
            BootVerdict::StayOnGround { sensor, who_am_i } => {
                write_sensor_missing_line(out, sensor.name(), who_am_i, sensor.who_am_i_value());
                true
            }
            BootVerdict::ClockFault(fault) => {
                out.clear();
                out.push_str("FATAL clock ");
                out.push_str(fault.description());
                out.push_str(": motors off, no flight until reset");
                out.finish_line();
                true
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL_ANSWER: [u8; 3] = [0x6A, 0x40, 0xB1];

    #[test]
    fn all_three_sensors_answering_may_fly() {
        assert_eq!(BootVerdict::from_answers(ALL_ANSWER), BootVerdict::Fly);
        assert!(BootVerdict::from_answers(ALL_ANSWER).may_fly());
    }

    #[test]
    fn a_missing_sensor_keeps_the_drone_on_the_ground() {
        for (i, sensor) in Sensor::ALL.into_iter().enumerate() {
            let mut answers = ALL_ANSWER;
            answers[i] = 0x00;
            let v = BootVerdict::from_answers(answers);
            assert_eq!(v, BootVerdict::StayOnGround { sensor, who_am_i: 0x00 });
            assert!(!v.may_fly());
        }
    }

    #[test]
    fn the_led_code_and_the_fatal_line_name_the_first_missing_sensor() {
        let v = BootVerdict::from_answers([0x6A, 0x41, 0x00]);
        assert_eq!(v.led_pattern(), LedPattern::SensorFault { blinks: 2 });
        let mut line = LineBuf::<96>::new();
        assert!(v.write_fatal_line(&mut line));
        assert!(line.as_str().starts_with("FATAL sensor LIS2MDL WHO_AM_I=0x41 expected 0x40"), "{}", line.as_str());
        assert!(!BootVerdict::Fly.write_fatal_line(&mut line));
    }

    #[test]
    fn a_failed_clock_keeps_the_drone_on_the_ground_and_says_which() {
        let fly = BootVerdict::from_answers(ALL_ANSWER);
        let no_crystal = fly.with_crystal(false);
        assert_eq!(no_crystal, BootVerdict::ClockFault(ClockFault::Crystal));
        assert!(!no_crystal.may_fly());
        assert_eq!(no_crystal.led_pattern(), LedPattern::SensorFault { blinks: 4 });
        let mut line = LineBuf::<96>::new();
        assert!(no_crystal.write_fatal_line(&mut line));
        assert!(line.as_str().starts_with("FATAL clock HSE crystal did not start"), "{}", line.as_str());

        assert_eq!(fly.with_crystal(true).with_watchdog(true), BootVerdict::Fly);
        assert_eq!(fly.with_crystal(true).with_pll(true), BootVerdict::Fly);
        assert_eq!(fly.with_pll(false), BootVerdict::ClockFault(ClockFault::Pll));
        assert_eq!(no_crystal.with_pll(false), no_crystal, "the crystal's fault, found first, is the one reported");
        let sensor_missing = BootVerdict::from_answers([0, 0, 0]);
        assert_eq!(sensor_missing.with_pll(false), BootVerdict::ClockFault(ClockFault::Pll));
        let no_watchdog = fly.with_crystal(true).with_watchdog(false);
        assert_eq!(no_watchdog, BootVerdict::ClockFault(ClockFault::WatchdogClock));
        assert_eq!(no_watchdog.led_pattern(), LedPattern::SensorFault { blinks: 5 });
        assert!(no_watchdog.write_fatal_line(&mut line));
        assert!(line.as_str().contains("LSI not running"), "{}", line.as_str());
        // A board already on the ground keeps its first reason.
        let missing = BootVerdict::from_answers([0x00, 0x40, 0xB1]);
        assert_eq!(missing.with_watchdog(false), missing);
    }
}
