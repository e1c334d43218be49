//! The link task: one period of the ground-station link's work, the same on the board and in
//! the host's tests.
//!
//! The firmware's link task (and the host's model of the board) owns a [`Service`] and, every
//! few milliseconds: hands it the latest status ([`Service::observe`]) and the bytes received
//! ([`Service::receive`]), runs its period ([`Service::period`]) and gives the control loop what
//! that returns, moves the bytes it has for the UART ([`Service::poll_tx`]), then asks what
//! flash or reset work is due ([`Service::due`]) and carries it out at once. Every decision is
//! here or in the [`Station`]; the owner moves bytes and words.
//!
//! Before a save or a reboot the link goes quiet: once the station says one is imminent (the
//! control tick refuses to arm for it, see [`crate::station`]), the bytes already queued are
//! let out, then nothing more is handed to the UART until it is idle. The acknowledgement of
//! the command that asked for it is then out, and the work neither waits for a flood of
//! requests to stop (the link keeps receiving and answering into its own queue meanwhile) nor
//! stalls the CPU with a byte half sent. A reboot waits [`REBOOT_QUIET_MS`] more, for the
//! UART's last byte, and the station is asked again at the instant the board resets.

use fcu_core::config::LinkProtocol;
use fcu_core::flight::{ConfigChange, Status};
use fcu_core::gcs::GcsInput;
use fcu_core::telemetry::LineBuf;
use fcu_core::Config;
use fcu_params::snapshot;

use crate::station::{Due, Station};
use fcu_link::{Link, LinkConfig, Severity};

/// How long the UART must have been idle, with the link quiet, before a reset: its shift
/// register still holds the last byte when its queue empties.
pub const REBOOT_QUIET_MS: u32 = 20;

/// What the control loop reported last.
#[derive(Clone, Copy, Debug)]
pub struct Observed {
    pub status: Status,
    pub battery_mv: u32,
    /// Radio pulse widths, capture counts, by input (0: none yet).
    pub rc_widths_counts: [u16; 4],
}

/// What the control loop is to take from one period.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ToControl {
    /// A changed configuration, for both halves of the control loop.
    pub config: Option<ConfigChange>,
    /// Commands and levels for the control tick ([`fcu_core::flight::ControlTick::take_gcs`]).
    pub gcs: Option<GcsInput>,
}

/// The link, the station behind it, and the link task's pacing (see the module docs).
/// `Clone`: a host harness copies a booted board instead of booting it again.
#[derive(Clone)]
pub struct Service<const TX: usize> {
    link: Link<TX>,
    station: Station,
    /// Where the parameters in force came from, said once the link runs.
    source: snapshot::Source,
    announced: bool,
    /// Bytes queued before the imminent save or reboot, still to go to the UART: `None` when
    /// none is imminent.
    owed_bytes: Option<usize>,
    /// Since when the UART has been idle with the link quiet.
    quiet_since_ms: Option<u32>,
}

impl<const TX: usize> Service<TX> {
    /// A link for the board that booted with `cfg` (found as `source` says), `defaults` being
    /// what a parameter reset restores.
    pub fn new(cfg: Config, defaults: &'static Config, source: snapshot::Source, link_config: LinkConfig) -> Self {
        let station = Station::new(cfg, defaults);
        let mut link = Link::new(link_config);
        link.set_rates(station.rates());
        Service { link, station, source, announced: false, owed_bytes: None, quiet_since_ms: None }
    }

    /// MAVLink from boot, or text lines until a ground station speaks MAVLink (the link's
    /// protocol parameter).
    pub fn speaks_mavlink_from_boot(&self) -> bool {
        self.station.config().link.protocol == LinkProtocol::Mavlink
    }

    /// The control loop's latest report.
    pub fn observe(&mut self, now_ms: u32, observed: &Observed) {
        self.station.observe(&observed.status, observed.battery_mv, observed.rc_widths_counts, now_ms);
    }

    /// Bytes the UART received (any number, any content).
    pub fn receive(&mut self, now_ms: u32, bytes: &[u8]) {
        self.link.receive(bytes, now_ms, &mut self.station);
    }

    /// A good MAVLink frame has been heard since boot.
    pub fn heard(&self) -> bool {
        self.link.stats().reader.frames > 0
    }

