//! The one resource through which the link task hands the control loop what it accepted.
//!
//! The firmware shares it between its link task and its control and outer tasks (each access
//! under a lock). Here, on the host, its rules are tested (`tests/mailbox.rs`).

use fcu_core::flight::{ChangeKind, ConfigChange, ControlTick};
use fcu_core::gcs::GcsInput;
use fcu_core::Config;

/// What the link task hands the control loop, in one resource: the latest change it accepted
/// (the core checked it against the flight state) until the control tick has taken or refused
/// it, the configuration the tick took until the outer step has taken it, and the station's
/// commands for the control tick. The outer step follows the tick: a change the tick refuses
/// (armed since the link accepted it) reaches neither half, so the two never run different
/// configurations.
pub struct Mailbox {
    change: ConfigChange,
    /// The control tick has not taken or refused `change` yet.
    tick_takes_change: bool,
    /// The configuration the tick took last, until the outer step takes it: a second copy,
    /// because a newer change may arrive before the outer step's turn and be refused.
    for_outer: Option<Config>,
    /// Commands, and the levels of a pending save or reboot (the tick then refuses to arm).
    gcs: Option<GcsInput>,
}

impl Mailbox {
    /// Nothing posted: `config` is the one both halves booted with.
    pub fn new(config: Config) -> Mailbox {
        Mailbox { change: ConfigChange { cfg: config, kind: ChangeKind::GroundOnly }, tick_takes_change: false, for_outer: None, gcs: None }
    }

    /// The link's output of one period. A change replaces one the tick has not taken yet (the
    /// station's change carries the widest kind of everything since the tick last took one);
    /// commands the tick has not taken yet are merged with, not overwritten.
    pub fn post(&mut self, change: Option<ConfigChange>, gcs: Option<GcsInput>) {
        if let Some(change) = change {
            self.change = change;
            self.tick_takes_change = true;
        }
        if let Some(input) = gcs {
            self.gcs = Some(self.gcs.map_or(input, |older| older.then(input)));
        }
    }

    /// The change and the commands for the control tick, taken between ticks (from the control
    /// task), every stage keeping its state. The change is read in place: a copy would cost
    /// its size every tick, change or not.
    pub fn deliver_to_tick(&mut self, tick: &mut ControlTick) {
        if core::mem::take(&mut self.tick_takes_change) && tick.take_config(&self.change).is_ok() {
            self.for_outer = Some(self.change.cfg);
        }
        if let Some(input) = self.gcs.take() {
            tick.take_gcs(&input);
        }
    }

    /// The configuration the tick took, for the outer step before its next step: moved out, so
    /// that the outer step takes it after the lock, which holds off the control tick.
    pub fn config_for_outer(&mut self) -> Option<Config> {
        self.for_outer.take()
    }
}
