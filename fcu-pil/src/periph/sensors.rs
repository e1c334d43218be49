//! The three sensors on the board's SPI2 bus (LSM6DSL, LIS2MDL, LPS22HB), modelled at the level
//! of their serial interface: chip select, command byte, register auto-increment, 3-wire versus
//! 4-wire answers, boot and reset times, and the I²C interface that stays enabled until it is
//! switched off.
//!
//! Facts are the datasheets' as summarised in `fcu-core/src/imu/registers.rs` and
//! `docs/reference.md#sensors`; register maps and reset values are the datasheets'
//! (LSM6DSL DocID030071 §9, LIS2MDL DocID027955 §8, LPS22HB DocID027083 §9).
//!
//! # The ST SPI protocol, as modelled
//! - CS falling starts a transaction, CS rising ends it (whatever byte was in flight is dropped).
//! - The first byte is the command: bit 7 = 1 for a read, bits 6..0 the register address.
//! - A write's following bytes are data, stored at the address, which then increments if the
//!   sensor's increment rule says so (LSM6DSL CTRL3_C.IF_INC, LPS22HB CTRL_REG2.IF_ADD_INC,
//!   LIS2MDL always: its command byte has no increment bit, all 7 address bits are used).
//! - A read's following bytes are driven by the sensor, from the address on, same increment rule.
//!   The sensor drives the shared data line (SDA/SDI/SDO pin) only in 3-wire mode (LSM6DSL
//!   CTRL3_C.SIM = 1, LPS22HB CTRL_REG1.SIM = 1, LIS2MDL unless CFG_REG_C.4WSPI = 1). In 4-wire
//!   mode it answers on its separate SDO pin, which is not connected on this board: the MCU then
//!   reads an undriven line, modelled as [`UNDRIVEN`] (0x00). Writes work in both modes (the data
//!   line is the sensors' SDI input either way).
//! - Once a sensor has started driving the line in a read it keeps driving it until CS rises
//!   (datasheets: SDO is disabled from CS rising, t_dis(SO)); [`SpiDevice::holds_line`] says so,
//!   so the SPI model can count bus contention.
//!
//! # Timing assumptions (the datasheets do not all give them; stated here)
//! - LSM6DSL: power-on boot and the BOOT bit take [`LSM6DSL_BOOT`] = 15 ms (the "boot time" of
//!   ST's own examples for this sensor family; Zephyr waits a 35 ms turn-on time after BOOT, which
//!   is the data settling time, not the interface's); SW_RESET takes [`SW_RESET_TIME`] = 50 µs
//!   (assumption), during which the bit reads 1 but the bus works.
//! - LIS2MDL: power-on boot and REBOOT take [`LIS2MDL_BOOT`] = 20 ms (ST examples' BOOT_TIME,
//!   assumption); SOFT_RST as SW_RESET above.
//! - LPS22HB: power-on boot and BOOT take [`LPS22HB_BOOT`] = 4.5 ms (assumption); SWRESET as
//!   SW_RESET above, except that a write while it runs is ignored (`sensors/lps22hb.rs`).
//! - During a boot the sensor ignores the bus entirely: a transaction started during it is ignored
//!   to its end, and the line is undriven.
//! - LSM6DSL and LIS2MDL: output registers change only between transactions (values given
//!   during a transaction are applied at CS rising), i.e. a burst always reads one coherent
//!   sample, as with BDU = 1. The LPS22HB samples on its own clock, mid-transaction too, and
//!   models BDU as its datasheet gives it (`sensors/lps22hb.rs`).

use super::Time;

/// The value the MCU reads from a line nobody drives (a sensor in 4-wire mode, a silent or
/// booting sensor, no sensor selected). Chosen, not measured: a floating line could read anything.
pub const UNDRIVEN: u8 = 0x00;

/// [`Time`] units in a millisecond and a microsecond.
const MS: Time = super::TIME_HZ / 1000;
const US: Time = super::TIME_HZ / 1_000_000;

/// LSM6DSL power-on boot / BOOT duration (assumption, see the module documentation).
pub const LSM6DSL_BOOT: Time = 15 * MS;
/// LIS2MDL power-on boot / REBOOT duration (assumption).
pub const LIS2MDL_BOOT: Time = 20 * MS;
/// LPS22HB power-on boot / BOOT duration (assumption).
pub const LPS22HB_BOOT: Time = 45 * MS / 10;
/// Software reset duration of all three (assumption).
pub const SW_RESET_TIME: Time = 50 * US;

