//! SPI2 (0x4000_3800, APB1) as the board uses it: master, 8-bit frames, one bidirectional data
//! line (PB15) shared by three sensors with software chip selects on GPIOs. The model owns the
//! sensors ([`Sensors`]) and moves bytes between the shift register and the selected one.
//!
//! Facts from RM0368 §20 (SPI; the same block as RM0090/RM0402 §28/§26) and the `stm32f4` PAC
//! (`spi1`: CR1, CR2, SR reset 0x0002, DR, CRCPR reset 0x0007, RXCRCR, TXCRCR, I2SCFGR,
//! I2SPR reset 0x000A):
//! - SCK = PCLK1 / 2^(BR+1); a frame is 8 SCK periods (DFF = 0).
//! - Master transmit: a DR write when the shift register is free moves the byte into it at once
//!   (TXE set again) and BSY stays set while shifting; a byte written while one is shifting waits
//!   in the Tx buffer (TXE = 0) and follows back to back.
//! - Receive-only master (BIDIMODE = 1 with BIDIOE = 0, or RXONLY = 1): "the master starts the
//!   sequence immediately when both SPI is enabled and receive-only mode is activated. The clock
//!   signal is provided by the master and it does not stop until either SPI or receive-only mode is
//!   disabled" — it receives one frame every 8 SCK periods. The RM's disable procedure for it
//!   (RM0090 §28.3.8 "Disabling the SPI", the same block as the F401's): wait for the
//!   second-to-last RXNE, then one SCK period, then SPE = 0, then the last RXNE. The window is
//!   enforced at both ends:
//!   - SPE cleared one SCK period or more into a frame: the clock stops at that frame's end, and
//!     the frame is received (the last byte);
//!   - SPE cleared less than one SCK period into a frame: the clock stops before that frame
//!     starts: the last byte never comes ([`Spi2::early_stops`]), and a read waiting for its
//!     RXNE times out;
//!   - SPE cleared after the last wanted frame ended: the next frame has begun and is clocked
//!     whole, an extra byte, overrunning the unread last one (OVR, [`Spi2::overruns`]).
//! - OVR: "an overrun condition occurs when the master … completes the reception of the next data
//!   frame while the read operation of the previous frame from the Rx buffer has not completed
//!   (RXNE set). The Rx buffer is not updated … All other subsequently transmitted data are lost."
//!   Cleared by a DR read followed by an SR read.
//! - MODF: a master whose internal NSS is low (SSM = 1 and SSI = 0) gets MODF set, SPE and MSTR
//!   cleared; cleared by an SR access while MODF is set followed by a CR1 write.
//! - BSY (RM0090 §28.3.7): set while a frame shifts, but in bidirectional receive mode
//!   (BIDIMODE = 1, BIDIOE = 0) it stays low on silicon however the clock runs, so it cannot
//!   tell when the last received frame has ended. Turning the line back to transmit while a
//!   receive frame is still clocked is counted ([`Spi2::mid_frame_turns`]).
//! - Bidirectional transmit (BIDIOE = 1): the receiver is not fed (RXNE/OVR do not follow the
//!   transmitted bytes). The RM only says the procedure is "similar to transmit-only"; ST's own
//!   HAL clears OVR after a transmit only in 2-line mode, which we take as the hardware's
//!   behaviour. In 2-line mode (BIDIMODE = 0) the receiver takes MISO (PB14, not connected: the
//!   undriven value) with every frame.
//!
//! Modelling choices, stated:
//! - A frame's exchange with the sensors happens atomically at its end; a sensor takes part only
//!   if its CS was low for the whole frame.
//! - Clearing BIDIOE (or setting RXONLY) while a transmit frame is shifting stops driving the line
//!   at once: the rest of that byte reaches the sensor as undriven bits
//!   ([`Spi2::truncated_writes`]). Clearing SPE lets the frame finish.
//! - Changing CPOL, CPHA, MSTR, BR, LSBFIRST or BIDIMODE while a frame is in flight is refused
//!   (RM: "should not be changed when communication is ongoing").
//! - DFF = 1, CRC (CRCEN/CRCNEXT), TI frame format (FRF), slave mode, hardware NSS input and I²S
//!   mode are not modelled. RXDMAEN hands each received byte to the DMA stream the board says is
//!   ready for it ([`Spi2::set_dma_budget`]), as the request is served at once; TXDMAEN is
//!   stored only (no transmit request is ever served). RXDMAEN set while a stream already
//!   stands ready is counted ([`Spi2::dma_order_errors`]): RM0368 §20.3.9 enables the stream
//!   after it.

use super::sensors::{Sensors, UNDRIVEN};
use super::{Clocks, Peripheral, Time, Unmodelled, TIME_HZ};

/// SPI2's base address (RM0368 table 1).
pub const BASE: u32 = 0x4000_3800;
const NAME: &str = "SPI2";

pub const CR1: u32 = 0x00;
pub const CR2: u32 = 0x04;
pub const SR: u32 = 0x08;
pub const DR: u32 = 0x0C;
pub const CRCPR: u32 = 0x10;
pub const RXCRCR: u32 = 0x14;
pub const TXCRCR: u32 = 0x18;
pub const I2SCFGR: u32 = 0x1C;
pub const I2SPR: u32 = 0x20;

// CR1 bits (PAC spi1::cr1).
pub const CR1_CPHA: u32 = 1 << 0;
pub const CR1_CPOL: u32 = 1 << 1;
pub const CR1_MSTR: u32 = 1 << 2;
pub const CR1_BR: u32 = 0b111 << 3;
pub const CR1_SPE: u32 = 1 << 6;
pub const CR1_LSBFIRST: u32 = 1 << 7;
pub const CR1_SSI: u32 = 1 << 8;
pub const CR1_SSM: u32 = 1 << 9;
pub const CR1_RXONLY: u32 = 1 << 10;
pub const CR1_DFF: u32 = 1 << 11;
pub const CR1_CRCNEXT: u32 = 1 << 12;
pub const CR1_CRCEN: u32 = 1 << 13;
pub const CR1_BIDIOE: u32 = 1 << 14;
pub const CR1_BIDIMODE: u32 = 1 << 15;

// CR2 bits.
pub const CR2_RXDMAEN: u32 = 1 << 0;
pub const CR2_TXDMAEN: u32 = 1 << 1;
pub const CR2_SSOE: u32 = 1 << 2;
pub const CR2_FRF: u32 = 1 << 4;
pub const CR2_ERRIE: u32 = 1 << 5;
pub const CR2_RXNEIE: u32 = 1 << 6;
pub const CR2_TXEIE: u32 = 1 << 7;

// SR bits.
pub const SR_RXNE: u32 = 1 << 0;
pub const SR_TXE: u32 = 1 << 1;
pub const SR_CHSIDE: u32 = 1 << 2;
pub const SR_UDR: u32 = 1 << 3;
pub const SR_CRCERR: u32 = 1 << 4;
pub const SR_MODF: u32 = 1 << 5;
pub const SR_OVR: u32 = 1 << 6;
pub const SR_BSY: u32 = 1 << 7;
pub const SR_FRE: u32 = 1 << 8;

