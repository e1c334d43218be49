//! The ground station's link: MAVLink 2 on USART1, with the `mavlink` feature.
//!
//! Every decision is fcu-link's, fcu-params' and fcu-core's (`fcu_link::station`: the parameter
//! table's rules, what a command may do); this module moves bytes and words. Received bytes come
//! from the DMA ring ([`crate::uart_rx`]); accepted parameter changes go to the control tick,
//! which passes on to the outer step what it takes ([`config_to_tick`]); accepted commands (and
//! whether a save runs) go to the control tick ([`to_control`]); saves go to flash
//! ([`crate::param_flash`]) once the changes settle, disarmed.
//! On a board set to text lines it listens, and the first valid MAVLink frame turns the UART to
//! MAVLink.

use crate::app::{Snapshot, UartOut};
use crate::watchdog::Watchdog;
use fcu_core::boot::BootVerdict;
use fcu_core::flight::{ConfigChange, ControlTick, OuterStep};
use fcu_core::ground::GroundInput;
use fcu_core::Config;

/// The link task's view of the shared resources it uses.
#[cfg_attr(not(feature = "mavlink"), allow(dead_code))]
pub struct Shared<U, L, B, T, G, W, M> {
    pub uart: U,
    pub latest: L,
    pub battery_mv: B,
    pub tick_config: T,
    pub ground_input: G,
    pub watchdog: W,
    pub mavlink_on: M,
}

#[cfg(not(feature = "mavlink"))]
/// Without the `mavlink` feature there is no link: nothing to keep.
pub struct GroundLink;

/// What the link would have in its place: no parameter store, no receiver.
#[cfg(not(feature = "mavlink"))]
pub struct Absent;

#[cfg(not(feature = "mavlink"))]
impl GroundLink {
    pub fn new(_cfg: Config, _defaults: &'static Config, _stored: Absent, _receiver: Absent) -> Self {
        GroundLink
    }

    pub fn speaks_mavlink_from_boot(&self) -> bool {
        false
    }
}

/// The configuration to boot with. Without the ground link nothing can change or save a
/// parameter: the build's defaults.
#[cfg(not(feature = "mavlink"))]
pub fn load_parameters(_flash: stm32f4xx_hal::pac::FLASH, defaults: &'static Config) -> (Config, Absent) {
    (*defaults, Absent)
}

/// Without the ground link USART1 receives nothing.
#[cfg(not(feature = "mavlink"))]
pub fn start_receiver(_dma: stm32f4xx_hal::pac::DMA2, _rcc: &mut stm32f4xx_hal::rcc::Rcc) -> Absent {
    Absent
}

/// The ground station's commands for the control tick, taken between ticks (from the control
/// task). Without the ground link there are none, and the slot is never locked.
#[cfg(not(feature = "mavlink"))]
pub fn to_control(_slot: &mut impl rtic::Mutex<T = Option<GroundInput>>, _tick: &mut ControlTick) {}

/// A parameter change for the control tick's half (from the control task, between ticks).
/// Without the ground link nothing changes the configuration: the slot is never locked, and
/// the image holds no code to take a change.
#[cfg(not(feature = "mavlink"))]
pub fn config_to_tick(
    _slot: &mut impl rtic::Mutex<T = Option<ConfigChange>>,
    _outer_slot: &mut impl rtic::Mutex<T = Option<Config>>,
    _tick: &mut ControlTick,
) {
}

/// A parameter change for the outer step's half (from the outer-step task); none without the
/// ground link.
#[cfg(not(feature = "mavlink"))]
pub fn config_to_outer(_slot: &mut impl rtic::Mutex<T = Option<Config>>, _outer: &mut OuterStep) {}

/// A parameter change the ground link accepted, for the control tick's half: taken between
/// ticks, every stage keeping its state, and then passed on to the outer step's half. The tick
/// refuses a ground-only change once changes are restricted (armed since it was asked for):
/// then neither half takes it. Read in place: moving the `Option` out would copy it every tick,
/// change or not.
#[cfg(feature = "mavlink")]
pub fn config_to_tick(
    slot: &mut impl rtic::Mutex<T = Option<ConfigChange>>,
    outer_slot: &mut impl rtic::Mutex<T = Option<Config>>,
    tick: &mut ControlTick,
) {
    let taken = slot.lock(|slot| {
        let taken = slot.as_ref().and_then(|change| tick.take_config(change).is_ok().then_some(change.cfg));
        *slot = None;
        taken
    });
    if let Some(cfg) = taken {
        outer_slot.lock(|slot| *slot = Some(cfg));
    }
}

/// The same change for the outer step's half, before its next step.
#[cfg(feature = "mavlink")]
pub fn config_to_outer(slot: &mut impl rtic::Mutex<T = Option<Config>>, outer: &mut OuterStep) {
    slot.lock(|slot| {
        if let Some(cfg) = slot.as_ref() {
            outer.take_config(cfg);
            *slot = None;
        }
    });
}

