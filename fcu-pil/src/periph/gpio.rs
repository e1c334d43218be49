//! GPIO ports (RM0368 §8), one [`Gpio`] per port: A at 0x4002_0000 … H at 0x4002_1C00.
//!
//! Modelled: MODER, OTYPER, OSPEEDR (stored, no timing effect), PUPDR, IDR, ODR, BSRR, AFRL,
//! AFRH. Not modelled: LCKR (the configuration lock), an [`Unmodelled`] error.
//!
//! Input levels: the board drives pins with [`Gpio::set_external`]. IDR, per pin (RM0368 §8.3, I/O configurations):
//! - input or alternate-function mode: the external level when driven, else the pull-up (1) or
//!   pull-down (0) level, else the pin floats: read as 0 and counted in
//!   [`Gpio::floating_reads`] / [`Gpio::floating_pins`];
//! - general-purpose output, push-pull: the ODR bit; open-drain: 0 when ODR is 0, else (the
//!   driver is off) as for an input;
//! - analog mode: 0 ("the Schmitt trigger input is disabled … read access to IDR returns 0").
//!
//! Alternate functions (RM0368 §8.3.2 "I/O pin multiplexer and mapping", §8.3.7 "I/O alternate
//! function input/output"): a pin reaches a peripheral only in alternate-function mode (MODER =
//! 10) with that peripheral's AF number in AFRL/AFRH; the multiplexer connects one alternate
//! function to a pin at a time, for its input as for its output. [`Gpio::routes`] answers that
//! question for the board, which connects (or not) each peripheral to its pins. The output a
//! peripheral drives on a pin is not seen here: the board should `set_external` such a pin if the
//! firmware reads it.
//!
//! Reset values (RM0368 §8.4, register descriptions): MODER A 0xA800_0000 (PA13/14/15 SWD/JTAG), B 0x0000_0280
//! (PB3/PB4), others 0; OSPEEDR A 0x0C00_0000 (PA13 very high), B 0x0000_00C0 (PB3 very high),
//! others 0; PUPDR A 0x6400_0000 (PA13 up, PA14 down, PA15 up), B 0x0000_0100 (PB4 up), others
//! 0. The SVD (PAC `gpioa/ospeedr.rs`) gives GPIOA.OSPEEDR a reset value of 0; the RM's
//! 0x0C00_0000 is used here.

use super::{Clocks, Peripheral, Time, Unmodelled};

/// Base address of a port ('A'..='E', 'H'), RM0368 memory map.
pub const fn base(port: char) -> Option<u32> {
    let index = match port.to_ascii_uppercase() {
        'A' => 0,
        'B' => 1,
        'C' => 2,
        'D' => 3,
        'E' => 4,
        'H' => 7,
        _ => return None,
    };
    Some(0x4002_0000 + 0x400 * index)
}

/// Size of each port's register block.
pub const SIZE: u32 = 0x400;

const MODER: u32 = 0x00;
const OTYPER: u32 = 0x04;
const OSPEEDR: u32 = 0x08;
const PUPDR: u32 = 0x0C;
const IDR: u32 = 0x10;
const ODR: u32 = 0x14;
const BSRR: u32 = 0x18;
const AFRL: u32 = 0x20;
const AFRH: u32 = 0x24;

/// MODER values.
pub const MODE_INPUT: u8 = 0b00;
pub const MODE_OUTPUT: u8 = 0b01;
pub const MODE_ALTERNATE: u8 = 0b10;
pub const MODE_ANALOG: u8 = 0b11;

/// One GPIO port.
#[derive(Clone, Debug)]
pub struct Gpio {
    name: String,
    reset: (u32, u32, u32),
    moder: u32,
    otyper: u32,
    ospeedr: u32,
    pupdr: u32,
    odr: u32,
    afrl: u32,
    afrh: u32,
    external: [Option<bool>; 16],
    floating_reads: u32,
    floating_pins: u16,
    pins_changed: bool,
}

