//! `cargo pil serve`: the emulated board at real time on the bench, its USART1 bridged to one TCP
//! client, so a ground station (MAVProxy, QGroundControl, pymavlink) talks to the release image
//! as to a board on a USB-UART adapter.
//!
//! The board boots as in a flight (the drone level and still; boot runs as fast as the emulator
//! goes), then flies the scenario's sticks (or sticks centred, throttle low: the drone sits on
//! the bench) paced to the host's clock. Each control period: the client's bytes go onto PA10 at
//! 115 200 baud ([`Board::push_uart_rx`], so a client that sends faster is held to the line's
//! rate, as a USB-UART adapter's buffer holds it), and every byte USART1 put on PA9 goes to the
//! clients. Bytes sent while no client is connected are dropped, as with no cable. Several
//! clients may be connected at once (a ground station and `fcu-ground`, say, as SITL serves
//! them): each hears everything the board sends, and the bytes of each go onto PA10 as they
//! come. What happens is printed as it happens (the boot, each client, each board reset), and a
//! summary at the end or on Ctrl-C.
//!
//! A reboot of the board (the firmware's reset request, the watchdog) keeps the flash contents
//! (see `Board::system_reset`). With `--flash FILE` the flash starts from the file (256 KiB, a
//! raw image of 0x0800_0000 on; the sectors the ELF programs are the ELF's) and the file is
//! rewritten whenever a program or erase has changed the memory, and at the end.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use fcu_core::imu::RawImu;
use fcu_testkit::sim::radio_model::TimedEdge;
use fcu_testkit::sim::scenario::{self, StickRow, Timeline};
use fcu_testkit::sim::{ComputerView, FlightComputer, RunOptions, SimError};

use crate::board::Board;
use crate::elf::Image;
use crate::periph::flash::ArmedCut;
use crate::rig::{self, BoardSetup, EmulatedBoard};

/// What to serve.
#[derive(Clone, Debug, Default)]
pub struct ServeOptions {
    pub elf: PathBuf,
    /// A scenario's sticks; `None`: centred, throttle low.
    pub scenario: Option<String>,
    /// The flash's contents, loaded at power-on and saved as they change.
    pub flash: Option<PathBuf>,
    /// Emulated seconds to run after boot.
    pub duration_s: f64,
    pub setup: BoardSetup,
    /// A power cut armed at a fraction of a flash operation to come ([`parse_power_cut`]).
    pub power_cut: Option<ArmedCut>,
    /// A parameter file (MAVProxy's `param save` format) to boot with: written into the
    /// flash as the only saved set ([`flash_with_parameters`]).
    pub params: Option<PathBuf>,
}

/// Where the firmware keeps its parameters: flash sectors 1 and 2 (16 KiB each), from
/// 0x0800_4000 (the repository's `memory.x`).
const PARAM_SECTORS: std::ops::Range<usize> = 0x4000..0xC000;

/// `flash` (a 256 KiB image of 0x0800_0000 on) with the parameter sectors holding one saved
/// set: the product's defaults with the values `text` names, as the firmware would have saved
/// it (fcu-core's snapshot, sequence 1, at the start of sector 1; sector 2 erased). A line that
/// names no parameter or a value the set refuses is an error naming the line.
pub fn flash_with_parameters(flash: Vec<u8>, text: &str) -> Result<Vec<u8>, String> {
    let cfg = fcu_params::apply_file(&fcu_core::Config::default(), text).map_err(fcu_testkit::cli::fly::describe_file_error)?;
    flash_with_config(flash, &cfg)
}