// I2SCFGR bits.
const I2SCFGR_I2SE: u32 = 1 << 10;
const I2SCFGR_I2SMOD: u32 = 1 << 11;

/// CR1 bits the model implements.
const CR1_MODELLED: u32 =
    CR1_CPHA | CR1_CPOL | CR1_MSTR | CR1_BR | CR1_SPE | CR1_LSBFIRST | CR1_SSI | CR1_SSM | CR1_RXONLY | CR1_BIDIOE | CR1_BIDIMODE;
/// CR1 bits that must not change while a frame is in flight.
const CR1_FRAME_CONFIG: u32 = CR1_CPHA | CR1_CPOL | CR1_MSTR | CR1_BR | CR1_LSBFIRST | CR1_BIDIMODE;

/// Sensors behind the chip selects, in order: LSM6DSL (PA8), LIS2MDL (PB12), LPS22HB (PC13).
pub const CS_NAMES: [&str; 3] = ["LSM6DSL", "LIS2MDL", "LPS22HB"];

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Dir {
    /// The MCU shifts this byte out (as written to DR; LSBFIRST applied at the wire).
    Tx(u8),
    /// Receive-only clocking.
    Rx,
}

#[derive(Clone, Copy, Debug)]
struct Frame {
    start: Time,
    end: Time,
    dir: Dir,
    /// Bits (from the first) the MCU actually drove, when its output was switched off mid-frame.
    driven_bits: Option<u32>,
    /// Chip-select epochs at the start: a sensor whose CS changed during the frame is not part of it.
    epochs: [u64; 3],
}

/// The SPI2 peripheral plus the three sensors on its bus.
#[derive(Clone, Debug)]
pub struct Spi2 {
    cr1: u32,
    cr2: u32,
    crcpr: u32,
    i2scfgr: u32,
    i2spr: u32,
    rx_buf: u8,
    rxne: bool,
    ovr: bool,
    modf: bool,
    crcerr: bool,
    /// DR was read while OVR was set (first half of the OVR clearing sequence).
    ovr_dr_read: bool,
    /// SR was accessed while MODF was set (first half of the MODF clearing sequence).
    modf_sr_seen: bool,
    tx_buf: Option<u8>,
    frame: Option<Frame>,
    pclk1_hz: u64,
    /// The sensors on the bus (public for fault injection and statistics).
    pub sensors: Sensors,
    cs_low: [bool; 3],
    cs_epoch: [u64; 3],
    contentions: u32,
    i2c_exposures: [u32; 3],
    overruns: u32,
    early_stops: u32,
    /// Bytes the DMA may still take, and the ones it took not yet handed over.
    dma_budget: u32,
    dma_bytes: Vec<u8>,
    cut_frames: u32,
    mode_errors: u32,
    truncated_writes: u32,
    mid_frame_turns: u32,
    dma_order_errors: u32,
    frames: u64,
}

impl Default for Spi2 {
    fn default() -> Self {
        Self::new()
    }
}

fn reverse_if(b: u8, lsb_first: bool) -> u8 {
    if lsb_first {
        b.reverse_bits()
    } else {
        b
    }
}

impl Spi2 {
    /// Reset state (PAC reset values), sensors powered on at time 0, chip selects high.
    pub fn new() -> Self {
        Spi2 {
            cr1: 0,
            cr2: 0,
            crcpr: 0x0007,
            i2scfgr: 0,
            i2spr: 0x000A,
            rx_buf: 0,
            rxne: false,
            ovr: false,
            modf: false,
            crcerr: false,
            ovr_dr_read: false,
            modf_sr_seen: false,
            tx_buf: None,
            frame: None,
            pclk1_hz: Clocks::RESET.pclk1_hz,
            sensors: Sensors::new(),
            cs_low: [false; 3],
            cs_epoch: [0; 3],
            contentions: 0,
            i2c_exposures: [0; 3],
            overruns: 0,
            early_stops: 0,
            dma_budget: 0,
            dma_bytes: Vec::new(),
            cut_frames: 0,
            mode_errors: 0,
            truncated_writes: 0,
            mid_frame_turns: 0,
            dma_order_errors: 0,
            frames: 0,
        }
    }

    /// The kernel clock (PCLK1) as `clocks` says; frames started from `now` on use it (the
    /// bus passes the RCC's clocks with every access and [`Spi2::advance`]).
    pub fn set_clocks(&mut self, clocks: Clocks, now: Time) {
        self.step(now);
        self.pclk1_hz = clocks.pclk1_hz;
    }

    /// RCC reset of SPI2 (APB1RSTR.SPI2RST): registers to their reset values, the frame in flight
    /// abandoned. The sensors, chip selects and statistics are the board's and stay.
    pub fn reset_registers(&mut self) {
        let keep = Spi2 {
            sensors: std::mem::take(&mut self.sensors),
            cs_low: self.cs_low,
            cs_epoch: self.cs_epoch,
            contentions: self.contentions,
            i2c_exposures: self.i2c_exposures,
            overruns: self.overruns,
            early_stops: self.early_stops,
            cut_frames: self.cut_frames,
            mode_errors: self.mode_errors,
            truncated_writes: self.truncated_writes,
            mid_frame_turns: self.mid_frame_turns,
            dma_order_errors: self.dma_order_errors,
            frames: self.frames,
            pclk1_hz: self.pclk1_hz,
            ..Spi2::new()
        };
        *self = keep;
    }

    /// The sensors, e.g. to keep them across an MCU reset (they are powered by the board).
    pub fn take_sensors(&mut self) -> Sensors {
        std::mem::take(&mut self.sensors)
    }

    /// Put back sensors taken with [`Spi2::take_sensors`]. A sensor whose chip select this model
    /// sees high (after a reset, all) has its transaction ended.
    pub fn put_sensors(&mut self, sensors: Sensors) {
        self.sensors = sensors;
        for i in 0..3 {
            if !self.cs_low[i] {
                if let Some(d) = self.sensors.device_mut(i) {
                    d.cs_rise(0);
                }
            }
        }
    }

    pub fn sensors(&self) -> &Sensors {
        &self.sensors
    }

    pub fn sensors_mut(&mut self) -> &mut Sensors {
        &mut self.sensors
    }

    /// Time units per SCK period: PCLK1 / 2^(BR+1).
    fn sck_units(&self) -> u64 {
        let br = (self.cr1 & CR1_BR) >> 3;
        let pclk = TIME_HZ.checked_div(self.pclk1_hz).unwrap_or(1).max(1);
        pclk << (br + 1)
    }

    fn frame_units(&self) -> u64 {
        8 * self.sck_units()
    }

    /// The configuration transmits DR writes (as opposed to receive-only clocking).
    fn transmit_mode(cr1: u32) -> bool {
        if cr1 & CR1_BIDIMODE != 0 {
            cr1 & CR1_BIDIOE != 0
        } else {
            cr1 & CR1_RXONLY == 0
        }
    }

    /// The MCU drives the shared data line (PB15) with this configuration.
    fn mcu_drives(cr1: u32) -> bool {
        cr1 & (CR1_SPE | CR1_MSTR) == (CR1_SPE | CR1_MSTR) && Self::transmit_mode(cr1)
    }

