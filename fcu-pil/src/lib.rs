//! fcu-pil: processor-in-the-loop. The release ELF of fcu-firmware, byte for byte the file that
//! is flashed, runs in an emulated STM32F401 against fcu-testkit's simulated drone.
//!
//! - [`machine`]: the Cortex-M4F (Unicorn for the instructions; our clock, exceptions, WFI,
//!   faults and memory-mapped I/O dispatch) with [`scs`], its NVIC, SCB, SysTick and DWT;
//! - [`periph`]: register-level models of the STM32F401 peripherals, from RM0368;
//! - [`board`]: the STEVAL-FCU001V1's wiring between them (radio, motors, sensors, LEDs, UART);
//! - [`rig`]: the board as a `fcu_testkit::sim::FlightComputer`, so every scenario flies it;
//! - [`timing`]: the two timing profiles (optimistic, pessimistic) that bracket the board's;
//! - [`telemetry`]: the firmware's UART lines read back; [`measure`]: costs on the image;
//! - [`serve`]: the board at real time with USART1 bridged to a TCP client (`cargo pil serve`).

pub mod board;
pub mod elf;
pub mod firmware;
pub mod machine;
pub mod measure;
pub mod periph;
pub mod rig;
pub mod scs;
pub mod serve;
pub mod telemetry;
pub mod timing;
