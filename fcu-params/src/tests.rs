use super::*;
use fcu_core::config::ConfigError;
use fcu_core::rc::{RcMap, CHANNELS};
use fcu_core::supervisor::SupervisorConfig as Supervisor;

fn idx(name: &str) -> usize {
    index_of(name.as_bytes()).unwrap_or_else(|| panic!("no parameter {name}"))
}

fn get(cfg: &Config, name: &str) -> f32 {
    value(cfg, idx(name)).unwrap()
}

#[test]
fn names_are_unique_upper_case_and_fit_a_param_id() {
    assert_eq!(count(), COUNT);
    for (i, p) in TABLE.iter().enumerate() {
        assert!(!p.name.is_empty() && p.name.len() <= NAME_LEN, "{}", p.name);
        assert!(p.name.bytes().all(|b| b.is_ascii_uppercase() || b.is_ascii_digit() || b == b'_'), "{}", p.name);
        assert_eq!(index_of(p.name.as_bytes()), Some(i), "{} is not unique", p.name);
        assert!(p.min < p.max, "{}", p.name);
        #[cfg(feature = "descriptions")]
        assert!(description(i).is_some_and(|d| !d.is_empty()), "{}", p.name);
        // Whole-number parameters are exact as f32.
        assert!(p.min.abs() < 16_777_216.0 && p.max.abs() < 16_777_216.0);
    }
}

#[test]
fn every_rule_fits_a_statustext_with_the_name() {
    let rules = [
        RULE_NOT_FINITE,
        RULE_BELOW_MIN,
        RULE_ABOVE_MAX,
        RULE_NOT_WHOLE,
        RULE_NOT_QUARTER_US,
        RULE_UNKNOWN,
        RULE_ARMED,
        RULE_NOT_TICKS,
        RULE_REV,
        RULE_NO_SAFETY,
        RULE_FILTER,
        RULE_FILTER_TICK,
    ];
    let errors = [
        ConfigError::ReferenceArithmetic,
        ConfigError::ReferenceRateLoop,
        ConfigError::Timing,
        ConfigError::ImuSensitivity,
        ConfigError::Calibration,
        ConfigError::Health,
        ConfigError::GyroFilter,
        ConfigError::Estimator,
        ConfigError::Rc,
        ConfigError::Control,
        ConfigError::Mixer,
        ConfigError::Supervisor,
        ConfigError::BatterySense,
        ConfigError::Link,
        ConfigError::Altitude,
    ];
    // Every rule RcConfig::problem can name: break each in turn.
    let mut rc_rules = std::vec::Vec::new();
    let d = Config::default().rc;
    for f in [
        &(|c: &mut fcu_core::rc::RcConfig| c.map.roll = 1) as &dyn Fn(&mut fcu_core::rc::RcConfig),
        &|c| c.full_scale = StickCounts(0),
        &|c| c.inputs[0].trim_counts = 9000,
        &|c| c.inputs[0].max_counts = c.inputs[0].trim_counts + 1,
        &|c| c.gesture_threshold = StickCounts(0),
        &|c| c.min_throttle = StickCounts(-1),
        &|c| c.max_tilt_deg = 90.0,
        &|c| c.yaw_deadband = StickCounts(-1),
        &|c| c.yaw_rate_max_deg_s = -1.0,
        &|c| c.link_timeout_ticks = 0,
        &|c| c.pulses = fcu_core::rc::PulseRules::Validated { min_counts: 1, max_counts: 0, max_pulse_ticks: 1 },
    ] {
        let mut c = d;
        f(&mut c);
        rc_rules.push(c.problem().expect("a broken radio configuration names its rule"));
    }
    assert_eq!(rc_rules.len(), 11);
    const { assert!(NAME_LEN + 2 + RULE_LEN <= 50) };
    for rule in rules.into_iter().chain(errors.map(ConfigError::rule)).chain(rc_rules) {
        assert!(!rule.is_empty() && rule.len() <= RULE_LEN, "{rule:?}");
    }
}

#[test]
fn the_default_set_is_on_its_bounds_and_steps_and_reads_back_bit_for_bit() {
    for base in [Config::default(), Config::esc()] {
        let v = values(&base);
        for (p, &x) in TABLE.iter().zip(&v) {
            assert_eq!(check_value(p, x), Ok(()), "{} = {x}", p.name);
        }
        // Loading the whole set, and setting each parameter to the value it reads: the very
        // same configuration (the golden vectors fly it).
        assert_eq!(with_values(&base, &v), Ok(base));
        for i in 0..count() {
            let mut c = base;
            let got = set(&mut c, i, v[i], false).unwrap_or_else(|r| panic!("{}: {r:?}", TABLE[i].name));
            assert_eq!(got, Applied { value: v[i], also_changed: None });
            assert_eq!(c, base, "{}", TABLE[i].name);
        }
    }
}