/// The ground station's commands for the control tick, taken between ticks (from the control
/// task).
#[cfg(feature = "mavlink")]
pub fn to_control(slot: &mut impl rtic::Mutex<T = Option<GroundInput>>, tick: &mut ControlTick) {
    slot.lock(|slot| {
        if let Some(input) = slot.take() {
            tick.take_ground(&input);
        }
    });
}

#[cfg(not(feature = "mavlink"))]
pub async fn run<U, L, B, T, G, W, M>(_ground: &mut GroundLink, _shared: Shared<U, L, B, T, G, W, M>, _boot: BootVerdict)
where
    U: rtic::Mutex<T = UartOut>,
    L: rtic::Mutex<T = Option<Snapshot>>,
    B: rtic::Mutex<T = u32>,
    T: rtic::Mutex<T = Option<ConfigChange>>,
    G: rtic::Mutex<T = Option<GroundInput>>,
    W: rtic::Mutex<T = Option<Watchdog>>,
    M: rtic::Mutex<T = bool>,
{
}

#[cfg(feature = "mavlink")]
pub use with_link::{load_parameters, run, start_receiver, GroundLink};

#[cfg(feature = "mavlink")]
mod with_link {
    use super::*;
    use crate::param_flash::{FlashError, ParamFlash, SECTORS};
    use crate::uart_rx::UartRx;
    use crate::Mono;
    use fcu_core::telemetry::LineBuf;
    use fcu_gcs::{Due, Observed, Service};
    use fcu_link::{LinkConfig, Severity};
    use fcu_params::snapshot;
    use rtic::Mutex;
    use rtic_monotonics::systick::prelude::*;

    /// Frames the link may hold before the UART queue takes them.
    const LINK_TX_BYTES: usize = 512;
    /// The link's period: 200 Hz, so a parameter download (one value per call) runs at its
    /// 100 Hz and received bytes wait at most 5 ms.
    const LINK_PERIOD_MS: u32 = 5;
    /// How often a fatal boot fault is repeated as a STATUSTEXT.
    const FAULT_REPEAT_MS: u32 = 2000;

    pub struct GroundLink {
        service: Service<LINK_TX_BYTES>,
        uart_rx: UartRx,
        flash: ParamFlash,
    }

    impl GroundLink {
        pub fn new(cfg: Config, defaults: &'static Config, stored: (ParamFlash, snapshot::Source), uart_rx: UartRx) -> Self {
            let (flash, source) = stored;
            GroundLink { service: Service::new(cfg, defaults, source, LinkConfig::DEFAULT), uart_rx, flash }
        }

        /// MAVLink from boot, or text lines until a ground station speaks MAVLink (the link's
        /// protocol parameter).
        pub fn speaks_mavlink_from_boot(&self) -> bool {
            self.service.speaks_mavlink_from_boot()
        }
    }

    /// The parameters saved in flash over the build's defaults, or the defaults alone (and
    /// why, said on the link once it runs): never a mix.
    pub fn load_parameters(flash: stm32f4xx_hal::pac::FLASH, defaults: &'static Config) -> (Config, (ParamFlash, snapshot::Source)) {
        let flash = ParamFlash::new(flash);
        let (cfg, source) = match (flash.sector(0), flash.sector(1)) {
            (Some(a), Some(b)) => snapshot::load_config([a, b], defaults),
            _ => (*defaults, snapshot::Source::NoSnapshot),
        };
        (cfg, (flash, source))
    }

    /// USART1's receiver into the DMA ring. USART1 must be set up with its receiver on.
    pub fn start_receiver(dma: stm32f4xx_hal::pac::DMA2, rcc: &mut stm32f4xx_hal::rcc::Rcc) -> UartRx {
        use stm32f4xx_hal::rcc::Enable;
        stm32f4xx_hal::pac::DMA2::enable(rcc);
        // SAFETY: USART1 belongs to the serial driver `init` set up; the receiver's DMA request
        // (CR3.DMAR) is a bit that driver never touches, set once here before any task runs.
        UartRx::start(dma, unsafe { &*stm32f4xx_hal::pac::USART1::ptr() })
    }

    pub async fn run<U, L, B, T, G, W, M>(g: &mut GroundLink, mut s: Shared<U, L, B, T, G, W, M>, boot: BootVerdict)
    where
        U: Mutex<T = UartOut>,
        L: Mutex<T = Option<Snapshot>>,
        B: Mutex<T = u32>,
        T: Mutex<T = Option<ConfigChange>>,
        G: Mutex<T = Option<GroundInput>>,
        W: Mutex<T = Option<Watchdog>>,
        M: Mutex<T = bool>,
    {
        let mut next_fatal_ms = 0;
        loop {
            let now_ms = Mono::now().duration_since_epoch().as_millis();
            step(g, &mut s, &boot, &mut next_fatal_ms, now_ms);
            Mono::delay(LINK_PERIOD_MS.millis()).await;
        }
    }

