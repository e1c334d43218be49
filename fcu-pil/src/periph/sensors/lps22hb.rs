//! The LPS22HB barometer (WHO_AM_I 0xB1) from its datasheet, DocID027083 §9: the serial
//! interface is the one the three sensors share (`sensors.rs`); this file adds what only the
//! barometer does.
//!
//! # What is modelled
//! - Its own sampling clock: a new sample every 1/ODR of emulated time (CTRL_REG1.ODR: 1, 10,
//!   25, 50, 75 Hz), the first one period after the ODR is written; none in power-down (ODR = 0)
//!   except one per CTRL_REG2.ONE_SHOT. A change of ODR restarts the clock. Samples land in the
//!   output registers at the emulated time they are made, in the middle of a transaction too.
//! - STATUS: P_DA / T_DA set by a new sample, cleared when PRESS_OUT_H / TEMP_OUT_H is read (the
//!   datasheet's rule for the data-available bits); P_OR / T_OR set when a sample replaces one
//!   whose high byte was not read, and cleared with the data-available bit (the datasheet
//!   describes only when they are set; clearing them with it is an assumption).
//! - BDU (CTRL_REG1 bit 1): with BDU = 1, once the low part of an output is read (PRESS_OUT_XL or
//!   _L, TEMP_OUT_L) the output registers of that quantity are not updated until its MSB
//!   (PRESS_OUT_H, TEMP_OUT_H) is read; the newest sample made meanwhile lands then. A driver
//!   that never reads the MSB freezes the output, as on the part. With BDU = 0 a read that spans
//!   a sample boundary tears (low bytes of one sample, high byte of the next).
//! - The pressure low-pass (EN_LPFP, LPFP_CFG): a first-order filter of bandwidth ODR/9 or
//!   ODR/20 on the samples of continuous mode (off: the samples themselves, ODR/2 being the
//!   sampling's own limit). Reading LPFP_RES (0x33) restarts it from the next sample, as does
//!   setting EN_LPFP.
//! - The input: the air's pressure (`set_pressure_pa`, or `set_height_m` by the ISA) and the
//!   part's temperature, quantised as the datasheet gives: 4096 LSB/hPa in a 24-bit two's
//!   complement word (saturated at its ends), 100 LSB/°C in 16 bits.
//!
//! # Wrong sequences, answered as the part would
//! - A write to a read-only (WHO_AM_I, STATUS, the outputs) or reserved register is ignored
//!   (and counted, `Sensor::unexpected_writes`).
//! - During the 4.5 ms of power-on boot or BOOT the part ignores the bus (`sensors.rs`).
//! - SWRESET: every register back to its reset value (SIM = 0: 4-wire again; CTRL_REG2 = 0x10),
//!   the outputs and STATUS cleared, the sampling stopped. While the reset runs
//!   ([`super::SW_RESET_TIME`], the SWRESET bit reads 1) a write is ignored and counted:
//!   the datasheet says the bit clears itself when the reset is done and gives no access in
//!   between; ignoring it is the assumption that catches a driver which does not wait.
//! - ONE_SHOT with ODR ≠ 0 does nothing (the datasheet's one-shot is for power-down).
//! - RES_CONF.LC_EN changed while the part converts (ODR ≠ 0) is ignored and counted: the
//!   datasheet asks for the change in power-down only and does not say what happens otherwise;
//!   ignoring it is the assumption that catches a driver writing it too late.
//!
//! # What a driver read
//! [`Lps22hb::pressure_reads`]: every read of PRESS_OUT_H (the byte that completes a pressure
//! word and clears P_DA), how many of them followed a STATUS read with P_DA set in the same
//! transaction (a burst from STATUS, as the firmware reads it), how many samples were replaced
//! before being read, and the last word read with its time. For the image's tests: the rate the
//! firmware reads at, that it misses no sample, and what it got.
//!
//! # Assumptions (not in the datasheet)
//! - A one-shot conversion is in the output registers when the write's byte ends, and the bit
//!   reads back 0 at once.
//! - Between bus events the samples are made lazily: a sample due before a call of the input
//!   setters but not yet looked at takes the new input. The rig sets the input once per control
//!   step (1.25 ms), far shorter than a sample period.
//! - FIFO modes, interrupts and the autozero functions are not modelled (FIFO_EN is stored only).

use super::{Access, Chip, Port, Spec, Time, LPS22HB_BOOT};
use crate::periph::TIME_HZ;

pub mod lps22hb_reg {
    pub const WHO_AM_I: u8 = 0x0F;
    pub const CTRL_REG1: u8 = 0x10;
    pub const CTRL_REG2: u8 = 0x11;
    pub const CTRL_REG3: u8 = 0x12;
    pub const STATUS: u8 = 0x27;
    pub const PRESS_OUT_XL: u8 = 0x28;
    pub const PRESS_OUT_L: u8 = 0x29;
    pub const PRESS_OUT_H: u8 = 0x2A;
    pub const TEMP_OUT_L: u8 = 0x2B;
    pub const TEMP_OUT_H: u8 = 0x2C;
    /// Reading it restarts the pressure low-pass.
    pub const LPFP_RES: u8 = 0x33;
    pub const RES_CONF: u8 = 0x1A;
    pub const WHO_AM_I_VALUE: u8 = 0xB1;

    /// CTRL_REG1 bits.
    pub const SIM: u8 = 0x01;
    pub const BDU: u8 = 0x02;
    pub const LPFP_CFG: u8 = 0x04;
    pub const EN_LPFP: u8 = 0x08;
    pub const ODR_MASK: u8 = 0x70;
    pub const ODR_SHIFT: u8 = 4;
    /// CTRL_REG2 bits.
    pub const ONE_SHOT: u8 = 0x01;
    pub const SWRESET: u8 = 0x04;
    pub const I2C_DIS: u8 = 0x08;
    pub const IF_ADD_INC: u8 = 0x10;
    pub const BOOT: u8 = 0x80;
    /// RES_CONF.LC_EN: low-current mode.
    pub const LC_EN: u8 = 0x01;
    /// STATUS bits.
    pub const P_DA: u8 = 0x01;
    pub const T_DA: u8 = 0x02;
    pub const P_OR: u8 = 0x10;
    pub const T_OR: u8 = 0x20;
}

