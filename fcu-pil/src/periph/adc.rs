//! ADC1 (RM0368 §11) at 0x4001_2000, with the ADC common registers at 0x4001_2300 (offset
//! [`COMMON_OFFSET`] from [`BASE`]): one model, offsets from [`BASE`].
//!
//! Modelled: single regular conversions started by SR SWSTART, as the HAL's `Adc::new`
//! (calibration against VREFINT) and `Adc::convert` do: CR2 ADON, SWSTART, ALIGN, EOCS (EXTSEL is
//! stored: it has no effect with EXTEN = 0); CR1 EOCIE and RES (12/10/8/6 bits); SMPR1/SMPR2;
//! SQR1 (L must be 0: one conversion) and SQR3's SQ1 (SQR2 and SQ13..16 are stored); SR EOC, STRT,
//! OVR (rc_w0); DR (reading it clears EOC); common CSR (read-only copy of ADC1's flags) and CCR
//! ADCPRE and TSVREFE. Not modelled (an [`Unmodelled`] error when set): continuous mode, scan,
//! discontinuous mode, DMA, external triggers, injected channels, the analog watchdog, overrun
//! interrupt, VBAT, and the registers behind them (JOFRx, HTR, LTR, JSQR, JDRx); the common
//! data register offset 0x308 is not modelled either (dual mode does not exist on the
//! single-ADC F401, and the SVD lists no register there).
//!
//! Timing (RM0368 §11.5 "Channel-wise programmable sampling time"): a conversion takes
//! (sampling cycles + resolution bits) ADC clock cycles, 3 + 12 = 15 at the fastest; ADCCLK =
//! PCLK2 / (2, 4, 6, 8) from CCR.ADCPRE. A conversion started with ADCCLK above 36 MHz (F401
//! datasheet, f_ADC max at VDDA 2.4–3.6 V) is an error. STRT sets at SWSTART; at the end DR is
//! written and EOC set; with EOCS = 1 an EOC still set from the previous conversion sets OVR
//! (RM0368 §11.8.1: overrun detection with DMA = 0 needs EOCS = 1); the new data replaces DR.
//!
//! Analog values: the board sets each channel's voltage with [`Adc::set_channel_volts`]; a
//! conversion of a channel never set is an error (the harness forgot an input). The result is
//! round(V / VDDA · (2^bits − 1)), clamped. Assumptions: VDDA = VREF+ = 3.3 V ([`VDDA_VOLTS`];
//! the reference converts with 3.3/4095, `docs/reference.md#battery`), VREFINT = 1.21 V (datasheet
//! typical), temperature sensor at 0.76 V (datasheet V25 typical: 25 °C). Channels: 0..=15
//! external (the machine should check the pin is in analog mode), 17 = VREFINT and 18 = the
//! temperature sensor, both only with CCR.TSVREFE = 1 (RM0368 §11.9/§11.10: on the F401 the
//! temperature sensor is on ADC1_IN18, shared with VBAT; IN16 is not connected, so a conversion
//! of channel 16 is an error).
//!
//! The battery (`docs/reference.md#pins`: PB1 = ADC1_IN9, divider 10 kΩ top, 20 kΩ bottom) is
//! seen at V_bat · 20/30: [`battery_pin_volts`].
//!
//! Diagnostics (not errors, see [`AdcDiagnostics`]): a conversion started less than
//! t_STAB = 3 µs after ADON (datasheet: ADC power-up time), or a VREFINT/temperature conversion
//! sampled for less than 10 µs or started less than 10 µs after TSVREFE (datasheet: T_S_vrefint,
//! T_S_temp and t_START minimums); the model converts these exactly anyway.
//!
//! Layout, reset values and access types from the `stm32f4` 0.16 PAC (`stm32f401/adc1/*.rs`,
//! `adc_common/ccr.rs`).

use super::{units_per_cycle, Clocks, Peripheral, Time, Unmodelled, TIME_HZ};

/// Base address of ADC1 (RM0368 memory map).
pub const BASE: u32 = 0x4001_2000;
/// Peripheral name used in error messages.
pub const NAME: &str = "ADC1";
/// Offset of the ADC common registers (0x4001_2300) from [`BASE`].
pub const COMMON_OFFSET: u32 = 0x300;
/// Name of the common block in error messages.
pub const COMMON_NAME: &str = "ADC_COMMON";

