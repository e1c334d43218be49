//! docs/parameters.md is generated from the parameter table. After changing the table:
//!
//! ```text
//! FCU_UPDATE_DOCS=1 cargo test -p fcu-params --test parameter_list
//! ```

use fcu_core::Config;
use fcu_params as parameters;

const PATH: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/parameters.md");

fn generated() -> String {
    let mut table = String::new();
    parameters::write_markdown(&mut table, &Config::default()).expect("writing to a String");
    format!(
        "# Parameters\n\n\
         <!-- Generated from fcu-params's parameter table (fcu-params/src/lib.rs); do not edit.\n     \
         Update: FCU_UPDATE_DOCS=1 cargo test -p fcu-params --test parameter_list -->\n\n\
         {count} parameters, every one a `REAL32` as MAVLink carries it; whole-number ones are exact.\n\
         The defaults are `Config::default()`'s. *Change*: `any time` applies at once, armed too (in RAM,\n\
         saved after disarming); `disarmed` is refused while armed and applies at once; `after reboot` is\n\
         refused while armed and takes effect at the next boot. Why: a new radio map, endpoint or\n\
         gesture threshold changes what the sticks mean under the pilot's thumbs, and a failsafe time\n\
         or filter changed mid-flight acts on a flight planned with the old one; gains and limits are\n\
         what a tune changes in the air, as on other autopilots. A set that is not finite, out of\n\
         range, off its step or that makes the configuration invalid is refused with the rule it\n\
         breaks, and the value in force stays. Setting the value a parameter already has is always\n\
         taken. A value taken is the value the board reports, saves and loads, bit for bit.\n\
         `RCMAP_*` gives an input to a function and the function that had it the old input, so the\n\
         map stays a permutation (both are reported); a whole set (a saved snapshot, a parameter\n\
         file) whose map is not a permutation is refused.\n\n\
         {table}",
        count = parameters::count(),
    )
}

#[test]
fn docs_parameters_md_is_the_table() {
    let want = generated();
    if std::env::var_os("FCU_UPDATE_DOCS").is_some() {
        std::fs::write(PATH, &want).expect("writing docs/parameters.md");
        return;
    }
    let have = std::fs::read_to_string(PATH).unwrap_or_default();
    assert!(
        have == want,
        "docs/parameters.md differs from the parameter table; update it with:\n  FCU_UPDATE_DOCS=1 cargo test -p fcu-params --test parameter_list"
    );
}
