//! USART1's receiver (PA10), its bytes written by DMA2 stream 2 (channel 4, RM0368 §9.3.3,
//! table 28) into a ring in RAM, in circular mode, with no interrupt: the link task reads what
//! has arrived whenever it runs.
//!
//! Why DMA: a parameter save erases a flash sector, and for up to 500 ms every instruction
//! fetch waits, interrupts included; the DMA moves the bytes from USART1 to SRAM without the
//! CPU or the flash, so a ground station's messages sent meanwhile are kept. The ring holds
//! [`RING_BYTES`], more than the line carries in the longest erase (115200 baud: 5,760 bytes
//! in 500 ms), so even a station sending without pause loses nothing to a save.

use core::sync::atomic::{AtomicU8, Ordering};
use stm32f4xx_hal::pac::{usart1, DMA2};

/// The ring's size: 6 KiB, 533 ms of the line at 115200 baud.
pub const RING_BYTES: usize = 6 * 1024;

/// DMA2 stream 2, channel 4: USART1_RX (stream 5 is the other choice; 2 is free).
const STREAM: usize = 2;
const CHANNEL: u8 = 4;
/// Reads of EN after clearing it: one byte transfer is a few bus cycles, far fewer than this.
const EN_READBACK_TRIES: u32 = 1000;

/// The ring, written by the DMA. Atomics: the CPU reads what another bus master wrote, with
/// no `unsafe`.
static RING: [AtomicU8; RING_BYTES] = [const { AtomicU8::new(0) }; RING_BYTES];

pub struct UartRx {
    dma: DMA2,
    /// Where the next unread byte is in the ring.
    read_at: usize,
}

impl UartRx {
    /// Starts the stream and USART1's receive requests. USART1 must be enabled, with RE set,
    /// and DMA2's clock on.
    pub fn start(dma: DMA2, usart: &usart1::RegisterBlock) -> Self {
        // RM0368 §9.3.17, the stream configuration procedure: stream off and EN read back as
        // 0 (a transfer in flight finishes first), flags cleared, addresses and count, then
        // the configuration and EN. After reset the stream is off and EN reads 0 at once; the
        // read-back is bounded so that a stream that never stops cannot hang the boot.
        let stream = dma.st(STREAM);
        stream.cr().write(|w| w.en().clear_bit());
        for _ in 0..EN_READBACK_TRIES {
            if stream.cr().read().en().bit_is_clear() {
                break;
            }
        }
        dma.lifcr().write(|w| w.cfeif2().clear().cdmeif2().clear().cteif2().clear().chtif2().clear().ctcif2().clear());
        let dr = usart.dr().as_ptr() as u32;
        let memory = RING.as_ptr() as u32;
        // SAFETY: the stream reads USART1's data register and writes RING, a static of exactly
        // NDTR bytes that only this module reads; nothing else is given to it.
        unsafe {
            stream.par().write(|w| w.pa().bits(dr));
            stream.m0ar().write(|w| w.m0a().bits(memory));
        }
        stream.ndtr().write(|w| w.ndt().set(RING_BYTES as u16));
        stream.cr().write(|w| w.chsel().set(CHANNEL).dir().peripheral_to_memory().minc().set_bit().circ().set_bit().pl().low());
        stream.cr().modify(|_, w| w.en().set_bit());
        usart.cr3().modify(|_, w| w.dmar().set_bit());
        UartRx { dma, read_at: 0 }
    }

    /// Moves the bytes received since the last call into `out`, in order, as many as fit;
    /// returns how many. If the DMA lapped the reader (more than the ring since the last
    /// call), the oldest bytes are gone: the frame reader finds the next start byte and a CRC
    /// throws out the torn frame.
    pub fn take(&mut self, out: &mut [u8]) -> usize {
        let remaining = usize::from(self.dma.st(STREAM).ndtr().read().ndt().bits());
        // NDTR counts down from RING_BYTES and reloads at 0: the next write goes here.
        let write_at = (RING_BYTES - remaining.min(RING_BYTES)) % RING_BYTES;
        let mut n = 0;
        for slot in out.iter_mut() {
            if self.read_at == write_at {
                break;
            }
            if let Some(b) = RING.get(self.read_at) {
                *slot = b.load(Ordering::Acquire);
            }
            self.read_at = (self.read_at + 1) % RING_BYTES;
            n += 1;
        }
        n
    }
}