/// Address of the factory VREFINT calibration value in system memory (F401 datasheet,
/// "Internal reference voltage calibration values": VREFIN_CAL, raw data at 30 °C, VDDA = 3.3 V).
pub const VREFINT_CAL_ADDR: u32 = 0x1FFF_7A2A;
/// Assumed analog supply and reference voltage.
pub const VDDA_VOLTS: f64 = 3.3;
/// Internal reference voltage (datasheet typical).
pub const VREFINT_VOLTS: f64 = 1.21;
/// Temperature-sensor output at 25 °C (datasheet V25 typical); slope 2.5 mV/°C.
pub const TEMP_SENSOR_V25_VOLTS: f64 = 0.76;
/// F401 datasheet: f_ADC maximum (VDDA 2.4–3.6 V).
pub const ADC_CLOCK_MAX_HZ: u64 = 36_000_000;
/// ADC power-up time t_STAB (datasheet maximum).
pub const T_STAB: Time = 3 * TIME_HZ / 1_000_000;
/// Minimum sampling time and start-up time of VREFINT and the temperature sensor (datasheet).
pub const T_INTERNAL_MIN: Time = 10 * TIME_HZ / 1_000_000;

/// Channel of the battery sense input (PB1 = ADC1_IN9).
pub const BATTERY_CHANNEL: u8 = 9;
/// Battery divider ratio: 20 kΩ / (10 kΩ + 20 kΩ).
pub const BATTERY_DIVIDER: f64 = 20.0 / 30.0;
/// Channel of VREFINT.
pub const VREFINT_CHANNEL: u8 = 17;
/// Channel of the temperature sensor on the F401.
pub const TEMP_SENSOR_CHANNEL: u8 = 18;

/// Voltage at the ADC pin for a battery voltage.
pub fn battery_pin_volts(battery_volts: f64) -> f64 {
    battery_volts * BATTERY_DIVIDER
}

/// Ideal conversion result of `volts` with reference `vdda` at `bits` resolution.
fn code(volts: f64, vdda: f64, bits: u32) -> u16 {
    let full = f64::from((1u32 << bits) - 1);
    let x = (volts / vdda * full).round();
    if x.is_nan() || x <= 0.0 {
        0
    } else if x >= full {
        full as u16
    } else {
        x as u16
    }
}

/// The factory VREFINT calibration value the machine maps at [`VREFINT_CAL_ADDR`]: the 12-bit
/// conversion of [`VREFINT_VOLTS`] at VDDA = 3.3 V, so that the HAL's calibration
/// (3300 mV · VREFINT_CAL / VREFINT sample) gives back VDDA.
pub fn vrefint_cal() -> u16 {
    code(VREFINT_VOLTS, VDDA_VOLTS, 12)
}

const SR: u32 = 0x00;
const CR1: u32 = 0x04;
const CR2: u32 = 0x08;
const SMPR1: u32 = 0x0C;
const SMPR2: u32 = 0x10;
const SQR1: u32 = 0x2C;
const SQR2: u32 = 0x30;
const SQR3: u32 = 0x34;
const DR: u32 = 0x4C;
const CSR: u32 = COMMON_OFFSET;
const CCR: u32 = COMMON_OFFSET + 0x04;

const SR_EOC: u32 = 1 << 1;
const SR_STRT: u32 = 1 << 4;
const SR_OVR: u32 = 1 << 5;
/// AWD, EOC, JEOC, JSTRT, STRT, OVR: rc_w0 (PAC: ZERO_TO_MODIFY_FIELDS_BITMAP 0x3F).
const SR_FLAGS: u32 = 0x3F;

const CR1_EOCIE: u32 = 1 << 5;
const CR1_RES: u32 = 0b11 << 24;

const CR2_ADON: u32 = 1 << 0;
const CR2_EOCS: u32 = 1 << 10;
const CR2_ALIGN: u32 = 1 << 11;
const CR2_EXTSEL: u32 = 0xF << 24;
const CR2_SWSTART: u32 = 1 << 30;

const SMPR1_FIELDS: u32 = 0x07FF_FFFF;
const SMPR2_FIELDS: u32 = 0x3FFF_FFFF;
const SQR1_FIELDS: u32 = 0x00FF_FFFF;
const SQR1_L: u32 = 0xF << 20;
const SQR2_FIELDS: u32 = 0x3FFF_FFFF;
const SQR3_FIELDS: u32 = 0x3FFF_FFFF;

const CCR_ADCPRE: u32 = 0b11 << 16;
const CCR_VBATE: u32 = 1 << 22;
const CCR_TSVREFE: u32 = 1 << 23;