#[test]
fn the_defaults_read_as_the_profile_says() {
    let d = Config::default();
    let want = [
        ("RCMAP_ROLL", 1.0),
        ("RCMAP_THROTTLE", 3.0),
        ("RC1_TRIM", 1465.5),
        ("RC1_MIN", 1015.5),
        ("RC1_MAX", 1915.5),
        ("RC3_MIN", 1112.5),
        ("RC3_TRIM", 1562.5),
        ("RC3_MAX", 2012.5),
        ("RC4_REV", 1.0),
        ("RC_TIMEOUT_MS", 100.0),
        ("GESTURE_US", 300.0),
        ("THR_MIN_US", 50.0),
        ("YAW_DEADBAND_US", 150.0),
        ("ARM_HOLD_MS", 1000.0),
        ("DISARM_DELAY_MS", 5000.0),
        ("FS_OFF_MS", 1000.0),
        ("FS_RECOVER_MS", 1000.0),
        ("ANG_RLL_P", 6.5),
        ("RATE_YAW_P", 1500.0),
        ("RATE_PIT_D", 7.0),
        ("GYRO_LPF_HZ", 150.0),
        ("RATE_D_LPF_K", 0.4),
        ("BATT_VOLT_MULT", 1.5),
        ("LINK_PROTOCOL", 1.0),
        ("LINK_ATT_HZ", 25.0),
        ("LINK_RC_HZ", 10.0),
    ];
    for (name, v) in want {
        assert_eq!(get(&d, name), v, "{name}");
    }
    assert!((get(&d, "ANGLE_MAX") - 20.0).abs() < 1e-5);
    assert!((get(&d, "YAW_RATE_MAX") - 120.0).abs() < 1e-4);
}

#[test]
fn every_parameter_sets_what_it_reads() {
    // Each parameter to another valid value: the getter reads what was set, the configuration
    // moved, and nothing else read differently (but a radio map entry's partner).
    let base = Config::default();
    for (i, p) in TABLE.iter().enumerate() {
        let old = p.get(&base);
        let candidates = [p.min, p.max, libm::roundf((p.min + p.max) / 2.0), old + 1.0, old - 1.0, old * 1.1, old * 0.9];
        let mut moved = false;
        for v in candidates {
            if v == old || check_value(p, v).is_err() {
                continue;
            }
            let mut c = base;
            if let Ok(a) = set(&mut c, i, v, false) {
                assert!((a.value - v).abs() <= 1e-4 * v.abs().max(1.0), "{} set {v} reads {}", p.name, a.value);
                assert_eq!(p.get(&c), a.value);
                assert_ne!(c, base, "{}", p.name);
                for (j, q) in TABLE.iter().enumerate() {
                    if j != i && q.get(&c) != q.get(&base) {
                        assert!(p.name.starts_with("RCMAP") && a.also_changed == Some(j), "{} moved {}", p.name, q.name);
                    }
                }
                moved = true;
            }
        }
        assert!(moved, "{}: no other value could be set", p.name);
    }
}

#[test]
fn bad_values_are_refused_with_their_rule_and_nothing_moves() {
    let base = Config::default();
    let cases: [(&str, f32, &str); 12] = [
        ("RATE_RLL_P", f32::NAN, RULE_NOT_FINITE),
        ("RATE_RLL_P", f32::INFINITY, RULE_NOT_FINITE),
        ("RATE_RLL_P", f32::NEG_INFINITY, RULE_NOT_FINITE),
        ("RATE_RLL_P", -1.0, RULE_BELOW_MIN),
        ("RATE_RLL_P", 5000.5, RULE_ABOVE_MAX),
        ("RCMAP_ROLL", 2.5, RULE_NOT_WHOLE),
        ("RC1_TRIM", 1500.1, RULE_NOT_QUARTER_US),
        ("RC1_REV", 0.0, RULE_REV),
        ("RC_TIMEOUT_MS", 101.0, RULE_NOT_TICKS),
        // Past its own endpoint: Config::validate's radio rule, named.
        ("RC1_TRIM", 1950.0, "RCn: need MIN <= TRIM <= MAX"),
        ("RC1_MAX", 1500.0, "RCn: MIN/TRIM/MAX too close"),
        ("GESTURE_US", 449.75, RULE_ABOVE_MAX),
    ];
    for (name, v, rule) in cases {
        let mut c = base;
        let r = set(&mut c, idx(name), v, false);
        assert_eq!(r, Err(Refusal { rule, value_in_force: Some(get(&base, name)) }), "{name} = {v}");
        assert_eq!(c, base, "{name} = {v}");
    }
    // The same values by name, and unknown names.
    let mut c = base;
    assert_eq!(set_by_name(&mut c, b"RATE_RLL_P", f32::NAN, false).map_err(|r| r.rule), Err(RULE_NOT_FINITE));
    for id in [&b"NO_SUCH_PARAM"[..], b"rate_rll_p", b"", b"RATE_RLL_P_AND_MORE_THAN_16"] {
        assert_eq!(set_by_name(&mut c, id, 1.0, false), Err(Refusal { rule: RULE_UNKNOWN, value_in_force: None }));
    }
    assert_eq!(set(&mut c, COUNT, 1.0, false), Err(Refusal { rule: RULE_UNKNOWN, value_in_force: None }));
    assert_eq!(c, base);
    // A radio timeout as long as the failsafe's stage-2 time: the supervisor's rule.
    let mut short = base;
    set(&mut short, idx("FS_OFF_MS"), 250.0, false).unwrap();
    let before = short;
    let r = set(&mut short, idx("RC_TIMEOUT_MS"), 250.0, false);
    assert_eq!(r, Err(Refusal { rule: "FS_* must exceed RC_TIMEOUT_MS", value_in_force: Some(100.0) }));
    assert_eq!(short, before);
    assert!(set(&mut short, idx("RC_TIMEOUT_MS"), 245.0, false).is_ok());
    // The cut-offs are designs for the 800 Hz tick.
    let mut slow = base;
    slow.timing.integration_hz = 600.0;
    let before = slow;
    assert_eq!(set(&mut slow, idx("GYRO_LPF_HZ"), 100.0, false).map_err(|r| r.rule), Err(RULE_FILTER_TICK));
    assert_eq!(slow, before);
}