    /// One period of the link's work once MAVLink is on the UART: the boot's greeting, the
    /// telemetry schedule, the texts about dropped actions, and what the control loop is to
    /// take.
    pub fn period(&mut self, now_ms: u32) -> ToControl {
        if !self.announced {
            self.announced = true;
            self.announce();
        }
        self.link.tick(now_ms, &mut self.station);
        let config = self.station.take_change();
        if config.is_some() {
            self.link.set_rates(self.station.rates());
        }
        let gcs = self.station.take_gcs();
        // Asked before `due`: what is dropped there is said in the next period.
        if let Some(text) = self.station.take_notice() {
            let _queued = self.link.send_text(Severity::Warning, text);
        }
        ToControl { config, gcs }
    }

    /// Moves bytes for the UART into `out`; returns how many. Before a save or a reboot only
    /// the bytes queued until then leave (see the module docs).
    pub fn poll_tx(&mut self, out: &mut [u8]) -> usize {
        if !self.station.action_imminent() {
            self.owed_bytes = None;
            return self.link.poll_tx(out);
        }
        let owed = *self.owed_bytes.get_or_insert(self.link.tx_pending());
        let n = self.link.poll_tx(out.get_mut(..owed.min(out.len())).unwrap_or_default());
        self.owed_bytes = Some(owed - n);
        n
    }

    /// The flash or reset work to carry out now, given whether the UART has sent everything it
    /// was given and whether the supply is high enough for the flash's writes (VDD ≥ 2.7 V for
    /// x32 programming, RM0368 §3.5.1). The station decides ([`Station::due`]) at this instant;
    /// the link must be quiet (see the module docs). The owner acts on the answer at once: a
    /// save then reports with [`Service::saved`].
    pub fn due(&mut self, now_ms: u32, uart_idle: bool, flash_supply_ok: bool) -> Due {
        let mut due = self.station.due();
        if due == Due::Save && !flash_supply_ok {
            self.station.supply_low();
            due = Due::Nothing;
        }
        let quiet = uart_idle && self.owed_bytes == Some(0);
        if due == Due::Nothing || !quiet {
            self.quiet_since_ms = None;
            return Due::Nothing;
        }
        let since = *self.quiet_since_ms.get_or_insert(now_ms);
        match due {
            Due::Reboot if now_ms.wrapping_sub(since) < REBOOT_QUIET_MS => Due::Nothing,
            due => due,
        }
    }

    /// The words to write for a save, given the sectors as they are.
    pub fn plan_save(&self, sectors: [&[u32]; 2]) -> snapshot::SavePlan {
        self.station.plan_save(sectors)
    }

    /// The save was written, or failed (`ok` false): said to the ground station.
    pub fn saved(&mut self, ok: bool) {
        self.station.saved(ok);
        self.quiet_since_ms = None;
        self.owed_bytes = None;
        let text: &[u8] = if ok { b"parameters saved" } else { b"parameters NOT saved: flash error" };
        let _queued = self.link.send_text(if ok { Severity::Info } else { Severity::Error }, text);
    }

    /// The link, for what the owner says itself (a boot fault).
    pub fn link_mut(&mut self) -> &mut Link<TX> {
        &mut self.link
    }

    pub fn link(&self) -> &Link<TX> {
        &self.link
    }

    pub fn station(&self) -> &Station {
        &self.station
    }

    /// Says where the parameters in force came from (the snapshot loaded, and why a newer one
    /// was passed over, in full: long texts go in chunks): a STATUSTEXT once the link runs, and
    /// again to each ground station that connects later (it missed the boot).
    fn announce(&mut self) {
        let severity = match self.source {
            snapshot::Source::Snapshot { passed_over: None, .. } => Severity::Info,
            snapshot::Source::NoSnapshot => Severity::Notice,
            snapshot::Source::Snapshot { passed_over: Some(_), .. } | snapshot::Source::Refused(_) => Severity::Warning,
        };
        let mut text = LineBuf::<{ snapshot::DESCRIBE_LEN }>::new();
        self.source.describe(&mut text);
        let _queued = self.link.greet(severity, text.as_bytes());
    }
}