/// What the SPI master needs from a device on the bus.
pub trait SpiDevice {
    /// Chip select went low.
    fn cs_fall(&mut self, now: Time);
    /// Chip select went high: the transaction ends.
    fn cs_rise(&mut self, now: Time);
    /// The byte the device drives on the shared data line during the byte being clocked now, if
    /// it drives it (no side effects: [`SpiDevice::clock`] follows).
    fn output(&self, now: Time) -> Option<u8>;
    /// A whole byte was clocked while selected; `line` is what was on the data line.
    fn clock(&mut self, line: u8, now: Time);
    /// Whether the device is driving the shared line now (it has started answering a read in
    /// 3-wire mode and CS is still low).
    fn holds_line(&self, now: Time) -> bool;
    /// Whether the device's I²C interface is still enabled (then SPI traffic to the other
    /// devices, on the shared SCL/SDA lines, looks like I²C traffic to it).
    fn i2c_enabled(&self) -> bool;
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    /// CS high.
    Idle,
    /// CS low but the sensor was booting when it fell: the transaction is ignored.
    Ignored,
    /// Waiting for the command byte.
    Command,
    /// Write data phase, next register.
    Write(u8),
    /// Read data phase, next register; `started` once a data byte was clocked.
    Read { addr: u8, started: bool },
}

/// What sets the three sensors' serial interfaces apart: the register map and the control
/// register that holds the software-reset and reboot bits (the datasheets' register tables).
#[derive(Debug)]
struct Spec {
    /// WHO_AM_I's address and the value the datasheet gives it.
    who_am_i: (u8, u8),
    /// The register holding the software-reset and reboot bits.
    control: u8,
    /// Software reset: the registers go back to their reset values; the bit reads 1 for
    /// [`SW_RESET_TIME`], while the bus works.
    sw_reset: u8,
    /// Reboot of the trimming memory: the interface is unavailable for `boot_time`.
    boot: u8,
    /// Further control bits that clear themselves (never read back as written).
    self_clearing: u8,
    /// Power-on boot and reboot duration.
    boot_time: Time,
    /// Read-write registers whose reset value is not 0: (address, value).
    reset_values: &'static [(u8, u8)],
    access: fn(u8) -> Access,
}

/// The serial-interface state and the register file every sensor shares; `O` is the sensor's
/// output sample.
#[derive(Clone, Debug)]
struct Port<O> {
    spec: &'static Spec,
    phase: Phase,
    /// The bus is ignored until then (power-on boot, BOOT/REBOOT).
    busy_until: Time,
    /// The software-reset bit reads 1 until then.
    reset_until: Time,
    silent: bool,
    who_am_i_override: Option<u8>,
    unexpected_writes: u32,
    regs: [u8; 128],
    /// Output given during a transaction, applied when CS rises.
    pending: Option<O>,
}

impl<O> Port<O> {
    /// Powered on at time 0: booting for the spec's boot time.
    fn new(spec: &'static Spec) -> Self {
        let mut p = Port {
            spec,
            phase: Phase::Idle,
            busy_until: spec.boot_time,
            reset_until: 0,
            silent: false,
            who_am_i_override: None,
            unexpected_writes: 0,
            regs: [0; 128],
            pending: None,
        };
        p.reset_registers();
        p
    }

    fn ready(&self, now: Time) -> bool {
        now >= self.busy_until
    }

    fn reg(&self, addr: u8) -> u8 {
        self.regs[usize::from(addr & 0x7F)]
    }

    fn reg_mut(&mut self, addr: u8) -> &mut u8 {
        &mut self.regs[usize::from(addr & 0x7F)]
    }

    fn reset_registers(&mut self) {
        for a in 0..128u8 {
            if (self.spec.access)(a) == Access::Rw {
                *self.reg_mut(a) = 0;
            }
        }
        for &(a, v) in self.spec.reset_values {
            *self.reg_mut(a) = v;
        }
    }

    /// The value a read of `addr` returns now (no side effects).
    fn peek(&self, addr: u8, now: Time) -> u8 {
        let (who_am_i, value) = self.spec.who_am_i;
        match addr {
            a if a == who_am_i => self.who_am_i_override.unwrap_or(value),
            a if a == self.spec.control && now < self.reset_until => self.reg(a) | self.spec.sw_reset,
            a => self.reg(a),
        }
    }

    /// A register write from the bus. A write to a read-only or reserved register is counted,
    /// and otherwise ignored as the sensor ignores it.
    fn write(&mut self, addr: u8, value: u8, now: Time) {
        let spec = self.spec;
        if (spec.access)(addr) != Access::Rw {
            self.unexpected_writes += 1;
            return;
        }
        if addr != spec.control {
            *self.reg_mut(addr) = value;
            return;
        }
        if value & spec.sw_reset != 0 {
            self.reset_registers();
            self.reset_until = now + SW_RESET_TIME;
        } else {
            *self.reg_mut(addr) = value & !(spec.boot | spec.self_clearing);
        }
        if value & spec.boot != 0 {
            self.busy_until = now + spec.boot_time;
        }
    }
}