/// Why a flash could not be prepared for a flight: the set saved in it, or the parameter file.
#[derive(Debug, PartialEq)]
pub enum FlightFlashError {
    /// The flash's newest saved set does not make a valid configuration (the rule).
    SavedSetRefused(&'static str),
    /// The parameter file: its line and rule, or the rule the whole set breaks.
    File(String),
}

/// `flash` for a flight the harness watches (`cargo pil fly --flash/--params`): the set saved
/// in it (the defaults if none), with the values `text` names over it, and its UART turned to
/// text lines, which are what the harness reads the board's state from. Saved as the only set,
/// as [`flash_with_parameters`] does.
pub fn flash_for_flight(flash: Vec<u8>, text: Option<&str>) -> Result<Vec<u8>, FlightFlashError> {
    use fcu_params::{self as parameters, snapshot};
    use fcu_testkit::cli::fly::describe_file_error;
    let (a, b) = (param_sector_words(&flash, 0), param_sector_words(&flash, 1));
    let (saved, source) = snapshot::load_config([&a, &b], &fcu_core::Config::default());
    if let snapshot::Source::Refused(rule) = source {
        return Err(FlightFlashError::SavedSetRefused(rule));
    }
    let with_file = match text {
        Some(t) => parameters::apply_file(&saved, t).map_err(|e| FlightFlashError::File(describe_file_error(e)))?,
        None => saved,
    };
    let cfg = parameters::apply_file(&with_file, "LINK_PROTOCOL 0").map_err(|e| FlightFlashError::File(describe_file_error(e)))?;
    flash_with_config(flash, &cfg).map_err(FlightFlashError::File)
}

/// The words of parameter sector `sector` (0 or 1) in a flash image of 0x0800_0000 on; none
/// where the image is too short to hold it.
fn param_sector_words(flash: &[u8], sector: usize) -> Vec<u32> {
    let base = PARAM_SECTORS.start + sector * 0x4000;
    flash
        .get(base..base + 0x4000)
        .map_or_else(Vec::new, |b| b.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
}

fn flash_with_config(mut flash: Vec<u8>, cfg: &fcu_core::Config) -> Result<Vec<u8>, String> {
    use fcu_params::{self as parameters, snapshot};
    flash.resize(256 * 1024, 0xFF);
    let sectors = flash.get_mut(PARAM_SECTORS).ok_or("flash image too short")?;
    sectors.fill(0xFF);
    for (at, word) in snapshot::encode(1, &parameters::values(cfg)).iter().enumerate() {
        if let Some(dst) = sectors.get_mut(4 * at..4 * at + 4) {
            dst.copy_from_slice(&word.to_le_bytes());
        }
    }
    Ok(flash)
}

/// `--lsi-hz`: the LSI's frequency in Hz, within DS9716's 17–47 kHz (the chip's spread over
/// parts, supply and temperature; the watchdog's timeout follows it). A value outside is
/// refused with the range.
pub fn parse_lsi_hz(text: &str) -> Result<u64, String> {
    use crate::periph::iwdg::{LSI_MAX_HZ, LSI_MIN_HZ};
    let range = format!("the LSI runs at {LSI_MIN_HZ} to {LSI_MAX_HZ} Hz (DS9716)");
    let hz: u64 = text.trim().parse().map_err(|_| format!("--lsi-hz {text}: not a frequency in Hz; {range}"))?;
    if (LSI_MIN_HZ..=LSI_MAX_HZ).contains(&hz) {
        Ok(hz)
    } else {
        Err(format!("--lsi-hz {text}: outside {LSI_MIN_HZ}..={LSI_MAX_HZ}; {range}"))
    }
}

/// of flash operation, the fraction of it at which the power fails, and which one.
pub fn parse_power_cut(text: &str) -> Result<ArmedCut, String> {
    let bad = || format!("--power-cut {text}: expected erase|program:FRACTION[@N], e.g. erase:3/8 or program:0.5@2");
    let (kind, rest) = text.split_once(':').ok_or_else(bad)?;
    let erase = match kind {
        "erase" => true,
        "program" => false,
        _ => return Err(bad()),
    };
    let (fraction, nth) = match rest.split_once('@') {
        Some((f, n)) => (f, n.parse::<u32>().map_err(|_| bad())?),
        None => (rest, 1),
    };
    let fraction = match fraction.split_once('/') {
        Some((a, b)) => {
            let (a, b) = (a.parse::<f64>().map_err(|_| bad())?, b.parse::<f64>().map_err(|_| bad())?);
            if b == 0.0 {
                return Err(bad());
            }
            a / b
        }
        None => fraction.parse::<f64>().map_err(|_| bad())?,
    };
    if !(0.0..=1.0).contains(&fraction) || nth == 0 {
        return Err(bad());
    }
    Ok(ArmedCut { erase, nth, fraction })
}

/// What a session moved, for the operator and the tests.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ServeReport {
    /// Bytes from the client put on PA10, and bytes of USART1's sent to the client.
    pub bytes_in: u64,
    pub bytes_out: u64,
    /// USART1's receiver: bytes it took, of them lost to an overrun, and bytes it ignored.
    pub rx_received: u32,
    pub rx_overrun: u32,
    pub rx_ignored: u32,
    /// Bytes on PA10 the receiver never saw (pin not on AF7, clock off).
    pub rx_lost_on_pin: usize,
    /// Board resets (watchdog, software, power cut) during the session, and of them power cuts.
    pub resets: usize,
    pub power_cuts: usize,
    pub clients: u32,
}

impl std::fmt::Display for ServeReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "link: {} client(s), {} bytes in, {} bytes out", self.clients, self.bytes_in, self.bytes_out)?;
        writeln!(
            f,
            "USART1 RX: {} bytes received, {} lost to overrun, {} ignored (receiver off), {} not on PA10",
            self.rx_received, self.rx_overrun, self.rx_ignored, self.rx_lost_on_pin
        )?;
        writeln!(f, "board resets: {} ({} power cuts)", self.resets, self.power_cuts)
    }
}