#[test]
fn a_param_id_is_read_up_to_its_nul_or_all_sixteen_bytes() {
    let mut id = [0u8; 16];
    id[..10].copy_from_slice(b"ANG_RLL_P\0");
    assert_eq!(index_of(&id), Some(idx("ANG_RLL_P")));
    // Sixteen characters fill the field with no NUL.
    let full = *b"RATE_D_LPF_K\0\0\0\0";
    assert_eq!(index_of(&full), Some(idx("RATE_D_LPF_K")));
    let sixteen = TABLE.iter().find(|p| p.name.len() == NAME_LEN).map(|p| p.name);
    if let Some(n) = sixteen {
        assert_eq!(index_of(n.as_bytes()), Some(idx(n)));
    }
    // Garbage after the NUL does not matter; no NUL within 16 bytes of a longer field is no name.
    assert_eq!(index_of(b"ANG_RLL_P\0XXXXXX"), Some(idx("ANG_RLL_P")));
    assert_eq!(index_of(b"ANG_RLL_PXXXXXXXY"), None);
    assert_eq!(index_of(b"ANG_RLL_"), None);
}

#[test]
fn while_armed_only_gains_and_rates_change() {
    let base = Config::default();
    for (i, p) in TABLE.iter().enumerate() {
        let old = p.get(&base);
        let v = if p.max > old { libm::floorf(old + 1.0).min(p.max) } else { libm::ceilf(old - 1.0).max(p.min) };
        let mut c = base;
        let r = set(&mut c, i, v, true);
        match p.applies {
            Applies::Anytime => assert!(r.is_ok(), "{}: {r:?}", p.name),
            Applies::Disarmed | Applies::Reboot => {
                assert_eq!(r, Err(Refusal { rule: RULE_ARMED, value_in_force: Some(old) }), "{}", p.name);
                assert_eq!(c, base);
                // The value it already has is no change: taken.
                assert_eq!(set(&mut c, i, old, true), Ok(Applied { value: old, also_changed: None }), "{}", p.name);
            }
        }
    }
    // What may change armed: the gains, the angle and yaw-rate limits, the telemetry rates, and
    // the altitude mode with the hold's gains and rate (the mode change is smooth, both ways).
    let anytime: std::vec::Vec<&str> = TABLE.iter().filter(|p| p.applies == Applies::Anytime).map(|p| p.name).collect();
    assert!(
        anytime.iter().all(|n| n.starts_with("ANG_")
            || n.starts_with("RATE_")
            || n.starts_with("LINK_")
            || ["ANGLE_MAX", "YAW_RATE_MAX", "YAW_FF"].contains(n)
            || ["ALT_MODE", "CLIMB_RATE_MAX", "ALT_POS_P", "ALT_VEL_P", "ALT_VEL_I", "ALT_HOVER_US"].contains(n)),
        "{anytime:?}"
    );
    assert!(!anytime.contains(&"RATE_D_LPF_K") && !anytime.contains(&"LINK_PROTOCOL"));
}

#[test]
fn a_radio_map_entry_swaps_with_the_function_that_had_the_input() {
    let mut c = Config::default();
    let a = set(&mut c, idx("RCMAP_ROLL"), 3.0, false).unwrap();
    assert_eq!(a, Applied { value: 3.0, also_changed: Some(idx("RCMAP_THROTTLE")) });
    assert_eq!(c.rc.map, RcMap { roll: 2, pitch: 1, throttle: 0, yaw: 3 });
    assert_eq!(c.validate(), Ok(()));
    // The endpoints stay with their inputs: an input whose trim sits at its bottom (as a
    // radio calibration leaves the throttle's) cannot carry a centred stick.
    let mut d = Config::default();
    set(&mut d, idx("RC3_TRIM"), 1112.5, false).unwrap();
    let before = d;
    assert_eq!(set(&mut d, idx("RCMAP_ROLL"), 3.0, false).map_err(|r| r.rule), Err("RCn: MIN/TRIM/MAX too close"));
    assert_eq!(d, before);
}

