//! The golden message values, built in Rust. `tests/python/golden.py` builds the same values
//! independently in Python; the golden and interop tests compare the two.

#![allow(dead_code)]

use equiarm_msgs::builtin_interfaces::Time;
use equiarm_msgs::msg::{GripperCommand, Observation};
use equiarm_msgs::sensor_msgs::Image;
use equiarm_msgs::std_msgs::Header;

pub const NAN32: f32 = f32::from_bits(0x7fc0_0001);
pub const SUB32: f32 = f32::from_bits(1);
pub const NAN64: f64 = f64::from_bits(0x7ff8_0000_0000_0001);
pub const SUB64: f64 = f64::from_bits(1);
pub const TEXT: &str = "caméra_optique_深度_🤖";

pub fn lowbias32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^ (x >> 16)
}

pub fn hash_words(n: usize, seed: u32) -> Vec<u8> {
    (0..n as u32)
        .flat_map(|i| lowbias32(i.wrapping_mul(0x9e37_79b1) ^ seed.wrapping_mul(0x85eb_ca77)).to_le_bytes())
        .collect()
}

pub fn ramp(n: usize, mul: usize, add: usize) -> Vec<u8> {
    (0..n).map(|i| ((i * mul + add) % 256) as u8).collect()
}

pub fn header(sec: i32, nanosec: u32, frame: &str) -> Header {
    Header { stamp: Time { sec, nanosec }, frame_id: frame.into() }
}

pub fn rgb8(h: u32, w: u32, frame: &str) -> Image {
    Image::rgb8(header(1, 2, frame), h, w, ramp((h * w * 3) as usize, 7, 3)).unwrap()
}

pub fn depth(h: u32, w: u32, frame: &str, seed: u32) -> Image {
    Image {
        header: header(1, 2, frame),
        height: h,
        width: w,
        encoding: "32FC1".into(),
        is_bigendian: 0,
        step: w * 4,
        data: hash_words((h * w) as usize, seed),
    }
}

pub fn command_special() -> GripperCommand {
    GripperCommand {
        header: header(-1, 5, "world"),
        obs_seq: u64::MAX,
        open_ratio: NAN32,
        dx: -0.0,
        dy: f32::INFINITY,
        dz: f32::NEG_INFINITY,
        dtheta: SUB32,
        source: GripperCommand::SOURCE_TELEOP,
    }
}

pub fn command_typical() -> GripperCommand {
    GripperCommand {
        header: header(10, 500_000_000, "world"),
        obs_seq: 42,
        open_ratio: 1.0,
        dx: 0.03125,
        dy: -0.0625,
        dz: 0.0,
        dtheta: f32::MAX,
        source: GripperCommand::SOURCE_EXPERT,
    }
}

pub fn observation(seq: u64, size: u32, seed: u32) -> Observation {
    Observation {
        header: header(3, 4, "world"),
        seq,
        env: "env0".into(),
        episode: 3,
        step: 49,
        // planes of arbitrary bytes (the CDR layout is checked here, the compression in obs_frame's
        // tests); colour of an odd length, so the depth's length needs alignment padding
        height: size,
        width: size,
        color: ramp(size as usize * 3 + 1, 7, 3),
        depth: hash_words(size as usize, seed),
        holding: true,
        expert_action: command_typical(),
        terminal: true,
    }
}
