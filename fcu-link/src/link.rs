//! The link: frames in, answers and telemetry out (see [`Link`]).

use mavlink::dialects::common::{ALTITUDE_DATA, SCALED_PRESSURE_DATA, VFR_HUD_DATA};
use mavlink::dialects::common::{
    ATTITUDE_DATA, AUTOPILOT_VERSION_DATA, BATTERY_STATUS_DATA, COMMAND_INT_DATA, COMMAND_LONG_DATA, FILE_TRANSFER_PROTOCOL_DATA,
    HEARTBEAT_DATA, MISSION_REQUEST_LIST_DATA, PARAM_REQUEST_LIST_DATA, PARAM_REQUEST_READ_DATA, PARAM_SET_DATA, RC_CHANNELS_DATA,
    SERVO_OUTPUT_RAW_DATA, STATUSTEXT_DATA, SYS_STATUS_DATA,
};
use mavlink::MessageData;

use crate::command::Command;
use crate::frame::{self, MAX_FRAME};
use crate::rates::Rates;
use crate::reader::{Frame, FrameReader, ReaderStats};
use crate::text::{Severity, Text, TEXT_LEN};
use crate::tx::TxQueue;
use crate::vehicle::{ParamMask, Vehicle};
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
    /// PARAM_REQUEST_READs with a negative index other than -1 (MAVLink's "by name"): no
    /// parameter has one; answered with nothing.
    pub param_bad_index: u32,
    /// Frames dropped because the transmit queue was full (telemetry is never dropped: a
    /// message that finds no room stays due).
    pub tx_dropped: u32,
    /// Answers to requests dropped because only the telemetry's reserve was left in the
    /// transmit queue (see [`TELEMETRY_RESERVE`]). The ground station asks again: a
    /// PARAM_REQUEST_READ, PARAM_SET or command without an answer is retried.
    pub answers_dropped: u32,
}

/// Bytes of the transmit queue that answers to requests leave free, for telemetry: every
/// stream due in the same tick, each frame at its longest (341 B). A ground station flooding
/// the link with requests (MAVProxy asking for parameters again and again) then fills the
/// queue up to here and no further, and HEARTBEAT, ATTITUDE and the rest keep their rates.
///
/// COMMAND_ACK is excepted: it may take the whole queue, as an event does. A ground station
/// that misses the ACK of a reboot or a save sends the command again, and a flood of
/// parameter requests must not cost it; commands come far slower than the line drains their
/// 22-byte ACKs, so they cannot starve the telemetry, which stays due until it has room.
pub const TELEMETRY_RESERVE: usize = telemetry_frame::<HEARTBEAT_DATA>()
    + telemetry_frame::<ATTITUDE_DATA>()
    + telemetry_frame::<SYS_STATUS_DATA>()
    + telemetry_frame::<BATTERY_STATUS_DATA>()
    + telemetry_frame::<RC_CHANNELS_DATA>()
    + telemetry_frame::<SERVO_OUTPUT_RAW_DATA>()
    + telemetry_frame::<VFR_HUD_DATA>()
    + telemetry_frame::<ALTITUDE_DATA>()
    + telemetry_frame::<SCALED_PRESSURE_DATA>();

const fn telemetry_frame<D: MessageData>() -> usize {
    frame::V2_HEADER + D::ENCODED_LEN + 2
}

/// The longest answer that is one frame: a queue too small for it and the whole reserve keeps
/// a smaller reserve, so that every answer can still go out.
const LONGEST_ANSWER: usize = frame::V2_HEADER + AUTOPILOT_VERSION_DATA::ENCODED_LEN + 2;

/// STATUSTEXT's payload with its MAVLink 2 extensions: severity, text, `id` (u16) and
/// `chunk_seq` (u8). The crate's struct has no extensions (see [`frame`]): they are written
/// into the payload by hand.
const STATUSTEXT_LEN: usize = 1 + TEXT_LEN + 3;