use lps22hb_reg::*;

const LPS22HB: Spec = Spec {
    who_am_i: (WHO_AM_I, WHO_AM_I_VALUE),
    control: CTRL_REG2,
    // SWRESET: registers back to their reset values (SIM = 0: 4-wire again).
    sw_reset: SWRESET,
    boot: BOOT,
    // ONE_SHOT self-clears (the conversion is taken at once, see the module documentation).
    self_clearing: ONE_SHOT,
    boot_time: LPS22HB_BOOT,
    // CTRL_REG2 = 0x10 (IF_ADD_INC).
    reset_values: &[(CTRL_REG2, IF_ADD_INC)],
    // Datasheet table "Registers address map".
    access: |addr| match addr {
        0x0B..=0x0D | 0x10..=0x12 | 0x14..=0x1A => Access::Rw,
        0x0F | 0x25..=0x2C | 0x33 => Access::Ro,
        _ => Access::Reserved,
    },
};

/// Standard sea-level pressure, Pa (the ISA's p0).
pub const ISA_SEA_LEVEL_PA: f64 = 101_325.0;
/// The ISA troposphere's height scale, m, and exponent: p = p0·(1 − h/44330.77)^(1/0.190263).
const ISA_HEIGHT_SCALE_M: f64 = 44_330.77;
const ISA_EXPONENT: f64 = 0.190_263;
/// PRESS_OUT counts per Pa (4096 LSB/hPa) and TEMP_OUT counts per °C.
const COUNTS_PER_PA: f64 = 4096.0 / 100.0;
const COUNTS_PER_DEG_C: f64 = 100.0;
/// The 24-bit two's complement word's ends.
const PRESS_COUNTS_MAX: i32 = (1 << 23) - 1;
const PRESS_COUNTS_MIN: i32 = -(1 << 23);

/// A rejected barometer input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BaroInputError {
    /// NaN or infinite.
    NotFinite,
    /// Air pressure below zero.
    NegativePressure,
    /// At or above the ISA troposphere formula's top (44.3 km), where it has no pressure.
    AboveIsaRange,
}

/// The sample period of a CTRL_REG1 value, `None` in power-down.
fn odr_period(ctrl_reg1: u8) -> Option<Time> {
    let hz: Time = match (ctrl_reg1 & ODR_MASK) >> ODR_SHIFT {
        0 => return None,
        1 => 1,
        2 => 10,
        3 => 25,
        4 => 50,
        // 0b101 is 75 Hz; 0b110 and 0b111 are not in the datasheet's table and taken as 75 Hz.
        _ => 75,
    };
    Some(TIME_HZ / hz)
}

/// The first-order low-pass's gain per sample for a CTRL_REG1 value, `None` when it is off:
/// `1 − e^(−2π·fc/ODR)` with fc = ODR/9 (LPFP_CFG = 0) or ODR/20.
fn lpf_gain(ctrl_reg1: u8) -> Option<f64> {
    if ctrl_reg1 & EN_LPFP == 0 {
        return None;
    }
    let divider = if ctrl_reg1 & LPFP_CFG != 0 { 20.0 } else { 9.0 };
    Some(1.0 - (-2.0 * std::f64::consts::PI / divider).exp())
}

/// The output registers of one quantity (pressure or temperature) and its BDU hold.
#[derive(Clone, Copy, Debug, Default)]
struct Output {
    /// BDU: the low part was read, the MSB not yet: the registers hold still.
    locked: bool,
    /// The newest sample made while locked, and how many were made.
    held: Option<(i32, u64)>,
}

/// The pressure as drivers read it ([`Lps22hb::pressure_reads`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PressureReads {
    /// Reads of PRESS_OUT_H: each completes a pressure word and clears P_DA.
    pub reads: u64,
    /// Of those, the ones whose transaction had read STATUS with P_DA set before: a driver
    /// reading the burst from STATUS was told the word is new.
    pub fresh: u64,
    /// Samples that never reached a read: replaced in the output registers before their MSB
    /// was read, or made and replaced while BDU held the outputs.
    pub lost: u64,
    /// The last word read (24-bit two's complement, sign-extended) and the time of its MSB.
    pub last: Option<(Time, i32)>,
}

/// What the transaction in progress has read so far: STATUS, and the pressure's low bytes.
#[derive(Clone, Copy, Debug, Default)]
struct TransactionReads {
    status: Option<u8>,
    xl: Option<u8>,
    l: Option<u8>,
}

/// LPS22HB barometer (WHO_AM_I 0xB1). 4-wire SPI at power-up (CTRL_REG1.SIM = 0).
#[derive(Clone, Debug)]
pub struct Lps22hb {
    port: Port<()>,
    pressure_pa: f64,
    temperature_c: f64,
    /// When the next continuous-mode sample is made; `None` in power-down.
    next_sample_at: Option<Time>,
    /// The low-pass's state, Pa; `None` restarts it at the next sample.
    filtered_pa: Option<f64>,
    pressure: Output,
    temperature: Output,
    samples: u64,
    transaction: TransactionReads,
    pressure_reads: PressureReads,
    /// The time of the latest bus event (every one brings the part up to its time first).
    bus_time: Time,
}

impl Default for Lps22hb {
    fn default() -> Self {
        Self::new()
    }
}

impl Lps22hb {
    /// Powered on at time 0: booting for [`LPS22HB_BOOT`], at sea-level pressure and 25 °C.
    pub fn new() -> Self {
        Lps22hb {
            port: Port::new(&LPS22HB),
            pressure_pa: ISA_SEA_LEVEL_PA,
            temperature_c: 25.0,
            next_sample_at: None,
            filtered_pa: None,
            pressure: Output::default(),
            temperature: Output::default(),
            samples: 0,
            transaction: TransactionReads::default(),
            pressure_reads: PressureReads::default(),
            bus_time: 0,
        }
    }

    /// The air's pressure at the part from now on, Pa.
    pub fn set_pressure_pa(&mut self, pressure_pa: f64) -> Result<(), BaroInputError> {
        if !pressure_pa.is_finite() {
            return Err(BaroInputError::NotFinite);
        }
        if pressure_pa < 0.0 {
            return Err(BaroInputError::NegativePressure);
        }
        self.pressure_pa = pressure_pa;
        Ok(())
    }

