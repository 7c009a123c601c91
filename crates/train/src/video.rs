//! Videos of episodes: one MP4 per episode, from frames of colour and depth with a caption (the bag
//! exporter, `equiarm bag video`, and the in-process loop's `--video-every`).
//!
//! A frame is the colour image beside the depth image in viridis colours (near = dark; scaled to the
//! episode's depth range), both enlarged by a whole factor to at least [`MIN_SIDE`] px (nearest
//! neighbour, so each pixel is a block of equal pixels), above a caption.
//!
//! H.264 by OpenH264 at a fixed quantiser ([`QP`], OpenH264's finest; 4:2:0 colour, BT.601 limited
//! range as decoders assume for an untagged stream), one keyframe every [`KEYFRAME_EVERY`] frames, in
//! an MP4 file (shiguredo_mp4), played at the rate given. What the codec changes is measured by
//! `tests/python/test_video.py` (PyAV decoding frame 0 against the Observation's colours) and stated
//! in docs/nodes.md.

use std::fs::File;
use std::io::{Seek, SeekFrom, Write};
use std::num::NonZeroU32;
use std::path::{Path, PathBuf};

use equiarm_types::files::{FileError, at};
use openh264::OpenH264API;
use openh264::encoder::{
    BitRate, Encoder, EncoderConfig, FrameRate, FrameType, IntraFramePeriod, QpRange, RateControlMode,
};
use openh264::formats::{RgbSliceU8, YUVBuffer};
use shiguredo_mp4::TrackKind;
use shiguredo_mp4::bitstream::h264::{
    H264SampleEntryConfig, LengthSize, annexb_to_length_prefixed, build_avc1_box_from_annexb,
};
use shiguredo_mp4::boxes::SampleEntry;
use shiguredo_mp4::mux::{Mp4FileMuxer, Sample};

/// Images are enlarged by a whole factor until their height is at least this many pixels.
pub const MIN_SIDE: u32 = 152;
/// The quantiser of every frame (OpenH264 accepts 12 ..= 51; 12 is the finest).
pub const QP: u8 = 12;
/// A keyframe every this many frames (so players can seek).
pub const KEYFRAME_EVERY: u32 = 30;
/// Height of the caption strip, px.
const CAPTION_H: u32 = 20;

/// Why a video could not be written.
#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    /// Creating or writing the file failed.
    #[error(transparent)]
    File(#[from] FileError),
    /// A frame does not fit the video, or encoding it failed.
    #[error("{}: {reason}", path.display())]
    Encode {
        /// The video.
        path: PathBuf,
        /// What failed.
        reason: String,
    },
}

/// One frame: rgb8 colour and depth in metres, both `height` × `width`, and its caption.
#[derive(Clone, Debug)]
pub struct Frame {
    /// rgb8, row-major.
    pub color: Vec<u8>,
    /// Metres, row-major.
    pub depth: Vec<f32>,
    /// The text below the images.
    pub caption: String,
}

/// Writes `frames` (each `height` × `width` px) as an MP4 at `fps` frames per second.
pub fn write(path: &Path, frames: &[Frame], (height, width): (u32, u32), fps: u32) -> Result<(), VideoError> {
    let enc = |reason: String| VideoError::Encode { path: path.to_path_buf(), reason };
    let n = (height * width) as usize;
    if height == 0 || width == 0 {
        return Err(enc("frames of no pixels".into()));
    }
    if let Some((k, f)) = frames.iter().enumerate().find(|(_, f)| f.color.len() != 3 * n || f.depth.len() != n) {
        return Err(enc(format!(
            "frame {k}: {} colour bytes and {} depths for {height}x{width} px",
            f.color.len(),
            f.depth.len()
        )));
    }
    let (lo, hi) = frames
        .iter()
        .flat_map(|f| f.depth.iter().copied().filter(|x| x.is_finite()))
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
    let layout = Layout::new(height, width);
    let mut mp4 = Mp4Writer::create(path, layout.width, layout.height, fps)?;
    for f in frames {
        mp4.frame(&layout.compose(&f.color, &f.depth, (lo, hi), &f.caption).map_err(enc)?)?;
    }
    mp4.finish()
}

/// Where the panels and the caption go in a frame.
#[derive(Clone, Copy, Debug)]
pub struct Layout {
    /// Image rows and columns of the Observation.
    pub src: (u32, u32),
    /// The enlargement factor.
    pub scale: u32,
    /// Frame width and height (even, as H.264's 4:2:0 needs).
    pub width: u32,
    /// Frame height.
    pub height: u32,
}

impl Layout {
    /// The layout for `h` × `w` px Observations.
    pub fn new(h: u32, w: u32) -> Self {
        let scale = MIN_SIDE.div_ceil(h).max(1);
        let width = (2 * w * scale).next_multiple_of(2);
        let height = (h * scale + CAPTION_H).next_multiple_of(2);
        Self { src: (h, w), scale, width, height }
    }

