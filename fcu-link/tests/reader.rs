//! The frame reader and the encoder against the `mavlink` crate, and random bytes.

mod support;

use fcu_link::frame::{encode, MAX_FRAME};
use fcu_link::{FrameReader, Link, LinkConfig, Version};
use mavlink::dialects::common;
use mavlink::MessageData;
use support::*;

fn read_all(reader: &mut FrameReader, bytes: &[u8]) -> Vec<(Version, u32, Vec<u8>)> {
    let mut out = Vec::new();
    for &b in bytes {
        if let Some(f) = reader.push(b) {
            out.push((f.version, f.message_id, f.payload.to_vec()));
        }
    }
    out
}

fn list() -> common::PARAM_REQUEST_LIST_DATA {
    common::PARAM_REQUEST_LIST_DATA { target_system: 1, target_component: 1 }
}

#[test]
fn reads_v1_and_v2_frames_back_to_back() {
    let mut bytes = v1(&list());
    bytes.extend(v2(&param_set("RC1_MIN", 1.0)));
    bytes.extend([0x00, 0x55]);
    bytes.extend(v2(&list()));
    let mut reader = FrameReader::new();
    let frames = read_all(&mut reader, &bytes);
    assert_eq!(frames.len(), 3);
    assert_eq!((frames[0].0, frames[0].1), (Version::V1, 21));
    assert_eq!((frames[1].0, frames[1].1), (Version::V2, 23));
    assert_eq!((frames[2].0, frames[2].1), (Version::V2, 21));
    assert_eq!(reader.stats().frames, 3);
    assert_eq!(reader.stats().noise_bytes, 2);
}

#[test]
fn a_bad_crc_is_dropped_and_counted_and_the_next_frame_still_read() {
    let mut bad = v2(&list());
    let last = bad.len() - 1;
    bad[last] ^= 1;
    bad.extend(v2(&list()));
    let mut reader = FrameReader::new();
    assert_eq!(read_all(&mut reader, &bad).len(), 1);
    assert_eq!(reader.stats().bad_crc, 1);
    // A payload bit flipped is a bad CRC too.
    let mut flipped = v2(&param_set("RC1_MIN", 1.0));
    flipped[12] ^= 0x10;
    assert!(read_all(&mut reader, &flipped).is_empty());
    assert_eq!(reader.stats().bad_crc, 2);
}

#[test]
fn a_message_we_do_not_handle_is_dropped_as_unknown() {
    let attitude = common::ATTITUDE_DATA::DEFAULT;
    let mut reader = FrameReader::new();
    assert!(read_all(&mut reader, &v2(&attitude)).is_empty());
    assert!(read_all(&mut reader, &v1(&attitude)).is_empty());
    assert_eq!(reader.stats().unknown_id, 2);
    assert_eq!(reader.stats().bad_crc, 0);
}

#[test]
fn signed_frames_are_skipped_whole_and_counted() {
    let mut signed = v2(&list());
    signed[2] = 0x01;
    // The CRC covers the flags: recompute it, then add a 13-byte signature.
    let n = signed.len();
    let crc = mavlink::calculate_crc(&signed[1..n - 2], common::PARAM_REQUEST_LIST_DATA::EXTRA_CRC);
    signed[n - 2..].copy_from_slice(&crc.to_le_bytes());
    signed.extend([0xFD; 13]);
    signed.extend(v2(&list()));
    let mut reader = FrameReader::new();
    let frames = read_all(&mut reader, &signed);
    assert_eq!(frames.len(), 1, "the signature's 0xFD bytes are not taken for a start");
    assert_eq!(reader.stats().signed, 1);
}

#[test]
fn unknown_incompatibility_flags_are_dropped_and_counted() {
    let mut odd = v2(&list());
    odd[2] = 0x04;
    let mut reader = FrameReader::new();
    assert!(read_all(&mut reader, &odd).is_empty());
    assert_eq!(reader.stats().incompatible, 1);
}