#[test]
fn another_transmitter_is_set_up_through_parameters_alone() {
    // Throttle on input 1, roll on 2, yaw on 3, pitch on 4 reversed; 1000..2000 us, trims
    // 1500 (the throttle's 1000). Sent as a ground station would, a parameter at a time,
    // with the endpoints first widened so that every step is valid.
    let mut c = Config::default();
    let steps: &[(&str, f32)] = &[
        ("RC1_MIN", 1000.0),
        ("RC1_MAX", 2000.0),
        ("RC1_TRIM", 1500.0),
        ("RC2_MIN", 1000.0),
        ("RC2_MAX", 2000.0),
        ("RC2_TRIM", 1500.0),
        ("RC3_MAX", 2000.0),
        ("RC3_TRIM", 1500.0),
        ("RC3_MIN", 1000.0),
        ("RC4_MIN", 1000.0),
        ("RC4_MAX", 2000.0),
        ("RC4_TRIM", 1500.0),
        ("RC4_REV", -1.0),
        ("RCMAP_THROTTLE", 1.0),
        ("RC1_TRIM", 1000.0),
        ("RCMAP_ROLL", 2.0),
        ("RCMAP_YAW", 3.0),
        ("RCMAP_PITCH", 4.0),
    ];
    for &(name, v) in steps {
        let r = set(&mut c, idx(name), v, false);
        assert!(r.is_ok(), "{name} = {v}: {r:?}");
    }
    assert_eq!(c.rc.map, RcMap { roll: 1, pitch: 3, throttle: 0, yaw: 2 });
    let mut s = fcu_core::rc::Sticks::default();
    for (input, w_us) in [(0, 1500u16), (1, 2000), (2, 1250), (3, 1250)] {
        c.rc.apply_width(&mut s, input, w_us * 4);
    }
    assert_eq!(s, fcu_core::rc::Sticks::new(1800, 900, 1800, -900));
    assert_eq!(c.validate(), Ok(()));
    let _ = CHANNELS;
}

#[test]
fn times_are_whole_ticks_and_the_reference_supervisor_has_none_to_set() {
    let mut c = Config::default();
    assert_eq!(set(&mut c, idx("RC_TIMEOUT_MS"), 105.0, false).map(|a| a.value), Ok(105.0));
    assert_eq!(c.rc.link_timeout_ticks, 84);
    assert_eq!(set(&mut c, idx("FS_OFF_MS"), 2000.0, false).map(|a| a.value), Ok(2000.0));
    assert_eq!(safety(&c).failsafe_off_ticks, 1600);
    assert_eq!(set(&mut c, idx("ARM_HOLD_MS"), 1001.0, false).map_err(|r| r.rule), Err(RULE_NOT_TICKS));
    let mut r = Config { supervisor: Supervisor::Reference, ..Config::default() };
    let before = r;
    assert_eq!(set(&mut r, idx("ARM_HOLD_MS"), 2000.0, false).map_err(|r| r.rule), Err(RULE_NO_SAFETY));
    assert_eq!(r, before);
}

#[test]
fn the_altitude_parameters_reach_the_configuration_in_their_units() {
    use fcu_core::altitude::AltMode;
    let mut c = Config::default();
    let alt = |c: &Config| c.altitude.expect("the default flies altitude");
    assert_eq!(get(&c, "ALT_MODE"), 0.0, "manual by default");
    assert_eq!(set(&mut c, idx("ALT_MODE"), 1.0, false).map(|a| a.value), Ok(1.0));
    assert_eq!(alt(&c).mode, AltMode::Hold);
    assert_eq!(set(&mut c, idx("ALT_MODE"), 0.5, false).map_err(|r| r.rule), Err(RULE_NOT_WHOLE));
    assert_eq!(set(&mut c, idx("ALT_MODE"), 2.0, false).map_err(|r| r.rule), Err(RULE_ABOVE_MAX));
    assert_eq!(set(&mut c, idx("CLIMB_RATE_MAX"), 2.5, false).map(|a| a.value), Ok(2.5));
    assert_eq!(alt(&c).hold.climb_rate_max_m_s, 2.5);
    assert_eq!(set(&mut c, idx("FS_DESCENT_RATE"), 0.05, false).map_err(|r| r.rule), Err(RULE_BELOW_MIN));
    // Throttles in µs of stick: four capture counts each.
    assert_eq!(set(&mut c, idx("ALT_DEADBAND_US"), 100.25, false).map(|a| a.value), Ok(100.25));
    assert_eq!(alt(&c).hold.deadband, StickCounts(401));
    assert_eq!(set(&mut c, idx("ALT_DEADBAND_US"), 100.1, false).map_err(|r| r.rule), Err(RULE_NOT_QUARTER_US));
    assert_eq!(set(&mut c, idx("ALT_HOVER_US"), 150.0, false).map(|a| a.value), Ok(150.0));
    assert_eq!(alt(&c).hold.hover_throttle, StickCounts(600));
    assert_eq!(set(&mut c, idx("ALT_VEL_P"), 300.0, false).map(|a| a.value), Ok(300.0));
    assert_eq!(alt(&c).hold.vel_p, 1200.0);
    assert_eq!(set(&mut c, idx("ALT_EST_TAU"), 2.0, false).map(|a| a.value), Ok(2.0));
    assert_eq!(alt(&c).estimator.time_constant_s, 2.0);
    assert_eq!(set(&mut c, idx("BARO_THRUST_PA"), -7.5, false).map(|a| a.value), Ok(-7.5));
    assert_eq!(alt(&c).estimator.thrust_scale_pa, -7.5);
}