/// A connected client: its socket and where it came from.
struct Client {
    stream: TcpStream,
    peer: String,
}

/// The emulated board between the simulation and the TCP clients, paced to the host's clock.
struct Bridge<'a> {
    board: &'a mut EmulatedBoard,
    listener: TcpListener,
    clients: Vec<Client>,
    uart_sent: usize,
    /// Board resets already said.
    resets_said: usize,
    /// Set by Ctrl-C: the session ends at the next step, with its summary.
    stop: Arc<AtomicBool>,
    started: Option<Instant>,
    flash: Option<PathBuf>,
    flash_saved: u64,
    report: ServeReport,
}

impl Bridge<'_> {
    fn accept(&mut self) {
        while let Ok((stream, peer)) = self.listener.accept() {
            if stream.set_nonblocking(true).is_err() {
                continue;
            }
            let _ = stream.set_nodelay(true);
            println!("fcu-pil serve: client {peer} connected ({} connected)", self.clients.len() + 1);
            self.clients.push(Client { stream, peer: peer.to_string() });
            self.report.clients += 1;
        }
    }

    fn drop_client(&mut self, i: usize, why: &str) {
        if i < self.clients.len() {
            let c = self.clients.remove(i);
            println!("fcu-pil serve: client {} {why} ({} connected)", c.peer, self.clients.len());
        }
    }

    /// Every client's bytes onto PA10, from now on at the line's rate.
    fn pump_in(&mut self) {
        let mut i = 0;
        while i < self.clients.len() {
            let mut buf = [0u8; 4096];
            match self.clients[i].stream.read(&mut buf) {
                Ok(0) => {
                    self.drop_client(i, "disconnected");
                    continue;
                }
                Ok(n) => {
                    let now = self.board.machine.now();
                    self.board.machine.board_mut().push_uart_rx(&buf[..n], now);
                    self.report.bytes_in += n as u64;
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
                Err(e) => {
                    self.drop_client(i, &format!("dropped ({e})"));
                    continue;
                }
            }
            i += 1;
        }
    }

    /// What USART1 put on PA9 since the last call, to every client.
    fn pump_out(&mut self) {
        let uart = &self.board.machine.board().records.uart;
        let new: Vec<u8> = uart.get(self.uart_sent..).unwrap_or_default().iter().map(|&(_, b)| b).collect();
        self.uart_sent = uart.len();
        if new.is_empty() {
            return;
        }
        let mut i = 0;
        while i < self.clients.len() {
            // A non-blocking socket may take part of it; the rest waits a millisecond at a time
            // (a client that stops reading stalls the bench, as a full adapter would).
            let mut rest = new.as_slice();
            let mut failed = None;
            while !rest.is_empty() {
                match self.clients[i].stream.write(rest) {
                    Ok(0) => break,
                    Ok(n) => {
                        self.report.bytes_out += n as u64;
                        rest = &rest[n..];
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => std::thread::sleep(Duration::from_millis(1)),
                    Err(e) => {
                        failed = Some(e);
                        break;
                    }
                }
            }
            match failed {
                Some(e) => self.drop_client(i, &format!("dropped ({e})")),
                None => i += 1,
            }
        }
    }

    /// Says each board reset as it happens.
    fn say_resets(&mut self) {
        let resets = &self.board.machine.state().resets;
        for r in resets.iter().skip(self.resets_said) {
            println!("fcu-pil serve: board reset ({}), booting again", r.1);
        }
        self.resets_said = resets.len();
    }

    fn save_flash(&mut self, force: bool) -> Result<(), SimError> {
        let Some(path) = self.flash.as_ref() else { return Ok(()) };
        let flash = &self.board.machine.board().flash;
        if !force && (flash.generation() == self.flash_saved || flash.busy_until().is_some()) {
            return Ok(());
        }
        self.flash_saved = flash.generation();
        std::fs::write(path, flash.memory()).map_err(|e| SimError::Computer(format!("--flash {}: {e}", path.display())))
    }

    fn pace(&mut self, t_end_s: f64) {
        let started = *self.started.get_or_insert_with(Instant::now);
        let ahead = t_end_s - started.elapsed().as_secs_f64();
        if ahead > 0.002 {
            std::thread::sleep(Duration::from_secs_f64(ahead));
        }
    }
}

impl FlightComputer for Bridge<'_> {
    fn tick_hz(&self) -> f64 {
        self.board.tick_hz()
    }

    fn step(&mut self, t_end_s: f64, edges: &[TimedEdge], imu: RawImu, battery_v: f64) -> Result<[u16; 4], SimError> {
        if self.stop.load(Ordering::Relaxed) {
            return Err(SimError::Computer(STOPPED.into()));
        }
        self.pace(t_end_s);
        self.accept();
        self.pump_in();
        let compares = self.board.step(t_end_s, edges, imu, battery_v)?;
        self.pump_out();
        self.say_resets();
        self.save_flash(false)?;
        Ok(compares)
    }

    fn air(&mut self, height_m: f64) -> Result<(), SimError> {
        self.board.air(height_m)
    }

    fn view(&self) -> ComputerView {
        self.board.view()
    }
}

