//! CDR (XCDR1) encoding of messages exactly as ROS 2 puts them on DDS and into rosbag2 MCAP files:
//! a 4-byte encapsulation header (`00 01 00 00`, CDR little endian) followed by the body.
//! Decoding also accepts big-endian CDR (`00 00 00 00`).

use crate::RosMessage;
use byteorder::{BigEndian, LittleEndian};

/// Encapsulation header of little-endian CDR, what ROS 2 writes.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];
/// Encapsulation header of big-endian CDR.
pub const CDR_BE_HEADER: [u8; 4] = [0x00, 0x00, 0x00, 0x00];

/// Why bytes could not be decoded (or a message encoded); names the type and what was wrong.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum CdrError {
    /// Fewer than the 4 header bytes.
    #[error("{type_name}: payload of {len} bytes is too short for a CDR encapsulation header")]
    TooShort {
        /// The ROS type being decoded, e.g. `sensor_msgs/msg/Image`.
        type_name: &'static str,
        /// Length of the whole payload (header included), bytes.
        len: usize,
    },
    /// The representation identifier is not plain CDR (e.g. XCDR2 or a parameter list).
    #[error("{type_name}: unsupported CDR representation {id:02x?} (expected 00 01 CDR_LE or 00 00 CDR_BE)")]
    Representation {
        /// The ROS type being decoded, e.g. `sensor_msgs/msg/Image`.
        type_name: &'static str,
        /// The representation identifier: the first two bytes of the encapsulation header.
        id: [u8; 2],
    },
    /// The body does not decode as this type (truncated, wrong layout, invalid bool or UTF-8).
    #[error("{type_name}: {len}-byte payload does not decode: {reason}")]
    Decode {
        /// The ROS type being decoded, e.g. `sensor_msgs/msg/Image`.
        type_name: &'static str,
        /// Length of the whole payload (header included), bytes.
        len: usize,
        /// The deserializer's error message.
        reason: String,
    },
    /// The body decoded but left bytes over beyond alignment padding: a different (larger) type.
    #[error("{type_name}: {len}-byte payload has {extra} bytes left over after the message (wrong type?)")]
    Trailing {
        /// The ROS type being decoded, e.g. `sensor_msgs/msg/Image`.
        type_name: &'static str,
        /// Length of the whole payload (header included), bytes.
        len: usize,
        /// Bytes left after the decoded body (more than the 3 accepted as padding).
        extra: usize,
    },
    /// The message cannot be encoded (a sequence longer than 2^32 - 1 elements).
    #[error("{type_name}: cannot encode: {reason}")]
    Encode {
        /// The ROS type being encoded, e.g. `sensor_msgs/msg/Image`.
        type_name: &'static str,
        /// The serializer's error message.
        reason: String,
    },
}

/// Encodes `msg` as little-endian CDR with its encapsulation header.
pub fn encode<M: RosMessage>(msg: &M) -> Result<Vec<u8>, CdrError> {
    let mut out = Vec::new();
    encode_into(msg, &mut out)?;
    Ok(out)
}

/// Appends the encoding of `msg` (header included) to `out`, reusing its allocation.
pub fn encode_into<M: RosMessage>(msg: &M, out: &mut Vec<u8>) -> Result<(), CdrError> {
    let start = out.len();
    out.extend_from_slice(&CDR_LE_HEADER);
    // NOTE: CDR alignment is relative to the start of the body, so the body is written to a fresh
    // writer positioned at 0 (the serializer counts its own bytes), never relative to `out`.
    cdr_encoding::to_writer::<_, LittleEndian, _>(&mut *out, msg).map_err(|e| {
        out.truncate(start);
        CdrError::Encode { type_name: M::TYPE_NAME, reason: e.to_string() }
    })
}

/// Decodes a CDR payload (encapsulation header included) as `M`.
///
/// Up to 3 bytes after the body are accepted (writers pad to 4-byte multiples); more is an error,
/// since it means the bytes were written for a different type.
pub fn decode<M: RosMessage>(bytes: &[u8]) -> Result<M, CdrError> {
    let type_name = M::TYPE_NAME;
    if bytes.len() < 4 {
        return Err(CdrError::TooShort { type_name, len: bytes.len() });
    }
    let body = &bytes[4..];
    let result = match [bytes[0], bytes[1]] {
        [0x00, 0x01] => cdr_encoding::from_bytes::<M, LittleEndian>(body),
        [0x00, 0x00] => cdr_encoding::from_bytes::<M, BigEndian>(body),
        id => return Err(CdrError::Representation { type_name, id }),
    };
    let (msg, used) = result.map_err(|e| CdrError::Decode { type_name, len: bytes.len(), reason: e.to_string() })?;
    let extra = body.len() - used;
    if extra > 3 {
        return Err(CdrError::Trailing { type_name, len: bytes.len(), extra });
    }
    Ok(msg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{builtin_interfaces::Time, msg::GripperCommand, sensor_msgs::Image, std_msgs::Header};

    #[test]
    fn header_layout_matches_hand_computed_bytes() {
        let h = Header { stamp: Time { sec: 1, nanosec: 2 }, frame_id: "ab".into() };
        let b = encode(&h).unwrap();
        // header | sec | nanosec | len=3 | 'a' 'b' 0
        assert_eq!(b, [0, 1, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0, b'a', b'b', 0]);
    }

    #[test]
    fn u64_after_header_is_aligned_to_8_from_body_start() {
        let c = GripperCommand { obs_seq: 0x0102030405060708, ..Default::default() };
        let b = encode(&c).unwrap();
        // body: sec(4) nanosec(4) strlen(4)=1 '\0' pad(3) -> offset 16, already 8-aligned
        assert_eq!(&b[4 + 16..4 + 24], &0x0102030405060708u64.to_le_bytes());
    }

    #[test]
    fn big_endian_payload_decodes() {
        let mut b = CDR_BE_HEADER.to_vec();
        b.extend_from_slice(&5i32.to_be_bytes());
        b.extend_from_slice(&6u32.to_be_bytes());
        assert_eq!(decode::<Time>(&b).unwrap(), Time { sec: 5, nanosec: 6 });
    }

    #[test]
    fn bad_payloads_are_errors_naming_the_type() {
        assert!(matches!(decode::<Time>(&[0, 1]), Err(CdrError::TooShort { .. })));
        assert!(matches!(decode::<Time>(&[0, 7, 0, 0, 1, 2, 3, 4]), Err(CdrError::Representation { .. })));
        let e = decode::<Image>(&[0, 1, 0, 0, 1, 0, 0, 0]).unwrap_err();
        assert!(e.to_string().starts_with("sensor_msgs/msg/Image: 8-byte payload does not decode"), "{e}");
        let mut long = encode(&Time { sec: 1, nanosec: 1 }).unwrap();
        long.extend_from_slice(&[0; 8]);
        assert!(matches!(decode::<Time>(&long), Err(CdrError::Trailing { extra: 8, .. })));
        // a sequence length far beyond the payload must fail without allocating it
        let mut huge = encode(&Header::default()).unwrap();
        huge.truncate(12);
        huge.extend_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(decode::<Header>(&huge), Err(CdrError::Decode { .. })));
    }

    #[test]
    fn invalid_bool_is_an_error() {
        use crate::sensor_msgs::RegionOfInterest;
        let mut b = encode(&RegionOfInterest::default()).unwrap();
        *b.last_mut().unwrap() = 2;
        assert!(matches!(decode::<RegionOfInterest>(&b), Err(CdrError::Decode { .. })));
    }
}