    /// The pressure of the ISA at `height_m` above a level where it is `ground_pa`:
    /// `ground_pa·(1 − h/44330.77)^(1/0.190263)`.
    pub fn set_height_m(&mut self, height_m: f64, ground_pa: f64) -> Result<(), BaroInputError> {
        if !height_m.is_finite() || !ground_pa.is_finite() {
            return Err(BaroInputError::NotFinite);
        }
        let base = 1.0 - height_m / ISA_HEIGHT_SCALE_M;
        if base <= 0.0 {
            return Err(BaroInputError::AboveIsaRange);
        }
        self.set_pressure_pa(ground_pa * base.powf(1.0 / ISA_EXPONENT))
    }

    /// The part's temperature from now on, °C.
    pub fn set_temperature_c(&mut self, temperature_c: f64) -> Result<(), BaroInputError> {
        if !temperature_c.is_finite() {
            return Err(BaroInputError::NotFinite);
        }
        self.temperature_c = temperature_c;
        Ok(())
    }

    /// Samples made since power-on (continuous and one-shot).
    pub fn samples_made(&self) -> u64 {
        self.samples
    }

    /// The pressure as drivers read it since power-on (see the module documentation).
    pub fn pressure_reads(&self) -> PressureReads {
        self.pressure_reads
    }

    /// A byte of `addr` is being read (before the read's own effects): what the driver got, for
    /// [`Lps22hb::pressure_reads`]. The registers hold what the line carried: the bus brought
    /// the part up to this instant before the byte was driven.
    fn note_read(&mut self, addr: u8) {
        let value = self.port.reg(addr);
        let seen = &mut self.transaction;
        match addr {
            STATUS => seen.status = Some(value),
            PRESS_OUT_XL => seen.xl = Some(value),
            PRESS_OUT_L => seen.l = Some(value),
            PRESS_OUT_H => {
                let xl = seen.xl.unwrap_or(self.port.reg(PRESS_OUT_XL));
                let l = seen.l.unwrap_or(self.port.reg(PRESS_OUT_L));
                let counts = i32::from_le_bytes([xl, l, value, 0]) << 8 >> 8;
                let fresh = seen.status.is_some_and(|st| st & P_DA != 0);
                let reads = &mut self.pressure_reads;
                reads.reads += 1;
                reads.fresh += u64::from(fresh);
                reads.last = Some((self.bus_time, counts));
            }
            _ => {}
        }
    }

    /// `n` ≥ 1 samples made since the last look, the last of them at the current input.
    fn take_samples(&mut self, n: u64, continuous: bool) {
        let x = self.pressure_pa;
        let ctrl1 = self.port.reg(CTRL_REG1);
        let y = match (continuous, lpf_gain(ctrl1), self.filtered_pa) {
            (true, Some(gain), Some(y0)) => {
                // n steps of y += gain·(x − y) at a constant input, in closed form.
                let steps = i32::try_from(n).unwrap_or(i32::MAX);
                x + (y0 - x) * (1.0 - gain).powi(steps)
            }
            _ => x,
        };
        self.filtered_pa = Some(y);
        self.samples += n;
        let press = ((y * COUNTS_PER_PA).round() as i32).clamp(PRESS_COUNTS_MIN, PRESS_COUNTS_MAX);
        // `as` saturates at i32's ends; the clamp keeps the word within 16 bits.
        let temp = ((self.temperature_c * COUNTS_PER_DEG_C).round() as i32).clamp(i16::MIN.into(), i16::MAX.into());
        if self.pressure.locked {
            self.pressure.held = Some((press, self.pressure.held.map_or(0, |(_, m)| m) + n));
        } else {
            self.land_pressure(press, n);
        }
        if self.temperature.locked {
            self.temperature.held = Some((temp, self.temperature.held.map_or(0, |(_, m)| m) + n));
        } else {
            self.land_temperature(temp, n);
        }
    }

    /// A sample into PRESS_OUT; `n` samples replaced the registers' content since the last.
    fn land_pressure(&mut self, counts: i32, n: u64) {
        let [xl, l, h, _] = counts.to_le_bytes();
        *self.port.reg_mut(PRESS_OUT_XL) = xl;
        *self.port.reg_mut(PRESS_OUT_L) = l;
        *self.port.reg_mut(PRESS_OUT_H) = h;
        let unread = u64::from(self.port.reg(STATUS) & P_DA != 0);
        self.pressure_reads.lost += n.saturating_sub(1) + unread;
        let status = self.port.reg_mut(STATUS);
        if *status & P_DA != 0 || n >= 2 {
            *status |= P_OR;
        }
        *status |= P_DA;
    }

    fn land_temperature(&mut self, counts: i32, n: u64) {
        let [l, h, _, _] = counts.to_le_bytes();
        *self.port.reg_mut(TEMP_OUT_L) = l;
        *self.port.reg_mut(TEMP_OUT_H) = h;
        let status = self.port.reg_mut(STATUS);
        if *status & T_DA != 0 || n >= 2 {
            *status |= T_OR;
        }
        *status |= T_DA;
    }

    /// BDU's hold ends (MSB read, or BDU cleared): the newest sample made meanwhile lands.
    fn release_pressure(&mut self) {
        self.pressure.locked = false;
        if let Some((counts, n)) = self.pressure.held.take() {
            self.land_pressure(counts, n);
        }
    }

    fn release_temperature(&mut self) {
        self.temperature.locked = false;
        if let Some((counts, n)) = self.temperature.held.take() {
            self.land_temperature(counts, n);
        }
    }

    /// What SWRESET clears besides the registers with a reset value.
    fn reset_outputs(&mut self) {
        for addr in STATUS..=TEMP_OUT_H {
            *self.port.reg_mut(addr) = 0;
        }
        self.next_sample_at = None;
        self.filtered_pa = None;
        self.pressure = Output::default();
        self.temperature = Output::default();
    }
}

impl Chip for Lps22hb {
    type Output = ();

