//! The decision in force: the supervisor's last decision and the sticks the pipeline flies
//! that follow from it. Its own module because the command stage writes it and the block reads
//! it into the outer job, and the block sits below the command stage.

use super::derived::TickParams;
use crate::rc::{StickCounts, Sticks};
use crate::supervisor::Decision;

/// The supervisor's last decision and what follows from it and the sticks, kept until the
/// supervisor decides again.
#[derive(Clone, Copy, Debug)]
pub(super) struct InForce {
    pub(super) decision: Decision,
    /// The sticks the pipeline flies with: the radio's, or the failsafe's while it holds.
    pub(super) sticks: Sticks,
    /// Whether their throttle is low (motors stopped, integrators and yaw reset).
    pub(super) throttle_low: bool,
    /// The throttle the sticks (or the failsafe) ask: `sticks.thr` unless the altitude hold
    /// flies its own ([`VerticalCommand::throttle`](crate::althold::VerticalCommand::throttle)).
    pub(super) command_thr: StickCounts,
}

impl InForce {
    /// A new decision, and what follows from it and the radio's sticks: the one writer of all
    /// three, written in place (docs/performance.md, «in place»).
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    pub(super) fn decided(&mut self, decision: Decision, radio_sticks: Sticks, p: &TickParams, hold: Option<StickCounts>) {
        self.decision = decision;
        self.sticks = decision.failsafe_throttle.map_or(radio_sticks, failsafe_sticks);
        self.command_thr = self.sticks.thr;
        if let Some(t) = hold {
            self.sticks.thr = t;
        }
        self.throttle_low = p.rc.throttle_low(&self.sticks);
    }
}

/// The sticks the failsafe flies with: centred (level, no yaw) and the held throttle.
fn failsafe_sticks(throttle: StickCounts) -> Sticks {
    Sticks { thr: throttle, ..Sticks::default() }
}