/// Which share of the transmit queue a frame may take, and what happens when it does not fit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Room {
    /// Periodic telemetry: the whole queue; without room it is not sent and stays due.
    Telemetry,
    /// An answer to a request: the queue less [`TELEMETRY_RESERVE`]; without room it is
    /// dropped ([`LinkStats::answers_dropped`]).
    Answer,
    /// The host's and the link's own events (STATUSTEXTs): the whole queue; without room
    /// dropped ([`LinkStats::tx_dropped`]).
    Event,
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
        let ready = self.ready(now_ms, period_ms);
        if ready {
            self.sent(now_ms, period_ms);
        }
        ready
    }

    /// Whether a message is due (never for a period of 0), without taking it.
    pub(crate) fn ready(&self, now_ms: u32, period_ms: u16) -> bool {
        period_ms != 0 && (now_ms.wrapping_sub(self.next_ms) as i32) >= 0
    }

    /// The due message went out: the next is due a period later.
    pub(crate) fn sent(&mut self, now_ms: u32, period_ms: u16) {
        let period = u32::from(period_ms);
        self.next_ms =
            if now_ms.wrapping_sub(self.next_ms) >= period { now_ms.wrapping_add(period) } else { self.next_ms.wrapping_add(period) };
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
    pub(crate) vfr_hud: Stream,
    pub(crate) altitude: Stream,
    pub(crate) scaled_pressure: Stream,
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
    /// PARAM_VALUEs a PARAM_SET called for that found no room: sent in index order as room
    /// comes ([`Link::tick`]).
    pub(crate) params_owed: ParamMask,
    /// The `id` of the last chunked STATUSTEXT (0: none yet).
    text_id: u16,
    /// The running motor test was asked to stop for the ground station's silence.
    pub(crate) motor_test_silence_stop: bool,
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
/// `TX` is the transmit queue's size in bytes: it must hold a tick's telemetry
/// ([`TELEMETRY_RESERVE`], 341 bytes, which answers to requests leave free) plus the answers
/// to a burst of requests; 512 is a good size at 115200 baud drained every few milliseconds.
/// Telemetry keeps its rates whatever the ground station asks: an answer that finds only the
/// reserve free is dropped and counted, a telemetry message that finds no room stays due.
///
/// Sent: HEARTBEAT (the flight state and the vertical mode: [`crate::heartbeat`]), ATTITUDE,
/// SYS_STATUS, BATTERY_STATUS, RC_CHANNELS, SERVO_OUTPUT_RAW, VFR_HUD, ALTITUDE and
/// SCALED_PRESSURE (from the barometer's first sample on) at [`Rates`]; STATUSTEXT on refusals and on the host's events ([`Link::send_text`]), in
/// chunks past 50 bytes ([`crate::text`]); AUTOPILOT_VERSION on request (capabilities
/// MAVLINK2 and PARAM_ENCODE_C_CAST).
///
/// Handled:
/// - PARAM_REQUEST_LIST: every PARAM_VALUE in index order, one per [`Rates::param_ms`];
/// - PARAM_REQUEST_READ by index, or by name when the index is -1; any other negative index
///   is no parameter's: no answer, counted ([`LinkStats::param_bad_index`]);
/// - PARAM_SET: always answered with a PARAM_VALUE carrying the value in force, whether the
///   set was taken or refused; a set taken then sends a PARAM_VALUE for every other parameter
///   it changed, in index order (setting RCMAP_ROLL swaps the channel of another RCMAP_*), and
///   what the queue has no room for goes out on the next ticks. A refusal also sends a
///   STATUSTEXT `NAME: rule`. NaN, infinities and types other than REAL32 are refused by the
///   link, everything else by the vehicle. A name the table does not have has no value to
///   echo: it gets a STATUSTEXT only;
/// - MISSION_REQUEST_LIST: MISSION_COUNT 0 of the asked mission type;
/// - FILE_TRANSFER_PROTOCOL: a NAK (UnknownCommand), so that MAVProxy falls back to the
///   parameter protocol at once;
/// - COMMAND_LONG and COMMAND_INT: always a COMMAND_ACK, UNSUPPORTED unless the command is one
///   of [`crate::command`]'s;
/// - SET_MODE: a set-mode as DO_SET_MODE's ([`crate::command`]), answered with a COMMAND_ACK
///   whose command is SET_MODE's message id, 11, as ArduPilot answers it.
///
/// Messages addressed to another system or component are counted and ignored. Signed MAVLink 2
/// frames are not supported: they are counted ([`ReaderStats::signed`]) and dropped, answered
/// with nothing.
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
                    vfr_hud: Stream { next_ms: 0 },
                    altitude: Stream { next_ms: 0 },
                    scaled_pressure: Stream { next_ms: 0 },
                    param: Stream { next_ms: 0 },
                },
                param_cursor: None,
                params_owed: ParamMask::EMPTY,
                text_id: 0,
                motor_test_silence_stop: false,
                last_rx_ms: None,
                greeting: None,
                now_ms: 0,
                reboot_pending: false,
                stats: LinkStats {
                    reader: ReaderStats { frames: 0, bad_crc: 0, bad_length: 0, unknown_id: 0, signed: 0, incompatible: 0, noise_bytes: 0 },
                    not_for_us: 0,
                    bad_payload: 0,
                    param_unknown: 0,
                    param_bad_index: 0,
                    tx_dropped: 0,
                    answers_dropped: 0,
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

    /// Runs the schedule at `now_ms`: a motor test's stop on silence, due telemetry, the PARAM_VALUEs
    /// owed to a PARAM_SET, the next PARAM_VALUE of a download. Call it at 100 Hz or faster
    /// (the parameter download sends at most one PARAM_VALUE per call).
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

    /// Sends a STATUSTEXT now (chunked past 50 bytes, cut at [`crate::text::TEXT_MAX_LEN`]: see
    /// [`crate::text`]) and again to every ground station that connects later: the first
    /// HEARTBEAT after [`STATION_GONE_MS`] of silence from the line. For what a station should
    /// always hear, once: where the parameters came from at boot (a long text is fine: it is
    /// re-sent in chunks too). A later call replaces the text.
    pub fn greet(&mut self, severity: Severity, text: &[u8]) -> bool {
        let text = Text::new().push_bytes(text);
        self.core.greeting = Some((severity, text));
        self.core.text(severity, text, Room::Event)
    }

    /// Sends a STATUSTEXT (chunked past 50 bytes, cut at [`crate::text::TEXT_MAX_LEN`]: see
    /// [`crate::text`]); false when the transmit queue had no room for all of it (then none
    /// of it is sent).
    ///
    /// Texts are bytes (ASCII, or UTF-8), not `str`: a host with its text in a byte buffer then
    /// needs no UTF-8 check, whose code and table are 600 bytes of flash.
    pub fn send_text(&mut self, severity: Severity, text: &[u8]) -> bool {
        self.core.text(severity, Text::new().push_bytes(text), Room::Event)
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

/// Counts one more, saturating.
pub(crate) fn bump(counter: &mut u32) {
    *counter = counter.saturating_add(1);
}

/// True for a message addressed to us or to everyone.
pub(crate) fn for_us(target_system: u8, target_component: u8) -> bool {
    (target_system == 0 || target_system == SYSTEM_ID) && (target_component == 0 || target_component == COMPONENT_ID)
}

impl<const TX: usize> Core<TX> {
    /// Bytes of the queue answers leave to telemetry: [`TELEMETRY_RESERVE`], less in a queue
    /// too small to hold it and the longest answer.
    const RESERVE: usize = if TX >= TELEMETRY_RESERVE + LONGEST_ANSWER { TELEMETRY_RESERVE } else { TX.saturating_sub(LONGEST_ANSWER) };

    /// Bytes a frame of `room` may take now.
    pub(crate) fn room(&self, room: Room) -> usize {
        match room {
            Room::Answer => self.tx.free().saturating_sub(Self::RESERVE),
            Room::Telemetry | Room::Event => self.tx.free(),
        }
    }

    /// Queues one message in `room`; false (and counted unless telemetry) when it had none.
    pub(crate) fn send<D: MessageData>(&mut self, data: &D, room: Room) -> bool {
        self.send_patched(data, &[], room)
    }

    /// [`Core::send`] with payload patches (see [`frame::encode_patched`]).
    pub(crate) fn send_patched<D: MessageData>(&mut self, data: &D, patches: &[frame::Patch], room: Room) -> bool {
        let mut payload = [0u8; frame::MAX_PAYLOAD];
        frame::serialize(data, &mut payload);
        self.queue(frame::Header::of::<D>(), &mut payload, patches, room)
    }

    /// Frames a serialized payload and queues it. Not generic over the message: one copy of
    /// the framing and queueing for every message sent.
    fn queue(&mut self, header: frame::Header, payload: &mut [u8; frame::MAX_PAYLOAD], patches: &[frame::Patch], room: Room) -> bool {
        let mut out = [0u8; MAX_FRAME];
        let len = frame::encode_payload(self.sequence, header, payload, patches, &mut out);
        if len > self.room(room) {
            // Telemetry that finds no room is not lost: it stays due and goes at a later tick.
            if room != Room::Telemetry {
                self.dropped(room);
            }
            return false;
        }
        self.sequence = self.sequence.wrapping_add(1);
        out.get(..len).is_some_and(|bytes| self.tx.push(bytes))
    }

    /// Counts a frame of `room` dropped for want of room.
    fn dropped(&mut self, room: Room) {
        // The sequence advances for dropped frames too, so the ground station's loss count
        // sees them.
        self.sequence = self.sequence.wrapping_add(1);
        bump(if room == Room::Answer { &mut self.stats.answers_dropped } else { &mut self.stats.tx_dropped });
    }

    fn handle<V: Vehicle>(&mut self, frame: Frame<'_>, vehicle: &mut V) {
        let silent_before = self.last_rx_ms.is_none_or(|last| self.now_ms.wrapping_sub(last) > STATION_GONE_MS);
        self.last_rx_ms = Some(self.now_ms);
        self.motor_test_silence_stop = false;
        match frame.message_id {
            HEARTBEAT_DATA::ID => {
                // A station that connects after the board booted missed what it said then.
                if let Some((severity, text)) = self.greeting.filter(|_| silent_before) {
                    self.text(severity, text, Room::Event);
                }
            }
            // target_system, target_component: its only fields.
            PARAM_REQUEST_LIST_DATA::ID if for_us(frame.byte(0), frame.byte(1)) => self.param_cursor = Some(0),
            PARAM_REQUEST_LIST_DATA::ID => bump(&mut self.stats.not_for_us),
            PARAM_REQUEST_READ_DATA::ID => self.param_request_read(&frame, vehicle),
            PARAM_SET_DATA::ID => self.param_set(&frame, vehicle),
            MISSION_REQUEST_LIST_DATA::ID => self.mission_request_list(&frame),
            crate::command::SET_MODE_ID => match Command::decode_set_mode(&frame) {
                Some(command) if for_us(command.target_system, command.target_component) => {
                    self.set_mode_message(&command, vehicle);
                }
                Some(_) => bump(&mut self.stats.not_for_us),
                None => bump(&mut self.stats.bad_payload),
            },
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
        self.send_owed_params(vehicle);
        self.param_download(vehicle);
    }

    /// Queues a STATUSTEXT, in chunks when it is longer than one (see [`crate::text`]): all of
    /// them or, when `room` cannot take all, none (a part would leave the receiver waiting for
    /// the rest).
    pub(crate) fn text(&mut self, severity: Severity, text: Text, room: Room) -> bool {
        let chunks = text.chunks();
        let id = if chunks == 1 { 0 } else { self.text_id.checked_add(1).unwrap_or(1) };
        let header = frame::Header { id: STATUSTEXT_DATA::ID, extra_crc: STATUSTEXT_DATA::EXTRA_CRC, encoded_len: STATUSTEXT_LEN };
        let need: usize = (0..chunks).map(|seq| frame::frame_len(header, &statustext(severity, &text, id, seq))).sum();
        if need > self.room(room) {
            for _ in 0..chunks {
                self.dropped(room);
            }
            return false;
        }
        if chunks > 1 {
            self.text_id = id;
        }
        for seq in 0..chunks {
            self.queue(header, &mut statustext(severity, &text, id, seq), &[], room);
        }
        true
    }
}

/// The payload of chunk `seq` of `text`, with the extensions `id` and `chunk_seq` after the 51
/// bytes the crate writes.
fn statustext(severity: Severity, text: &Text, id: u16, seq: usize) -> [u8; frame::MAX_PAYLOAD] {
    let mut payload = [0u8; frame::MAX_PAYLOAD];
    let data = STATUSTEXT_DATA { severity: severity.mav(), text: mavlink::types::CharArray::new(text.chunk(seq)) };
    frame::serialize(&data, &mut payload);
    let [lo, hi] = id.to_le_bytes();
    if let Some(ext) = payload.get_mut(1 + TEXT_LEN..STATUSTEXT_LEN) {
        ext.copy_from_slice(&[lo, hi, seq as u8]);
    }
    payload
}

#[cfg(test)]
mod tests {
    use mavlink::dialects::common::{ATTITUDE_DATA, HEARTBEAT_DATA, PARAM_REQUEST_READ_DATA, PARAM_VALUE_DATA};
    use mavlink::MessageData;

    use super::*;
    use crate::rates::UART_BYTES_PER_S;
    use crate::test_support::*;

    /// The firmware's link task runs every 5 ms: it takes what the UART received, ticks the
    /// link and hands the UART what it can send.
    const LINK_PERIOD_MS: u32 = 5;

    /// When each frame's last byte left a UART drained at 115200 baud (11.52 bytes a ms), by
    /// message id, over `duration_ms` of a ground station sending `frames_every_100_ms` spread
    /// over each 100 ms and a HEARTBEAT each second.
    fn departures(link: &mut Link<512>, frames_every_100_ms: &[u8], duration_ms: u32) -> Vec<(u32, u32)> {
        let mut mock = Mock::new();
        let heartbeat = v2(&HEARTBEAT_DATA::DEFAULT);
        let mut out = Vec::new();
        let mut on_the_wire: Vec<u8> = Vec::new();
        // Bytes the line could have carried and has not, in thousandths.
        let mut budget = 0u32;
        let mut buf = [0u8; 512];
        let len = frames_every_100_ms.len();
        for now in (0..duration_ms).step_by(LINK_PERIOD_MS as usize) {
            if now % 1000 == 0 {
                link.receive(&heartbeat, now, &mut mock);
            }
            let (from, to) = (len * (now % 100) as usize / 100, len * (now % 100 + LINK_PERIOD_MS) as usize / 100);
            link.receive(&frames_every_100_ms[from..to.min(len)], now, &mut mock);
            link.tick(now, &mut mock);
            budget += UART_BYTES_PER_S * LINK_PERIOD_MS;
            let n = link.poll_tx(&mut buf[..(budget / 1000).min(512) as usize]);
            // An idle line saves nothing up.
            budget = (budget - n as u32 * 1000).min(1000);
            on_the_wire.extend_from_slice(&buf[..n]);
            while on_the_wire.len() >= 12 && on_the_wire.len() >= 12 + usize::from(on_the_wire[1]) {
                let frame_len = 12 + usize::from(on_the_wire[1]);
                out.push((now, u32::from_le_bytes([on_the_wire[7], on_the_wire[8], on_the_wire[9], 0])));
                on_the_wire.drain(..frame_len);
            }
        }
        out
    }

    fn gaps(departures: &[(u32, u32)], id: u32, duration_ms: u32) -> (usize, u32) {
        let times: Vec<u32> = departures.iter().filter(|d| d.1 == id).map(|d| d.0).collect();
        let mut widest = times.first().copied().unwrap_or(duration_ms);
        for pair in times.windows(2) {
            widest = widest.max(pair[1] - pair[0]);
        }
        widest = widest.max(duration_ms - times.last().copied().unwrap_or(0));
        (times.len(), widest)
    }

    #[test]
    fn heartbeat_and_attitude_keep_their_rates_under_a_param_request_read_flood() {
        // About 60 PARAM_REQUEST_READs every 0.1 s: twice what the line can answer.
        let mut flood = Vec::new();
        for i in 0..60 {
            let read = PARAM_REQUEST_READ_DATA { param_index: i % 4, target_system: 1, target_component: 1, param_id: name16("") };
            flood.extend_from_slice(&v2(&read));
        }
        let mut link: Link<512> = Link::new(LinkConfig::DEFAULT);
        let duration_ms = 10_000;
        let sent = departures(&mut link, &flood, duration_ms);
        let (heartbeats, heartbeat_gap_ms) = gaps(&sent, HEARTBEAT_DATA::ID, duration_ms);
        assert!(heartbeat_gap_ms <= 1200, "a HEARTBEAT {heartbeat_gap_ms} ms after the last ({heartbeats} sent)");
        let (attitudes, attitude_gap_ms) = gaps(&sent, ATTITUDE_DATA::ID, duration_ms);
        let expected = (duration_ms / u32::from(Rates::DEFAULT.attitude_ms)) as usize;
        assert!(attitudes * 100 >= expected * 98, "{attitudes} ATTITUDEs of {expected}");
        assert!(attitude_gap_ms <= 2 * u32::from(Rates::DEFAULT.attitude_ms), "an ATTITUDE {attitude_gap_ms} ms after the last");
        // The flood was one: answers filled their share of the line and the rest were dropped.
        let answers = sent.iter().filter(|d| d.1 == PARAM_VALUE_DATA::ID).count();
        assert!(answers > 1500, "{answers} PARAM_VALUEs");
        assert!(link.stats().answers_dropped > 0);
        assert_eq!(link.stats().tx_dropped, 0);
    }
}