#[test]
fn in_flight_the_altitude_mode_and_the_holds_gains_change_and_the_failsafe_and_estimator_do_not() {
    let mut c = Config::default();
    for (name, v) in [
        ("ALT_MODE", 1.0),
        ("CLIMB_RATE_MAX", 0.5),
        ("ALT_POS_P", 2.0),
        ("ALT_VEL_P", 200.0),
        ("ALT_VEL_I", 100.0),
        ("ALT_HOVER_US", 140.0),
    ] {
        assert_eq!(set(&mut c, idx(name), v, true).map(|a| a.value), Ok(v), "{name}");
    }
    for (name, v) in [("FS_DESCENT_RATE", 1.0), ("ALT_DEADBAND_US", 50.0), ("ALT_EST_TAU", 3.0), ("BARO_THRUST_PA", 5.0)] {
        assert_eq!(set(&mut c, idx(name), v, true).map_err(|r| r.rule), Err(RULE_ARMED), "{name}");
    }
    // A change of the mode alone is an in-flight change the controller takes armed.
    let mut hold = Config::default();
    set(&mut hold, idx("ALT_MODE"), 1.0, false).unwrap();
    assert_eq!(check_change(&Config::default(), &hold, true).map(|c| c.kind), Ok(ChangeKind::InFlight));
}

#[test]
fn the_reference_profile_has_no_altitude_to_set() {
    let mut r = Config::reference();
    r.reference_arithmetic = false;
    let before = r;
    assert_eq!(get(&r, "ALT_MODE"), 0.0);
    assert_eq!(set(&mut r, idx("ALT_MODE"), 1.0, false).map_err(|r| r.rule), Err(RULE_NO_SAFETY));
    assert_eq!(r, before);
}

#[test]
fn the_gyro_cut_off_is_designed_as_the_profile_designs_it() {
    // The table is the design, bit for bit.
    for &(hz, a1, a2, b0) in GYRO_DESIGNS_800_HZ.iter() {
        let c = BiquadCoeffs::butterworth_lowpass(f32::from(hz), 800.0).unwrap();
        assert_eq!([c.a1, c.a2, c.b0, c.b1, c.b2].map(f32::to_bits), [a1, a2, b0, (2.0 * f32::from_bits(b0)).to_bits(), b0], "{hz} Hz");
    }
    let mut c = Config::default();
    assert_eq!(get(&c, "GYRO_LPF_HZ"), 150.0);
    set(&mut c, idx("GYRO_LPF_HZ"), 100.0, false).unwrap();
    assert_eq!(Some(c.gyro_filter), BiquadCoeffs::butterworth_lowpass(100.0, 800.0));
    assert_eq!(get(&c, "GYRO_LPF_HZ"), 100.0);
    set(&mut c, idx("GYRO_LPF_HZ"), 150.0, false).unwrap();
    assert_eq!(c.gyro_filter, BiquadCoeffs::GYRO_150_HZ_AT_800_HZ);
    // Every cut-off offered reads back as itself; any other is refused.
    for hz in 40..=300 {
        let r = set(&mut c, idx("GYRO_LPF_HZ"), hz as f32, false);
        if hz % 10 == 0 {
            assert!(r.is_ok(), "{hz}");
            assert_eq!(get(&c, "GYRO_LPF_HZ"), hz as f32);
        } else {
            assert_eq!(r.map_err(|r| r.rule), Err(RULE_FILTER), "{hz}");
        }
    }
    // A design the table does not list reads as its Butterworth cut-off.
    c.gyro_filter = BiquadCoeffs::butterworth_lowpass(123.0, 800.0).unwrap();
    assert_eq!(get(&c, "GYRO_LPF_HZ"), 123.0);
}

#[test]
fn the_layout_hash_follows_names_and_order() {
    let mut swapped = TABLE;
    swapped.swap(0, 1);
    assert_ne!(layout_hash(&swapped), LAYOUT_HASH);
    let mut renamed = TABLE;
    renamed[5].name = "RC1_TRIX";
    assert_ne!(layout_hash(&renamed), LAYOUT_HASH);
    assert_ne!(layout_hash(&TABLE[..COUNT - 1]), LAYOUT_HASH);
    assert_eq!(layout_hash(&TABLE), LAYOUT_HASH);
}

#[test]
fn a_whole_set_is_checked_as_a_whole() {
    let base = Config::default();
    let mut v = values(&base);
    // Endpoints that are only valid together: loaded at once, they pass.
    v[idx("RC1_MIN")] = 1000.0;
    v[idx("RC1_TRIM")] = 1500.0;
    v[idx("RC1_MAX")] = 2000.0;
    let c = with_values(&base, &v).unwrap();
    assert_eq!(c.rc.inputs[0].trim_counts, 6000);
    v[idx("RC1_TRIM")] = 2100.0;
    assert_eq!(with_values(&base, &v), Err("RCn: need MIN <= TRIM <= MAX"));
    v[idx("RC1_TRIM")] = f32::NAN;
    assert_eq!(with_values(&base, &v), Err(RULE_NOT_FINITE));
}