/// Parses `tcp:HOST:PORT` into a listener.
pub fn listen(link: &str) -> Result<TcpListener, String> {
    let addr = link.strip_prefix("tcp:").ok_or_else(|| format!("--link {link}: expected tcp:HOST:PORT"))?;
    TcpListener::bind(addr).map_err(|e| format!("--link {link}: {e}"))
}

/// Why a session ended early: its stop flag (Ctrl-C).
const STOPPED: &str = "stopped";

/// Serves the board on `listener` until `duration_s` of emulated time after boot.
pub fn serve_on(listener: TcpListener, opts: &ServeOptions) -> Result<ServeReport, String> {
    serve_until(listener, opts, Arc::new(AtomicBool::new(false)))
}

/// [`serve_on`], ending early (with the same report) once `stop` is set, as Ctrl-C sets it.
pub fn serve_until(listener: TcpListener, opts: &ServeOptions, stop: Arc<AtomicBool>) -> Result<ServeReport, String> {
    listener.set_nonblocking(true).map_err(|e| format!("listener: {e}"))?;
    let duration_s = opts.duration_s.max(0.0);
    let sc = match &opts.scenario {
        Some(name) => fcu_testkit::cli::fly::prepare_scenario(name, None, Some(duration_s)).map_err(|e| e.0)?,
        None => scenario::from_timeline("bench", Timeline { rows: vec![StickRow::idle(0.0)] }, duration_s),
    };
    // The board as shipped: with no saved parameters its UART speaks MAVLink from boot.
    let mut setup = rig::BoardSetup { mavlink_from_boot: true, ..opts.setup.clone() };
    if let Some(path) = &opts.flash {
        if path.exists() {
            setup.flash_contents = Some(std::fs::read(path).map_err(|e| format!("--flash {}: {e}", path.display()))?);
        }
    }
    if let Some(path) = &opts.params {
        let text = std::fs::read_to_string(path).map_err(|e| format!("--params {}: {e}", path.display()))?;
        let flash = flash_with_parameters(setup.flash_contents.take().unwrap_or_default(), &text)
            .map_err(|e| format!("--params {}: {e}", path.display()))?;
        setup.flash_contents = Some(flash);
    }
    let image = Image::load(&opts.elf)?;
    let mut board = EmulatedBoard::boot(image, &setup, rig::imu_at_rest(1)).map_err(|e| format!("boot: {e}"))?;
    if !board.flying() {
        return Err(format!("{} (within the boot timeout)", board.boot_stall()));
    }
    board.faults_expected = true;
    board.raw_uart = true;
    println!("fcu-pil serve: board booted ({}), serving {}", opts.elf.display(), sc.name);
    if let Some(cut) = opts.power_cut {
        board.machine.board_mut().flash.arm_power_cut(cut);
    }
    let mut bridge = Bridge {
        board: &mut board,
        listener,
        clients: Vec::new(),
        uart_sent: 0,
        resets_said: 0,
        stop,
        started: None,
        flash: opts.flash.clone(),
        flash_saved: u64::MAX,
        report: ServeReport::default(),
    };
    let run = RunOptions { seed: 1, duration_s: Some(duration_s), ..Default::default() };
    let flown = match fcu_testkit::sim::run_with(&mut bridge, &sc, fcu_testkit::Profile::Default, &run) {
        Err(SimError::Computer(why)) if why == STOPPED => Ok(()),
        other => other.map(|_| ()),
    };
    bridge.save_flash(true).map_err(|e| e.to_string())?;
    let mut report = std::mem::take(&mut bridge.report);
    flown.map_err(|e| e.to_string())?;
    let b: &Board = board.machine.board();
    (report.rx_received, report.rx_overrun, report.rx_ignored) = b.usart1.rx_counts();
    report.rx_lost_on_pin = b.records.uart_rx_lost.len();
    report.resets = board.machine.state().resets.len();
    report.power_cuts = board.machine.state().resets.iter().filter(|r| r.1 == "power cut").count();
    if let Some(f) = board.fault_report() {
        eprintln!("fcu-pil serve: {f}");
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_lsi_frequency_outside_17_to_47_khz_is_refused_with_the_range() {
        assert_eq!(parse_lsi_hz("17000"), Ok(17_000));
        assert_eq!(parse_lsi_hz("47000"), Ok(47_000));
        for bad in ["16999", "47001", "0", "32k", "-1"] {
            let err = parse_lsi_hz(bad).unwrap_err();
            assert!(err.contains(&format!("--lsi-hz {bad}")) && err.contains("17000") && err.contains("47000"), "{err}");
        }
    }

    #[test]
    fn a_parameter_file_becomes_the_only_saved_set() {
        use fcu_params::{self as parameters, snapshot};
        // Whatever the sectors held before is gone.
        let old = vec![0u8; 256 * 1024];
        let flash = flash_with_parameters(old, "ANGLE_MAX 30\n# a comment\nRC1_TRIM 1500\n").unwrap();
        let (a, b) = (param_sector_words(&flash, 0), param_sector_words(&flash, 1));
        let (cfg, source) = snapshot::load_config([&a, &b], &fcu_core::Config::default());
        assert_eq!(source, snapshot::Source::Snapshot { sequence: 1, passed_over: None });
        let value = |name: &str| parameters::value(&cfg, parameters::index_of(name.as_bytes()).unwrap()).unwrap();
        // ANGLE_MAX is kept in radians: it reads back within a float's rounding.
        assert!((value("ANGLE_MAX") - 30.0).abs() < 1e-4, "{}", value("ANGLE_MAX"));
        assert_eq!(value("RC1_TRIM"), 1500.0);
        assert!(b.iter().all(|&w| w == u32::MAX), "sector 2 erased");
        assert!(flash[..PARAM_SECTORS.start].iter().all(|&x| x == 0), "the rest of the flash untouched");
    }

    #[test]
    fn a_flight_keeps_the_flash_set_takes_the_file_over_it_and_talks_text() {
        use fcu_params::{self as parameters, snapshot};
        let saved = flash_with_parameters(Vec::new(), "ANGLE_MAX 30\nRC1_TRIM 1500\n").unwrap();
        let flash = flash_for_flight(saved, Some("RC1_TRIM 1400\n")).unwrap();
        let (cfg, source) =
            snapshot::load_config([&param_sector_words(&flash, 0), &param_sector_words(&flash, 1)], &fcu_core::Config::default());
        assert_eq!(source, snapshot::Source::Snapshot { sequence: 1, passed_over: None });
        let value = |name: &str| parameters::value(&cfg, parameters::index_of(name.as_bytes()).unwrap()).unwrap();
        assert!((value("ANGLE_MAX") - 30.0).abs() < 1e-4, "the flash's set kept");
        assert_eq!(value("RC1_TRIM"), 1400.0, "the file over it");
        assert_eq!(value("LINK_PROTOCOL"), 0.0, "text lines for the harness");
        // No flash: the defaults, text lines.
        let (cfg, _) = {
            let f = flash_for_flight(Vec::new(), None).unwrap();
            snapshot::load_config([&param_sector_words(&f, 0), &param_sector_words(&f, 1)], &fcu_core::Config::default())
        };
        assert_eq!(parameters::value(&cfg, parameters::index_of(b"LINK_PROTOCOL").unwrap()), Some(0.0));
        assert_eq!(
            flash_for_flight(Vec::new(), Some("NO_SUCH 1\n")),
            Err(FlightFlashError::File(format!("line 1: {}", parameters::RULE_UNKNOWN)))
        );
    }

    #[test]
    fn a_file_the_set_refuses_names_its_line() {
        let e = flash_with_parameters(Vec::new(), "ANGLE_MAX 30\nNO_SUCH 1\n").unwrap_err();
        assert!(e.starts_with("line 2:"), "{e}");
        let e = flash_with_parameters(Vec::new(), "# angles\nANGLE_MAX 300\n").unwrap_err();
        assert!(e.starts_with("line 2:"), "{e}");
        // Each line fine, the set they make refused (a trim outside its endpoints).
        let e = flash_with_parameters(Vec::new(), "RC1_MIN 1000\nRC1_MAX 1200\nRC1_TRIM 1300\n").unwrap_err();
        assert!(e.starts_with("the set is refused:"), "{e}");
    }

    #[test]
    fn power_cuts_parse_with_a_kind_a_fraction_and_an_index() {
        assert_eq!(parse_power_cut("erase:3/8"), Ok(ArmedCut { erase: true, nth: 1, fraction: 0.375 }));
        assert_eq!(parse_power_cut("program:0.5@2"), Ok(ArmedCut { erase: false, nth: 2, fraction: 0.5 }));
        for bad in ["erase", "write:1/2", "erase:9/8", "erase:1/0", "program:0.5@0", "erase:x"] {
            assert!(parse_power_cut(bad).is_err(), "{bad}");
        }
    }
}