/// Register behaviour of one sensor; the transaction logic is shared (blanket [`SpiDevice`]).
trait Chip {
    type Output;
    fn port(&self) -> &Port<Self::Output>;
    fn port_mut(&mut self) -> &mut Port<Self::Output>;
    /// Puts a new sample in the output registers, if the sensor's mode takes it.
    fn apply_output(&mut self, out: Self::Output);
    /// Side effects of reading `addr` (flags cleared, burst tracking).
    fn read_effects(&mut self, addr: u8);
    /// A register write from the bus.
    fn write(&mut self, addr: u8, value: u8, now: Time) {
        self.port_mut().write(addr, value, now);
    }
    fn three_wire(&self) -> bool;
    fn increments(&self) -> bool;
    fn i2c_on(&self) -> bool;
    /// CS rose after a transaction (not an ignored one), before a pending sample is applied.
    fn end_transaction(&mut self) {}
    /// Brings a sensor that samples on its own clock up to `now` (called at every bus event
    /// before it is handled). The others are given their samples by the rig.
    fn advance(&mut self, _now: Time) {}
    /// The value a read of `addr` returns at `now`, without side effects.
    fn read_value(&self, addr: u8, now: Time) -> u8 {
        self.port().peek(addr, now)
    }

    /// A new sample: in the output registers at once between transactions, else when CS rises.
    fn stage_output(&mut self, out: Self::Output) {
        if self.port().phase == Phase::Idle {
            self.apply_output(out);
        } else {
            self.port_mut().pending = Some(out);
        }
    }
}

fn next_addr(addr: u8, inc: bool) -> u8 {
    if inc {
        addr.wrapping_add(1) & 0x7F
    } else {
        addr
    }
}

impl<T: Chip> SpiDevice for T {
    fn cs_fall(&mut self, now: Time) {
        self.advance(now);
        let p = self.port_mut();
        p.phase = if p.ready(now) { Phase::Command } else { Phase::Ignored };
    }

    fn cs_rise(&mut self, now: Time) {
        self.advance(now);
        let phase = self.port().phase;
        self.port_mut().phase = Phase::Idle;
        if !matches!(phase, Phase::Idle | Phase::Ignored) {
            self.end_transaction();
            if let Some(out) = self.port_mut().pending.take() {
                self.apply_output(out);
            }
        }
    }

    fn output(&self, now: Time) -> Option<u8> {
        let p = self.port();
        match p.phase {
            Phase::Read { addr, .. } if !p.silent && p.ready(now) && self.three_wire() => Some(self.read_value(addr, now)),
            _ => None,
        }
    }

    fn clock(&mut self, line: u8, now: Time) {
        self.advance(now);
        if !self.port().ready(now) {
            // A BOOT written earlier in this transaction: the rest of it is ignored.
            if self.port().phase != Phase::Idle {
                self.port_mut().phase = Phase::Ignored;
            }
            return;
        }
        let inc = self.increments();
        match self.port().phase {
            Phase::Idle | Phase::Ignored => {}
            Phase::Command => {
                let addr = line & 0x7F;
                self.port_mut().phase = if line & 0x80 != 0 { Phase::Read { addr, started: false } } else { Phase::Write(addr) };
            }
            Phase::Write(addr) => {
                self.write(addr, line, now);
                // The write may have reset the increment bit (software reset): use the new rule.
                let inc = self.increments();
                if self.port().phase == Phase::Write(addr) {
                    self.port_mut().phase = Phase::Write(next_addr(addr, inc));
                }
            }
            Phase::Read { addr, .. } => {
                self.read_effects(addr);
                self.port_mut().phase = Phase::Read { addr: next_addr(addr, inc), started: true };
            }
        }
    }

    fn holds_line(&self, now: Time) -> bool {
        let p = self.port();
        matches!(p.phase, Phase::Read { started: true, .. }) && !p.silent && p.ready(now) && self.three_wire()
    }

    fn i2c_enabled(&self) -> bool {
        self.i2c_on()
    }
}

/// A sensor on the bus: what the SPI master needs of it, and the fault injection and
/// statistics the harness and the tests use.
pub trait Sensor: SpiDevice {
    /// Make `WHO_AM_I` answer `value` instead of the datasheet's (None: the real one).
    fn set_who_am_i_override(&mut self, value: Option<u8>);
    /// A silent sensor never drives the line (reads are undriven); writes still work.
    fn set_silent(&mut self, silent: bool);
    /// Writes to read-only or undocumented registers (accepted silently by a real sensor).
    fn unexpected_writes(&self) -> u32;
    /// The register's current content as the bus would read it at `now`.
    fn register(&self, addr: u8, now: Time) -> u8;
    /// Whether the sensor answers on the bus at `now` (not booting).
    fn is_ready(&self, now: Time) -> bool;
}

impl<T: Chip> Sensor for T {
    fn set_who_am_i_override(&mut self, value: Option<u8>) {
        self.port_mut().who_am_i_override = value;
    }

    fn set_silent(&mut self, silent: bool) {
        self.port_mut().silent = silent;
    }

    fn unexpected_writes(&self) -> u32 {
        self.port().unexpected_writes
    }

    fn register(&self, addr: u8, now: Time) -> u8 {
        self.read_value(addr & 0x7F, now)
    }