/// Sampling time in ADC cycles for SMPx codes 0..=7 (RM0368 ADC_SMPRx).
const SAMPLE_CYCLES: [u64; 8] = [3, 15, 28, 56, 84, 112, 144, 480];

/// Timing diagnostics, counts of conversions that real hardware would convert inaccurately.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AdcDiagnostics {
    /// Conversions started less than [`T_STAB`] after ADON was set.
    pub started_before_stabilisation: u32,
    /// VREFINT/temperature conversions sampled for less than 10 µs.
    pub internal_sample_too_short: u32,
    /// VREFINT/temperature conversions started less than 10 µs after TSVREFE was set.
    pub internal_started_too_soon: u32,
    /// SWSTART writes with ADON = 0 (RM: no conversion is launched) or during a conversion.
    pub ignored_starts: u32,
    /// Conversions that completed with EOC still set and EOCS = 1 (OVR set).
    pub overruns: u32,
}

#[derive(Clone, Copy, Debug)]
struct Conversion {
    end: Time,
    result: u16,
}

/// ADC1 and the ADC common registers.
#[derive(Clone, Debug)]
pub struct Adc {
    sr: u32,
    cr1: u32,
    cr2: u32,
    smpr1: u32,
    smpr2: u32,
    sqr1: u32,
    sqr2: u32,
    sqr3: u32,
    dr: u32,
    ccr: u32,
    conversion: Option<Conversion>,
    adon_at: Option<Time>,
    tsvrefe_at: Option<Time>,
    volts: [Option<f64>; 19],
    vdda: f64,
    diagnostics: AdcDiagnostics,
}

impl Default for Adc {
    fn default() -> Self {
        Adc::new()
    }
}

impl Adc {
    /// Reset state (all registers 0), VDDA 3.3 V, VREFINT 1.21 V, temperature sensor at 25 °C,
    /// external channels not set.
    pub fn new() -> Self {
        let mut volts = [None; 19];
        volts[usize::from(VREFINT_CHANNEL)] = Some(VREFINT_VOLTS);
        volts[usize::from(TEMP_SENSOR_CHANNEL)] = Some(TEMP_SENSOR_V25_VOLTS);
        Adc {
            sr: 0,
            cr1: 0,
            cr2: 0,
            smpr1: 0,
            smpr2: 0,
            sqr1: 0,
            sqr2: 0,
            sqr3: 0,
            dr: 0,
            ccr: 0,
            conversion: None,
            adon_at: None,
            tsvrefe_at: None,
            volts,
            vdda: VDDA_VOLTS,
            diagnostics: AdcDiagnostics::default(),
        }
    }

    /// Registers back to reset (RCC ADCRST, "common to all ADCs", or a system reset); analog
    /// inputs, VDDA and the diagnostics are kept.
    pub fn reset_registers(&mut self) {
        let (volts, vdda, diagnostics) = (self.volts, self.vdda, self.diagnostics);
        *self = Adc::new();
        self.volts = volts;
        self.vdda = vdda;
        self.diagnostics = diagnostics;
    }

    /// Sets the voltage at `channel` (0..=15 external; 17 VREFINT and 18 temperature sensor to
    /// override their defaults). Other channels are ignored.
    pub fn set_channel_volts(&mut self, channel: u8, volts: f64) {
        if channel != 16 {
            if let Some(slot) = self.volts.get_mut(usize::from(channel)) {
                *slot = Some(volts);
            }
        }
    }

    /// Takes the board's analog inputs (channel voltages and VDDA) from `other`, e.g. a copy kept
    /// across a system reset.
    pub fn copy_inputs_from(&mut self, other: &Adc) {
        self.volts = other.volts;
        self.vdda = other.vdda;
    }

    /// Sets VDDA (= VREF+); the factory calibration stays the one taken at 3.3 V.
    pub fn set_vdda(&mut self, volts: f64) {
        self.vdda = volts;
    }

    pub fn diagnostics(&self) -> AdcDiagnostics {
        self.diagnostics
    }

    /// The ADC interrupt line: EOC and EOCIE (the other sources are not modelled).
    pub fn irq_line(&self) -> bool {
        self.sr & SR_EOC != 0 && self.cr1 & CR1_EOCIE != 0
    }

    /// End of the conversion in progress.
    pub fn next_event(&self) -> Option<Time> {
        self.conversion.map(|c| c.end)
    }

    /// Completes a conversion due by `now` (its length was fixed at its start, so `clocks` is
    /// not used).
    pub fn advance(&mut self, now: Time, _clocks: Clocks) {
        self.complete(now);
    }