    fn port(&self) -> &Port<()> {
        &self.port
    }
    fn port_mut(&mut self) -> &mut Port<()> {
        &mut self.port
    }

    /// The rig gives no samples: the part makes its own ([`Chip::advance`]).
    fn apply_output(&mut self, (): ()) {}

    fn advance(&mut self, now: Time) {
        self.bus_time = self.bus_time.max(now);
        let Some(next) = self.next_sample_at else { return };
        if now < next {
            return;
        }
        let Some(period) = odr_period(self.port.reg(CTRL_REG1)) else {
            self.next_sample_at = None;
            return;
        };
        let n = (now - next) / period + 1;
        self.next_sample_at = Some(next + n * period);
        self.take_samples(n, true);
    }

    fn read_value(&self, addr: u8, now: Time) -> u8 {
        if self.next_sample_at.is_some_and(|t| now >= t) {
            let mut later = self.clone();
            later.advance(now);
            later.port.peek(addr, now)
        } else {
            self.port.peek(addr, now)
        }
    }

    fn read_effects(&mut self, addr: u8) {
        self.note_read(addr);
        let bdu = self.port.reg(CTRL_REG1) & BDU != 0;
        match addr {
            PRESS_OUT_XL | PRESS_OUT_L if bdu => self.pressure.locked = true,
            PRESS_OUT_H => {
                *self.port.reg_mut(STATUS) &= !(P_DA | P_OR);
                self.release_pressure();
            }
            TEMP_OUT_L if bdu => self.temperature.locked = true,
            TEMP_OUT_H => {
                *self.port.reg_mut(STATUS) &= !(T_DA | T_OR);
                self.release_temperature();
            }
            LPFP_RES => self.filtered_pa = None,
            _ => {}
        }
    }

    fn end_transaction(&mut self) {
        self.transaction = TransactionReads::default();
    }

    fn write(&mut self, addr: u8, value: u8, now: Time) {
        if now < self.port.reset_until {
            self.port.unexpected_writes += 1;
            return;
        }
        let converting = odr_period(self.port.reg(CTRL_REG1)).is_some();
        if addr == RES_CONF && (value ^ self.port.reg(RES_CONF)) & LC_EN != 0 && converting {
            self.port.unexpected_writes += 1;
            return;
        }
        let before = self.port.reg(CTRL_REG1);
        self.port.write(addr, value, now);
        if addr == CTRL_REG2 && value & SWRESET != 0 {
            self.reset_outputs();
        }
        let after = self.port.reg(CTRL_REG1);
        if odr_period(after) != odr_period(before) {
            self.next_sample_at = odr_period(after).map(|period| now + period);
        }
        if after & EN_LPFP != 0 && before & EN_LPFP == 0 {
            self.filtered_pa = None;
        }
        if after & BDU == 0 {
            self.release_pressure();
            self.release_temperature();
        }
        let one_shot = addr == CTRL_REG2 && value & (ONE_SHOT | SWRESET | BOOT) == ONE_SHOT;
        if one_shot && odr_period(after).is_none() {
            self.take_samples(1, false);
        }
    }

    fn three_wire(&self) -> bool {
        self.port.reg(CTRL_REG1) & SIM != 0
    }
    fn increments(&self) -> bool {
        self.port.reg(CTRL_REG2) & IF_ADD_INC != 0
    }
    fn i2c_on(&self) -> bool {
        self.port.reg(CTRL_REG2) & I2C_DIS == 0
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Sensor, SpiDevice, SW_RESET_TIME, UNDRIVEN};
    use super::*;

    const MS: Time = TIME_HZ / 1000;
    const T0: Time = 10 * MS;
    /// 75 Hz's period.
    const P75: Time = TIME_HZ / 75;

    /// One transaction, all bytes at `now` (None: the master leaves the line to the sensor).
    fn transact(dev: &mut Lps22hb, bytes: &[Option<u8>], times: &[Time]) -> Vec<u8> {
        dev.cs_fall(times[0]);
        let mut out = Vec::new();
        for (i, b) in bytes.iter().enumerate() {
            let now = times[i.min(times.len() - 1)];
            let line = b.or(dev.output(now)).unwrap_or(UNDRIVEN);
            dev.clock(line, now);
            out.push(line);
        }
        dev.cs_rise(*times.last().unwrap_or(&0));
        out
    }

    fn write(dev: &mut Lps22hb, addr: u8, data: &[u8], now: Time) {
        let mut bytes = vec![Some(addr & 0x7F)];
        bytes.extend(data.iter().map(|&d| Some(d)));
        transact(dev, &bytes, &[now]);
    }

    /// A read whose data byte i is clocked at `times[i + 1]` (command at `times[0]`).
    fn read_at(dev: &mut Lps22hb, addr: u8, n: usize, times: &[Time]) -> Vec<u8> {
        let mut bytes = vec![Some(addr | 0x80)];
        bytes.extend(std::iter::repeat_n(None, n));
        transact(dev, &bytes, times)[1..].to_vec()
    }

    fn read(dev: &mut Lps22hb, addr: u8, n: usize, now: Time) -> Vec<u8> {
        read_at(dev, addr, n, &[now])
    }

    fn pressure_counts(b: &[u8]) -> i32 {
        i32::from_le_bytes([b[0], b[1], b[2], 0]) << 8 >> 8
    }

    /// 3-wire, then `ctrl1` (SIM added).
    fn configured(ctrl1: u8) -> Lps22hb {
        let mut s = Lps22hb::new();
        write(&mut s, CTRL_REG1, &[SIM], T0);
        write(&mut s, CTRL_REG1, &[ctrl1 | SIM], T0);
        s
    }

