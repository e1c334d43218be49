//! The link task: the ground station's link, MAVLink 2 on USART1.
//!
//! Every decision is fcu-gcs', fcu-params' and fcu-core's (`fcu_gcs::station`: the parameter
//! table's rules, what a command may do); this module moves bytes and words. Received bytes come
//! from the DMA ring ([`crate::uart_rx`]); accepted parameter changes and commands (and whether a
//! save runs) go to the control loop through one [`Mailbox`]; saves go to flash
//! ([`crate::param_flash`]) once the changes settle, disarmed. On a board set to text lines it
//! listens, and the first valid MAVLink frame turns the UART to MAVLink.

use crate::app::gcs_link::SharedResources;
use crate::param_flash::{FlashError, ParamFlash, SECTORS};
use crate::uart_rx::UartRx;
use crate::watchdog::Watchdog;
use crate::Mono;
use fcu_core::boot::BootVerdict;
use fcu_core::flight::OuterStep;
use fcu_core::telemetry::LineBuf;
use fcu_core::Config;
use fcu_gcs::{Due, Mailbox, Observed, Service};
use fcu_link::{LinkConfig, Severity};
use fcu_params::snapshot;
use rtic::Mutex;
use rtic_monotonics::systick::prelude::*;

/// Gives the outer step the change the link posted, if there is one.
pub fn config_to_outer(mailbox: &mut impl Mutex<T = Mailbox>, outer: &mut OuterStep) {
    if let Some(cfg) = mailbox.lock(Mailbox::config_for_outer) {
        outer.take_config(&cfg);
    }
}

/// Frames the link may hold before the UART queue takes them.
const LINK_TX_BYTES: usize = 512;
/// The link's period: 200 Hz, so a parameter download (one value per call) runs at its
/// 100 Hz and received bytes wait at most 5 ms.
const LINK_PERIOD_MS: u32 = 5;
/// How often a fatal boot fault is repeated as a STATUSTEXT.
const FAULT_REPEAT_MS: u32 = 2000;

pub struct LinkTask {
    service: Service<LINK_TX_BYTES>,
    uart_rx: UartRx,
    flash: ParamFlash,
}

impl LinkTask {
    pub fn new(cfg: Config, defaults: &'static Config, stored: (ParamFlash, snapshot::Source), uart_rx: UartRx) -> Self {
        let (flash, source) = stored;
        LinkTask { service: Service::new(cfg, defaults, source, LinkConfig::DEFAULT), uart_rx, flash }
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

/// The link task's loop (`app::gcs_link`), with the resources it shares: one period every
/// `LINK_PERIOD_MS`.
pub async fn run(g: &mut LinkTask, mut s: SharedResources<'_>, boot: BootVerdict) {
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
fn step(g: &mut LinkTask, s: &mut SharedResources<'_>, boot: &BootVerdict, next_fatal_ms: &mut u32, now_ms: u32) {
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
    if to.config.is_some() || to.gcs.is_some() {
        s.mailbox.lock(|mailbox| mailbox.post(to.config, to.gcs));
    }
    let service = &mut g.service;
    let uart_idle = s.uart.lock(|uart| {
        // Everything the UART queue has room for, through a small buffer: a tick whose
        // streams all fall due (341 bytes) leaves the link's queue at once, and a request
        // that comes in the next period finds room for its answer beside the telemetry's
        // reserve (`fcu_link::TELEMETRY_RESERVE`).
        let mut out = [0u8; 128];
        loop {
            let room = uart.room().min(out.len());
            let n = service.poll_tx(out.get_mut(..room).unwrap_or_default());
            if n == 0 {
                break;
            }
            uart.send(out.get(..n).unwrap_or_default());
        }
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