    /// Receive-only clocking runs with this configuration.
    fn rx_clocking(cr1: u32) -> bool {
        cr1 & (CR1_SPE | CR1_MSTR) == (CR1_SPE | CR1_MSTR) && !Self::transmit_mode(cr1)
    }

    /// Tell the model the chip-select levels (true = low = selected):
    /// [LSM6DSL on PA8, LIS2MDL on PB12, LPS22HB on PC13].
    pub fn set_chip_selects(&mut self, cs_low: [bool; 3], now: Time) {
        self.step(now);
        for (i, &low) in cs_low.iter().enumerate() {
            if low == self.cs_low[i] {
                continue;
            }
            if !low && self.frame.is_some_and(|f| f.dir == Dir::Rx && f.epochs[i] == self.cs_epoch[i]) {
                // Deselected while the receive clock still runs: a byte past the last one read.
                self.cut_frames += 1;
            }
            self.cs_low[i] = low;
            self.cs_epoch[i] += 1;
            if let Some(dev) = self.sensors.device_mut(i) {
                if low {
                    dev.cs_fall(now);
                } else {
                    dev.cs_rise(now);
                }
            }
        }
    }

    /// The chip-select levels last given (true = low).
    pub fn chip_selects(&self) -> [bool; 3] {
        self.cs_low
    }

    /// Whether a selected sensor is driving the data line at `now`.
    fn sensor_driving(&self, now: Time) -> bool {
        (0..3).any(|i| {
            self.cs_low[i]
                && self.sensors.device(i).is_some_and(|d| {
                    d.holds_line(now) || (self.frame.is_some_and(|f| f.epochs[i] == self.cs_epoch[i]) && d.output(now).is_some())
                })
        })
    }

    fn start_frame(&mut self, start: Time, dir: Dir) {
        let end = start + self.frame_units();
        self.frame = Some(Frame { start, end, dir, driven_bits: None, epochs: self.cs_epoch });
    }

    /// After a frame or a configuration change: start the next frame at `t` if one is due.
    fn maybe_start(&mut self, t: Time) {
        if self.frame.is_some() {
            return;
        }
        if Self::mcu_drives(self.cr1) {
            if let Some(b) = self.tx_buf.take() {
                self.start_frame(t, Dir::Tx(b));
            }
        } else if Self::rx_clocking(self.cr1) {
            self.start_frame(t, Dir::Rx);
        }
    }

    fn push_rx(&mut self, v: u8) {
        if self.cr2 & CR2_RXDMAEN != 0 && self.dma_budget > 0 && !self.rxne {
            // RXNE raises a DMA request (RM0368 §20.3.9, "SPI communication using DMA"): the
            // stream reads DR at once, so RXNE never shows.
            self.dma_budget -= 1;
            self.dma_bytes.push(v);
            return;
        }
        if self.rxne || self.ovr {
            self.ovr = true;
            self.overruns += 1;
        } else {
            self.rx_buf = v;
            self.rxne = true;
        }
    }

    fn complete(&mut self, f: Frame) {
        let t = f.end;
        self.frames += 1;
        let lsb_first = self.cr1 & CR1_LSBFIRST != 0;
        let mcu_out = match f.dir {
            Dir::Tx(b) => {
                let wire = reverse_if(b, lsb_first);
                Some(match f.driven_bits {
                    // The undriven remainder reads as UNDRIVEN's bits.
                    Some(n) if n < 8 => {
                        let keep = !(0xFFu8.checked_shr(n).unwrap_or(0));
                        (wire & keep) | (UNDRIVEN & !keep)
                    }
                    _ => wire,
                })
            }
            Dir::Rx => None,
        };
        let selected: [bool; 3] = std::array::from_fn(|i| self.cs_low[i] && f.epochs[i] == self.cs_epoch[i]);
        let outs: [Option<u8>; 3] =
            std::array::from_fn(|i| if selected[i] { self.sensors.device(i).and_then(|d| d.output(t)) } else { None });
        let drivers = usize::from(mcu_out.is_some()) + outs.iter().flatten().count();
        if drivers >= 2 {
            self.contentions += 1;
        }
        let line = mcu_out.or(outs.iter().flatten().next().copied());
        if selected.iter().any(|&s| s) && (self.cr1 & CR1_CPOL != 0) != (self.cr1 & CR1_CPHA != 0) {
            // ST sensors sample on SCK rising edges: SPI modes 0 and 3 only.
            self.mode_errors += 1;
        }
        for (i, &sel) in selected.iter().enumerate() {
            if let Some(dev) = self.sensors.device_mut(i) {
                if sel {
                    dev.clock(line.unwrap_or(UNDRIVEN), t);
                } else if dev.i2c_enabled() {
                    self.i2c_exposures[i] += 1;
                }
            }
        }
        // What the MCU's receiver gets.
        if self.cr1 & CR1_BIDIMODE != 0 {
            if f.dir == Dir::Rx {
                self.push_rx(reverse_if(line.unwrap_or(UNDRIVEN), lsb_first));
            }
        } else {
            // 2-line mode: the receiver samples MISO (PB14), which nothing drives on this board.
            self.push_rx(UNDRIVEN);
        }
    }

    /// Bring the bus up to `now` (finish the frames that ended, start the ones that follow), then
    /// take the kernel clock of `clocks` for the frames to come.
    pub fn advance(&mut self, now: Time, clocks: Clocks) {
        self.set_clocks(clocks, now);
    }

    /// Bring the bus up to `now`.
    fn step(&mut self, now: Time) {
        while let Some(f) = self.frame {
            if f.end > now {
                break;
            }
            // Fast path: receive-only clocking with nobody selected only counts frames.
            if f.dir == Dir::Rx && !self.cs_low.iter().any(|&l| l) && Self::rx_clocking(self.cr1) {
                let unit = self.frame_units();
                let n = (now - f.start) / unit;
                if n > 1 {
                    let skip = n - 1;
                    for i in 0..3 {
                        if self.sensors.device(i).is_some_and(|d| d.i2c_enabled()) {
                            self.i2c_exposures[i] = self.i2c_exposures[i].saturating_add(skip.min(u64::from(u32::MAX)) as u32);
                        }
                    }
                    // Nobody drives the line (bidirectional) or MISO (2-line): undriven frames.
                    let v = reverse_if(UNDRIVEN, self.cr1 & CR1_LSBFIRST != 0 && self.cr1 & CR1_BIDIMODE != 0);
                    for _ in 0..skip.min(2) {
                        self.push_rx(v);
                    }
                    if skip > 2 {
                        self.overruns = self.overruns.saturating_add((skip - 2).min(u64::from(u32::MAX)) as u32);
                    }
                    self.frames += skip;
                    let start = f.start + skip * unit;
                    self.frame = Some(Frame { start, end: start + unit, ..f });
                    continue;
                }
            }
            self.frame = None;
            self.complete(f);
            self.maybe_start(f.end);
        }
    }

    /// The interrupt line: (RXNEIE and RXNE) or (TXEIE and TXE) or (ERRIE and an error flag).
    pub fn irq_line(&self) -> bool {
        (self.cr2 & CR2_RXNEIE != 0 && self.rxne)
            || (self.cr2 & CR2_TXEIE != 0 && self.tx_buf.is_none())
            || (self.cr2 & CR2_ERRIE != 0 && (self.ovr || self.modf || self.crcerr))
    }