    #[test]
    fn register_addresses_and_bits_are_fcu_cores() {
        use fcu_core::baro::registers as core;
        let ours = [
            WHO_AM_I,
            WHO_AM_I_VALUE,
            CTRL_REG1,
            CTRL_REG2,
            CTRL_REG3,
            STATUS,
            PRESS_OUT_XL,
            PRESS_OUT_L,
            PRESS_OUT_H,
            TEMP_OUT_L,
            TEMP_OUT_H,
            LPFP_RES,
        ];
        let theirs = [
            core::WHO_AM_I,
            core::WHO_AM_I_VALUE,
            core::CTRL_REG1,
            core::CTRL_REG2,
            core::CTRL_REG3,
            core::STATUS,
            core::PRESS_OUT_XL,
            core::PRESS_OUT_L,
            core::PRESS_OUT_H,
            core::TEMP_OUT_L,
            core::TEMP_OUT_H,
            core::LPFP_RES,
        ];
        assert_eq!(ours, theirs);
        assert_eq!(
            [SIM, BDU, LPFP_CFG, EN_LPFP, ODR_MASK],
            [core::ctrl_reg1::SIM, core::ctrl_reg1::BDU, core::ctrl_reg1::LPFP_CFG, core::ctrl_reg1::EN_LPFP, core::ctrl_reg1::ODR_MASK]
        );
        assert_eq!(
            [ONE_SHOT, SWRESET, I2C_DIS, IF_ADD_INC, BOOT],
            [
                core::ctrl_reg2::ONE_SHOT,
                core::ctrl_reg2::SWRESET,
                core::ctrl_reg2::I2C_DIS,
                core::ctrl_reg2::IF_ADD_INC,
                core::ctrl_reg2::BOOT
            ]
        );
        assert_eq!([P_DA, T_DA, P_OR, T_OR], [core::status::P_DA, core::status::T_DA, core::status::P_OR, core::status::T_OR]);
    }

    #[test]
    fn reset_values_are_the_datasheets_and_who_am_i_answers_only_in_3_wire_mode() {
        let mut s = Lps22hb::new();
        let t = LPS22HB_BOOT;
        assert_eq!(s.register(CTRL_REG2, t), 0x10, "CTRL_REG2 reset: IF_ADD_INC");
        for addr in [CTRL_REG1, CTRL_REG3, STATUS, PRESS_OUT_XL, PRESS_OUT_L, PRESS_OUT_H, TEMP_OUT_L, TEMP_OUT_H] {
            assert_eq!(s.register(addr, t), 0, "register {addr:#04x}");
        }
        assert!(s.i2c_enabled());
        assert_eq!(read(&mut s, WHO_AM_I, 1, t), [UNDRIVEN], "4-wire at power-up");
        write(&mut s, CTRL_REG1, &[SIM], t);
        assert_eq!(read(&mut s, WHO_AM_I, 1, t), [0xB1]);
    }

    #[test]
    fn reset_and_boot_clear_sim_as_the_reference_expects() {
        let mut s = configured(0);
        write(&mut s, CTRL_REG2, &[0x94], T0);
        assert_eq!(read(&mut s, WHO_AM_I, 1, T0 + LPS22HB_BOOT - 1), [UNDRIVEN], "booting");
        let later = T0 + LPS22HB_BOOT;
        assert_eq!(read(&mut s, WHO_AM_I, 1, later), [UNDRIVEN], "SIM cleared by SWRESET");
        assert_eq!(s.register(CTRL_REG2, later), 0x10);
        write(&mut s, CTRL_REG1, &[SIM], later);
        assert_eq!(read(&mut s, WHO_AM_I, 1, later), [0xB1]);
    }

    #[test]
    fn a_read_during_the_boot_is_undriven_and_a_write_is_ignored() {
        let mut s = Lps22hb::new();
        write(&mut s, CTRL_REG1, &[SIM], LPS22HB_BOOT - 1);
        assert_eq!(s.register(CTRL_REG1, LPS22HB_BOOT), 0, "write ignored");
        let mut s = configured(0);
        write(&mut s, CTRL_REG2, &[BOOT | IF_ADD_INC], T0);
        assert_eq!(read(&mut s, WHO_AM_I, 1, T0 + 1), [UNDRIVEN]);
        assert_eq!(read(&mut s, WHO_AM_I, 1, T0 + LPS22HB_BOOT), [0xB1], "BOOT keeps the registers");
    }

    #[test]
    fn the_i2c_interface_stays_on_until_i2c_dis() {
        let mut s = configured(0);
        write(&mut s, CTRL_REG2, &[IF_ADD_INC | I2C_DIS], T0);
        assert!(!s.i2c_enabled());
    }

    #[test]
    fn a_sample_comes_every_period_of_each_odr_and_none_in_power_down() {
        for (bits, hz) in [(0x10, 1), (0x20, 10), (0x30, 25), (0x40, 50), (0x50, 75)] {
            let mut s = configured(bits);
            let period = TIME_HZ / hz;
            assert_eq!(s.register(STATUS, T0 + period - 1) & P_DA, 0, "{hz} Hz: not before one period");
            assert_eq!(s.register(STATUS, T0 + period) & (P_DA | T_DA), P_DA | T_DA, "{hz} Hz");
            s.advance(T0 + 10 * period);
            assert_eq!(s.samples_made(), 10, "{hz} Hz: ten periods, ten samples");
        }
        let mut s = configured(0);
        s.advance(T0 + 10 * TIME_HZ);
        assert_eq!((s.samples_made(), s.register(STATUS, T0 + 10 * TIME_HZ)), (0, 0), "power-down");
    }

    #[test]
    fn one_shot_makes_one_sample_in_power_down_and_nothing_at_an_odr() {
        let mut s = configured(0);
        s.set_pressure_pa(100_000.0).unwrap();
        write(&mut s, CTRL_REG2, &[IF_ADD_INC | ONE_SHOT], T0);
        assert_eq!(s.register(CTRL_REG2, T0), IF_ADD_INC, "ONE_SHOT reads back clear");
        assert_eq!(s.samples_made(), 1);
        assert_eq!(pressure_counts(&read(&mut s, PRESS_OUT_XL, 3, T0)), 4_096_000);
        s.advance(T0 + TIME_HZ);
        assert_eq!(s.samples_made(), 1, "no sample after it");
        let mut s = configured(0x50);
        write(&mut s, CTRL_REG2, &[IF_ADD_INC | ONE_SHOT], T0 + 1);
        assert_eq!(s.samples_made(), 0, "ONE_SHOT at 75 Hz");
    }

