//! A transmitter that is not the reference's Devo 7E, set up through parameters alone:
//! [`Transmitter::OTHER`] sends its channels in another order, its pitch reversed, every
//! stick from 1000 to 2000 µs, and rests its throttle on its bottom. The simulated pilot flies
//! the usual scenarios through it. With its parameter file (`data/other-transmitter.parm`,
//! the one the `other-transmitter` scenario names) the drone arms by gesture and flies the
//! scenario's criteria; without it, it does not.

use fcu_core::Config;
use fcu_params as parameters;
use fcu_testkit::sim::radio_model::Transmitter;
use fcu_testkit::sim::{self, metrics, scenario, InProcess, Profile, RunOptions};

const PARAMS: &str = include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/data/other-transmitter.parm"));

/// The scenario flown through the other transmitter: its log and the criteria it failed.
fn fly(name: &str, cfg: Config) -> (sim::FlightLog, Vec<String>) {
    let mut sc = scenario::by_name(name).unwrap_or_else(|| panic!("unknown scenario {name}"));
    sc.radio.transmitter = Some(Transmitter::OTHER);
    let mut computer = InProcess::new(cfg).unwrap_or_else(|e| panic!("{e}"));
    let log = sim::run_with(&mut computer, &sc, Profile::Default, &RunOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let failed =
        metrics::check_all(&log, &sc).into_iter().filter(|v| !v.passed).map(|v| format!("{} — {}", v.criterion, v.detail)).collect();
    (log, failed)
}

#[test]
fn another_transmitter_flies_once_set_up_by_parameters() {
    let cfg = parameters::apply_file(&Config::default(), PARAMS).unwrap_or_else(|e| panic!("{e:?}"));
    for name in ["hover", "steps", "yaw"] {
        let (log, failed) = fly(name, cfg);
        assert!(failed.is_empty(), "{name}: {failed:#?}");
        // The sticks read as the Devo's do: the roll and pitch targets of the same flight
        // with the Devo itself, to the pulses' jitter (0.5 µs rms on each edge, up to 0.2° between the two; 20° /
        // 1800 a count) and with no bias, but where a stick moved: this transmitter's pulses
        // end at other times in the frame, so a new stick position can reach the core a frame
        // (20 ms) apart.
        let sc = scenario::by_name(name).unwrap_or_else(|| panic!("{name}"));
        let devo = sim::run(&sc, Profile::Default, &RunOptions::default()).unwrap_or_else(|e| panic!("{e}"));
        let armed: Vec<_> = log.rows.iter().zip(&devo.rows).filter(|(a, _)| a.armed).collect();
        assert!(!armed.is_empty(), "{name}: never armed");
        let n = armed.len() as f64;
        let bias_roll = armed.iter().map(|(a, b)| a.roll_target_deg - b.roll_target_deg).sum::<f64>() / n;
        let bias_pitch = armed.iter().map(|(a, b)| a.pitch_target_deg - b.pitch_target_deg).sum::<f64>() / n;
        assert!(bias_roll.abs() < 0.01 && bias_pitch.abs() < 0.01, "{name}: targets biased by {bias_roll}° roll, {bias_pitch}° pitch");
        let apart = armed
            .iter()
            .filter(|(a, b)| (a.roll_target_deg - b.roll_target_deg).abs().max((a.pitch_target_deg - b.pitch_target_deg).abs()) > 0.2)
            .count();
        assert!(apart * 100 < armed.len(), "{name}: targets differ by more than the jitter at {apart} of {} armed ticks", armed.len());
    }
}

#[test]
fn without_its_parameters_the_same_transmitter_does_not_fly() {
    // Not any failed criterion: the board must never arm (the gesture is not understood).
    let (log, failed) = fly("hover", Config::default());
    assert!(!failed.is_empty());
    assert!(log.rows.iter().all(|r| !r.armed), "armed on a transmitter it was not set up for");
}

#[test]
fn the_scenario_is_the_hover_through_that_transmitter() {
    let sc = scenario::by_name("other-transmitter").unwrap_or_else(|| panic!("other-transmitter"));
    assert_eq!(sc.radio.transmitter, Some(Transmitter::OTHER));
    assert!(sc.about.contains("other-transmitter.parm"), "{}", sc.about);
    let cfg = parameters::apply_file(&Config::default(), PARAMS).unwrap_or_else(|e| panic!("{e:?}"));
    let mut computer = InProcess::new(cfg).unwrap_or_else(|e| panic!("{e}"));
    let log = sim::run_with(&mut computer, &sc, Profile::Default, &RunOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let failed: Vec<_> = metrics::check_all(&log, &sc).into_iter().filter(|v| !v.passed).collect();
    assert!(failed.is_empty(), "{failed:#?}");
}
