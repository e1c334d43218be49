//! What the board does once its sensors' boot tables are played: fly, or stay on the ground
//! with the missing sensor named on the LEDs and the UART (`docs/safety.md#boot`: a WHO_AM_I
//! wrong at boot means no flight, an LED code, a message on the UART, never a silent hang). The
//! firmware collects the answers and acts on the verdict; the rule is here.

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

    pub fn may_fly(self) -> bool {
        self == BootVerdict::Fly
    }

    /// The LED code from boot on: nothing yet when flying (the flight status takes over),
    /// both on with the sensor's blink count when not.
    pub fn led_pattern(self) -> LedPattern {
        match self {
            BootVerdict::Fly => LedPattern::Off,
            BootVerdict::StayOnGround { sensor, .. } => LedPattern::SensorFault { blinks: sensor.blink_count() },
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
}