#[test]
fn a_parameter_file_round_trips_and_bad_lines_are_named() {
    let base = Config::default();
    let mut text = std::string::String::new();
    write_file(&mut text, &base).unwrap();
    assert_eq!(text.lines().count(), COUNT);
    assert!(text.starts_with("RCMAP_ROLL 1\nRCMAP_PITCH 2\n"), "{text}");
    assert_eq!(apply_file(&base, &text), Ok(base));
    // MAVProxy's own layout: padded names, six decimals, comments; a whole radio at once in
    // an order that one set at a time would refuse (the trim past the old maximum first).
    let other = "# from another board\nRC1_TRIM      1950.000000\nRC1_MAX 2100\n\nRATE_RLL_P,250.5 # tuned\n";
    let c = apply_file(&base, other).unwrap();
    assert_eq!((c.rc.inputs[0].trim_counts, c.rc.inputs[0].max_counts, c.control.roll.inner_kp), (7800, 8400, 250.5));
    let mut one_at_a_time = base;
    assert!(set(&mut one_at_a_time, idx("RC1_TRIM"), 1950.0, false).is_err());
    assert_eq!(apply_file(&base, "ANG_RLL_P 5\nNO_SUCH 1\n"), Err(FileError { line: 2, rule: RULE_UNKNOWN }));
    assert_eq!(apply_file(&base, "ANG_RLL_P five\n"), Err(FileError { line: 1, rule: "value is not a number" }));
    assert_eq!(apply_file(&base, "ANG_RLL_P\n"), Err(FileError { line: 1, rule: "expected NAME VALUE" }));
    assert_eq!(apply_file(&base, "ANG_RLL_P 1 2\n"), Err(FileError { line: 1, rule: "expected NAME VALUE" }));
    // A value outside its own bounds is its line's; a set refused as a whole is line 0.
    assert_eq!(apply_file(&base, "# a comment\nANG_RLL_P nan\n"), Err(FileError { line: 2, rule: RULE_NOT_FINITE }));
    assert_eq!(apply_file(&base, "RC1_MIN 100\n"), Err(FileError { line: 1, rule: RULE_BELOW_MIN }));
    assert_eq!(apply_file(&base, "RC1_TRIM 2400\n").map_err(|e| e.line), Err(0));
}

/// `v` (in the parameter's bounds) moved onto its step, rounding down.
fn on_step(p: &Param, v: f32) -> f32 {
    match p.step {
        Step::Any => v,
        Step::Integer => libm::floorf(v),
        Step::QuarterUs => libm::floorf(v * 4.0) / 4.0,
    }
}

/// The values of `p` every round-trip test tries: its ends, and every multiple of ten (of
/// degrees for an angle) within its bounds.
fn ends_and_tens(p: &Param) -> std::vec::Vec<f32> {
    let mut v = std::vec![p.min, p.max];
    let mut x = libm::ceilf(p.min / 10.0) * 10.0;
    while x <= p.max {
        v.push(x);
        x += 10.0;
    }
    v
}

/// A set of `v` on parameter `i` of `base`, if taken, reads back, saves and loads as exactly
/// `v`, and the loaded set is accepted as it is.
fn assert_round_trip(base: &Config, i: usize, v: f32) {
    let p = &TABLE[i];
    let mut cfg = *base;
    let Ok(applied) = set(&mut cfg, i, v, false) else { return };
    assert_eq!(applied.value.to_bits(), v.to_bits(), "{} set {v} echoes {}", p.name, applied.value);
    assert_eq!(p.get(&cfg).to_bits(), v.to_bits(), "{} set {v} reads {}", p.name, p.get(&cfg));
    let saved = values(&cfg);
    let words = snapshot::encode(7, &saved);
    let decoded = snapshot::decode(&words).expect("a snapshot just written decodes");
    assert_eq!(decoded.values.map(f32::to_bits), saved.map(f32::to_bits), "{} = {v}", p.name);
    let mut sector = std::vec![snapshot::ERASED; snapshot::SECTOR_WORDS];
    sector[..words.len()].copy_from_slice(&words);
    let erased = std::vec![snapshot::ERASED; snapshot::SECTOR_WORDS];
    let (loaded, source) = snapshot::load_config([&sector, &erased], base);
    assert_eq!(source, snapshot::Source::Snapshot { sequence: 7, passed_over: None }, "{} = {v}: the saved set is refused", p.name);
    assert_eq!(values(&loaded).map(f32::to_bits), saved.map(f32::to_bits), "{} = {v}", p.name);
    assert_eq!(loaded, cfg, "{} = {v}: the loaded configuration differs", p.name);
    for (j, &x) in saved.iter().enumerate() {
        assert_eq!(check_value(&TABLE[j], x), Ok(()), "{} = {v}: {} = {x} is off its bounds", p.name, TABLE[j].name);
    }
    // Setting the loaded value again changes nothing.
    let mut again = loaded;
    assert_eq!(set(&mut again, i, v, false).map(|a| a.value.to_bits()), Ok(v.to_bits()));
    assert_eq!(again, loaded);
}