    /// One period of the link's work (`fcu_link::service` decides; this moves bytes and
    /// words). A plain function, out of line: the task's future then holds only what lives
    /// across an await, not every local of the link's work.
    #[inline(never)]
    fn step<U, L, B, T, G, W, M>(
        g: &mut GroundLink,
        s: &mut Shared<U, L, B, T, G, W, M>,
        boot: &BootVerdict,
        next_fatal_ms: &mut u32,
        now_ms: u32,
    ) where
        U: Mutex<T = UartOut>,
        L: Mutex<T = Option<Snapshot>>,
        B: Mutex<T = u32>,
        T: Mutex<T = Option<ConfigChange>>,
        G: Mutex<T = Option<GroundInput>>,
        W: Mutex<T = Option<Watchdog>>,
        M: Mutex<T = bool>,
    {
        if let Some(snapshot) = s.latest.lock(Option::take) {
            let battery_mv = s.battery_mv.lock(|mv| *mv);
            let observed = Observed { status: snapshot.status, battery_mv, rc_widths_counts: snapshot.rc_widths_counts };
            g.service.observe(now_ms, &observed);
        }
        let mut bytes = [0u8; 64];
        loop {
            let n = g.uart_rx.take(&mut bytes);
            if n == 0 {
                break;
            }
            g.service.receive(now_ms, bytes.get(..n).unwrap_or_default());
        }
        let heard = g.service.heard();
        if !s.mavlink_on.lock(|on| core::mem::replace(on, *on || heard) || heard) {
            return;
        }
        if !boot.may_fly() && now_ms.wrapping_sub(*next_fatal_ms) as i32 >= 0 {
            *next_fatal_ms = now_ms.wrapping_add(FAULT_REPEAT_MS);
            let mut line = LineBuf::<96>::new();
            let _grounded = boot.write_fatal_line(&mut line);
            // The line is ASCII: an ASCII trim of its bytes keeps the Unicode whitespace table
            // and the UTF-8 check out of flash.
            let _queued = g.service.link_mut().send_text(Severity::Critical, line.as_bytes().trim_ascii_end());
        }
        let to = g.service.period(now_ms);
        if let Some(change) = to.config {
            s.tick_config.lock(|slot| *slot = Some(change));
        }
        // Commands, and the levels of a pending save or reboot (the tick then refuses to arm).
        // One the tick has not taken yet is merged with, not overwritten.
        if let Some(input) = to.ground {
            s.ground_input.lock(|slot| *slot = Some(slot.map_or(input, |older| older.then(input))));
        }
        let service = &mut g.service;
        let uart_idle = s.uart.lock(|uart| {
            let mut out = [0u8; 128];
            let room = uart.room().min(out.len());
            let n = service.poll_tx(out.get_mut(..room).unwrap_or_default());
            uart.send(out.get(..n).unwrap_or_default());
            uart.is_idle()
        });
        // Asked at the instant of acting, and acted on at once.
        match g.service.due(now_ms, uart_idle, crate::supply::vdd_ok_for_flash()) {
            Due::Nothing => {}
            Due::Save => {
                let saved = save_parameters(&g.service, &mut g.flash, &mut s.watchdog);
                g.service.saved(saved.is_ok());
            }
            Due::Reboot => cortex_m::peripheral::SCB::sys_reset(),
        }
    }

    /// Writes the parameters in force to flash as the service plans it: erase a sector if the
    /// plan says so (the watchdog's timeout stretched over it: every fetch stalls meanwhile,
    /// the control tick's included), then the snapshot's words, its commit word last.
    fn save_parameters(
        service: &Service<LINK_TX_BYTES>,
        flash: &mut ParamFlash,
        watchdog: &mut impl Mutex<T = Option<Watchdog>>,
    ) -> Result<(), FlashError> {
        let (Some(a), Some(b)) = (flash.sector(0), flash.sector(1)) else {
            return Err(FlashError::OutOfRange);
        };
        let plan = service.plan_save([a, b]);
        if let Some(sector) = plan.erase {
            watchdog.lock(|w| w.as_mut().map_or(Ok(()), Watchdog::stretch_for_flash)).map_err(|_| FlashError::Timeout)?;
            let erased = flash.erase(sector);
            watchdog.lock(|w| w.as_mut().map_or(Ok(()), Watchdog::restore)).map_err(|_| FlashError::Timeout)?;
            erased?;
        }
        let &(_, base) = SECTORS.get(plan.sector).ok_or(FlashError::OutOfRange)?;
        flash.program(base + 4 * plan.first_word as u32, &plan.words)
    }
}