    #[test]
    fn data_available_clears_when_the_high_byte_is_read() {
        let mut s = configured(0x50);
        let t = T0 + P75;
        assert_eq!(read(&mut s, STATUS, 1, t)[0] & (P_DA | T_DA), P_DA | T_DA);
        read(&mut s, PRESS_OUT_XL, 2, t);
        assert_eq!(s.register(STATUS, t) & P_DA, P_DA, "XL and L leave P_DA");
        read(&mut s, PRESS_OUT_H, 1, t);
        assert_eq!(s.register(STATUS, t) & (P_DA | T_DA), T_DA, "PRESS_OUT_H clears P_DA only");
        read(&mut s, TEMP_OUT_L, 1, t);
        assert_eq!(s.register(STATUS, t) & T_DA, T_DA);
        read(&mut s, TEMP_OUT_H, 1, t);
        assert_eq!(s.register(STATUS, t), 0);
    }

    #[test]
    fn a_sample_replacing_an_unread_one_sets_the_overrun_bits() {
        let mut s = configured(0x50);
        assert_eq!(s.register(STATUS, T0 + P75) & (P_OR | T_OR), 0);
        assert_eq!(s.register(STATUS, T0 + 2 * P75), P_DA | T_DA | P_OR | T_OR);
        // A burst from STATUS to TEMP_OUT_H reads both high bytes: all four bits clear.
        let burst = read(&mut s, STATUS, 6, T0 + 2 * P75);
        assert_eq!(burst[0], 0x33);
        assert_eq!(s.register(STATUS, T0 + 2 * P75), 0);
        // Read in time, no overrun.
        read(&mut s, STATUS, 6, T0 + 3 * P75);
        assert_eq!(s.register(STATUS, T0 + 3 * P75), 0);
        assert_eq!(s.register(STATUS, T0 + 4 * P75), P_DA | T_DA);
    }

    #[test]
    fn the_pressure_and_temperature_words_are_the_datasheets_units() {
        let mut s = configured(0x50);
        s.set_pressure_pa(101_325.0).unwrap();
        s.set_temperature_c(-12.34).unwrap();
        let b = read(&mut s, PRESS_OUT_XL, 5, T0 + P75);
        // 1013.25 hPa · 4096 = 4 150 272; −12.34 °C · 100 = −1234.
        assert_eq!(pressure_counts(&b), 4_150_272);
        assert_eq!(i16::from_le_bytes([b[3], b[4]]), -1234);
        let raw = fcu_core::baro::decode_burst(&[0, b[0], b[1], b[2], b[3], b[4]]);
        assert_eq!((raw.pressure_pa(), raw.temperature_c()), (101_325.0, -12.34));
    }

    #[test]
    fn the_24_bit_word_saturates_at_its_ends() {
        let mut s = configured(0x50);
        s.set_pressure_pa(1.0e9).unwrap();
        s.set_temperature_c(1.0e6).unwrap();
        let b = read(&mut s, PRESS_OUT_XL, 5, T0 + P75);
        assert_eq!(pressure_counts(&b), (1 << 23) - 1);
        assert_eq!(i16::from_le_bytes([b[3], b[4]]), i16::MAX);
    }

    #[test]
    fn bad_inputs_are_refused_and_the_last_good_one_kept() {
        let mut s = Lps22hb::new();
        assert_eq!(s.set_pressure_pa(f64::NAN), Err(BaroInputError::NotFinite));
        assert_eq!(s.set_pressure_pa(-1.0), Err(BaroInputError::NegativePressure));
        assert_eq!(s.set_temperature_c(f64::INFINITY), Err(BaroInputError::NotFinite));
        assert_eq!(s.set_height_m(50_000.0, ISA_SEA_LEVEL_PA), Err(BaroInputError::AboveIsaRange));
        assert_eq!(s.set_height_m(f64::NAN, ISA_SEA_LEVEL_PA), Err(BaroInputError::NotFinite));
        assert_eq!(s.pressure_pa, ISA_SEA_LEVEL_PA);
    }

    #[test]
    fn height_gives_the_isa_pressure() {
        let mut s = Lps22hb::new();
        s.set_height_m(0.0, 100_000.0).unwrap();
        assert_eq!(s.pressure_pa, 100_000.0);
        s.set_height_m(1.0, ISA_SEA_LEVEL_PA).unwrap();
        // Near the ground a metre is ρ·g ≈ 12.0 Pa.
        assert!((ISA_SEA_LEVEL_PA - s.pressure_pa - 12.01).abs() < 0.05, "{}", s.pressure_pa);
        s.set_height_m(1000.0, ISA_SEA_LEVEL_PA).unwrap();
        assert!((s.pressure_pa - 89_874.6).abs() < 1.0, "ISA table at 1 km: {}", s.pressure_pa);
    }

    /// A burst from PRESS_OUT_XL whose first byte is read before a sample boundary and the other
    /// two after it, the samples 0x3F_F0FF then 0x40_0000 (each byte differs).
    fn read_across_a_sample_boundary(ctrl1: u8) -> (i32, Lps22hb) {
        let mut s = configured(ctrl1 | 0x50);
        s.set_pressure_pa(f64::from(0x3F_F0FF) / COUNTS_PER_PA).unwrap();
        s.advance(T0 + P75);
        s.set_pressure_pa(f64::from(0x40_0000) / COUNTS_PER_PA).unwrap();
        let boundary = T0 + 2 * P75;
        let b = read_at(&mut s, PRESS_OUT_XL, 3, &[boundary - 2, boundary - 1, boundary, boundary + 1]);
        (pressure_counts(&b), s)
    }

    #[test]
    fn with_bdu_a_read_spanning_a_sample_boundary_stays_coherent() {
        let (counts, mut s) = read_across_a_sample_boundary(BDU);
        assert_eq!(counts, 0x3F_F0FF, "the old sample whole");
        // The MSB read released the hold: the new sample is there, flagged.
        let t = T0 + 2 * P75 + 2;
        assert_eq!(s.register(STATUS, t) & P_DA, P_DA);
        assert_eq!(pressure_counts(&read(&mut s, PRESS_OUT_XL, 3, t)), 0x40_0000);
    }

    #[test]
    fn without_bdu_a_read_spanning_a_sample_boundary_tears() {
        let (counts, _) = read_across_a_sample_boundary(0);
        assert_eq!(counts, 0x40_00FF, "torn: XL from the old sample, L and H from the new");
    }