#[test]
fn lengths_the_definition_does_not_allow_are_dropped() {
    // MAVLink 2: longer than the message (with a good CRC).
    let mut payload = vec![1u8, 1, 0];
    payload.push(9);
    let long = v2_raw(21, common::PARAM_REQUEST_LIST_DATA::EXTRA_CRC, &payload);
    // MAVLink 2: empty.
    let empty = v2_raw(21, common::PARAM_REQUEST_LIST_DATA::EXTRA_CRC, &[]);
    // MAVLink 1: shorter than the message.
    let mut short = vec![0xFE, 1, 0, GCS_SYSTEM, GCS_COMPONENT, 21, 1];
    let crc = mavlink::calculate_crc(&short[1..], common::PARAM_REQUEST_LIST_DATA::EXTRA_CRC);
    short.extend(crc.to_le_bytes());
    let mut reader = FrameReader::new();
    for f in [long, empty, short] {
        assert!(read_all(&mut reader, &f).is_empty(), "{f:?}");
    }
    assert_eq!(reader.stats().bad_length, 3);
    // A truncated MAVLink 2 payload is fine.
    let truncated = v2_raw(21, common::PARAM_REQUEST_LIST_DATA::EXTRA_CRC, &[1]);
    assert_eq!(read_all(&mut reader, &truncated).len(), 1);
}

#[test]
fn the_encoder_writes_what_the_crate_writes() {
    let header = mavlink::MavHeader { system_id: 1, component_id: 1, sequence: 200 };
    fn check<D: MessageData>(data: &D, header: mavlink::MavHeader) {
        let mut ours = [0u8; MAX_FRAME];
        let n = encode(header.sequence, data, &mut ours);
        let mut theirs = mavlink::MAVLinkV2MessageRaw::new();
        theirs.serialize_message_data(header, data);
        assert_eq!(&ours[..n], theirs.raw_bytes(), "{}", D::NAME);
    }
    check(&common::HEARTBEAT_DATA::DEFAULT, header);
    check(&common::ATTITUDE_DATA { roll: 0.5, yawspeed: -1.0, ..common::ATTITUDE_DATA::DEFAULT }, header);
    check(&param_set("RC1_MIN", 0.0), header);
    check(&common::STATUSTEXT_DATA { text: "hello".into(), ..common::STATUSTEXT_DATA::DEFAULT }, header);
    check(&common::COMMAND_ACK_DATA::DEFAULT, header);
    check(&common::AUTOPILOT_VERSION_DATA { uid: 7, ..common::AUTOPILOT_VERSION_DATA::DEFAULT }, header);
}

/// xorshift64*: the tests' random bytes, the same on every run.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
}

#[test]
fn random_bytes_change_nothing_and_the_link_works_after() {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let mut link: TestLink = Link::new(LinkConfig::DEFAULT);
    let mut mock = Mock::new();
    let mut buf = [0u8; 512];
    for round in 0..4000u32 {
        let mut chunk = [0u8; 64];
        for b in chunk.iter_mut() {
            let r = rng.next();
            // Start bytes more often than chance, so that headers get parsed too.
            *b = if r.is_multiple_of(8) { [0xFD, 0xFE][(r >> 8) as usize % 2] } else { (r >> 16) as u8 };
        }
        link.receive(&chunk, round, &mut mock);
        link.tick(round, &mut mock);
        while link.poll_tx(&mut buf) > 0 {}
    }
    let stats = link.stats().reader;
    assert!(stats.bad_crc + stats.unknown_id + stats.bad_length + stats.incompatible > 1000, "{stats:?}");
    assert_eq!(stats.frames, 0, "{stats:?}");
    assert!(mock.sets.is_empty());
    assert!(mock.requests.is_empty());
    assert_eq!(mock.value("RC1_MIN"), 1000.0);
    // The request right after the noise, with no quiet gap, is answered.
    let read = common::PARAM_REQUEST_READ_DATA { param_index: 1, target_system: 1, target_component: 1, param_id: name16("") };
    link.receive(&v2(&read), 5000, &mut mock);
    assert_eq!(param_values(&drain(&mut link)), [("RC1_MIN".to_string(), 1000.0, 1, 4)]);
}