    fn complete(&mut self, now: Time) {
        if let Some(c) = self.conversion {
            if c.end <= now {
                self.conversion = None;
                if self.sr & SR_EOC != 0 && self.cr2 & CR2_EOCS != 0 {
                    self.sr |= SR_OVR;
                    self.diagnostics.overruns = self.diagnostics.overruns.saturating_add(1);
                }
                self.dr = u32::from(self.align(c.result));
                self.sr |= SR_EOC;
            }
        }
    }

    fn resolution_bits(&self) -> u32 {
        12 - 2 * ((self.cr1 & CR1_RES) >> 24)
    }

    /// DR layout (RM0368 "Data alignment"): right aligned, or left aligned to bit 15, except 6-bit
    /// left alignment which aligns to bit 7.
    fn align(&self, result: u16) -> u16 {
        if self.cr2 & CR2_ALIGN == 0 {
            result
        } else {
            let bits = self.resolution_bits();
            let shift = if bits == 6 { 2 } else { 16 - bits };
            result << shift
        }
    }

    /// `clocks` is not needed for a read (a conversion's length is fixed at its start); it is
    /// taken for a uniform interface with [`Adc::write`].
    pub fn read(&mut self, offset: u32, now: Time, _clocks: Clocks) -> Result<u32, Unmodelled> {
        self.complete(now);
        Ok(match offset {
            SR => self.sr,
            CR1 => self.cr1,
            CR2 => self.cr2,
            SMPR1 => self.smpr1,
            SMPR2 => self.smpr2,
            SQR1 => self.sqr1,
            SQR2 => self.sqr2,
            SQR3 => self.sqr3,
            DR => {
                self.sr &= !SR_EOC;
                self.dr
            }
            // ADC_CSR: ADC1's flags in bits 5:0.
            CSR => self.sr & SR_FLAGS,
            CCR => self.ccr,
            _ if offset >= COMMON_OFFSET => return Err(Unmodelled::offset(COMMON_NAME, offset - COMMON_OFFSET, false)),
            _ => return Err(Unmodelled::offset(NAME, offset, false)),
        })
    }

    /// `clocks` gives PCLK2 for the ADC clock of a conversion started by this write.
    pub fn write(&mut self, offset: u32, value: u32, now: Time, clocks: Clocks) -> Result<(), Unmodelled> {
        self.complete(now);
        match offset {
            SR => {
                Unmodelled::check_bits("ADC1.SR", value, SR_FLAGS)?;
                // rc_w0: writing 0 clears a flag, writing 1 leaves it.
                self.sr &= value | !SR_FLAGS;
            }
            CR1 => {
                Unmodelled::check_bits("ADC1.CR1", value, CR1_EOCIE | CR1_RES)?;
                self.cr1 = value;
            }
            CR2 => self.write_cr2(value, now, clocks)?,
            SMPR1 => {
                Unmodelled::check_bits("ADC1.SMPR1", value, SMPR1_FIELDS)?;
                self.smpr1 = value;
            }
            SMPR2 => {
                Unmodelled::check_bits("ADC1.SMPR2", value, SMPR2_FIELDS)?;
                self.smpr2 = value;
            }
            SQR1 => {
                Unmodelled::check_bits("ADC1.SQR1", value, SQR1_FIELDS)?;
                if value & SQR1_L != 0 {
                    return Err(Unmodelled::new(
                        "ADC1.SQR1",
                        format!("L = {}: regular sequences longer than one conversion are not modelled", (value & SQR1_L) >> 20),
                    ));
                }
                self.sqr1 = value;
            }
            SQR2 => {
                Unmodelled::check_bits("ADC1.SQR2", value, SQR2_FIELDS)?;
                self.sqr2 = value;
            }
            SQR3 => {
                Unmodelled::check_bits("ADC1.SQR3", value, SQR3_FIELDS)?;
                self.sqr3 = value;
            }
            DR => return Err(Unmodelled::new("ADC1.DR", format!("write of {value:#010x} to a read-only register"))),
            CSR => return Err(Unmodelled::new("ADC_COMMON.CSR", format!("write of {value:#010x} to a read-only register"))),
            CCR => {
                if value & CCR_VBATE != 0 {
                    return Err(Unmodelled::new(
                        "ADC_COMMON.CCR",
                        format!("write of {value:#010x} sets VBATE: the VBAT channel is not modelled"),
                    ));
                }
                Unmodelled::check_bits("ADC_COMMON.CCR", value, CCR_ADCPRE | CCR_TSVREFE)?;
                if value & CCR_TSVREFE != 0 && self.ccr & CCR_TSVREFE == 0 {
                    self.tsvrefe_at = Some(now);
                } else if value & CCR_TSVREFE == 0 {
                    self.tsvrefe_at = None;
                }
                self.ccr = value;
            }
            _ if offset >= COMMON_OFFSET => return Err(Unmodelled::offset(COMMON_NAME, offset - COMMON_OFFSET, true)),
            _ => return Err(Unmodelled::offset(NAME, offset, true)),
        }
        Ok(())
    }

