//! The link to the board: a byte stream (TCP or a serial port), a thread that parses what the
//! board sends, and a ground station's HEARTBEAT at 1 Hz.
//!
//! Only frames from the board (system [`BOARD_SYSTEM`], component [`BOARD_COMPONENT`]) are
//! handed on; frames that do not parse (a CRC error, a message outside the common dialect) are
//! skipped, as a ground station skips them.

use std::io::{ErrorKind, Read, Write};
use std::net::{TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use mavlink::dialects::common::{MavAutopilot, MavMessage, MavModeFlag, MavState, MavType, HEARTBEAT_DATA};
use mavlink::error::MessageReadError;
use mavlink::{MAVLinkV2MessageRaw, MavHeader, MavlinkReader};

use crate::address::LinkAddress;

/// The board's MAVLink system id.
pub const BOARD_SYSTEM: u8 = 1;
/// The board's MAVLink component id (the autopilot).
pub const BOARD_COMPONENT: u8 = 1;
/// Ours: a ground station's system id, as MAVProxy and QGroundControl use.
pub const GCS_SYSTEM: u8 = 255;
/// Ours: `MAV_COMP_ID_MISSIONPLANNER`, a ground station's component.
pub const GCS_COMPONENT: u8 = 190;

/// How long a blocked read waits before the reading thread looks whether it should stop.
const READ_POLL: Duration = Duration::from_millis(200);
/// Our HEARTBEAT period.
const HEARTBEAT_PERIOD: Duration = Duration::from_secs(1);

/// Something went wrong on the link; the text names the link.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LinkError(pub String);

impl std::fmt::Display for LinkError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for LinkError {}

enum Incoming {
    Message(Box<MavMessage>),
    /// The stream ended or failed: the reason.
    Closed(String),
}

struct Sender {
    out: Box<dyn Write + Send>,
    sequence: u8,
}

impl Sender {
    fn send(&mut self, msg: &MavMessage) -> std::io::Result<()> {
        let header = MavHeader { system_id: GCS_SYSTEM.into(), component_id: GCS_COMPONENT, sequence: self.sequence };
        self.sequence = self.sequence.wrapping_add(1);
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.serialize_message(header, msg);
        self.out.write_all(raw.raw_bytes())?;
        self.out.flush()
    }
}

/// An open link to the board.
pub struct Connection {
    address: LinkAddress,
    sender: Arc<Mutex<Sender>>,
    incoming: Receiver<Incoming>,
    stop: Arc<AtomicBool>,
    closed: Option<String>,
}

impl Connection {
    /// Opens the link (within `timeout` for a TCP connection) and starts our HEARTBEAT.
    pub fn open(address: &LinkAddress, timeout: Duration) -> Result<Connection, LinkError> {
        let (reader, writer): (Box<dyn Read + Send>, Box<dyn Write + Send>) = match address {
            LinkAddress::Tcp { host, port } => {
                let stream = connect_tcp(host, *port, timeout).map_err(|e| LinkError(format!("--link {address}: {e}")))?;
                let _ = stream.set_nodelay(true);
                stream.set_read_timeout(Some(READ_POLL)).map_err(|e| LinkError(format!("--link {address}: {e}")))?;
                let reader = stream.try_clone().map_err(|e| LinkError(format!("--link {address}: {e}")))?;
                (Box::new(reader), Box::new(stream))
            }
            LinkAddress::Serial { path, baud } => {
                let port = serialport::new(path, *baud)
                    .timeout(READ_POLL)
                    .open()
                    .map_err(|e| LinkError(format!("--link {address}: cannot open the serial port: {e}")))?;
                let reader = port.try_clone().map_err(|e| LinkError(format!("--link {address}: {e}")))?;
                (Box::new(reader), Box::new(port))
            }
        };
        let stop = Arc::new(AtomicBool::new(false));
        let (tx, incoming) = mpsc::channel();
        let sender = Arc::new(Mutex::new(Sender { out: writer, sequence: 0 }));
        {
            let stop = Arc::clone(&stop);
            std::thread::spawn(move || read_loop(reader, &tx, &stop));
        }
        {
            let stop = Arc::clone(&stop);
            let sender = Arc::clone(&sender);
            std::thread::spawn(move || heartbeat_loop(&sender, &stop));
        }
        Ok(Connection { address: address.clone(), sender, incoming, stop, closed: None })
    }

    /// The address the link was opened on.
    pub fn address(&self) -> &LinkAddress {
        &self.address
    }

    /// Sends one message to the board.
    pub fn send(&self, msg: &MavMessage) -> Result<(), LinkError> {
        let mut sender = self.sender.lock().map_err(|_| LinkError("the link's sender failed".into()))?;
        sender.send(msg).map_err(|e| LinkError(format!("--link {}: sending: {e}", self.address)))
    }

    /// The board's next message, `None` when nothing came within `timeout`; an error when the
    /// link closed.
    pub fn recv(&mut self, timeout: Duration) -> Result<Option<MavMessage>, LinkError> {
        if let Some(reason) = &self.closed {
            return Err(LinkError(reason.clone()));
        }
        match self.incoming.recv_timeout(timeout) {
            Ok(Incoming::Message(m)) => Ok(Some(*m)),
            Ok(Incoming::Closed(reason)) => {
                let reason = format!("--link {}: {reason}", self.address);
                self.closed = Some(reason.clone());
                Err(LinkError(reason))
            }
            Err(RecvTimeoutError::Timeout) => Ok(None),
            Err(RecvTimeoutError::Disconnected) => Err(LinkError(format!("--link {}: the link's reader stopped", self.address))),
        }
    }

    /// Waits for the board's HEARTBEAT, at most `timeout`.
    pub fn wait_for_board(&mut self, timeout: Duration) -> Result<HEARTBEAT_DATA, LinkError> {
        let deadline = Instant::now() + timeout;
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            if let Some(MavMessage::HEARTBEAT(hb)) = self.recv(left)? {
                return Ok(hb);
            }
        }
        Err(LinkError(format!(
            "--link {}: the board did not answer: no HEARTBEAT from system {BOARD_SYSTEM} within {:.0} s \
             (is it powered, is this its port and baud rate, does it speak MAVLink?)",
            self.address,
            timeout.as_secs_f64()
        )))
    }
}