    fn is_ready(&self, now: Time) -> bool {
        self.port().ready(now)
    }
}

/// Register access class in a sensor's map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Access {
    Rw,
    Ro,
    Reserved,
}

// ---------------------------------------------------------------------------------------------
// LSM6DSL

pub mod lsm6dsl_reg {
    pub const FUNC_CFG_ACCESS: u8 = 0x01;
    pub const FIFO_CTRL5: u8 = 0x0A;
    pub const WHO_AM_I: u8 = 0x0F;
    pub const CTRL1_XL: u8 = 0x10;
    pub const CTRL2_G: u8 = 0x11;
    pub const CTRL3_C: u8 = 0x12;
    pub const CTRL4_C: u8 = 0x13;
    pub const CTRL9_XL: u8 = 0x18;
    pub const CTRL10_C: u8 = 0x19;
    pub const STATUS_REG: u8 = 0x1E;
    pub const OUTX_L_G: u8 = 0x22;
    pub const OUTX_L_XL: u8 = 0x28;
    pub const OUTZ_H_XL: u8 = 0x2D;
    pub const WHO_AM_I_VALUE: u8 = 0x6A;

    /// CTRL3_C bits.
    pub const SW_RESET: u8 = 0x01;
    pub const IF_INC: u8 = 0x04;
    pub const SIM: u8 = 0x08;
    pub const BDU: u8 = 0x40;
    pub const BOOT: u8 = 0x80;
    /// CTRL4_C.I2C_disable.
    pub const I2C_DISABLE: u8 = 0x04;
    /// STATUS_REG bits.
    pub const XLDA: u8 = 0x01;
    pub const GDA: u8 = 0x02;
}

const LSM6DSL: Spec = Spec {
    who_am_i: (lsm6dsl_reg::WHO_AM_I, lsm6dsl_reg::WHO_AM_I_VALUE),
    control: lsm6dsl_reg::CTRL3_C,
    sw_reset: lsm6dsl_reg::SW_RESET,
    boot: lsm6dsl_reg::BOOT,
    self_clearing: 0,
    boot_time: LSM6DSL_BOOT,
    // CTRL3_C = 0x04 (IF_INC), CTRL9_XL = 0xE0 (DEN_X/Y/Z).
    reset_values: &[(lsm6dsl_reg::CTRL3_C, lsm6dsl_reg::IF_INC), (lsm6dsl_reg::CTRL9_XL, 0xE0)],
    // Datasheet table "Registers address map".
    access: |addr| match addr {
        0x01 | 0x04..=0x0B | 0x0D | 0x0E | 0x10..=0x1A | 0x42 | 0x58..=0x61 | 0x73..=0x75 => Access::Rw,
        0x0F | 0x1B..=0x1E | 0x20..=0x41 | 0x49..=0x55 | 0x66..=0x6B => Access::Ro,
        _ => Access::Reserved,
    },
};

/// LSM6DSL accelerometer + gyroscope (WHO_AM_I 0x6A).
#[derive(Clone, Debug)]
pub struct Lsm6dsl {
    /// Output sample: gyro X, Y, Z then accel X, Y, Z.
    port: Port<([i16; 3], [i16; 3])>,
    /// Output registers 0x22..=0x2D read in this transaction (bit n = 0x22 + n).
    burst: u16,
    reads: u64,
}

impl Default for Lsm6dsl {
    fn default() -> Self {
        Self::new()
    }
}

impl Lsm6dsl {
    /// Powered on at time 0: booting for [`LSM6DSL_BOOT`].
    pub fn new() -> Self {
        Lsm6dsl { port: Port::new(&LSM6DSL), burst: 0, reads: 0 }
    }

    /// New sensor output (raw LSB, sensor axes): gyro X, Y, Z then accel X, Y, Z, stored from
    /// OUTX_L_G (0x22) little-endian as in the datasheet. A half whose ODR is 0 (power-down) keeps
    /// its old output. Given during a transaction, it is applied when CS rises.
    pub fn set_output(&mut self, gyro: [i16; 3], accel: [i16; 3]) {
        self.stage_output((gyro, accel));
    }

    /// Completed output-burst reads: transactions that read all 12 bytes OUTX_L_G..OUTZ_H_XL.
    pub fn reads(&self) -> u64 {
        self.reads
    }
}

impl Chip for Lsm6dsl {
    type Output = ([i16; 3], [i16; 3]);

    fn port(&self) -> &Port<Self::Output> {
        &self.port
    }
    fn port_mut(&mut self) -> &mut Port<Self::Output> {
        &mut self.port
    }