impl Gpio {
    /// Port `port` ('A', 'B', 'C', …) at its reset values.
    pub fn new(port: char) -> Self {
        let port = port.to_ascii_uppercase();
        // (MODER, OSPEEDR, PUPDR) reset values, RM0368 GPIOx_MODER, _OSPEEDR, _PUPDR.
        let reset = match port {
            'A' => (0xA800_0000, 0x0C00_0000, 0x6400_0000),
            'B' => (0x0000_0280, 0x0000_00C0, 0x0000_0100),
            _ => (0, 0, 0),
        };
        Gpio {
            name: format!("GPIO{port}"),
            reset,
            moder: reset.0,
            otyper: 0,
            ospeedr: reset.1,
            pupdr: reset.2,
            odr: 0,
            afrl: 0,
            afrh: 0,
            external: [None; 16],
            floating_reads: 0,
            floating_pins: 0,
            pins_changed: false,
        }
    }

    /// Registers back to their reset values (an RCC reset pulse or a system reset). The board's
    /// external levels and the floating-read counters are kept.
    pub fn reset_registers(&mut self) {
        let before = self.pin_state();
        self.moder = self.reset.0;
        self.otyper = 0;
        self.ospeedr = self.reset.1;
        self.pupdr = self.reset.2;
        self.odr = 0;
        self.afrl = 0;
        self.afrh = 0;
        if before != self.pin_state() {
            self.pins_changed = true;
        }
    }

    /// The registers that decide what the pins do (see [`Gpio::take_pins_changed`]).
    fn pin_state(&self) -> [u32; 6] {
        [self.moder, self.otyper, self.pupdr, self.odr, self.afrl, self.afrh]
    }

    /// Port name, e.g. `GPIOB`.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Drives `pin` from outside (`Some(level)`) or leaves it undriven (`None`). Pins above 15
    /// are ignored.
    pub fn set_external(&mut self, pin: u8, level: Option<bool>) {
        if let Some(slot) = self.external.get_mut(usize::from(pin)) {
            *slot = level;
        }
    }

    /// MODER of `pin`: [`MODE_INPUT`], [`MODE_OUTPUT`], [`MODE_ALTERNATE`] or [`MODE_ANALOG`].
    pub fn mode(&self, pin: u8) -> u8 {
        field2(self.moder, pin)
    }

    /// Alternate function number (AFRL/AFRH) of `pin`, 0..=15.
    pub fn alternate(&self, pin: u8) -> u8 {
        match pin {
            0..=7 => ((self.afrl >> (4 * u32::from(pin))) & 0xF) as u8,
            8..=15 => ((self.afrh >> (4 * u32::from(pin - 8))) & 0xF) as u8,
            _ => 0,
        }
    }

    /// Whether `pin` is connected to alternate function `af`: alternate-function mode with `af`
    /// selected in AFRL/AFRH. Any other mode or AF number leaves the peripheral cut off from it.
    pub fn routes(&self, pin: u8, af: u8) -> bool {
        pin < 16 && self.mode(pin) == MODE_ALTERNATE && self.alternate(pin) == af
    }

    /// PUPDR of `pin`: 0 none, 1 pull-up, 2 pull-down.
    pub fn pull(&self, pin: u8) -> u8 {
        field2(self.pupdr, pin)
    }

    /// OSPEEDR of `pin` (stored only).
    pub fn speed(&self, pin: u8) -> u8 {
        field2(self.ospeedr, pin)
    }

    /// Whether `pin` is open-drain (OTYPER).
    pub fn open_drain(&self, pin: u8) -> bool {
        pin < 16 && (self.otyper >> pin) & 1 != 0
    }

    /// The level the port drives on `pin`: `Some` only in general-purpose output mode. Push-pull:
    /// the ODR bit. Open-drain: low when ODR is 0; when ODR is 1 the driver is off, so the pin is
    /// high only through the pull-up (`Some(true)`), else not driven (`None`).
    pub fn output_level(&self, pin: u8) -> Option<bool> {
        if pin >= 16 || self.mode(pin) != MODE_OUTPUT {
            return None;
        }
        let odr = (self.odr >> pin) & 1 != 0;
        if !self.open_drain(pin) || !odr {
            Some(odr)
        } else if self.pull(pin) == 0b01 {
            Some(true)
        } else {
            None
        }
    }