    #[test]
    fn with_bdu_a_driver_that_never_reads_the_msb_freezes_the_output() {
        let mut s = configured(BDU | 0x50);
        s.set_pressure_pa(90_000.0).unwrap();
        let t = T0 + P75;
        let first = read(&mut s, PRESS_OUT_XL, 2, t);
        s.set_pressure_pa(100_000.0).unwrap();
        let later = t + 10 * P75;
        assert_eq!(read(&mut s, PRESS_OUT_XL, 2, later), first, "held while the MSB is unread");
        read(&mut s, PRESS_OUT_H, 1, later);
        assert_eq!(s.register(STATUS, later) & (P_DA | P_OR), P_DA | P_OR, "ten samples replaced one another unread");
        assert_eq!(pressure_counts(&read(&mut s, PRESS_OUT_XL, 3, later)), 4_096_000);
    }

    #[test]
    fn clearing_bdu_releases_a_held_sample() {
        let mut s = configured(BDU | 0x50);
        read(&mut s, PRESS_OUT_XL, 1, T0 + P75);
        s.set_pressure_pa(100_000.0).unwrap();
        write(&mut s, CTRL_REG1, &[SIM | 0x50], T0 + 2 * P75);
        assert_eq!(pressure_counts(&read(&mut s, PRESS_OUT_XL, 3, T0 + 2 * P75)), 4_096_000);
    }

    #[test]
    fn a_burst_auto_increments_only_with_if_add_inc() {
        let mut s = configured(0x50);
        s.set_pressure_pa(101_325.0).unwrap();
        let t = T0 + P75;
        let b = read(&mut s, STATUS, 6, t);
        assert_eq!(pressure_counts(&b[1..4]), 4_150_272);
        write(&mut s, CTRL_REG2, &[0], t);
        assert_eq!(read(&mut s, WHO_AM_I, 3, t), [0xB1, 0xB1, 0xB1], "no increment: the same register");
        write(&mut s, CTRL_REG1, &[SIM, 0x55], t);
        assert_eq!(s.register(CTRL_REG2, t), 0, "nor in a write: the second byte went to CTRL_REG1 too");
        assert_eq!(s.register(CTRL_REG1, t), 0x55);
    }

    #[test]
    fn the_low_pass_follows_a_step_at_odr_over_9_or_20() {
        for (cfg, divider) in [(EN_LPFP, 9.0), (EN_LPFP | LPFP_CFG, 20.0)] {
            let mut s = configured(0x50 | cfg);
            s.set_pressure_pa(100_000.0).unwrap();
            s.advance(T0 + P75);
            s.set_pressure_pa(100_100.0).unwrap();
            s.advance(T0 + 2 * P75);
            let gain = 1.0 - (-2.0 * std::f64::consts::PI / divider).exp();
            let expected = 100_000.0 + 100.0 * gain;
            let got = pressure_counts(&read(&mut s, PRESS_OUT_XL, 3, T0 + 2 * P75)) as f64 / COUNTS_PER_PA;
            assert!((got - expected).abs() < 0.03, "ODR/{divider}: {got} against {expected}");
            // Many samples later the step has passed.
            s.advance(T0 + 200 * P75);
            let settled = pressure_counts(&read(&mut s, PRESS_OUT_XL, 3, T0 + 200 * P75)) as f64 / COUNTS_PER_PA;
            assert!((settled - 100_100.0).abs() < 0.03, "{settled}");
        }
        let mut s = configured(0x50);
        s.set_pressure_pa(100_000.0).unwrap();
        s.advance(T0 + P75);
        s.set_pressure_pa(100_100.0).unwrap();
        assert_eq!(pressure_counts(&read(&mut s, PRESS_OUT_XL, 3, T0 + 2 * P75)), 4_100_096, "filter off: the step at once");
    }

    #[test]
    fn reading_lpfp_res_restarts_the_low_pass_at_the_input() {
        let mut s = configured(0x50 | EN_LPFP | LPFP_CFG);
        s.set_pressure_pa(100_000.0).unwrap();
        s.advance(T0 + P75);
        s.set_pressure_pa(100_100.0).unwrap();
        read(&mut s, LPFP_RES, 1, T0 + P75);
        assert_eq!(pressure_counts(&read(&mut s, PRESS_OUT_XL, 3, T0 + 2 * P75)), 4_100_096);
    }

    #[test]
    fn writes_to_read_only_and_reserved_registers_are_ignored() {
        let mut s = configured(0x50);
        let t = T0 + P75;
        let before = read(&mut s, STATUS, 6, t);
        for addr in [WHO_AM_I, STATUS, PRESS_OUT_XL, PRESS_OUT_H, TEMP_OUT_H, 0x13, 0x00] {
            write(&mut s, addr, &[0xAA], t);
        }
        assert_eq!(s.unexpected_writes(), 7);
        assert_eq!(s.register(WHO_AM_I, t), 0xB1);
        assert_eq!(s.register(PRESS_OUT_XL, t), before[1]);
        assert_eq!(s.register(0x13, t), 0);
    }

    #[test]
    fn swreset_clears_the_outputs_and_stops_the_sampling() {
        let mut s = configured(BDU | 0x50);
        s.advance(T0 + 2 * P75);
        write(&mut s, CTRL_REG2, &[SWRESET | IF_ADD_INC], T0 + 2 * P75);
        assert_eq!(s.register(CTRL_REG2, T0 + 2 * P75), IF_ADD_INC | SWRESET, "SWRESET reads 1 while it runs");
        let after = T0 + 2 * P75 + SW_RESET_TIME;
        assert_eq!(s.register(CTRL_REG2, after), IF_ADD_INC);
        assert_eq!(s.register(CTRL_REG1, after), 0);
        for addr in STATUS..=TEMP_OUT_H {
            assert_eq!(s.register(addr, after + 10 * P75), 0, "register {addr:#04x}: no sample after the reset");
        }
    }