    fn apply_output(&mut self, (gyro, accel): Self::Output) {
        use lsm6dsl_reg::*;
        let p = &mut self.port;
        let xl_on = p.reg(CTRL1_XL) >> 4 != 0;
        let g_on = p.reg(CTRL2_G) >> 4 != 0;
        let mut put = |base: u8, v: [i16; 3]| {
            for (i, axis) in v.iter().enumerate() {
                let [lo, hi] = axis.to_le_bytes();
                let a = base + 2 * i as u8;
                *p.reg_mut(a) = lo;
                *p.reg_mut(a + 1) = hi;
            }
        };
        if g_on {
            put(OUTX_L_G, gyro);
        }
        if xl_on {
            put(OUTX_L_XL, accel);
        }
        let status = p.reg_mut(STATUS_REG);
        if g_on {
            *status |= GDA;
        }
        if xl_on {
            *status |= XLDA;
        }
    }

    fn read_effects(&mut self, addr: u8) {
        use lsm6dsl_reg::*;
        if (OUTX_L_G..=OUTZ_H_XL).contains(&addr) {
            self.burst |= 1 << (addr - OUTX_L_G);
            // Simplification: reading any byte of a set clears its data-ready flag.
            let flag = if addr < OUTX_L_XL { GDA } else { XLDA };
            *self.port.reg_mut(STATUS_REG) &= !flag;
        }
    }

    fn write(&mut self, addr: u8, value: u8, now: Time) {
        self.port.write(addr, value, now);
        // FUNC_CFG_EN switches to the embedded-functions bank, which is not modelled.
        if addr == lsm6dsl_reg::FUNC_CFG_ACCESS && value != 0 {
            self.port.unexpected_writes += 1;
        }
    }

    fn three_wire(&self) -> bool {
        self.port.reg(lsm6dsl_reg::CTRL3_C) & lsm6dsl_reg::SIM != 0
    }
    fn increments(&self) -> bool {
        self.port.reg(lsm6dsl_reg::CTRL3_C) & lsm6dsl_reg::IF_INC != 0
    }
    fn i2c_on(&self) -> bool {
        self.port.reg(lsm6dsl_reg::CTRL4_C) & lsm6dsl_reg::I2C_DISABLE == 0
    }

    fn end_transaction(&mut self) {
        if self.burst == 0x0FFF {
            self.reads += 1;
        }
        self.burst = 0;
    }
}

// ---------------------------------------------------------------------------------------------
// LIS2MDL

pub mod lis2mdl_reg {
    pub const WHO_AM_I: u8 = 0x4F;
    pub const CFG_REG_A: u8 = 0x60;
    pub const CFG_REG_B: u8 = 0x61;
    pub const CFG_REG_C: u8 = 0x62;
    pub const INT_CTRL_REG: u8 = 0x63;
    pub const STATUS_REG: u8 = 0x67;
    pub const OUTX_L_REG: u8 = 0x68;
    pub const WHO_AM_I_VALUE: u8 = 0x40;

    /// CFG_REG_A bits.
    pub const SOFT_RST: u8 = 0x20;
    pub const REBOOT: u8 = 0x40;
    pub const MD_MASK: u8 = 0x03;
    /// CFG_REG_C bits.
    pub const SPI_4WIRE: u8 = 0x04;
    pub const BDU: u8 = 0x10;
    pub const I2C_DIS: u8 = 0x20;
    /// STATUS_REG.Zyxda.
    pub const ZYXDA: u8 = 0x08;
}

const LIS2MDL: Spec = Spec {
    who_am_i: (lis2mdl_reg::WHO_AM_I, lis2mdl_reg::WHO_AM_I_VALUE),
    control: lis2mdl_reg::CFG_REG_A,
    sw_reset: lis2mdl_reg::SOFT_RST,
    boot: lis2mdl_reg::REBOOT,
    self_clearing: 0,
    boot_time: LIS2MDL_BOOT,
    // CFG_REG_A = 0x03 (MD = 11, idle), INT_CRTL_REG = 0xE0.
    reset_values: &[(lis2mdl_reg::CFG_REG_A, 0x03), (lis2mdl_reg::INT_CTRL_REG, 0xE0)],
    // Datasheet table "Register address map".
    access: |addr| match addr {
        0x45..=0x4A | 0x60..=0x63 | 0x65 | 0x66 => Access::Rw,
        0x4F | 0x64 | 0x67..=0x6F => Access::Ro,
        _ => Access::Reserved,
    },
};

/// LIS2MDL magnetometer (WHO_AM_I 0x40). 3-wire SPI is its power-up default.
#[derive(Clone, Debug)]
pub struct Lis2mdl {
    /// Output sample: X, Y, Z.
    port: Port<[i16; 3]>,
}

impl Default for Lis2mdl {
    fn default() -> Self {
        Self::new()
    }
}

impl Lis2mdl {
    /// Powered on at time 0: booting for [`LIS2MDL_BOOT`].
    pub fn new() -> Self {
        Lis2mdl { port: Port::new(&LIS2MDL) }
    }

    /// New magnetometer output (raw LSB, X, Y, Z), stored from OUTX_L_REG (0x68) little-endian.
    /// Taken only in continuous (MD = 00) or single (MD = 01, then idle) mode.
    pub fn set_output(&mut self, mag: [i16; 3]) {
        self.stage_output(mag);
    }
}