    /// True once after a write (or reset) that changed ODR, MODER, OTYPER, PUPDR, AFRL or AFRH,
    /// i.e. the levels, modes or alternate-function routing the board sees.
    pub fn take_pins_changed(&mut self) -> bool {
        std::mem::take(&mut self.pins_changed)
    }

    /// Number of IDR reads in which at least one pin in input or alternate-function mode was
    /// floating (neither driven nor pulled). IDR is read whole, so this counts pins the firmware
    /// may not look at: see [`Gpio::floating_pins`] to filter.
    pub fn floating_reads(&self) -> u32 {
        self.floating_reads
    }

    /// Mask of the pins that were floating in some IDR read.
    pub fn floating_pins(&self) -> u16 {
        self.floating_pins
    }

    /// IDR as the firmware would read it now, without counting floating pins.
    pub fn idr(&self) -> u16 {
        self.compute_idr().0
    }

    fn compute_idr(&self) -> (u16, u16) {
        let mut idr = 0u16;
        let mut floating = 0u16;
        for pin in 0..16u8 {
            let outside = self.external[usize::from(pin)].or(match self.pull(pin) {
                0b01 => Some(true),
                0b10 => Some(false),
                _ => None,
            });
            let level = match self.mode(pin) {
                MODE_OUTPUT => {
                    let odr = (self.odr >> pin) & 1 != 0;
                    if self.open_drain(pin) && odr {
                        outside
                    } else {
                        Some(odr)
                    }
                }
                MODE_ANALOG => Some(false),
                _ => outside,
            };
            match level {
                Some(true) => idr |= 1 << pin,
                Some(false) => {}
                None => floating |= 1 << pin,
            }
        }
        (idr, floating)
    }

    pub fn read(&mut self, offset: u32, _now: Time) -> Result<u32, Unmodelled> {
        Ok(match offset {
            MODER => self.moder,
            OTYPER => self.otyper,
            OSPEEDR => self.ospeedr,
            PUPDR => self.pupdr,
            IDR => {
                let (idr, floating) = self.compute_idr();
                if floating != 0 {
                    self.floating_reads = self.floating_reads.saturating_add(1);
                    self.floating_pins |= floating;
                }
                u32::from(idr)
            }
            ODR => self.odr,
            // RM0368 GPIOx_BSRR: BSRR bits are write-only; "a read to these bits returns the value 0x0000".
            BSRR => 0,
            AFRL => self.afrl,
            AFRH => self.afrh,
            _ => return Err(Unmodelled::offset(&self.name, offset, false)),
        })
    }

    pub fn write(&mut self, offset: u32, value: u32, _now: Time) -> Result<(), Unmodelled> {
        let before = self.pin_state();
        match offset {
            MODER => self.moder = value,
            OTYPER => {
                Unmodelled::check_bits(&format!("{}.OTYPER", self.name), value, 0xFFFF)?;
                self.otyper = value;
            }
            OSPEEDR => self.ospeedr = value,
            PUPDR => {
                // 0b11 is reserved (RM0368 GPIOx_PUPDR).
                let reserved = (0..16).filter(|&pin| field2(value, pin) == 0b11).fold(0u32, |m, pin| m | (0b11 << (2 * u32::from(pin))));
                if reserved != 0 {
                    return Err(Unmodelled::new(
                        format!("{}.PUPDR", self.name),
                        format!("write of {value:#010x} uses the reserved value 0b11 (bits {reserved:#010x})"),
                    ));
                }
                self.pupdr = value;
            }
            IDR => return Err(Unmodelled::new(format!("{}.IDR", self.name), format!("write of {value:#010x} to a read-only register"))),
            ODR => {
                Unmodelled::check_bits(&format!("{}.ODR", self.name), value, 0xFFFF)?;
                self.odr = value;
            }
            BSRR => {
                // RM0368 GPIOx_BSRR: "If both BSx and BRx are set, BSx has priority."
                let set = value & 0xFFFF;
                let reset = value >> 16;
                self.odr = (self.odr & !reset) | set;
            }
            AFRL => self.afrl = value,
            AFRH => self.afrh = value,
            _ => return Err(Unmodelled::offset(&self.name, offset, true)),
        }
        if before != self.pin_state() {
            self.pins_changed = true;
        }
        Ok(())
    }
}