    fn write_cr2(&mut self, value: u32, now: Time, clocks: Clocks) -> Result<(), Unmodelled> {
        // CONT, DMA, DDS, JEXTSEL, JEXTEN, JSWSTART and EXTEN are not modelled.
        Unmodelled::check_bits("ADC1.CR2", value, CR2_ADON | CR2_EOCS | CR2_ALIGN | CR2_EXTSEL | CR2_SWSTART)?;
        let was_on = self.cr2 & CR2_ADON != 0;
        // SWSTART is cleared by hardware as soon as the conversion starts: it is not stored.
        self.cr2 = value & !CR2_SWSTART;
        if value & CR2_ADON == 0 {
            // ADC off: power down, a conversion in progress is lost.
            self.adon_at = None;
            self.conversion = None;
        } else if !was_on {
            self.adon_at = Some(now);
        }
        if value & CR2_SWSTART != 0 {
            // RM0368 ADC_CR2: "This bit can be set only when ADON = 1 otherwise no conversion is
            // launched." A start during a conversion is ignored too.
            if value & CR2_ADON == 0 || self.conversion.is_some() {
                self.diagnostics.ignored_starts = self.diagnostics.ignored_starts.saturating_add(1);
            } else {
                self.start(now, clocks)?;
            }
        }
        Ok(())
    }

    fn start(&mut self, now: Time, clocks: Clocks) -> Result<(), Unmodelled> {
        let err = |what: String| Unmodelled::new("ADC1.CR2", what);
        let prescaler = 2 * (u64::from((self.ccr & CCR_ADCPRE) >> 16) + 1);
        let pclk2 = clocks.pclk2_hz;
        let adc_hz = pclk2 / prescaler;
        if pclk2 % prescaler != 0 {
            return Err(err(format!("ADC clock PCLK2 {pclk2} Hz / {prescaler} is not a whole number of Hz")));
        }
        if adc_hz > ADC_CLOCK_MAX_HZ {
            return Err(err(format!(
                "ADC clock {} MHz above the F401's 36 MHz maximum (PCLK2 {} MHz / {prescaler}: ADC_CCR.ADCPRE)",
                adc_hz as f64 / 1e6,
                pclk2 as f64 / 1e6
            )));
        }
        let Some(units) = units_per_cycle(adc_hz) else {
            return Err(err(format!("ADC clock {adc_hz} Hz does not divide the emulator's 336 MHz time base")));
        };
        let channel = (self.sqr3 & 0x1F) as u8;
        let internal = channel == VREFINT_CHANNEL || channel == TEMP_SENSOR_CHANNEL;
        if channel == 16 {
            return Err(err(
                "conversion of channel 16: RM0368 connects the F401's temperature sensor to ADC1_IN18; IN16 is not connected".into()
            ));
        }
        if channel > 18 {
            return Err(err(format!("conversion of channel {channel}: the F401's ADC1 has channels 0..=18")));
        }
        if internal && self.ccr & CCR_TSVREFE == 0 {
            return Err(err(format!("conversion of internal channel {channel} with ADC_CCR.TSVREFE = 0: the input is not connected")));
        }
        let Some(volts) = self.volts[usize::from(channel)] else {
            return Err(err(format!("conversion of channel {channel}, whose voltage the board never set")));
        };
        let smp = if channel >= 10 { self.smpr1 >> (3 * u32::from(channel - 10)) } else { self.smpr2 >> (3 * u32::from(channel)) } & 0b111;
        let sample_cycles = SAMPLE_CYCLES[smp as usize];
        let bits = self.resolution_bits();
        let duration = (sample_cycles + u64::from(bits)) * units;

        if self.adon_at.is_some_and(|t| now < t + T_STAB) {
            self.diagnostics.started_before_stabilisation = self.diagnostics.started_before_stabilisation.saturating_add(1);
        }
        if internal {
            if sample_cycles * units < T_INTERNAL_MIN {
                self.diagnostics.internal_sample_too_short = self.diagnostics.internal_sample_too_short.saturating_add(1);
            }
            if self.tsvrefe_at.is_some_and(|t| now < t + T_INTERNAL_MIN) {
                self.diagnostics.internal_started_too_soon = self.diagnostics.internal_started_too_soon.saturating_add(1);
            }
        }
        self.sr |= SR_STRT;
        self.conversion = Some(Conversion { end: now + duration, result: code(volts, self.vdda, bits) });
        Ok(())
    }
}