    /// The rgb8 frame: colour left, depth right, caption below.
    fn compose(&self, color: &[u8], depth: &[f32], (lo, hi): (f32, f32), caption: &str) -> Result<Vec<u8>, String> {
        let (h, w, k) = (self.src.0 as usize, self.src.1 as usize, self.scale as usize);
        let fw = self.width as usize;
        let mut out = vec![0u8; fw * self.height as usize * 3];
        let span = if hi > lo { (hi - lo) as f64 } else { 1.0 };
        for y in 0..h * k {
            for x in 0..w * k {
                let p = (y / k) * w + x / k;
                let c = &color[3 * p..3 * p + 3];
                let d = crate::plot::viridis((depth[p] - lo) as f64 / span);
                let row = y * fw * 3;
                out[row + 3 * x..row + 3 * x + 3].copy_from_slice(c);
                let xd = w * k + x;
                out[row + 3 * xd..row + 3 * xd + 3].copy_from_slice(&d);
            }
        }
        let top = h * k * fw * 3;
        let caption_h = self.height - (h * k) as u32;
        crate::plot::caption(&mut out[top..], self.width, caption_h, caption, caption_h * 7 / 10)
            .map_err(|e| e.to_string())?;
        Ok(out)
    }
}

/// An MP4 file being written: H.264 samples appended as they are encoded, the index at the end.
struct Mp4Writer {
    path: PathBuf,
    file: File,
    encoder: Encoder,
    muxer: Mp4FileMuxer,
    fps: NonZeroU32,
    size: (u32, u32),
    offset: u64,
    frames: u32,
}

impl Mp4Writer {
    fn create(path: &Path, width: u32, height: u32, fps: u32) -> Result<Self, VideoError> {
        let enc = |reason: String| VideoError::Encode { path: path.to_path_buf(), reason };
        let config = EncoderConfig::new()
            .rate_control_mode(RateControlMode::Quality)
            .qp(QpRange::new(QP, QP))
            // frame skipping on (OpenH264 warns otherwise) under a bit rate no frame comes near: a
            // skipped frame is an error below
            .skip_frames(true)
            .bitrate(BitRate::from_bps(100_000_000))
            .max_frame_rate(FrameRate::from_hz(fps as f32))
            .intra_frame_period(IntraFramePeriod::from_num_frames(KEYFRAME_EVERY))
            .scene_change_detect(false)
            .adaptive_quantization(false)
            .background_detection(false)
            .num_threads(1);
        let encoder = Encoder::with_api_config(OpenH264API::from_source(), config)
            .map_err(|e| enc(format!("H.264 encoder: {e}")))?;
        let muxer = Mp4FileMuxer::new().map_err(|e| enc(format!("MP4: {e}")))?;
        let mut file = File::create(path).map_err(at(path))?;
        let head = muxer.initial_boxes_bytes();
        file.write_all(head).map_err(at(path))?;
        Ok(Self {
            path: path.to_path_buf(),
            file,
            encoder,
            offset: head.len() as u64,
            muxer,
            fps: NonZeroU32::new(fps.max(1)).expect("at least 1"),
            size: (width, height),
            frames: 0,
        })
    }

    fn frame(&mut self, rgb: &[u8]) -> Result<(), VideoError> {
        let path = self.path.clone();
        let enc = |reason: String| VideoError::Encode { path: path.clone(), reason };
        let (w, h) = (self.size.0 as usize, self.size.1 as usize);
        let yuv = YUVBuffer::from_rgb8_source(RgbSliceU8::new(rgb, (w, h)));
        let bits = self.encoder.encode(&yuv).map_err(|e| enc(format!("H.264 frame {}: {e}", self.frames)))?;
        let keyframe = matches!(bits.frame_type(), FrameType::IDR | FrameType::I);
        if matches!(bits.frame_type(), FrameType::Skip | FrameType::Invalid) {
            return Err(enc(format!("H.264 frame {}: the encoder skipped it", self.frames)));
        }
        let annexb = bits.to_vec();
        let entry = if self.frames == 0 {
            let cfg = H264SampleEntryConfig { length_size: LengthSize::FourBytes };
            Some(SampleEntry::Avc1(
                build_avc1_box_from_annexb(&annexb, &cfg).map_err(|e| enc(format!("MP4 avc1: {e}")))?,
            ))
        } else {
            None
        };
        let data = annexb_to_length_prefixed(&annexb, LengthSize::FourBytes).map_err(|e| enc(format!("MP4: {e}")))?;
        self.file.write_all(&data).map_err(at(&self.path))?;
        let sample = Sample {
            track_kind: TrackKind::Video,
            sample_entry: entry,
            keyframe,
            timescale: self.fps,
            duration: 1,
            composition_time_offset: None,
            data_offset: self.offset,
            data_size: data.len(),
        };
        self.muxer.append_sample(&sample).map_err(|e| enc(format!("MP4 sample {}: {e}", self.frames)))?;
        self.offset += data.len() as u64;
        self.frames += 1;
        Ok(())
    }

    fn finish(mut self) -> Result<(), VideoError> {
        let path = self.path.clone();
        let boxes = self
            .muxer
            .finalize()
            .map_err(|e| VideoError::Encode { path: path.clone(), reason: format!("MP4: {e}") })?;
        for (offset, bytes) in boxes.offset_and_bytes_pairs() {
            self.file.seek(SeekFrom::Start(offset)).and_then(|_| self.file.write_all(bytes)).map_err(at(&path))?;
        }
        self.file.flush().map_err(at(&path))?;
        Ok(())
    }
}
