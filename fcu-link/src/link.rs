//! The link: frames in, answers and telemetry out (see [`Link`]).

use mavlink::dialects::common::{
    COMMAND_INT_DATA, COMMAND_LONG_DATA, FILE_TRANSFER_PROTOCOL_DATA, HEARTBEAT_DATA, MISSION_REQUEST_LIST_DATA, PARAM_REQUEST_LIST_DATA,
    PARAM_REQUEST_READ_DATA, PARAM_SET_DATA,
};
use mavlink::MessageData;

use crate::command::Command;
use crate::frame::{self, MAX_FRAME};
use crate::motor_test::{MotorTest, MotorTestState};
use crate::rates::Rates;
use crate::reader::{Frame, FrameReader, ReaderStats};
use crate::text::{Severity, Text};
use crate::tx::TxQueue;
use crate::vehicle::Vehicle;
use crate::{COMPONENT_ID, SYSTEM_ID};

/// What the link is set up with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LinkConfig {
    /// Telemetry rates.
    pub rates: Rates,
    /// AUTOPILOT_VERSION's `flight_sw_version` (MAVLink packs it as major << 24 | minor << 16
    /// | patch << 8 | type).
    pub flight_sw_version: u32,
    /// AUTOPILOT_VERSION's `uid` (the chip's unique id folded to 64 bits; 0 when unknown).
    pub uid: u64,
}

impl LinkConfig {
    /// Default rates, version 0.1.0 (type "dev"), no uid.
    pub const DEFAULT: Self = Self { rates: Rates::DEFAULT, flight_sw_version: 0x0001_0000, uid: 0 };
}

impl Default for LinkConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Everything the link counted. Counters saturate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// The frame reader's counts (kept frames and why others were dropped).
    pub reader: ReaderStats,
    /// Good frames addressed to another system or component.
    pub not_for_us: u32,
    /// Good frames whose payload the dialect could not decode (an enum value it does not list
    /// where the link needs the enum).
    pub bad_payload: u32,
    /// PARAM_REQUEST_READs of a parameter that does not exist (answered with nothing, as the
    /// parameter protocol has it: the ground station times out).
    pub param_unknown: u32,
    /// Frames dropped because the transmit queue was full.
    pub tx_dropped: u32,
}

/// A time-based stream: sends when `now` reaches `next_ms`.
/// A line silent this long has no ground station on it any more: the next HEARTBEAT is a new
/// one, which is greeted ([`Link::greet`]). Ground stations send theirs every second.
pub const STATION_GONE_MS: u32 = 5000;

#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Stream {
    next_ms: u32,
}

impl Stream {
    /// True once per `period_ms` (never for 0). A stream that fell more than a period behind
    /// (a stalled caller) restarts from now instead of bursting to catch up.
    pub(crate) fn due(&mut self, now_ms: u32, period_ms: u16) -> bool {
        if period_ms == 0 || (now_ms.wrapping_sub(self.next_ms) as i32) < 0 {
            return false;
        }
        let period = u32::from(period_ms);
        self.next_ms =
            if now_ms.wrapping_sub(self.next_ms) >= period { now_ms.wrapping_add(period) } else { self.next_ms.wrapping_add(period) };
        true
    }
}

#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Schedule {
    pub(crate) heartbeat: Stream,
    pub(crate) attitude: Stream,
    pub(crate) sys_status: Stream,
    pub(crate) battery: Stream,
    pub(crate) rc_channels: Stream,
    pub(crate) servo_output: Stream,
    pub(crate) param: Stream,
}

/// Everything but the reader, so that a frame borrowed from the reader can be handled.
#[derive(Clone, Debug)]
pub(crate) struct Core<const TX: usize> {
    pub(crate) tx: TxQueue<TX>,
    sequence: u8,
    pub(crate) config: LinkConfig,
    pub(crate) schedule: Schedule,
    pub(crate) param_cursor: Option<u16>,
    pub(crate) motor_test: Option<MotorTest>,
    pub(crate) last_rx_ms: Option<u32>,
    /// Said when the host asked ([`Link::greet`]) and again to each ground station that
    /// connects afterwards.
    greeting: Option<(Severity, Text)>,
    pub(crate) now_ms: u32,
    pub(crate) reboot_pending: bool,
    pub(crate) stats: LinkStats,
}