/// Finding (2026-11-28, `cargo pil serve`): after five seconds of line noise the board answered
/// none of a ground station's requests for some 20 s. The noise's last start byte made a header
/// that the reader trusted, up to 255 payload bytes, and it swallowed every request sent within
/// them. A header that is no frame the link keeps is dropped as soon as it is in.
#[test]
fn the_frame_right_after_line_noise_is_read_whatever_the_noise_ended_with() {
    let mut rng = Rng(0x2545_F491_4F6C_DD1D);
    let request = v2(&list());
    let heartbeat = v2(&common::HEARTBEAT_DATA::DEFAULT);
    for trial in 0..5000 {
        let len = 1 + (rng.next() % 600) as usize;
        let mut bytes: Vec<u8> = (0..len).map(|_| (rng.next() >> 24) as u8).collect();
        bytes.extend(&request);
        // The ground station goes on as ground stations do, with its heartbeat: a candidate
        // that began in the noise and still waits for bytes is decided by them (a reader
        // cannot know before that it is no frame).
        for _ in 0..15 {
            bytes.extend(&heartbeat);
        }
        let mut reader = FrameReader::new();
        let ids: Vec<u32> = read_all(&mut reader, &bytes).iter().map(|f| f.1).collect();
        assert_eq!(
            ids.iter().filter(|&&id| id == 21).count(),
            1,
            "trial {trial}: the request after {len} noise bytes was lost: frames {ids:?}, tail {:02X?}, {:?}",
            &bytes[len.saturating_sub(20)..len],
            reader.stats()
        );
        assert!(ids.iter().filter(|&&id| id == 0).count() >= 14, "trial {trial}: heartbeats lost: {ids:?}");
    }
}

#[test]
fn a_false_header_that_claims_the_longest_payload_swallows_nothing() {
    // A MAVLink 2 start byte, 255 bytes of payload claimed, a message id no one handles, and
    // the request: each partial header the request's own bytes complete is dropped too.
    for cut in 1..=10 {
        let false_header = [0xFD, 255, 0, 0, 9, 9, 9, 0x33, 0x44, 0x55];
        let mut bytes = false_header[..cut].to_vec();
        bytes.extend(v2(&list()));
        let mut reader = FrameReader::new();
        assert_eq!(read_all(&mut reader, &bytes).len(), 1, "after {cut} bytes of the false header");
    }
    // MAVLink 1 the same.
    let mut bytes = vec![0xFE, 255, 0, 9, 9, 0x99];
    bytes.extend(v1(&list()));
    assert_eq!(read_all(&mut FrameReader::new(), &bytes).len(), 1);
}

/// What is left: a false header that names a message the link handles, with a length that
/// message allows (1 in 7,282 MAVLink 1 start bytes of noise), is read to its claimed end and
/// its CRC drops it whole, with any frame that began inside it. Here "FE 09" makes the next
/// MAVLink 2 frame's first bytes a MAVLink 1 HEARTBEAT header (id 0 from its flags byte):
/// the request inside is lost, and the frames after the false one are read.
#[test]
fn a_false_header_of_a_handled_message_drops_only_what_it_claims() {
    let mut bytes = vec![0xFE, 0x09];
    bytes.extend(v2(&list()));
    for _ in 0..3 {
        bytes.extend(v2(&common::HEARTBEAT_DATA::DEFAULT));
    }
    let mut reader = FrameReader::new();
    let ids: Vec<u32> = read_all(&mut reader, &bytes).iter().map(|f| f.1).collect();
    // 17 bytes claimed: the request (12) and the first heartbeat's first 5.
    assert_eq!(ids, [0, 0]);
    assert_eq!(reader.stats().bad_crc, 1);
}