impl Drop for Connection {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn connect_tcp(host: &str, port: u16, timeout: Duration) -> std::io::Result<TcpStream> {
    let mut last = std::io::Error::new(ErrorKind::NotFound, format!("{host} has no address"));
    for addr in (host, port).to_socket_addrs()? {
        match TcpStream::connect_timeout(&addr, timeout) {
            Ok(s) => return Ok(s),
            Err(e) => last = e,
        }
    }
    Err(last)
}

/// A std stream as embedded-io's reader, keeping the last error (embedded-io's carries only
/// a kind) for the message.
pub(crate) struct Io {
    pub(crate) inner: Box<dyn Read + Send>,
    pub(crate) error: Option<std::io::Error>,
}

impl embedded_io::ErrorType for Io {
    type Error = embedded_io::ErrorKind;
}

impl embedded_io::Read for Io {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        match self.inner.read(buf) {
            Ok(0) if !buf.is_empty() => {
                self.error = Some(std::io::Error::new(ErrorKind::UnexpectedEof, "the board's end closed the link"));
                Err(embedded_io::ErrorKind::Other)
            }
            Ok(n) => Ok(n),
            Err(e) => {
                self.error = Some(e);
                Err(embedded_io::ErrorKind::Other)
            }
        }
    }
}

fn read_loop(source: Box<dyn Read + Send>, tx: &mpsc::Sender<Incoming>, stop: &AtomicBool) {
    let mut reader = MavlinkReader::new(Io { inner: source, error: None });
    while !stop.load(Ordering::Relaxed) {
        match reader.read_any_message::<MavMessage>() {
            Ok((header, msg)) => {
                if header.system_id != u32::from(BOARD_SYSTEM) || header.component_id != BOARD_COMPONENT {
                    continue;
                }
                if tx.send(Incoming::Message(Box::new(msg))).is_err() {
                    return;
                }
            }
            Err(MessageReadError::Io) => {
                let Some(e) = reader.get_mut().error.take() else { continue };
                // A read timeout only lets the loop look at `stop`; the reader keeps any partial
                // frame for the next read.
                if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted) {
                    continue;
                }
                let _ = tx.send(Incoming::Closed(e.to_string()));
                return;
            }
            // A frame that does not parse is skipped; the reader resynchronises on the next.
            Err(MessageReadError::Parse(_)) => {}
        }
    }
}

fn heartbeat_loop(sender: &Mutex<Sender>, stop: &AtomicBool) {
    let heartbeat = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_GCS,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    });
    while !stop.load(Ordering::Relaxed) {
        let sent = match sender.lock() {
            Ok(mut s) => s.send(&heartbeat).is_ok(),
            Err(_) => false,
        };
        if !sent {
            // The reader reports the link's end; nothing more to send on it.
            return;
        }
        std::thread::sleep(HEARTBEAT_PERIOD);
    }
}