/// The 2-bit field of `pin` in a MODER/OSPEEDR/PUPDR-style register (0 for pins above 15).
fn field2(reg: u32, pin: u8) -> u8 {
    if pin < 16 {
        ((reg >> (2 * u32::from(pin))) & 0b11) as u8
    } else {
        0
    }
}

impl Peripheral for Gpio {
    fn read(&mut self, offset: u32, now: Time, _clocks: Clocks) -> Result<u32, Unmodelled> {
        Gpio::read(self, offset, now)
    }

    fn write(&mut self, offset: u32, value: u32, now: Time, _clocks: Clocks) -> Result<(), Unmodelled> {
        Gpio::write(self, offset, value, now)
    }

    fn reset(&mut self) {
        // The pins' external levels (the radio) survive a reset of the port's registers.
        self.reset_registers();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(g: &mut Gpio, offset: u32) -> u32 {
        g.read(offset, 0).expect("modelled")
    }

    #[test]
    fn reset_values_differ_for_ports_a_and_b() {
        let mut a = Gpio::new('A');
        assert_eq!((read(&mut a, MODER), read(&mut a, OSPEEDR), read(&mut a, PUPDR)), (0xA800_0000, 0x0C00_0000, 0x6400_0000));
        let mut b = Gpio::new('B');
        assert_eq!((read(&mut b, MODER), read(&mut b, OSPEEDR), read(&mut b, PUPDR)), (0x0000_0280, 0x0000_00C0, 0x0000_0100));
        let mut c = Gpio::new('C');
        assert_eq!((read(&mut c, MODER), read(&mut c, OSPEEDR), read(&mut c, PUPDR)), (0, 0, 0));
        assert_eq!(read(&mut c, ODR), 0);
        assert_eq!(base('A'), Some(0x4002_0000));
        assert_eq!(base('C'), Some(0x4002_0800));
        assert_eq!(base('H'), Some(0x4002_1C00));
        assert_eq!(base('F'), None);
    }

    #[test]
    fn bsrr_set_wins_over_reset() {
        let mut g = Gpio::new('C');
        g.write(ODR, 0x0003, 0).unwrap();
        // Set pin 2, reset pin 0, and both set and reset pin 5.
        g.write(BSRR, (1 << 2) | (1 << 16) | (1 << 5) | (1 << 21), 0).unwrap();
        assert_eq!(read(&mut g, ODR), 0b10_0110);
        assert_eq!(read(&mut g, BSRR), 0, "write-only, reads 0");
    }

    #[test]
    fn push_pull_output_reads_odr_and_reports_its_level() {
        let mut g = Gpio::new('C');
        g.write(MODER, 0b01 << 26, 0).unwrap();
        assert!(g.take_pins_changed());
        assert!(!g.take_pins_changed(), "only once");
        assert_eq!(g.output_level(13), Some(false));
        g.write(BSRR, 1 << 13, 0).unwrap();
        assert!(g.take_pins_changed());
        assert_eq!(g.output_level(13), Some(true));
        g.set_external(13, Some(false));
        assert_eq!(read(&mut g, IDR) & (1 << 13), 1 << 13, "ODR wins on a push-pull output");
        g.write(BSRR, 1 << 13, 0).unwrap();
        assert!(!g.take_pins_changed(), "no change");
        assert_eq!(g.output_level(12), None, "input pin");
    }

    #[test]
    fn open_drain_released_pin_reads_the_line() {
        let mut g = Gpio::new('C');
        g.write(MODER, 0b01, 0).unwrap();
        g.write(OTYPER, 1, 0).unwrap();
        g.write(ODR, 1, 0).unwrap();
        assert_eq!(g.output_level(0), None);
        g.set_external(0, Some(false));
        assert_eq!(read(&mut g, IDR) & 1, 0);
        g.set_external(0, None);
        g.write(PUPDR, 0b01, 0).unwrap();
        assert_eq!(g.output_level(0), Some(true));
        assert_eq!(read(&mut g, IDR) & 1, 1);
    }

    #[test]
    fn input_reads_external_then_pull_then_floats() {
        let mut g = Gpio::new('C');
        // All of port C is input floating at reset: pin 0 pulled down, pin 1 pulled up.
        g.write(PUPDR, 0b01_10, 0).unwrap();
        g.set_external(2, Some(true));
        let idr = read(&mut g, IDR);
        assert_eq!(idr & 0b111, 0b110);
        assert_eq!(g.floating_reads(), 1);
        assert_eq!(g.floating_pins(), 0xFFF8);
        g.set_external(1, Some(false));
        assert_eq!(read(&mut g, IDR) & 0b111, 0b100, "a driven level beats the pull-up");
    }

    #[test]
    fn alternate_mode_pin_reads_like_an_input() {
        let mut g = Gpio::new('A');
        g.write(MODER, 0xA800_0000 | 0b10, 0).unwrap();
        g.write(AFRL, 1, 0).unwrap();
        g.write(PUPDR, 0x6400_0000 | 0b10, 0).unwrap();
        assert_eq!(g.mode(0), MODE_ALTERNATE);
        assert_eq!(g.alternate(0), 1);
        assert_eq!(read(&mut g, IDR) & 1, 0);
        g.set_external(0, Some(true));
        assert_eq!(read(&mut g, IDR) & 1, 1);
        g.write(AFRH, 7 << 4, 0).unwrap();
        assert_eq!(g.alternate(9), 7);
    }

    #[test]
    fn routing_needs_alternate_mode_and_the_af_number() {
        let mut g = Gpio::new('A');
        assert!(!g.routes(9, 7), "input at reset");
        g.write(AFRH, 7 << 4, 0).unwrap();
        assert!(g.take_pins_changed(), "an AF change is a routing change");
        assert!(!g.routes(9, 7), "AF7 selected, but the pin is still an input");
        g.write(MODER, 0xA800_0000 | (0b10 << 18), 0).unwrap();
        assert!(g.routes(9, 7));
        assert!(!g.routes(9, 1), "one alternate function at a time");
        g.write(AFRH, 8 << 4, 0).unwrap();
        assert!(g.take_pins_changed());
        assert!(!g.routes(9, 7));
        g.write(AFRH, 8 << 4, 0).unwrap();
        assert!(!g.take_pins_changed(), "no change");
        assert!(!g.routes(16, 0));
    }

    #[test]
    fn analog_pin_reads_zero_without_counting_as_floating() {
        let mut g = Gpio::new('C');
        g.write(MODER, 0xFFFF_FFFF, 0).unwrap();
        g.set_external(3, Some(true));
        assert_eq!(read(&mut g, IDR), 0);
        assert_eq!(g.floating_reads(), 0);
    }

    #[test]
    fn reset_restores_registers_but_keeps_external_levels() {
        let mut g = Gpio::new('B');
        g.set_external(1, Some(true));
        g.write(MODER, 0, 0).unwrap();
        g.write(ODR, 0xFF, 0).unwrap();
        g.take_pins_changed();
        g.reset_registers();
        assert!(g.take_pins_changed());
        assert_eq!(read(&mut g, MODER), 0x280);
        assert_eq!(read(&mut g, ODR), 0);
        assert_eq!(read(&mut g, IDR) & 0b10, 0b10);
    }

    #[test]
    fn lckr_reserved_bits_and_idr_writes_are_errors() {
        let mut g = Gpio::new('A');
        assert!(g.read(0x1C, 0).is_err());
        assert!(g.write(0x1C, 1 << 16, 0).is_err());
        assert!(g.write(IDR, 0, 0).is_err());
        assert!(g.write(ODR, 1 << 16, 0).is_err());
        assert!(g.write(OTYPER, 1 << 16, 0).is_err());
        assert!(g.write(PUPDR, 0b11, 0).is_err());
        assert!(g.read(0x28, 0).is_err());
    }

    #[test]
    fn out_of_range_pins_do_not_panic() {
        let mut g = Gpio::new('A');
        g.set_external(16, Some(true));
        assert_eq!(g.mode(200), 0);
        assert_eq!(g.alternate(16), 0);
        assert_eq!(g.output_level(31), None);
    }
}