impl Chip for Lis2mdl {
    type Output = [i16; 3];

    fn port(&self) -> &Port<Self::Output> {
        &self.port
    }
    fn port_mut(&mut self) -> &mut Port<Self::Output> {
        &mut self.port
    }

    fn apply_output(&mut self, mag: Self::Output) {
        use lis2mdl_reg::*;
        let p = &mut self.port;
        let md = p.reg(CFG_REG_A) & MD_MASK;
        if md > 1 {
            return;
        }
        for (i, axis) in mag.iter().enumerate() {
            let [lo, hi] = axis.to_le_bytes();
            *p.reg_mut(OUTX_L_REG + 2 * i as u8) = lo;
            *p.reg_mut(OUTX_L_REG + 2 * i as u8 + 1) = hi;
        }
        *p.reg_mut(STATUS_REG) |= ZYXDA;
        if md == 1 {
            *p.reg_mut(CFG_REG_A) |= MD_MASK;
        }
    }

    fn read_effects(&mut self, addr: u8) {
        use lis2mdl_reg::*;
        if (OUTX_L_REG..OUTX_L_REG + 6).contains(&addr) {
            *self.port.reg_mut(STATUS_REG) &= !ZYXDA;
        }
    }

    fn three_wire(&self) -> bool {
        self.port.reg(lis2mdl_reg::CFG_REG_C) & lis2mdl_reg::SPI_4WIRE == 0
    }
    fn increments(&self) -> bool {
        true
    }
    fn i2c_on(&self) -> bool {
        self.port.reg(lis2mdl_reg::CFG_REG_C) & lis2mdl_reg::I2C_DIS == 0
    }
}

// ---------------------------------------------------------------------------------------------
// LPS22HB: its own file, for its sampling clock, BDU and pressure input.

mod lps22hb;
pub use lps22hb::{lps22hb_reg, BaroInputError, Lps22hb, PressureReads, ISA_SEA_LEVEL_PA};

// ---------------------------------------------------------------------------------------------

/// The three sensors of the board, in chip-select order: LSM6DSL (PA8), LIS2MDL (PB12),
/// LPS22HB (PC13).
#[derive(Clone, Debug, Default)]
pub struct Sensors {
    pub lsm6dsl: Lsm6dsl,
    pub lis2mdl: Lis2mdl,
    pub lps22hb: Lps22hb,
}

impl Sensors {
    /// All three powered on at time 0.
    pub fn new() -> Self {
        Sensors { lsm6dsl: Lsm6dsl::new(), lis2mdl: Lis2mdl::new(), lps22hb: Lps22hb::new() }
    }

    /// The sensor behind chip select `i` (0 = LSM6DSL, 1 = LIS2MDL, 2 = LPS22HB).
    pub fn device(&self, i: usize) -> Option<&dyn Sensor> {
        match i {
            0 => Some(&self.lsm6dsl),
            1 => Some(&self.lis2mdl),
            2 => Some(&self.lps22hb),
            _ => None,
        }
    }

    /// Mutable [`Sensors::device`].
    pub fn device_mut(&mut self, i: usize) -> Option<&mut dyn Sensor> {
        match i {
            0 => Some(&mut self.lsm6dsl),
            1 => Some(&mut self.lis2mdl),
            2 => Some(&mut self.lps22hb),
            _ => None,
        }
    }

    /// `WHO_AM_I` override of the sensor behind chip select `i` (see [`Sensors::device`]).
    pub fn set_who_am_i_override(&mut self, i: usize, value: Option<u8>) {
        if let Some(d) = self.device_mut(i) {
            d.set_who_am_i_override(value);
        }
    }

    /// Silence the sensor behind chip select `i`.
    pub fn set_silent(&mut self, i: usize, silent: bool) {
        if let Some(d) = self.device_mut(i) {
            d.set_silent(silent);
        }
    }