    #[test]
    fn a_write_while_swreset_runs_is_ignored() {
        let mut s = configured(0);
        write(&mut s, CTRL_REG2, &[SWRESET | IF_ADD_INC], T0);
        write(&mut s, CTRL_REG1, &[SIM], T0 + SW_RESET_TIME - 1);
        assert_eq!(s.unexpected_writes(), 1);
        assert_eq!(s.register(CTRL_REG1, T0 + SW_RESET_TIME), 0, "still 4-wire");
        write(&mut s, CTRL_REG1, &[SIM], T0 + SW_RESET_TIME);
        assert_eq!(s.register(CTRL_REG1, T0 + SW_RESET_TIME), SIM);
    }

    #[test]
    fn a_change_of_odr_restarts_the_sample_clock() {
        let mut s = configured(0x10);
        let t = T0 + TIME_HZ / 2;
        write(&mut s, CTRL_REG1, &[SIM | 0x50], t);
        assert_eq!(s.register(STATUS, t + P75 - 1), 0);
        assert_eq!(s.register(STATUS, t + P75), P_DA | T_DA);
        write(&mut s, CTRL_REG1, &[SIM], t + P75);
        s.advance(t + TIME_HZ);
        assert_eq!(s.samples_made(), 1, "power-down stops it");
    }

    /// Plays `writes` (a table of fcu-core's) at `now`.
    fn play(s: &mut Lps22hb, writes: &[fcu_core::imu::registers::RegWrite], now: Time) {
        for w in writes {
            write(s, w.addr, &[w.value], now);
        }
    }

    #[test]
    fn the_cores_boot_sequence_sets_the_flight_configuration_and_the_burst_reads_a_fresh_sample() {
        use fcu_core::baro::registers as core;
        let mut s = Lps22hb::new();
        s.set_pressure_pa(101_325.0).unwrap();
        s.set_temperature_c(25.0).unwrap();
        play(&mut s, &core::INTERFACE, T0);
        let settled = T0 + Time::from(core::RESET_SETTLE_MS) * MS;
        play(&mut s, &core::AFTER_RESET, settled);
        assert_eq!(read(&mut s, WHO_AM_I, 1, settled), [0xB1]);
        play(&mut s, &core::CONFIG, settled);
        assert_eq!(
            (s.register(CTRL_REG1, settled), s.register(CTRL_REG2, settled)),
            (0x5F, 0x18),
            "75 Hz, ODR/20, BDU, 3-wire; IF_ADD_INC, I2C off"
        );
        assert_eq!(s.unexpected_writes(), 0);
        assert!(!s.i2c_enabled());
        assert_eq!(read(&mut s, STATUS, 1, settled + P75 - 1), [0], "no sample before one 75 Hz period");
        let burst = read(&mut s, core::BURST_START, core::BURST_LEN, settled + P75);
        let raw = fcu_core::baro::decode_burst(&burst.clone().try_into().unwrap());
        assert!(raw.pressure_fresh(), "{burst:02x?}");
        assert_eq!((raw.pressure_pa(), raw.temperature_c()), (101_325.0, 25.0), "the filter starts at the first sample");
        let reads = s.pressure_reads();
        assert_eq!((reads.reads, reads.fresh, reads.lost), (1, 1, 0));
        assert_eq!(reads.last, Some((settled + P75, 4_150_272)));
    }

    #[test]
    fn without_the_settle_the_reset_swallows_the_3_wire_write_and_who_am_i_is_undriven() {
        use fcu_core::baro::registers as core;
        let mut s = Lps22hb::new();
        play(&mut s, &core::INTERFACE, T0);
        play(&mut s, &core::AFTER_RESET, T0 + 1);
        assert_eq!(s.unexpected_writes(), 1, "the write during the reset");
        assert_eq!(read(&mut s, WHO_AM_I, 1, T0 + SW_RESET_TIME), [UNDRIVEN], "still 4-wire");
    }

    #[test]
    fn a_burst_from_status_at_80_hz_reads_every_75_hz_sample_once() {
        let mut s = configured(0x50 | EN_LPFP | LPFP_CFG | BDU);
        write(&mut s, CTRL_REG2, &[IF_ADD_INC | I2C_DIS], T0);
        let period_80 = TIME_HZ / 80;
        for k in 1..=80 {
            read(&mut s, STATUS, 6, T0 + k * period_80);
        }
        let reads = s.pressure_reads();
        assert_eq!(s.samples_made(), 75);
        assert_eq!(reads.reads, 80);
        assert_eq!((reads.fresh, reads.lost), (75, 0), "each sample read once, as new, and none lost");
        // At 70 Hz, slower than the part, samples replace unread ones.
        let mut s = configured(0x50 | BDU);
        for k in 1..=70 {
            read(&mut s, STATUS, 6, T0 + k * (TIME_HZ / 70));
        }
        assert!(s.pressure_reads().lost >= 4, "{:?}", s.pressure_reads());
    }

    #[test]
    fn a_read_of_the_low_bytes_only_with_bdu_loses_the_samples_it_holds_back() {
        let mut s = configured(0x50 | BDU);
        read(&mut s, PRESS_OUT_XL, 2, T0 + P75);
        read(&mut s, PRESS_OUT_H, 1, T0 + 5 * P75);
        let reads = s.pressure_reads();
        // The MSB read completes the first sample's word; of the four made while it was held,
        // the newest lands (new, P_DA set), the three before it never reach the registers.
        assert_eq!((reads.reads, reads.fresh, reads.lost), (1, 0, 3));
        assert_eq!(s.register(STATUS, T0 + 5 * P75) & P_DA, P_DA);
    }

    #[test]
    fn a_change_of_lc_en_while_converting_is_ignored_and_counted() {
        let mut s = configured(0);
        write(&mut s, RES_CONF, &[LC_EN], T0);
        assert_eq!((s.register(RES_CONF, T0), s.unexpected_writes()), (LC_EN, 0), "in power-down it is taken");
        let mut s = configured(0x50);
        write(&mut s, RES_CONF, &[LC_EN], T0);
        assert_eq!((s.register(RES_CONF, T0), s.unexpected_writes()), (0, 1), "at 75 Hz it is not");
        write(&mut s, RES_CONF, &[0], T0);
        assert_eq!(s.unexpected_writes(), 1, "writing the value it has changes nothing");
    }
}