#[test]
fn every_end_and_multiple_of_ten_reads_saves_and_loads_bit_for_bit() {
    // ANGLE_MAX 15, 30, 31, 60 and YAW_RATE_MAX 120 were stored in radians and read back as
    // other floats (60.000004, above the maximum: the saved set was refused at boot).
    let angle = idx("ANGLE_MAX");
    let yaw = idx("YAW_RATE_MAX");
    for base in [Config::default(), Config::esc()] {
        for (i, p) in TABLE.iter().enumerate() {
            for v in ends_and_tens(p) {
                assert_round_trip(&base, i, on_step(p, v));
            }
        }
        for v in [15.0, 30.0, 31.0, 60.0, 5.0, 20.000_002] {
            assert_round_trip(&base, angle, v);
        }
        for deg_s in 1..=72 {
            assert_round_trip(&base, yaw, deg_s as f32 * 10.0);
        }
    }
    assert_eq!(get(&Config::default(), "YAW_RATE_MAX").to_bits(), 120.0f32.to_bits());
    assert_eq!(get(&Config::default(), "ANGLE_MAX").to_bits(), 20.0f32.to_bits());
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(4096))]

    #[test]
    fn any_value_taken_reads_saves_and_loads_bit_for_bit(i in 0..COUNT, t in 0.0f64..=1.0, bits in proptest::num::u32::ANY) {
        let p = &TABLE[i];
        // Anywhere in the bounds on the step, and for an any-valued parameter also a value
        // with arbitrary low mantissa bits (every f32 in the range is a candidate).
        let spread = (f64::from(p.min) + t * (f64::from(p.max) - f64::from(p.min))) as f32;
        let v = on_step(p, spread.clamp(p.min, p.max));
        let v = if p.step == Step::Any { f32::from_bits((v.to_bits() & !0xFFF) | (bits & 0xFFF)).clamp(p.min, p.max) } else { v };
        assert_round_trip(&Config::default(), i, v);
    }
}

#[test]
fn a_whole_set_with_a_radio_map_that_is_no_permutation_is_refused_not_rearranged() {
    // One at a time, RCMAP_ROLL 2 would swap with pitch and RCMAP_PITCH 2 swap back: the map
    // came out as the identity, silently. Whole, it is refused with the entry at fault.
    let base = Config::default();
    let mut v = values(&base);
    v[idx("RCMAP_ROLL")] = 2.0;
    assert_eq!(with_values_at(&base, &v), Err((Some(idx("RCMAP_PITCH")), RULE_RCMAP)));
    assert_eq!(with_values(&base, &v), Err(RULE_RCMAP));
    assert_eq!(base.rc.problem().map(|_| ()), None);
    let mut broken = base;
    broken.rc.map.roll = 1;
    assert_eq!(broken.rc.problem(), Some(RULE_RCMAP));
    // A permutation in any order loads as given.
    v[idx("RCMAP_PITCH")] = 1.0;
    let c = with_values(&base, &v).unwrap();
    assert_eq!((get(&c, "RCMAP_ROLL"), get(&c, "RCMAP_PITCH")), (2.0, 1.0));
}

#[test]
fn a_parameter_file_with_a_radio_map_that_is_no_permutation_is_refused_at_its_line() {
    let base = Config::default();
    // Only one entry: it collides with the base's pitch.
    assert_eq!(apply_file(&base, "ANG_RLL_P 5\nRCMAP_ROLL 2\n"), Err(FileError { line: 2, rule: RULE_RCMAP }));
    // The whole map, two entries naming input 2: the later line.
    let text = "RCMAP_ROLL 2\nRCMAP_PITCH 2\nRCMAP_THROTTLE 3\nRCMAP_YAW 4\n";
    assert_eq!(apply_file(&base, text), Err(FileError { line: 2, rule: RULE_RCMAP }));
    let text = "RCMAP_ROLL 2\nRCMAP_PITCH 1\nRCMAP_THROTTLE 3\nRCMAP_YAW 4\n";
    assert_eq!(apply_file(&base, text).map(|c| (get(&c, "RCMAP_ROLL"), get(&c, "RCMAP_PITCH"))), Ok((2.0, 1.0)));
    // A name twice is refused too (the second would win unseen).
    assert_eq!(apply_file(&base, "ANG_RLL_P 5\nANG_RLL_P 6\n"), Err(FileError { line: 2, rule: file::RULE_TWICE }));
}

#[test]
fn a_parameter_file_may_start_with_a_byte_order_mark() {
    let base = Config::default();
    let c = apply_file(&base, "\u{feff}ANG_RLL_P 5\n").unwrap();
    assert_eq!(get(&c, "ANG_RLL_P"), 5.0);
    // Only at the start: elsewhere it is part of a name.
    assert_eq!(apply_file(&base, "ANG_RLL_P 5\n\u{feff}ANG_PIT_P 5\n"), Err(FileError { line: 2, rule: RULE_UNKNOWN }));
}