/// The MAVLink 2 link of one flight controller.
///
/// `TX` is the transmit queue's size in bytes: it must hold a tick's telemetry (under 300
/// bytes at once) plus the answers to a burst of requests; 512 is a good size at 115200 baud
/// drained every few milliseconds.
///
/// Sent: HEARTBEAT, ATTITUDE, SYS_STATUS, BATTERY_STATUS, RC_CHANNELS, SERVO_OUTPUT_RAW at
/// [`Rates`]; STATUSTEXT on refusals and on the host's events ([`Link::send_text`]);
/// AUTOPILOT_VERSION on request (capabilities MAVLINK2 and PARAM_ENCODE_C_CAST).
///
/// Handled:
/// - PARAM_REQUEST_LIST: every PARAM_VALUE in index order, one per [`Rates::param_ms`];
/// - PARAM_REQUEST_READ by index, or by name when the index is -1;
/// - PARAM_SET: always answered with a PARAM_VALUE carrying the value in force, whether the
///   set was taken or refused; a refusal also sends a STATUSTEXT `NAME: rule`. NaN, infinities
///   and types other than REAL32 are refused by the link, everything else by the vehicle. A
///   name the table does not have has no value to echo: it gets a STATUSTEXT only;
/// - MISSION_REQUEST_LIST: MISSION_COUNT 0 of the asked mission type;
/// - FILE_TRANSFER_PROTOCOL: a NAK (UnknownCommand), so that MAVProxy falls back to the
///   parameter protocol at once;
/// - COMMAND_LONG and COMMAND_INT: always a COMMAND_ACK, UNSUPPORTED unless the command is one
///   of [`crate::command`]'s.
///
/// Messages addressed to another system or component are counted and ignored.
#[derive(Clone, Debug)]
pub struct Link<const TX: usize> {
    reader: FrameReader,
    core: Core<TX>,
}

impl<const TX: usize> Default for Link<TX> {
    fn default() -> Self {
        Self::new(LinkConfig::DEFAULT)
    }
}

impl<const TX: usize> Link<TX> {
    /// A link that has heard nothing yet.
    pub const fn new(config: LinkConfig) -> Self {
        Self {
            reader: FrameReader::new(),
            core: Core {
                tx: TxQueue::new(),
                sequence: 0,
                config,
                schedule: Schedule {
                    heartbeat: Stream { next_ms: 0 },
                    attitude: Stream { next_ms: 0 },
                    sys_status: Stream { next_ms: 0 },
                    battery: Stream { next_ms: 0 },
                    rc_channels: Stream { next_ms: 0 },
                    servo_output: Stream { next_ms: 0 },
                    param: Stream { next_ms: 0 },
                },
                param_cursor: None,
                motor_test: None,
                last_rx_ms: None,
                greeting: None,
                now_ms: 0,
                reboot_pending: false,
                stats: LinkStats {
                    reader: ReaderStats { frames: 0, bad_crc: 0, bad_length: 0, unknown_id: 0, signed: 0, incompatible: 0, noise_bytes: 0 },
                    not_for_us: 0,
                    bad_payload: 0,
                    param_unknown: 0,
                    tx_dropped: 0,
                },
            },
        }
    }

    /// Takes the bytes the UART received (any number, any content) at `now_ms` and handles
    /// every good frame among them.
    pub fn receive<V: Vehicle>(&mut self, bytes: &[u8], now_ms: u32, vehicle: &mut V) {
        self.core.now_ms = now_ms;
        for &byte in bytes {
            if let Some(frame) = self.reader.push(byte) {
                self.core.handle(frame, vehicle);
            }
        }
    }

    /// Runs the schedule at `now_ms`: the motor test's limits, due telemetry, the next
    /// PARAM_VALUE of a download. Call it at 100 Hz or faster (the parameter download sends at
    /// most one PARAM_VALUE per call).
    pub fn tick<V: Vehicle>(&mut self, now_ms: u32, vehicle: &mut V) {
        self.core.now_ms = now_ms;
        self.core.tick(vehicle);
    }

    /// Moves waiting bytes into `out` (for the UART); returns how many.
    pub fn poll_tx(&mut self, out: &mut [u8]) -> usize {
        self.core.tx.pop(out)
    }

    /// Bytes waiting to be sent.
    pub fn tx_pending(&self) -> usize {
        self.core.tx.len()
    }

    /// Sends a STATUSTEXT now (cut at 50 bytes) and again to every ground station that
    /// connects later: the first HEARTBEAT after [`STATION_GONE_MS`] of silence from the
    /// line. For what a station should always hear, once: where the parameters came from at
    /// boot. A later call replaces the text.
    pub fn greet(&mut self, severity: Severity, text: &[u8]) -> bool {
        let text = Text::new().push_bytes(text);
        self.core.greeting = Some((severity, text));
        self.core.text(severity, text)
    }

    /// Sends a STATUSTEXT (cut at 50 bytes); false when the transmit queue had no room.
    ///
    /// Texts are bytes (ASCII, or UTF-8), not `str`: a host with its text in a byte buffer then
    /// needs no UTF-8 check, whose code and table are 600 bytes of flash.
    pub fn send_text(&mut self, severity: Severity, text: &[u8]) -> bool {
        self.core.text(severity, Text::new().push_bytes(text))
    }

    /// The motor test running, if any.
    pub fn motor_test(&self) -> Option<MotorTestState> {
        self.core.motor_test.map(|t| t.state(self.core.now_ms))
    }