    /// Unexpected writes summed over the three.
    pub fn unexpected_writes(&self) -> u32 {
        (0..3).filter_map(|i| self.device(i)).map(|d| d.unexpected_writes()).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const AFTER_BOOT: Time = 100 * MS;

    /// One transaction at the byte level: `bytes` clocked by the master (None = the master does
    /// not drive the line); returns what was on the line for each byte.
    fn transact(dev: &mut dyn SpiDevice, bytes: &[Option<u8>], now: Time) -> Vec<u8> {
        dev.cs_fall(now);
        let mut out = Vec::new();
        for b in bytes {
            let line = b.or(dev.output(now)).unwrap_or(UNDRIVEN);
            dev.clock(line, now);
            out.push(line);
        }
        dev.cs_rise(now);
        out
    }

    fn write(dev: &mut dyn SpiDevice, addr: u8, data: &[u8], now: Time) {
        let mut bytes = vec![Some(addr & 0x7F)];
        bytes.extend(data.iter().map(|&d| Some(d)));
        transact(dev, &bytes, now);
    }

    fn read(dev: &mut dyn SpiDevice, addr: u8, n: usize, now: Time) -> Vec<u8> {
        let mut bytes = vec![Some(addr | 0x80)];
        bytes.extend(std::iter::repeat_n(None, n));
        transact(dev, &bytes, now)[1..].to_vec()
    }

    #[test]
    fn lsm6dsl_who_am_i_answers_on_the_data_line_only_in_3_wire_mode() {
        let mut s = Lsm6dsl::new();
        assert_eq!(read(&mut s, 0x0F, 1, AFTER_BOOT), [UNDRIVEN], "4-wire at power-up: SDO not wired");
        write(&mut s, 0x12, &[0x0C], AFTER_BOOT);
        assert_eq!(read(&mut s, 0x0F, 1, AFTER_BOOT), [0x6A]);
        assert_eq!(s.unexpected_writes(), 0);
    }

    #[test]
    fn lsm6dsl_reset_values_match_the_datasheet() {
        let s = Lsm6dsl::new();
        assert_eq!(s.register(0x12, AFTER_BOOT), 0x04, "CTRL3_C: IF_INC");
        assert_eq!(s.register(0x18, AFTER_BOOT), 0xE0, "CTRL9_XL");
        assert_eq!(s.register(0x13, AFTER_BOOT), 0x00, "CTRL4_C: I2C enabled");
        assert!(s.i2c_enabled());
    }

    #[test]
    fn a_write_then_read_back_returns_the_value() {
        let mut s = Lsm6dsl::new();
        write(&mut s, 0x12, &[0x4C], AFTER_BOOT);
        write(&mut s, 0x10, &[0xA8], AFTER_BOOT);
        assert_eq!(read(&mut s, 0x10, 3, AFTER_BOOT), [0xA8, 0x00, 0x4C]);
    }

    #[test]
    fn a_12_byte_burst_auto_increments_gyro_then_accel_little_endian() {
        let mut s = Lsm6dsl::new();
        write(&mut s, 0x12, &[0x4C], AFTER_BOOT);
        write(&mut s, 0x10, &[0xA8, 0x6C], AFTER_BOOT);
        s.set_output([1, -1, i16::MIN], [0x1234, i16::MAX, -1008]);
        assert_eq!(s.register(0x1E, AFTER_BOOT) & 0x03, 0x03, "XLDA and GDA");
        let got = read(&mut s, 0x22, 12, AFTER_BOOT);
        assert_eq!(got, [0x01, 0x00, 0xFF, 0xFF, 0x00, 0x80, 0x34, 0x12, 0xFF, 0x7F, 0x10, 0xFC]);
        assert_eq!(s.reads(), 1);
        assert_eq!(s.register(0x1E, AFTER_BOOT) & 0x03, 0, "flags cleared by the read");
    }

    #[test]
    fn without_if_inc_a_burst_repeats_the_same_register() {
        let mut s = Lsm6dsl::new();
        write(&mut s, 0x12, &[0x08], AFTER_BOOT); // SIM only
        assert_eq!(read(&mut s, 0x0F, 3, AFTER_BOOT), [0x6A, 0x6A, 0x6A]);
    }

    #[test]
    fn outputs_stay_put_while_the_sensor_is_powered_down() {
        let mut s = Lsm6dsl::new();
        write(&mut s, 0x12, &[0x0C], AFTER_BOOT);
        s.set_output([5, 5, 5], [7, 7, 7]);
        assert_eq!(read(&mut s, 0x22, 12, AFTER_BOOT), [0; 12]);
    }

    #[test]
    fn output_given_during_a_transaction_is_applied_when_cs_rises() {
        let mut s = Lsm6dsl::new();
        write(&mut s, 0x12, &[0x4C], AFTER_BOOT);
        write(&mut s, 0x10, &[0xA8, 0x6C], AFTER_BOOT);
        s.set_output([1, 1, 1], [1, 1, 1]);
        s.cs_fall(AFTER_BOOT);
        s.clock(0xA2, AFTER_BOOT);
        s.set_output([2, 2, 2], [2, 2, 2]);
        let first = s.output(AFTER_BOOT);
        s.clock(first.unwrap_or(UNDRIVEN), AFTER_BOOT);
        s.cs_rise(AFTER_BOOT);
        assert_eq!(first, Some(1));
        assert_eq!(read(&mut s, 0x22, 1, AFTER_BOOT), [2]);
    }

    #[test]
    fn a_sensor_ignores_the_bus_while_booting() {
        let mut s = Lsm6dsl::new();
        assert!(!s.is_ready(LSM6DSL_BOOT - 1));
        write(&mut s, 0x12, &[0x0C], LSM6DSL_BOOT - 1);
        assert_eq!(s.register(0x12, LSM6DSL_BOOT), 0x04, "write ignored");
        assert!(s.is_ready(LSM6DSL_BOOT));
    }

    #[test]
    fn sw_reset_restores_defaults_and_reads_set_until_done() {
        let mut s = Lsm6dsl::new();
        write(&mut s, 0x12, &[0x4C], AFTER_BOOT);
        write(&mut s, 0x13, &[0x04], AFTER_BOOT);
        write(&mut s, 0x12, &[0x01], AFTER_BOOT);
        assert_eq!(s.register(0x12, AFTER_BOOT), 0x05);
        assert_eq!(s.register(0x12, AFTER_BOOT + SW_RESET_TIME), 0x04);
        assert_eq!(s.register(0x13, AFTER_BOOT), 0x00);
    }

    #[test]
    fn boot_bit_makes_the_lsm6dsl_deaf_for_its_boot_time() {
        let mut s = Lsm6dsl::new();
        write(&mut s, 0x12, &[0x8C], AFTER_BOOT);
        assert_eq!(read(&mut s, 0x0F, 1, AFTER_BOOT + LSM6DSL_BOOT - 1), [UNDRIVEN]);
        assert_eq!(read(&mut s, 0x0F, 1, AFTER_BOOT + LSM6DSL_BOOT), [0x6A], "control registers kept");
    }

    #[test]
    fn writes_to_read_only_registers_are_counted_not_stored() {
        let mut s = Lsm6dsl::new();
        write(&mut s, 0x0F, &[0x00], AFTER_BOOT);
        write(&mut s, 0x22, &[0x55], AFTER_BOOT);
        write(&mut s, 0x00, &[0x55], AFTER_BOOT);
        assert_eq!(s.unexpected_writes(), 3);
        assert_eq!(s.register(0x22, AFTER_BOOT), 0);
    }

    #[test]
    fn who_am_i_override_and_silence_inject_faults() {
        let mut s = Lsm6dsl::new();
        write(&mut s, 0x12, &[0x0C], AFTER_BOOT);
        s.set_who_am_i_override(Some(0x69));
        assert_eq!(read(&mut s, 0x0F, 1, AFTER_BOOT), [0x69]);
        s.set_who_am_i_override(None);
        s.set_silent(true);
        assert_eq!(read(&mut s, 0x0F, 1, AFTER_BOOT), [UNDRIVEN]);
    }

    #[test]
    fn a_reading_sensor_holds_the_line_until_cs_rises() {
        let mut s = Lsm6dsl::new();
        write(&mut s, 0x12, &[0x0C], AFTER_BOOT);
        s.cs_fall(AFTER_BOOT);
        s.clock(0x8F, AFTER_BOOT);
        assert!(!s.holds_line(AFTER_BOOT), "not before the first data clock");
        let b = s.output(AFTER_BOOT).unwrap_or(UNDRIVEN);
        s.clock(b, AFTER_BOOT);
        assert!(s.holds_line(AFTER_BOOT));
        s.cs_rise(AFTER_BOOT);
        assert!(!s.holds_line(AFTER_BOOT));
    }

    #[test]
    fn lis2mdl_is_3_wire_at_power_up_and_4wspi_moves_answers_to_sdo() {
        let mut s = Lis2mdl::new();
        let t = LIS2MDL_BOOT;
        assert_eq!(read(&mut s, 0x4F, 1, t), [0x40]);
        assert_eq!(s.register(0x60, t), 0x03, "CFG_REG_A reset: idle");
        write(&mut s, 0x62, &[0x04], t);
        assert_eq!(read(&mut s, 0x4F, 1, t), [UNDRIVEN]);
    }

    #[test]
    fn lis2mdl_i2c_dis_and_soft_reset() {
        let mut s = Lis2mdl::new();
        let t = LIS2MDL_BOOT;
        assert!(s.i2c_enabled());
        write(&mut s, 0x62, &[0x30], t);
        assert!(!s.i2c_enabled());
        write(&mut s, 0x60, &[0x20], t);
        assert!(s.i2c_enabled(), "SOFT_RST clears CFG_REG_C");
        assert_eq!(s.register(0x60, t), 0x23);
        assert_eq!(s.register(0x60, t + SW_RESET_TIME), 0x03);
    }

    #[test]
    fn lis2mdl_writes_auto_increment() {
        let mut s = Lis2mdl::new();
        let t = LIS2MDL_BOOT;
        write(&mut s, 0x60, &[0x8C, 0x02, 0x10], t);
        assert_eq!(read(&mut s, 0x60, 3, t), [0x8C, 0x02, 0x10]);
        s.set_output([0x0102, -2, 3]);
        assert_eq!(read(&mut s, 0x68, 6, t), [0x02, 0x01, 0xFE, 0xFF, 0x03, 0x00]);
    }

    #[test]
    fn sensors_are_indexed_in_chip_select_order() {
        let mut s = Sensors::new();
        assert!(s.device(0).is_some() && s.device(2).is_some() && s.device(3).is_none());
        s.set_who_am_i_override(1, Some(0));
        s.set_who_am_i_override(7, Some(0));
        assert_eq!(s.lis2mdl.register(0x4F, AFTER_BOOT), 0);
        assert_eq!(s.unexpected_writes(), 0);
    }
}