#[test]
fn a_message_we_do_not_handle_with_start_bytes_in_its_payload_costs_the_next_frame_nothing() {
    // ATTITUDE (not handled) whose floats put 0xFD and 0xFE near its end, the CRC's bytes
    // included, then a request: the request is read, and nothing else.
    let mut rng = Rng(7);
    for trial in 0..500 {
        let word = |rng: &mut Rng| f32::from_bits(0xFDFE_0000 | (rng.next() as u32 & 0xFFFF));
        let attitude = common::ATTITUDE_DATA {
            time_boot_ms: rng.next() as u32,
            roll: word(&mut rng),
            pitch: word(&mut rng),
            yaw: word(&mut rng),
            rollspeed: word(&mut rng),
            pitchspeed: word(&mut rng),
            yawspeed: word(&mut rng),
        };
        let mut bytes = v2(&attitude);
        bytes.extend(v2(&list()));
        let mut reader = FrameReader::new();
        let frames = read_all(&mut reader, &bytes);
        assert_eq!(frames.iter().map(|f| f.1).collect::<Vec<_>>(), [21], "trial {trial}");
        assert!(reader.stats().unknown_id >= 1, "the ATTITUDE frame was not seen as one: {:?}", reader.stats());
    }
}

#[test]
fn frames_split_anywhere_across_receive_calls() {
    let mut link: TestLink = Link::new(LinkConfig::DEFAULT);
    let mut mock = Mock::new();
    let frame = v2(&param_set("RC1_MIN", 1200.0));
    for split in 0..=frame.len() {
        drain(&mut link);
        link.receive(&frame[..split], 0, &mut mock);
        link.receive(&frame[split..], 0, &mut mock);
        assert_eq!(param_values(&drain(&mut link)).len(), 1, "split at {split}");
    }
}

#[test]
fn commands_decode_as_the_crate_decodes_them() {
    let long = common::COMMAND_LONG_DATA {
        param1: 1.5,
        param2: -2.0,
        param3: 3.25,
        param4: 4.0,
        param5: 5.0,
        param6: -6.5,
        param7: 7.0,
        command: common::MavCmd::MAV_CMD_DO_MOTOR_TEST,
        target_system: 1,
        target_component: 0,
        confirmation: 3,
    };
    let int = common::COMMAND_INT_DATA {
        param1: 1.5,
        param2: 0.0,
        param3: 0.0,
        param4: 4.0,
        x: -123_456,
        y: 42,
        z: 9.5,
        command: common::MavCmd::MAV_CMD_PREFLIGHT_STORAGE,
        target_system: 1,
        target_component: 1,
        frame: common::MavFrame::MAV_FRAME_LOCAL_NED,
        current: 0,
        autocontinue: 0,
    };
    let mut reader = FrameReader::new();
    let mut commands = Vec::new();
    for bytes in [v2(&long), v1(&long), v2(&int)] {
        for b in bytes {
            if let Some(f) = reader.push(b) {
                commands.push(fcu_link::command::Command::decode(&f).expect("decodes"));
            }
        }
    }
    assert_eq!(commands.len(), 3);
    for c in &commands[..2] {
        assert_eq!(c.id, 209);
        assert_eq!(c.params, [1.5, -2.0, 3.25, 4.0, 5.0, -6.5, 7.0]);
        assert_eq!((c.target_system, c.target_component), (1, 0));
        assert_eq!((c.system_id, c.component_id), (GCS_SYSTEM, GCS_COMPONENT));
    }
    assert_eq!(commands[2].id, 245);
    assert_eq!(commands[2].params, [1.5, 0.0, 0.0, 4.0, -123_456.0, 42.0, 9.5]);
    assert_eq!((commands[2].target_system, commands[2].target_component), (1, 1));
}
