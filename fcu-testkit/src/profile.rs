//! The two configurations every tool here runs.

use fcu_core::Config;

/// Which `Config` flies, replays or estimates.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Profile {
    /// `Config::default()`: the product, the reference with the safety layer and the
    /// differences listed in `docs/profiles.md`.
    Default,
    /// `Config::reference()`: ST's reference firmware, number for number.
    Reference,
}

impl Profile {
    pub fn name(self) -> &'static str {
        match self {
            Profile::Default => "default",
            Profile::Reference => "reference",
        }
    }

    pub fn config(self) -> Config {
        match self {
            Profile::Default => Config::default(),
            Profile::Reference => Config::reference(),
        }
    }

    pub fn parse(s: &str) -> Option<Profile> {
        match s {
            "default" => Some(Profile::Default),
            "reference" => Some(Profile::Reference),
            _ => None,
        }
    }
}