    /// The end of the frame in flight, when an interrupt is enabled (the line can only change
    /// by itself at a frame's end).
    pub fn next_event(&self) -> Option<Time> {
        let dma = self.cr2 & CR2_RXDMAEN != 0 && self.dma_budget > 0;
        if self.cr2 & (CR2_RXNEIE | CR2_TXEIE | CR2_ERRIE) == 0 && !dma {
            return None;
        }
        self.frame.map(|f| f.end)
    }

    /// How many received bytes a DMA stream takes from now on (its NDTR, 0 when none is
    /// enabled for SPI2_RX); the board keeps it current.
    pub fn set_dma_budget(&mut self, bytes: u32) {
        self.dma_budget = bytes;
    }

    /// The received bytes the DMA took since the last call, in order.
    pub fn take_dma_bytes(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.dma_bytes)
    }

    fn sr_value(&self) -> u32 {
        let mut v = 0;
        if self.rxne {
            v |= SR_RXNE;
        }
        if self.tx_buf.is_none() {
            v |= SR_TXE;
        }
        if self.crcerr {
            v |= SR_CRCERR;
        }
        if self.modf {
            v |= SR_MODF;
        }
        if self.ovr {
            v |= SR_OVR;
        }
        if self.frame.is_some() && !Self::bidi_receive(self.cr1) {
            v |= SR_BSY;
        }
        v
    }

    /// Bidirectional receive mode (BIDIMODE = 1, BIDIOE = 0), where BSY stays low on silicon
    /// while frames are clocked (RM0090 §28.3.7, the F401's SPI block).
    fn bidi_receive(cr1: u32) -> bool {
        cr1 & CR1_BIDIMODE != 0 && cr1 & CR1_BIDIOE == 0
    }

    /// A 32-bit read at `offset`; `clocks` are the RCC's now (PCLK1 times the frames).
    pub fn read(&mut self, offset: u32, now: Time, clocks: Clocks) -> Result<u32, Unmodelled> {
        self.set_clocks(clocks, now);
        Ok(match offset {
            CR1 => self.cr1,
            CR2 => self.cr2,
            SR => {
                let v = self.sr_value();
                if self.ovr && self.ovr_dr_read {
                    self.ovr = false;
                    self.ovr_dr_read = false;
                }
                if self.modf {
                    self.modf_sr_seen = true;
                }
                v
            }
            DR => {
                self.rxne = false;
                if self.ovr {
                    self.ovr_dr_read = true;
                }
                u32::from(self.rx_buf)
            }
            CRCPR => self.crcpr,
            // CRC is never enabled (CRCEN refused), so both CRC registers keep their reset value.
            RXCRCR | TXCRCR => 0,
            I2SCFGR => self.i2scfgr,
            I2SPR => self.i2spr,
            _ => return Err(Unmodelled::offset(NAME, offset, false)),
        })
    }

    /// A 32-bit write at `offset`; `clocks` are the RCC's now.
    pub fn write(&mut self, offset: u32, value: u32, now: Time, clocks: Clocks) -> Result<(), Unmodelled> {
        self.set_clocks(clocks, now);
        match offset {
            CR1 => self.write_cr1(value, now),
            CR2 => {
                Unmodelled::check_bits("SPI2.CR2", value, CR2_RXDMAEN | CR2_TXDMAEN | CR2_SSOE | CR2_ERRIE | CR2_RXNEIE | CR2_TXEIE)?;
                if value & !self.cr2 & CR2_RXDMAEN != 0 && self.dma_budget > 0 {
                    // RM0368 §20.3.9: RXDMAEN first, then the stream, then SPE.
                    self.dma_order_errors += 1;
                }
                self.cr2 = value;
                Ok(())
            }
            SR => {
                // Only CRCERR is writable (rc_w0); the other flags are read-only.
                if value & SR_CRCERR == 0 {
                    self.crcerr = false;
                }
                if self.modf {
                    self.modf_sr_seen = true;
                }
                Ok(())
            }
            DR => {
                // 8-bit frames (DFF = 1 is refused): only DR[7:0] is sent.
                let b = (value & 0xFF) as u8;
                // A write when TXE = 0 overwrites the Tx buffer (software must wait for TXE).
                self.tx_buf = Some(b);
                self.maybe_start(now);
                Ok(())
            }
            CRCPR => {
                Unmodelled::check_bits("SPI2.CRCPR", value, 0xFFFF)?;
                self.crcpr = value;
                Ok(())
            }
            RXCRCR | TXCRCR => Ok(()), // read-only
            I2SCFGR => {
                // SPI mode only: I2SMOD and I2SE refused, the I2S configuration fields are stored.
                Unmodelled::check_bits("SPI2.I2SCFGR", value, 0x0FFF & !(I2SCFGR_I2SMOD | I2SCFGR_I2SE))?;
                self.i2scfgr = value;
                Ok(())
            }
            I2SPR => {
                Unmodelled::check_bits("SPI2.I2SPR", value, 0x03FF)?;
                self.i2spr = value;
                Ok(())
            }
            _ => Err(Unmodelled::offset(NAME, offset, true)),
        }
    }

    fn write_cr1(&mut self, value: u32, now: Time) -> Result<(), Unmodelled> {
        Unmodelled::check_bits("SPI2.CR1", value, CR1_MODELLED)?;
        let mut value = value;
        if self.modf {
            if self.modf_sr_seen {
                // Second half of the clearing sequence: MSTR and SPE may be set again by this write.
                self.modf = false;
                self.modf_sr_seen = false;
            } else {
                value &= !(CR1_SPE | CR1_MSTR);
            }
        }
        if self.frame.is_some() && (value ^ self.cr1) & CR1_FRAME_CONFIG != 0 {
            return Err(Unmodelled::new(
                "SPI2.CR1",
                format!("write of {value:#06x} changes the frame configuration (CPOL/CPHA/MSTR/BR/LSBFIRST/BIDIMODE) while a frame is in flight"),
            ));
        }
        if value & CR1_MSTR != 0 {
            if value & CR1_SSM != 0 {
                if value & CR1_SSI == 0 {
                    // Master with internal NSS low: mode fault.
                    self.modf = true;
                    self.modf_sr_seen = false;
                    value &= !(CR1_SPE | CR1_MSTR);
                }
            } else if self.cr2 & CR2_SSOE == 0 && value & CR1_SPE != 0 {
                return Err(Unmodelled::new("SPI2.CR1", "master with hardware NSS input (SSM = 0, SSOE = 0): the NSS pin is not modelled"));
            }
        } else if value & CR1_SPE != 0 {
            return Err(Unmodelled::new("SPI2.CR1", format!("write of {value:#06x} enables the SPI in slave mode, not modelled")));
        }

        let old = self.cr1;
        if Self::rx_clocking(old) && !Self::rx_clocking(value) {
            let sck = self.sck_units();
            if self.frame.is_some_and(|f| f.dir == Dir::Rx && now.saturating_sub(f.start) < sck) {
                // Stopped within the frame's first SCK period: it is never clocked.
                self.frame = None;
                self.early_stops += 1;
            }
        }
        let drove = Self::mcu_drives(old);
        self.cr1 = value;
        let drives = Self::mcu_drives(value);

        if let Some(f) = self.frame.as_mut() {
            if matches!(f.dir, Dir::Tx(_)) && !Self::transmit_mode(value) && f.driven_bits.is_none() {
                // Output switched off mid-byte: the rest of the byte is not driven.
                let sck = ((f.end - f.start) / 8).max(1);
                let bits = ((now.saturating_sub(f.start)) / sck).min(8) as u32;
                if bits < 8 {
                    f.driven_bits = Some(bits);
                    self.truncated_writes += 1;
                }
            }
        }
        if Self::bidi_receive(old) && !Self::bidi_receive(value) && self.frame.is_some_and(|f| f.dir == Dir::Rx) {
            // The MCU takes the line back while a received byte is still being clocked.
            self.mid_frame_turns += 1;
        }
        if !drove && drives && self.sensor_driving(now) {
            self.contentions += 1;
        }
        self.maybe_start(now);
        Ok(())
    }

    /// Times the MCU put its output on the data line (or transmitted) while a selected sensor was
    /// driving it, plus frames in which two or more devices drove the line.
    pub fn contentions(&self) -> u32 {
        self.contentions
    }

    /// Frames clocked on the bus while each sensor's CS was high and its I²C interface enabled,
    /// in chip-select order [LSM6DSL, LIS2MDL, LPS22HB].
    pub fn i2c_exposures(&self) -> [u32; 3] {
        self.i2c_exposures
    }

    /// Received frames lost because RXNE or OVR was still set.
    pub fn overruns(&self) -> u32 {
        self.overruns
    }

    /// Receive-only clocking stopped less than one SCK period into a frame: a last byte that
    /// never came (the end-of-read window's early side).
    pub fn early_stops(&self) -> u32 {
        self.early_stops
    }

    /// Receive frames still being clocked when their sensor's chip select went high: SPE was
    /// cleared late, and an extra byte was clocked past the last one read (the end-of-read
    /// window's late side, as a firmware that deselects right after its last byte shows it).
    pub fn cut_frames(&self) -> u32 {
        self.cut_frames
    }

    /// Frames exchanged with a selected sensor in SPI mode 1 or 2 (the sensors need 0 or 3).
    pub fn mode_errors(&self) -> u32 {
        self.mode_errors
    }

    /// Transmit frames whose output was switched off (BIDIOE cleared) before their last bit.
    pub fn truncated_writes(&self) -> u32 {
        self.truncated_writes
    }

    /// Times the line was turned back to transmit (BIDIOE set) while a receive frame was still
    /// being clocked: on silicon BSY does not show that frame, so a firmware that waits on BSY
    /// before the turn does it mid-byte.
    pub fn mid_frame_turns(&self) -> u32 {
        self.mid_frame_turns
    }

    /// Times RXDMAEN was set while a DMA stream already stood ready for SPI2_RX: the order of
    /// RM0368 §20.3.9 ("SPI communication using DMA") is RXDMAEN, then the stream, then SPE.
    pub fn dma_order_errors(&self) -> u32 {
        self.dma_order_errors
    }

    /// Frames clocked since reset.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Whether a frame is being shifted (SR.BSY).
    pub fn busy(&self) -> bool {
        self.frame.is_some()
    }
}

