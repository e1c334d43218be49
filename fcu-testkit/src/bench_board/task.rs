//! The board's link task, one 5 ms period at a time, as the firmware runs it today
//! (`fcu-firmware/src/ground.rs`, `with_link::step`): a mirror kept here until the firmware's
//! per-period decisions move into fcu-link, after which the bench runs that code instead.

use fcu_core::flight::Status;
use fcu_core::ground::GroundInput;
use fcu_core::parameters::snapshot;
use fcu_core::Config;
use fcu_link::station::Station;
use fcu_link::{Link, LinkConfig, Severity};

/// The link's transmit queue, bytes (the firmware's `LINK_TX_BYTES`).
pub const LINK_TX_BYTES: usize = 512;

/// What the control loop last published for the link task.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observed {
    pub status: Status,
    pub battery_mv: u32,
    pub rc_widths_counts: [u16; 4],
}

/// What the control loop must take after a period.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ToControl {
    /// For both halves' `take_config`.
    pub config: Option<Config>,
    /// For the control tick's `take_ground`.
    pub ground: Option<GroundInput>,
}

/// Flash or reset work the task wants done now.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Due {
    Nothing,
    Save,
    Reboot,
}

/// The link task as the firmware composes it today.
pub struct Today {
    link: Link<LINK_TX_BYTES>,
    station: Station,
    source: snapshot::Source,
    announced: bool,
}

impl Today {
    pub fn new(cfg: Config, defaults: &'static Config, source: snapshot::Source, link: LinkConfig) -> Self {
        let station = Station::new(cfg, defaults);
        let mut link = Link::new(link);
        link.set_rates(station.rates());
        Today { link, station, source, announced: false }
    }

    /// One period: the status, the bytes received, the schedule, and what the control loop
    /// must take. (The firmware's text-line mode is not modelled: the bench speaks MAVLink.)
    pub fn period(&mut self, now_ms: u32, observed: Option<Observed>, rx: &[u8]) -> ToControl {
        if let Some(o) = observed {
            self.station.observe(&o.status, o.battery_mv, o.rc_widths_counts, now_ms);
        }
        self.link.receive(rx, now_ms, &mut self.station);
        if !self.announced {
            self.announced = true;
            let _queued = match self.source {
                snapshot::Source::Snapshot { .. } => self.link.greet(Severity::Info, b"parameters loaded from flash"),
                snapshot::Source::NoSnapshot => self.link.greet(Severity::Notice, b"no saved parameters: defaults"),
                snapshot::Source::Refused(_) => self.link.greet(Severity::Warning, b"saved parameters refused: defaults"),
            };
        }
        self.link.tick(now_ms, &mut self.station);
        let config = self.station.take_change();
        if config.is_some() {
            self.link.set_rates(self.station.rates());
        }
        ToControl { config, ground: self.station.take_ground() }
    }

    pub fn poll_tx(&mut self, out: &mut [u8]) -> usize {
        self.link.poll_tx(out)
    }

    /// The firmware's two checks after the UART took its bytes: a save once everything queued
    /// is out, a reboot once the acknowledgement left the link and nothing is unsaved (today
    /// without looking at the flight state again).
    pub fn due(&mut self, _now_ms: u32, uart_idle: bool) -> Due {
        if self.station.save_due() && uart_idle && self.link.tx_pending() == 0 {
            Due::Save
        } else if self.station.reboot_asked() && self.link.reboot_ready() && !self.station.unsaved() {
            Due::Reboot
        } else {
            Due::Nothing
        }
    }

    pub fn plan_save(&self, sectors: [&[u32]; 2]) -> snapshot::SavePlan {
        self.station.plan_save(sectors)
    }

    pub fn saved(&mut self, ok: bool) {
        self.station.saved(ok);
        let _queued = if ok {
            self.link.send_text(Severity::Info, b"parameters saved")
        } else {
            self.link.send_text(Severity::Error, b"parameters NOT saved: flash error")
        };
    }
}