impl Peripheral for Adc {
    fn read(&mut self, offset: u32, now: Time, clocks: Clocks) -> Result<u32, Unmodelled> {
        Adc::read(self, offset, now, clocks)
    }

    fn write(&mut self, offset: u32, value: u32, now: Time, clocks: Clocks) -> Result<(), Unmodelled> {
        Adc::write(self, offset, value, now, clocks)
    }

    fn next_event(&self) -> Option<Time> {
        Adc::next_event(self)
    }

    fn advance(&mut self, now: Time, clocks: Clocks) {
        Adc::advance(self, now, clocks)
    }

    fn irq_line(&self, _line: usize) -> bool {
        Adc::irq_line(self)
    }

    fn reset(&mut self) {
        self.reset_registers();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const US: Time = TIME_HZ / 1_000_000;

    fn write(adc: &mut Adc, offset: u32, value: u32, now: Time) {
        adc.write(offset, value, now, Clocks::PLL_84_MHZ).expect("modelled");
    }

    /// ADCPRE = /4 (21 MHz), channel `ch` with sample code `smp`, ADON, then SWSTART at `t`.
    fn convert(adc: &mut Adc, ch: u32, smp: u32, t: Time) {
        write(adc, CCR, (1 << 16) | (adc.ccr & CCR_TSVREFE), t);
        write(adc, SQR3, ch, t);
        if ch >= 10 {
            write(adc, SMPR1, smp << (3 * (ch - 10)), t);
        } else {
            write(adc, SMPR2, smp << (3 * ch), t);
        }
        let keep = adc.cr2 & (CR2_ALIGN | CR2_EOCS);
        write(adc, CR2, keep | CR2_ADON, t);
        write(adc, CR2, keep | CR2_ADON | CR2_SWSTART, t + T_STAB);
    }

    #[test]
    fn reset_values_are_zero() {
        let mut adc = Adc::new();
        for offset in [SR, CR1, CR2, SMPR1, SMPR2, SQR1, SQR2, SQR3, DR, CSR, CCR] {
            assert_eq!(adc.read(offset, 0, Clocks::PLL_84_MHZ), Ok(0), "offset {offset:#x}");
        }
    }

    #[test]
    fn conversion_takes_sample_plus_12_adc_cycles() {
        let mut adc = Adc::new();
        adc.set_channel_volts(BATTERY_CHANNEL, 1.65);
        convert(&mut adc, 9, 0, 0);
        let start = T_STAB;
        assert_eq!(adc.read(SR, start, Clocks::PLL_84_MHZ).unwrap() & (SR_STRT | SR_EOC), SR_STRT);
        assert_eq!(adc.read(CR2, start, Clocks::PLL_84_MHZ).unwrap() & CR2_SWSTART, 0, "SWSTART cleared by hardware");
        // 21 MHz ADC clock = 16 units per cycle; 3 + 12 cycles.
        let end = start + 15 * 16;
        assert_eq!(adc.next_event(), Some(end));
        assert_eq!(adc.read(SR, end - 1, Clocks::PLL_84_MHZ).unwrap() & SR_EOC, 0);
        assert_eq!(adc.read(SR, end, Clocks::PLL_84_MHZ).unwrap() & (SR_STRT | SR_EOC), SR_STRT | SR_EOC);
        assert_eq!(adc.read(DR, end, Clocks::PLL_84_MHZ), Ok(2048), "round(1.65 / 3.3 x 4095) = round(2047.5)");
        assert_eq!(adc.read(SR, end, Clocks::PLL_84_MHZ).unwrap() & SR_EOC, 0, "reading DR clears EOC");
        assert_eq!(adc.diagnostics(), AdcDiagnostics::default());
    }

    #[test]
    fn adc_clock_above_36_mhz_is_an_error() {
        let mut adc = Adc::new();
        adc.set_channel_volts(0, 1.0);
        // ADCPRE = /2 (reset value): 84 MHz / 2 = 42 MHz.
        write(&mut adc, CR2, CR2_ADON, 0);
        let e = adc.write(CR2, CR2_ADON | CR2_SWSTART, T_STAB, Clocks::PLL_84_MHZ).unwrap_err();
        assert!(e.what.contains("ADC clock 42 MHz above the F401's 36 MHz maximum"), "{e}");
    }

    #[test]
    fn result_is_clamped_and_follows_vdda() {
        let mut adc = Adc::new();
        adc.set_channel_volts(3, 4.0);
        convert(&mut adc, 3, 0, 0);
        assert_eq!(adc.read(DR, 1_000 * US, Clocks::PLL_84_MHZ), Ok(4095));
        adc.set_channel_volts(3, -0.2);
        write(&mut adc, CR2, CR2_ADON | CR2_SWSTART, 1_000 * US);
        assert_eq!(adc.read(DR, 2_000 * US, Clocks::PLL_84_MHZ), Ok(0));
    }

    #[test]
    fn left_alignment_and_lower_resolutions() {
        let mut adc = Adc::new();
        adc.set_channel_volts(1, 3.3);
        write(&mut adc, CR1, 0b01 << 24, 0); // 10 bits
        write(&mut adc, CR2, CR2_ALIGN, 0);
        convert(&mut adc, 1, 0, 0);
        assert_eq!(adc.next_event(), Some(T_STAB + 13 * 16), "3 + 10 cycles");
        assert_eq!(adc.read(DR, 1_000 * US, Clocks::PLL_84_MHZ), Ok(1023 << 6));
        write(&mut adc, CR1, 0b11 << 24, 1_000 * US); // 6 bits, left aligned to bit 7
        write(&mut adc, CR2, CR2_ADON | CR2_ALIGN | CR2_SWSTART, 1_000 * US);
        assert_eq!(adc.read(DR, 2_000 * US, Clocks::PLL_84_MHZ), Ok(63 << 2));
    }

    #[test]
    fn vrefint_reads_the_calibration_value_at_3v3() {
        let mut adc = Adc::new();
        write(&mut adc, CCR, CCR_TSVREFE, 0);
        convert(&mut adc, 17, 7, 20 * US);
        let sample = adc.read(DR, 1_000 * US, Clocks::PLL_84_MHZ).unwrap();
        assert_eq!(sample, u32::from(vrefint_cal()));
        assert!((1490..=1510).contains(&vrefint_cal()), "1.21 V / 3.3 V x 4095 = 1501.5");
        // The HAL's VDDA estimate: 3300 x VREFINT_CAL / sample.
        assert_eq!(3300 * u32::from(vrefint_cal()) / sample, 3300);
        // At VDDA = 3.0 V the same VREFINT converts higher and the HAL computes ~3000 mV.
        adc.set_vdda(3.0);
        write(&mut adc, CR2, CR2_ADON | CR2_SWSTART, 1_000 * US);
        let sample = adc.read(DR, 2_000 * US, Clocks::PLL_84_MHZ).unwrap();
        assert!((2995..=3005).contains(&(3300 * u32::from(vrefint_cal()) / sample)));
        assert_eq!(adc.diagnostics(), AdcDiagnostics::default(), "480 cycles at 21 MHz = 22.9 µs");
    }

    #[test]
    fn internal_channels_need_tsvrefe_and_channel_16_is_not_connected() {
        let mut adc = Adc::new();
        write(&mut adc, CCR, 1 << 16, 0);
        write(&mut adc, CR2, CR2_ADON, 0);
        write(&mut adc, SQR3, 17, 0);
        assert!(adc.write(CR2, CR2_ADON | CR2_SWSTART, 10 * US, Clocks::PLL_84_MHZ).is_err());
        write(&mut adc, CCR, (1 << 16) | CCR_TSVREFE, 10 * US);
        write(&mut adc, SQR3, 16, 10 * US);
        assert!(adc.write(CR2, CR2_ADON | CR2_SWSTART, 30 * US, Clocks::PLL_84_MHZ).is_err());
        write(&mut adc, SQR3, 18, 30 * US);
        write(&mut adc, SMPR1, 7 << 24, 30 * US);
        write(&mut adc, CR2, CR2_ADON | CR2_SWSTART, 30 * US);
        assert_eq!(adc.read(DR, 1_000 * US, Clocks::PLL_84_MHZ), Ok(u32::from(code(0.76, 3.3, 12))));
    }

    #[test]
    fn unset_channel_is_an_error() {
        let mut adc = Adc::new();
        write(&mut adc, CCR, 1 << 16, 0);
        write(&mut adc, CR2, CR2_ADON, 0);
        write(&mut adc, SQR3, 5, 0);
        assert!(adc.write(CR2, CR2_ADON | CR2_SWSTART, 10 * US, Clocks::PLL_84_MHZ).is_err());
    }

    #[test]
    fn eoc_interrupt_line_needs_eocie() {
        let mut adc = Adc::new();
        adc.set_channel_volts(9, 1.0);
        write(&mut adc, CR1, CR1_EOCIE, 0);
        convert(&mut adc, 9, 0, 0);
        assert!(!adc.irq_line());
        adc.advance(1_000 * US, Clocks::PLL_84_MHZ);
        assert!(adc.irq_line());
        // rc_w0: writing 1 keeps EOC, writing 0 clears it.
        write(&mut adc, SR, SR_FLAGS, 1_000 * US);
        assert!(adc.irq_line());
        write(&mut adc, SR, SR_FLAGS & !SR_EOC, 1_000 * US);
        assert!(!adc.irq_line());
        assert_eq!(adc.read(SR, 1_000 * US, Clocks::PLL_84_MHZ), Ok(SR_STRT));
        assert_eq!(adc.read(CSR, 1_000 * US, Clocks::PLL_84_MHZ), Ok(SR_STRT));
    }

    #[test]
    fn start_without_adon_is_ignored_and_early_start_is_counted() {
        let mut adc = Adc::new();
        adc.set_channel_volts(0, 1.0);
        write(&mut adc, CCR, 1 << 16, 0);
        write(&mut adc, CR2, CR2_SWSTART, 0);
        assert_eq!(adc.next_event(), None);
        write(&mut adc, CR2, CR2_ADON, 10);
        write(&mut adc, CR2, CR2_ADON | CR2_SWSTART, 20);
        assert!(adc.next_event().is_some());
        write(&mut adc, CR2, CR2_ADON | CR2_SWSTART, 30);
        let d = adc.diagnostics();
        assert_eq!((d.ignored_starts, d.started_before_stabilisation), (2, 1));
    }

    #[test]
    fn overrun_sets_ovr_only_with_eocs() {
        let mut adc = Adc::new();
        adc.set_channel_volts(0, 1.0);
        convert(&mut adc, 0, 0, 0);
        write(&mut adc, CR2, CR2_ADON | CR2_SWSTART, 100 * US);
        assert_eq!(adc.read(SR, 200 * US, Clocks::PLL_84_MHZ).unwrap() & SR_OVR, 0, "EOCS = 0: no overrun detection");
        write(&mut adc, CR2, CR2_ADON | CR2_EOCS | CR2_SWSTART, 200 * US);
        assert_eq!(adc.read(SR, 300 * US, Clocks::PLL_84_MHZ).unwrap() & SR_OVR, SR_OVR);
        assert_eq!(adc.diagnostics().overruns, 1);
    }

    #[test]
    fn unmodelled_features_are_errors() {
        let mut adc = Adc::new();
        for (offset, value) in [
            (CR2, 1 << 1),
            (CR2, 1 << 8),
            (CR2, 1 << 28),
            (CR1, 1 << 8),
            (CR1, 1 << 23),
            (CCR, CCR_VBATE),
            (SQR1, 1 << 20),
            (DR, 0),
            (CSR, 0),
        ] {
            assert!(adc.write(offset, value, 0, Clocks::PLL_84_MHZ).is_err(), "{offset:#x} {value:#x}");
        }
        assert!(adc.read(0x24, 0, Clocks::PLL_84_MHZ).is_err(), "HTR");
        assert!(adc.read(COMMON_OFFSET + 8, 0, Clocks::PLL_84_MHZ).is_err(), "CDR");
    }

    #[test]
    fn reset_keeps_inputs() {
        let mut adc = Adc::new();
        adc.set_channel_volts(9, 2.0);
        write(&mut adc, CCR, 1 << 16, 0);
        adc.reset_registers();
        assert_eq!(adc.read(CCR, 0, Clocks::PLL_84_MHZ), Ok(0));
        convert(&mut adc, 9, 0, 0);
        assert_eq!(adc.read(DR, 1_000 * US, Clocks::PLL_84_MHZ), Ok(u32::from(code(2.0, 3.3, 12))));
    }

    #[test]
    fn battery_divider_is_two_thirds() {
        assert!((battery_pin_volts(4.2) - 2.8).abs() < 1e-12);
    }
}