impl Peripheral for Spi2 {
    fn read(&mut self, offset: u32, now: Time, clocks: Clocks) -> Result<u32, Unmodelled> {
        Spi2::read(self, offset, now, clocks)
    }

    fn write(&mut self, offset: u32, value: u32, now: Time, clocks: Clocks) -> Result<(), Unmodelled> {
        Spi2::write(self, offset, value, now, clocks)
    }

    fn next_event(&self) -> Option<Time> {
        Spi2::next_event(self)
    }

    fn advance(&mut self, now: Time, clocks: Clocks) {
        Spi2::advance(self, now, clocks)
    }

    fn irq_line(&self, _line: usize) -> bool {
        Spi2::irq_line(self)
    }

    fn reset(&mut self) {
        self.reset_registers();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::periph::sensors::{Sensor, LPS22HB_BOOT, UNDRIVEN};

    /// After every sensor's boot.
    const T0: Time = 50 * (TIME_HZ / 1000);
    /// PCLK1 42 MHz = 8 units; BR = 011 → /16 → 128 units per SCK; 1024 per byte.
    const BYTE: Time = 1024;

    impl Spi2 {
        fn advance_to(&mut self, now: Time) {
            self.advance(now, Clocks::PLL_84_MHZ);
        }
    }

    /// A test driver doing what a correct firmware does, advancing time as it goes.
    struct Fw {
        spi: Spi2,
        t: Time,
    }

    impl Fw {
        /// The register sequence of stm32f4xx-hal 0.23 `Spi::new_bidi` (mode 3, 2.625 MHz).
        fn new() -> Self {
            let mut spi = Spi2::new();
            spi.set_clocks(Clocks::PLL_84_MHZ, 0);
            let mut fw = Fw { spi, t: T0 };
            fw.w(CR2, 0);
            fw.w(CR1, CR1_CPHA | CR1_CPOL | CR1_MSTR | (0b011 << 3) | CR1_SSM | CR1_SSI);
            let cr1 = fw.r(CR1);
            fw.w(CR1, cr1 | CR1_BIDIMODE | CR1_BIDIOE | CR1_SPE);
            fw
        }
        fn w(&mut self, off: u32, v: u32) {
            self.t += 8;
            self.spi.write(off, v, self.t, Clocks::PLL_84_MHZ).unwrap();
        }
        fn r(&mut self, off: u32) -> u32 {
            self.t += 8;
            self.spi.read(off, self.t, Clocks::PLL_84_MHZ).unwrap()
        }
        fn cs(&mut self, i: usize, low: bool) {
            self.t += 8;
            let mut c = self.spi.chip_selects();
            c[i] = low;
            self.spi.set_chip_selects(c, self.t);
        }
        fn wait(&mut self, mask: u32, set: bool) {
            for _ in 0..10_000 {
                if (self.r(SR) & mask != 0) == set {
                    return;
                }
            }
            panic!("SR {mask:#x} never became {set}");
        }
        fn send(&mut self, bytes: &[u8]) {
            for &b in bytes {
                self.wait(SR_TXE, true);
                self.w(DR, u32::from(b));
            }
            self.wait(SR_BSY, false);
        }
        fn write_reg(&mut self, i: usize, addr: u8, data: &[u8]) {
            self.cs(i, true);
            let mut bytes = vec![addr];
            bytes.extend_from_slice(data);
            self.send(&bytes);
            self.cs(i, false);
        }
        /// 3-wire read: address out, then receive-only clocking, SPE cleared during the last byte.
        fn read_reg(&mut self, i: usize, addr: u8, n: usize) -> Vec<u8> {
            self.cs(i, true);
            self.send(&[addr | 0x80]);
            let cr1 = self.r(CR1);
            self.w(CR1, cr1 & !CR1_BIDIOE);
            let mut out = Vec::new();
            for k in 0..n {
                if k == n - 1 {
                    // RM: after the second-to-last RXNE, one SCK later, disable.
                    self.t += 128;
                    let cr1 = self.r(CR1);
                    self.w(CR1, cr1 & !CR1_SPE);
                }
                self.wait(SR_RXNE, true);
                out.push(self.r(DR) as u8);
            }
            self.wait(SR_BSY, false);
            self.cs(i, false);
            let cr1 = self.r(CR1);
            self.w(CR1, cr1 | CR1_BIDIOE | CR1_SPE);
            out
        }
    }

    #[test]
    fn reset_values_are_the_pacs() {
        let mut s = Spi2::new();
        assert_eq!(s.read(SR, 0, Clocks::PLL_84_MHZ), Ok(0x0002));
        assert_eq!(s.read(CRCPR, 0, Clocks::PLL_84_MHZ), Ok(0x0007));
        assert_eq!(s.read(I2SPR, 0, Clocks::PLL_84_MHZ), Ok(0x000A));
        assert_eq!(s.read(CR1, 0, Clocks::PLL_84_MHZ), Ok(0));
        assert!(s.read(0x24, 0, Clocks::PLL_84_MHZ).is_err());
    }

    #[test]
    fn a_byte_takes_8_sck_periods_of_pclk1_over_2_pow_br_plus_1() {
        let mut fw = Fw::new();
        let t = fw.t;
        fw.spi.write(DR, 0x12, t, Clocks::PLL_84_MHZ).unwrap();
        assert_eq!(
            fw.spi.read(SR, t, Clocks::PLL_84_MHZ).unwrap() & (SR_TXE | SR_BSY),
            SR_TXE | SR_BSY,
            "moved to the shift register at once"
        );
        fw.spi.write(DR, 0x34, t, Clocks::PLL_84_MHZ).unwrap();
        assert_eq!(fw.spi.read(SR, t, Clocks::PLL_84_MHZ).unwrap() & SR_TXE, 0, "second byte waits in the Tx buffer");
        assert_eq!(fw.spi.read(SR, t + BYTE - 1, Clocks::PLL_84_MHZ).unwrap() & SR_TXE, 0);
        assert_eq!(fw.spi.read(SR, t + BYTE, Clocks::PLL_84_MHZ).unwrap() & (SR_TXE | SR_BSY), SR_TXE | SR_BSY);
        assert_eq!(fw.spi.read(SR, t + 2 * BYTE, Clocks::PLL_84_MHZ).unwrap() & SR_BSY, 0);
        assert_eq!(fw.spi.read(SR, t + 2 * BYTE, Clocks::PLL_84_MHZ).unwrap() & SR_RXNE, 0, "bidi transmit does not feed the receiver");
        assert_eq!(fw.spi.frames(), 2);
    }

    #[test]
    fn hal_new_bidi_sequence_is_accepted_and_leaves_the_line_driven() {
        let fw = Fw::new();
        assert_eq!(fw.spi.cr1 & (CR1_BIDIMODE | CR1_BIDIOE | CR1_SPE | CR1_MSTR), CR1_BIDIMODE | CR1_BIDIOE | CR1_SPE | CR1_MSTR);
        assert!(!fw.spi.busy());
    }

    #[test]
    fn ssi_low_in_master_mode_is_a_mode_fault() {
        let mut s = Spi2::new();
        s.write(CR1, CR1_MSTR | CR1_SSM | CR1_SPE, 10, Clocks::PLL_84_MHZ).unwrap();
        assert_eq!(s.read(CR1, 11, Clocks::PLL_84_MHZ).unwrap() & (CR1_MSTR | CR1_SPE), 0, "MSTR and SPE cleared");
        assert_ne!(s.read(SR, 12, Clocks::PLL_84_MHZ).unwrap() & SR_MODF, 0);
        s.write(CR1, CR1_MSTR | CR1_SSM | CR1_SSI, 13, Clocks::PLL_84_MHZ).unwrap();
        assert_eq!(s.read(SR, 14, Clocks::PLL_84_MHZ).unwrap() & SR_MODF, 0, "SR read then CR1 write clears MODF");
        assert_ne!(s.read(CR1, 15, Clocks::PLL_84_MHZ).unwrap() & CR1_MSTR, 0);
    }

    #[test]
    fn unmodelled_bits_are_refused() {
        let mut s = Spi2::new();
        assert!(s.write(CR1, CR1_DFF, 0, Clocks::PLL_84_MHZ).is_err());
        assert!(s.write(CR1, CR1_CRCEN, 0, Clocks::PLL_84_MHZ).is_err());
        assert!(s.write(CR2, CR2_FRF, 0, Clocks::PLL_84_MHZ).is_err());
        assert!(s.write(I2SCFGR, I2SCFGR_I2SMOD, 0, Clocks::PLL_84_MHZ).is_err());
        assert!(s.write(CR1, CR1_SPE, 0, Clocks::PLL_84_MHZ).is_err(), "slave mode");
    }

    #[test]
    fn three_wire_who_am_i_read_through_the_bus() {
        let mut fw = Fw::new();
        fw.write_reg(0, 0x12, &[0x0C]);
        assert_eq!(fw.read_reg(0, 0x0F, 1), [0x6A]);
        fw.write_reg(2, 0x10, &[0x01]);
        assert_eq!(fw.read_reg(2, 0x0F, 1), [0xB1]);
        assert_eq!(fw.read_reg(1, 0x4F, 1), [0x40]);
        assert_eq!(fw.spi.contentions(), 0);
        assert_eq!(fw.spi.overruns(), 0);
        assert_eq!(fw.spi.sensors.unexpected_writes(), 0);
        assert_eq!(fw.spi.truncated_writes(), 0);
    }

    #[test]
    fn a_read_in_4_wire_mode_returns_the_undriven_value() {
        let mut fw = Fw::new();
        assert_eq!(fw.read_reg(0, 0x0F, 1), [UNDRIVEN]);
    }

    #[test]
    fn write_then_read_back_and_a_12_byte_burst() {
        let mut fw = Fw::new();
        fw.write_reg(0, 0x12, &[0x4C]);
        fw.write_reg(0, 0x10, &[0xA8, 0x6C]);
        assert_eq!(fw.read_reg(0, 0x10, 3), [0xA8, 0x6C, 0x4C]);
        fw.spi.sensors.lsm6dsl.set_output([1, -1, i16::MIN], [0x1234, i16::MAX, -1008]);
        let got = fw.read_reg(0, 0x22, 12);
        assert_eq!(got, [0x01, 0x00, 0xFF, 0xFF, 0x00, 0x80, 0x34, 0x12, 0xFF, 0x7F, 0x10, 0xFC]);
        assert_eq!(fw.spi.sensors.lsm6dsl.reads(), 1);
        assert_eq!(fw.spi.overruns(), 0);
    }

    #[test]
    fn receive_only_clock_runs_continuously_and_overruns_when_dr_is_not_read() {
        let mut fw = Fw::new();
        fw.write_reg(0, 0x12, &[0x0C]);
        fw.cs(0, true);
        fw.send(&[0x8F]);
        let t = fw.t;
        fw.spi.write(CR1, fw.spi.cr1 & !CR1_BIDIOE, t, Clocks::PLL_84_MHZ).unwrap();
        assert_eq!(fw.spi.read(SR, t + BYTE - 1, Clocks::PLL_84_MHZ).unwrap() & SR_RXNE, 0);
        assert_ne!(fw.spi.read(SR, t + BYTE, Clocks::PLL_84_MHZ).unwrap() & (SR_RXNE | SR_BSY), 0, "first byte in, clock still running");
        assert_eq!(fw.spi.read(SR, t + 2 * BYTE, Clocks::PLL_84_MHZ).unwrap() & SR_OVR, SR_OVR);
        fw.spi.advance_to(t + 5 * BYTE);
        assert_eq!(fw.spi.overruns(), 4, "bytes 2..5 lost");
        assert_eq!(fw.spi.read(DR, t + 5 * BYTE + 1, Clocks::PLL_84_MHZ).unwrap(), 0x6A, "DR keeps the first byte");
        assert_eq!(fw.spi.read(SR, t + 5 * BYTE + 2, Clocks::PLL_84_MHZ).unwrap() & SR_OVR, SR_OVR, "this read clears OVR");
        assert_eq!(fw.spi.read(SR, t + 5 * BYTE + 3, Clocks::PLL_84_MHZ).unwrap() & SR_OVR, 0);
    }

    #[test]
    fn clearing_spe_mid_byte_finishes_that_byte_and_stops_the_clock() {
        let mut fw = Fw::new();
        fw.write_reg(0, 0x12, &[0x0C]);
        fw.cs(0, true);
        fw.send(&[0x8F]);
        let t = fw.t;
        fw.spi.write(CR1, fw.spi.cr1 & !CR1_BIDIOE, t, Clocks::PLL_84_MHZ).unwrap();
        fw.spi.write(CR1, fw.spi.cr1 & !CR1_SPE, t + BYTE / 2, Clocks::PLL_84_MHZ).unwrap();
        assert!(fw.spi.busy(), "still shifting");
        assert_eq!(fw.spi.read(SR, t + BYTE - 1, Clocks::PLL_84_MHZ).unwrap() & (SR_RXNE | SR_BSY), 0, "BSY stays low in receive");
        let sr = fw.spi.read(SR, t + BYTE, Clocks::PLL_84_MHZ).unwrap();
        assert_eq!(sr & (SR_RXNE | SR_BSY), SR_RXNE, "byte received, clock stopped");
        assert!(!fw.spi.busy());
        assert_eq!(fw.spi.read(DR, t + BYTE + 1, Clocks::PLL_84_MHZ).unwrap(), 0x6A);
        fw.spi.advance_to(t + 10 * BYTE);
        assert_eq!(fw.spi.frames(), 4, "0x12, 0x0C, the address, one received byte, no more");
    }

    /// A 12-byte receive (the IMU burst after its address) as the firmware does it: SPE
    /// cleared `after` time units after the 11th RXNE is seen, then the last RXNE awaited and
    /// read `read_delay` later. (bytes received, frames clocked in the receive, early stops,
    /// overruns).
    fn burst_stopped(after: Time, read_delay: Time) -> (Vec<u8>, u64, u32, u32) {
        let mut fw = Fw::new();
        fw.write_reg(0, 0x12, &[0x0C]);
        fw.cs(0, true);
        fw.send(&[0x22 | 0x80]);
        let frames_before = fw.spi.frames();
        let cr1 = fw.r(CR1);
        fw.w(CR1, cr1 & !CR1_BIDIOE);
        let mut out = Vec::new();
        for _ in 0..11 {
            fw.wait(SR_RXNE, true);
            out.push(fw.r(DR) as u8);
        }
        let seen = fw.t;
        fw.spi.write(CR1, fw.spi.cr1 & !CR1_SPE, seen + after, Clocks::PLL_84_MHZ).unwrap();
        fw.t = seen + after + read_delay;
        for _ in 0..1000 {
            if fw.r(SR) & SR_RXNE != 0 {
                out.push(fw.r(DR) as u8);
                break;
            }
        }
        fw.spi.advance_to(fw.t + 10 * BYTE);
        (out, fw.spi.frames() - frames_before, fw.spi.early_stops(), fw.spi.overruns())
    }

    /// Deselects right after reading the 12th byte of a burst whose SPE was cleared a byte
    /// late: how many frames the chip select cut.
    fn fw_cut_after_late_stop() -> u32 {
        let mut fw = Fw::new();
        fw.cs(0, true);
        fw.send(&[0x22 | 0x80]);
        let cr1 = fw.r(CR1);
        fw.w(CR1, cr1 & !CR1_BIDIOE);
        for _ in 0..11 {
            fw.wait(SR_RXNE, true);
            fw.r(DR);
        }
        fw.t += BYTE + 200;
        let cr1 = fw.r(CR1);
        fw.w(CR1, cr1 & !CR1_SPE);
        fw.wait(SR_RXNE, true);
        fw.r(DR);
        fw.cs(0, false);
        fw.spi.cut_frames()
    }

    /// Rule (RM0090 §28.3.8): after the second-to-last RXNE, wait one SCK period before
    /// clearing SPE. The wrong sequence, clearing it at once, loses the last byte.
    #[test]
    fn clearing_spe_within_one_sck_of_the_second_to_last_rxne_loses_the_last_byte() {
        let (bytes, frames, early, overruns) = burst_stopped(0, 0);
        assert_eq!(bytes.len(), 11, "the 12th byte never comes");
        assert_eq!((frames, early, overruns), (11, 1, 0));
    }

    /// Inside the window (one SCK period up to the end of the last byte) the read is whole
    /// and the clock stops on its last byte.
    #[test]
    fn clearing_spe_inside_the_window_ends_the_read_on_its_last_byte() {
        // The RXNE was seen up to one poll (8 units) after it rose: the window measured from
        // the observation is [1 SCK, 1 byte - 1 poll).
        for after in [128, 200, 600, BYTE - 16] {
            let (bytes, frames, early, overruns) = burst_stopped(after, 0);
            assert_eq!(bytes.len(), 12, "cleared {after} units after the 11th RXNE");
            assert_eq!((frames, early, overruns), (12, 0, 0), "cleared {after} units after the 11th RXNE");
        }
    }

    /// Cleared after the last byte ended: a 13th byte is clocked; read after it lands, the
    /// 12th is overrun.
    #[test]
    fn clearing_spe_after_the_last_byte_clocks_an_extra_byte_and_overruns() {
        let (bytes, frames, early, overruns) = burst_stopped(BYTE + 200, 0);
        assert_eq!(bytes.len(), 12);
        assert_eq!(fw_cut_after_late_stop(), 1, "deselected with the 13th byte in flight");
        assert_eq!((frames, early, overruns), (13, 0, 0), "an extra byte clocked");
        let (_, frames, _, overruns) = burst_stopped(BYTE + 200, BYTE);
        assert_eq!((frames, overruns), (13, 1), "the extra byte overruns the unread last one");
    }

    #[test]
    fn chip_select_switching_between_sensors() {
        let mut fw = Fw::new();
        fw.write_reg(0, 0x12, &[0x0C]);
        fw.write_reg(2, 0x10, &[0x01]);
        for _ in 0..3 {
            assert_eq!(fw.read_reg(0, 0x0F, 1), [0x6A]);
            assert_eq!(fw.read_reg(1, 0x4F, 1), [0x40]);
            assert_eq!(fw.read_reg(2, 0x0F, 1), [0xB1]);
        }
        assert_eq!(fw.spi.contentions(), 0);
    }

    #[test]
    fn turning_the_output_on_while_the_sensor_still_drives_is_contention() {
        let mut fw = Fw::new();
        fw.write_reg(0, 0x12, &[0x0C]);
        fw.cs(0, true);
        fw.send(&[0x8F]);
        let cr1 = fw.r(CR1);
        fw.w(CR1, cr1 & !CR1_BIDIOE);
        fw.t += 128;
        let cr1 = fw.r(CR1);
        fw.w(CR1, cr1 & !CR1_SPE);
        fw.wait(SR_RXNE, true);
        fw.r(DR);
        fw.wait(SR_BSY, false);
        // Defect under test: the line is turned back to output before CS rises.
        let cr1 = fw.r(CR1);
        fw.w(CR1, cr1 | CR1_BIDIOE | CR1_SPE);
        assert_eq!(fw.spi.contentions(), 1);
        fw.cs(0, false);
    }

    /// Rule (RM0090 §28.3.7): BSY stays low in bidirectional receive mode, so a wait on it
    /// passes while the last frame still clocks. The wrong sequence, SPE cleared and the line
    /// turned back once BSY reads 0, turns it mid-byte.
    #[test]
    fn turning_the_line_on_bsy_after_a_receive_turns_it_mid_byte() {
        let mut fw = Fw::new();
        fw.write_reg(0, 0x12, &[0x0C]);
        fw.cs(0, true);
        fw.send(&[0x8F]);
        let cr1 = fw.r(CR1);
        fw.w(CR1, cr1 & !CR1_BIDIOE);
        fw.t += 2 * 128;
        let cr1 = fw.r(CR1);
        fw.w(CR1, cr1 & !CR1_SPE);
        fw.wait(SR_BSY, false);
        assert!(fw.spi.busy(), "the frame still clocks");
        fw.cs(0, false);
        let cr1 = fw.r(CR1);
        fw.w(CR1, cr1 | CR1_BIDIOE);
        assert_eq!(fw.spi.mid_frame_turns(), 1);
        // Waiting out the frame (its RXNE) first turns it between bytes.
        let mut fw = Fw::new();
        fw.read_reg(0, 0x0F, 1);
        assert_eq!(fw.spi.mid_frame_turns(), 0);
    }

    /// Rule (RM0368 §20.3.9): RXDMAEN before the stream is enabled. Set after, it is counted.
    #[test]
    fn rxdmaen_set_after_the_stream_is_counted() {
        let mut fw = Fw::new();
        fw.spi.set_dma_budget(11);
        fw.w(CR2, CR2_RXDMAEN);
        assert_eq!(fw.spi.dma_order_errors(), 1);
        let mut fw = Fw::new();
        fw.w(CR2, CR2_RXDMAEN);
        fw.spi.set_dma_budget(11);
        assert_eq!(fw.spi.dma_order_errors(), 0);
    }

    #[test]
    fn transmitting_to_a_sensor_answering_a_read_is_contention() {
        let mut fw = Fw::new();
        fw.write_reg(0, 0x12, &[0x0C]);
        fw.cs(0, true);
        fw.send(&[0x8F, 0x00]);
        fw.cs(0, false);
        assert_eq!(fw.spi.contentions(), 1);
    }

    #[test]
    fn bus_bytes_are_i2c_exposure_for_deselected_sensors_until_i2c_is_disabled() {
        let mut fw = Fw::new();
        fw.write_reg(0, 0x12, &[0x0C]);
        assert_eq!(fw.spi.i2c_exposures(), [0, 2, 2]);
        fw.write_reg(0, 0x13, &[0x04]);
        fw.write_reg(1, 0x62, &[0x30]);
        fw.write_reg(2, 0x11, &[0x18]);
        let before = fw.spi.i2c_exposures();
        assert_eq!(before, [0, 4, 6]);
        fw.read_reg(0, 0x0F, 1);
        assert_eq!(fw.spi.i2c_exposures(), before, "all three have I2C off now");
    }

    #[test]
    fn switching_to_receive_mid_byte_truncates_the_address() {
        let mut fw = Fw::new();
        fw.write_reg(0, 0x12, &[0x0C]);
        fw.cs(0, true);
        let t = fw.t;
        fw.spi.write(DR, 0x8F, t, Clocks::PLL_84_MHZ).unwrap();
        fw.spi.write(CR1, fw.spi.cr1 & !CR1_BIDIOE, t + 4 * 128, Clocks::PLL_84_MHZ).unwrap();
        assert_eq!(fw.spi.truncated_writes(), 1);
        // 0x8F with the last 4 bits undriven (0) = 0x80: a read of register 0x00 (reserved, 0).
        fw.spi.advance_to(t + 2 * BYTE);
        assert_eq!(fw.spi.read(DR, t + 2 * BYTE, Clocks::PLL_84_MHZ).unwrap(), 0x00);
    }

    #[test]
    fn a_booting_sensor_leaves_the_line_undriven() {
        let mut spi = Spi2::new();
        spi.set_clocks(Clocks::PLL_84_MHZ, 0);
        let mut fw = Fw { spi, t: 0 };
        fw.w(CR1, CR1_CPHA | CR1_CPOL | CR1_MSTR | (0b011 << 3) | CR1_SSM | CR1_SSI | CR1_BIDIMODE | CR1_BIDIOE | CR1_SPE);
        fw.write_reg(2, 0x10, &[0x01]);
        assert_eq!(fw.spi.sensors.lps22hb.register(0x10, LPS22HB_BOOT), 0, "write during boot ignored");
    }

    #[test]
    fn irq_line_and_next_event_follow_the_enables() {
        let mut fw = Fw::new();
        assert_eq!(fw.spi.next_event(), None);
        fw.w(CR2, CR2_RXNEIE);
        assert!(!fw.spi.irq_line());
        fw.cs(1, true);
        fw.send(&[0xCF]);
        let cr1 = fw.r(CR1);
        fw.w(CR1, cr1 & !CR1_BIDIOE);
        let end = fw.spi.next_event().unwrap();
        fw.spi.advance_to(end);
        assert!(fw.spi.irq_line());
    }

    #[test]
    fn long_idle_receive_clocking_is_counted_arithmetically() {
        let mut fw = Fw::new();
        let cr1 = fw.r(CR1);
        fw.w(CR1, cr1 & !CR1_BIDIOE);
        let t = fw.t;
        fw.spi.advance_to(t + TIME_HZ); // one second: 328 125 frames
        let frames = fw.spi.frames();
        assert!((328_000..328_200).contains(&frames), "{frames}");
        assert_eq!(u64::from(fw.spi.overruns()) + 1, frames, "all but the first are lost");
    }
}