#[test]
fn a_qgroundcontrol_params_file_reads_as_the_same_set() {
    let base = Config::default();
    let qgc = "# Onboard parameters for Vehicle 1\n#\n# Vehicle-Id Component-Id Name Value Type\n\
               1\t1\tANG_RLL_P\t5.5\t9\n1\t1\tRC1_MIN\t1000.25\t9\n1\t1\tRCMAP_YAW\t4\t9\n";
    let mavproxy = "ANG_RLL_P 5.5\nRC1_MIN 1000.25\nRCMAP_YAW 4\n";
    let c = apply_file(&base, qgc).unwrap();
    assert_eq!(c, apply_file(&base, mavproxy).unwrap());
    assert_eq!((get(&c, "ANG_RLL_P"), get(&c, "RC1_MIN")), (5.5, 1000.25));
    // Five words that are not SYS COMP NAME VALUE TYPE, or four: refused with the line.
    assert_eq!(apply_file(&base, "1 1 ANG_RLL_P 5 x\n"), Err(FileError { line: 1, rule: file::RULE_LINE }));
    assert_eq!(apply_file(&base, "1 1 ANG_RLL_P 5\n"), Err(FileError { line: 1, rule: file::RULE_LINE }));
    assert_eq!(apply_file(&base, "1\t1\tANG_RLL_P\tfive\t9\n"), Err(FileError { line: 1, rule: file::RULE_NOT_A_NUMBER }));
}

/// The default with the reference's supervisor: a configuration a test can classify changes of.
fn flown() -> Config {
    Config { supervisor: Supervisor::Reference, ..Config::default() }
}

fn with(name: &str, value: f32) -> Config {
    let mut cfg = Config::default();
    set_by_name(&mut cfg, name.as_bytes(), value, false).unwrap();
    cfg
}

#[test]
fn every_parameter_changes_as_the_table_says_it_applies() {
    // One parameter at a time, each to another value on its step: the change check derives
    // its kind from the table, with no list of fields of its own.
    for (i, p) in TABLE.iter().enumerate() {
        let old = Config::default();
        let v = p.get(&old);
        let candidates = [p.min, p.max, v + 1.0, v - 1.0, v + 10.0, v - 10.0];
        let mut new = old;
        let Some(changed) = candidates.iter().find(|&&c| c != v && set(&mut new, i, c, false).is_ok()) else {
            panic!("no other value for {}", p.name);
        };
        let expected = p.applies.kind();
        assert_eq!(check_change(&old, &new, false).map(|c| c.kind), Ok(expected), "{} to {changed}", p.name);
        let restricted = if expected == ChangeKind::InFlight { Ok(()) } else { Err(ApplyError::Armed) };
        assert_eq!(check_change(&old, &new, true).map(|_| ()), restricted, "{} to {changed}", p.name);
    }
}

#[test]
fn while_restricted_only_in_flight_parameters_change_and_a_setting_no_parameter_reaches_never_does() {
    let old = Config::default();
    assert_eq!(check_change(&old, &with("RC1_TRIM", 1470.0), true), Err(ApplyError::Armed));
    assert_eq!(check_change(&old, &with("GYRO_LPF_HZ", 80.0), true), Err(ApplyError::Armed));
    assert_eq!(check_change(&old, &with("RCMAP_ROLL", 2.0), true), Err(ApplyError::Armed));
    let swapped = check_change(&old, &with("RCMAP_ROLL", 2.0), false).unwrap();
    assert_eq!((swapped.kind, swapped.cfg), (ChangeKind::GroundOnly, with("RCMAP_ROLL", 2.0)));
    assert_eq!(check_change(&old, &with("RATE_RLL_P", 260.0), true).map(|c| c.kind), Ok(ChangeKind::InFlight));
    assert_eq!(check_change(&old, &old, true).map(|c| c.kind), Ok(ChangeKind::InFlight));
    // Not a parameter at all, or not valid: refused restricted or not.
    let mut mixer = old;
    mixer.mixer.max_compare -= 1.0;
    assert_eq!(check_change(&old, &mixer, false), Err(ApplyError::NeedsRestart));
    let mut invalid = old;
    invalid.control.roll.inner_kp = -1.0;
    assert_eq!(check_change(&old, &invalid, false), Err(ApplyError::Invalid(ConfigError::Control)));
    assert_eq!(check_change(&flown(), &old, false), Err(ApplyError::NeedsRestart));
    // A setting a parameter reaches, at a value no parameter sets: not a parameter change.
    let mut between = old;
    between.gyro_filter = BiquadCoeffs::butterworth_lowpass(123.0, 800.0).unwrap();
    assert_eq!(check_change(&old, &between, false), Err(ApplyError::NeedsRestart));
    assert_eq!(ApplyError::Armed.rule(), RULE_ARMED);
}

#[test]
fn a_refused_apply_changes_nothing_and_a_taken_one_reaches_the_controller() {
    let mut fc = FlightController::new(&Config::default()).unwrap();
    assert_eq!(apply(&mut fc, &with("RC1_TRIM", 1470.0)), Ok(()));
    assert_eq!(fc.config(), &with("RC1_TRIM", 1470.0));
    let mut mixer = *fc.config();
    mixer.mixer.max_compare -= 1.0;
    assert_eq!(apply(&mut fc, &mixer), Err(ApplyError::NeedsRestart));
    assert_eq!(fc.config(), &with("RC1_TRIM", 1470.0));
}