    /// True once a reboot was accepted and its COMMAND_ACK has left the queue: the host
    /// reboots when this is true, its UART has sent the last byte and no save is pending.
    pub fn reboot_ready(&self) -> bool {
        self.core.reboot_pending && self.core.tx.is_empty()
    }

    /// Changes the telemetry rates (from the parameter table).
    pub fn set_rates(&mut self, rates: Rates) {
        self.core.config.rates = rates;
    }

    /// What was counted so far.
    pub fn stats(&self) -> LinkStats {
        let mut stats = self.core.stats;
        stats.reader = self.reader.stats();
        stats
    }
}

/// Counts one more, saturating. Out of line: some twenty counters are bumped, each then a call.
#[inline(never)]
pub(crate) fn bump(counter: &mut u32) {
    *counter = counter.saturating_add(1);
}

/// True for a message addressed to us or to everyone.
#[inline(never)]
pub(crate) fn for_us(target_system: u8, target_component: u8) -> bool {
    (target_system == 0 || target_system == SYSTEM_ID) && (target_component == 0 || target_component == COMPONENT_ID)
}

impl<const TX: usize> Core<TX> {
    /// Queues one message; false (and counted) when the queue had no room.
    pub(crate) fn send<D: MessageData>(&mut self, data: &D) -> bool {
        self.send_patched(data, &[])
    }

    /// [`Core::send`] with payload patches (see [`frame::encode_patched`]).
    pub(crate) fn send_patched<D: MessageData>(&mut self, data: &D, patches: &[frame::Patch]) -> bool {
        let mut payload = [0u8; frame::MAX_PAYLOAD];
        frame::serialize(data, &mut payload);
        self.queue(frame::Header::of::<D>(), &mut payload, patches)
    }

    /// Frames a serialized payload and queues it. Out of line and not generic over the
    /// message: one copy of the framing and queueing for every message sent.
    #[inline(never)]
    fn queue(&mut self, header: frame::Header, payload: &mut [u8; frame::MAX_PAYLOAD], patches: &[frame::Patch]) -> bool {
        let mut out = [0u8; MAX_FRAME];
        let len = frame::encode_payload(self.sequence, header, payload, patches, &mut out);
        // The sequence advances for dropped frames too, so the ground station's loss count
        // sees them.
        self.sequence = self.sequence.wrapping_add(1);
        let sent = out.get(..len).is_some_and(|bytes| self.tx.push(bytes));
        if !sent {
            bump(&mut self.stats.tx_dropped);
        }
        sent
    }

    fn handle<V: Vehicle>(&mut self, frame: Frame<'_>, vehicle: &mut V) {
        let silent_before = self.last_rx_ms.is_none_or(|last| self.now_ms.wrapping_sub(last) > STATION_GONE_MS);
        self.last_rx_ms = Some(self.now_ms);
        let payload = frame.payload;
        match frame.message_id {
            HEARTBEAT_DATA::ID => {
                // A station that connects after the board booted missed what it said then.
                if let Some((severity, text)) = self.greeting.filter(|_| silent_before) {
                    self.text(severity, text);
                }
            }
            PARAM_REQUEST_LIST_DATA::ID => match frame::decode::<PARAM_REQUEST_LIST_DATA>(payload) {
                Some(m) if for_us(m.target_system, m.target_component) => {
                    self.param_cursor = Some(0);
                }
                Some(_) => bump(&mut self.stats.not_for_us),
                None => bump(&mut self.stats.bad_payload),
            },
            PARAM_REQUEST_READ_DATA::ID => match frame::decode::<PARAM_REQUEST_READ_DATA>(payload) {
                Some(m) => self.param_request_read(&m, vehicle),
                None => bump(&mut self.stats.bad_payload),
            },
            PARAM_SET_DATA::ID => self.param_set(payload, vehicle),
            MISSION_REQUEST_LIST_DATA::ID => self.mission_request_list(&frame),
            COMMAND_LONG_DATA::ID | COMMAND_INT_DATA::ID => match Command::decode(&frame) {
                Some(command) if for_us(command.target_system, command.target_component) => {
                    self.command(&command, vehicle);
                }
                Some(_) => bump(&mut self.stats.not_for_us),
                None => bump(&mut self.stats.bad_payload),
            },
            FILE_TRANSFER_PROTOCOL_DATA::ID => self.file_transfer(&frame),
            _ => {}
        }
    }

    fn tick<V: Vehicle>(&mut self, vehicle: &mut V) {
        let state = vehicle.state();
        self.check_motor_test(&state, vehicle);
        self.telemetry(&state);
        self.param_download(vehicle);
    }

    /// Queues a STATUSTEXT.
    pub(crate) fn text(&mut self, severity: Severity, text: Text) -> bool {
        let data =
            mavlink::dialects::common::STATUSTEXT_DATA { severity: severity.mav(), text: mavlink::types::CharArray::new(text.bytes()) };
        self.send(&data)
    }
}
