//! MAVLink's frame checksum: CRC-16/MCRF4XX (the X.25 polynomial 0x1021, reflected, from
//! 0xFFFF, no final XOR) over the frame after its start byte, then the message's extra CRC
//! byte.
//!
//! Computed a byte at a time with shifts (MAVLink's own `crc_accumulate`) rather than the
//! `mavlink` crate's `calculate_crc`, whose 512-byte lookup table costs more flash than the
//! link's few frames a millisecond need in speed.

/// The checksum of `bytes` followed by `extra_crc`.
pub fn checksum(bytes: &[u8], extra_crc: u8) -> u16 {
    let mut crc = 0xFFFF;
    for &byte in bytes {
        crc = accumulate(crc, byte);
    }
    accumulate(crc, extra_crc)
}

fn accumulate(crc: u16, byte: u8) -> u16 {
    let mut tmp = byte ^ (crc as u8);
    tmp ^= tmp << 4;
    let tmp = u16::from(tmp);
    (crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_standard_check_value() {
        // CRC-16/MCRF4XX of "123456789" is 0x6F91; the extra byte is one more data byte.
        assert_eq!(checksum(b"12345678", b'9'), 0x6F91);
    }

    #[test]
    fn agrees_with_the_mavlink_crate() {
        let mut state = 0x1234_5678u32;
        let mut bytes = [0u8; 300];
        for len in 0..bytes.len() {
            for b in bytes.iter_mut() {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                *b = state as u8;
            }
            let extra = (len * 7) as u8;
            assert_eq!(checksum(&bytes[..len], extra), mavlink::calculate_crc(&bytes[..len], extra), "length {len}");
        }
    }
}
