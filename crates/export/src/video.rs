//! Episode videos (`equiarm bag video BAG --out DIR`): one MP4 per episode, one frame per step plus the
//! episode's last frame, at the simulated rate (fps = 1 / the simulated step, as the stamps say).
//!
//! A frame is the colour image beside the depth image in viridis colours (near = dark; scaled to the
//! episode's depth range), both enlarged by a whole factor to at least [`MIN_SIDE`] px (nearest
//! neighbour, so each pixel of the Observation is a block of equal pixels), above a caption: the env
//! and episode, the step, its reward and who chose its action (`expert`, `policy`, `random`,
//! `teleop`; `eval` for evaluation episodes), and on the last frame whether the episode succeeded.
//!
//! H.264 by OpenH264 at a fixed quantiser ([`QP`], OpenH264's finest; 4:2:0 colour, BT.601 limited
//! range as decoders assume for an untagged stream), one keyframe every [`KEYFRAME_EVERY`] frames, in
//! an MP4 file (shiguredo_mp4). What the codec changes is measured by `tests/python/test_video.py`
//! (PyAV decoding frame 0 against the Observation's colours) and stated in docs/nodes.md.

use std::fs::File;
use std::io::{Seek, SeekFrom, Write};
use std::num::NonZeroU32;
use std::path::{Path, PathBuf};

use equiarm_msgs::command_source_name;
use equiarm_msgs::msg::Observation;
use equiarm_types::files::at;
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

use crate::ExportError;
use crate::steps::{Episode, StepReport, episodes};

/// Images are enlarged by a whole factor until their height is at least this many pixels.
pub const MIN_SIDE: u32 = 152;
/// The quantiser of every frame (OpenH264 accepts 12 ..= 51; 12 is the finest).
pub const QP: u8 = 12;
/// A keyframe every this many frames (so players can seek).
pub const KEYFRAME_EVERY: u32 = 30;
/// Height of the caption strip, px.
const CAPTION_H: u32 = 20;

/// Which episodes to write.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum Selection {
    /// Every episode.
    #[default]
    All,
    /// These: `(env, None)` all of an env's, `(env, Some(k))` its episode k, and the evaluation
    /// episodes with `eval`.
    Some {
        /// (env, episode) items.
        items: Vec<(String, Option<u32>)>,
        /// Every evaluation episode too.
        eval: bool,
    },
}

impl Selection {
    /// Parses a comma-separated list of `ENV:EPISODE`, `ENV` and `eval` (e.g. `env0:3,env1,eval`).
    pub fn parse(s: &str) -> Result<Self, String> {
        let (mut items, mut eval) = (Vec::new(), false);
        for part in s.split(',').map(str::trim) {
            match part.split_once(':') {
                _ if part == "eval" => eval = true,
                None if !part.is_empty() => items.push((part.to_string(), None)),
                Some((env, k)) if !env.is_empty() => {
                    let k = k.parse().map_err(|_| format!("'{part}': the episode after ':' must be a whole number"))?;
                    items.push((env.to_string(), Some(k)));
                }
                _ => return Err(format!("'{part}': expected ENV, ENV:EPISODE or eval")),
            }
        }
        Ok(Selection::Some { items, eval })
    }

    fn wants(&self, e: &Episode) -> bool {
        match self {
            Selection::All => true,
            Selection::Some { items, eval } => {
                (*eval && e.result.as_ref().is_some_and(|r| r.eval))
                    || items.iter().any(|(env, k)| *env == e.env && k.is_none_or(|k| k == e.episode))
            }
        }
    }
}

/// What `bag video` wrote.
#[derive(Clone, Debug, Default)]
pub struct VideoReport {
    /// What reading the bag found.
    pub steps: StepReport,
    /// The files written, with their frame counts.
    pub files: Vec<(PathBuf, usize)>,
}

/// Writes one MP4 per selected episode of `bag` into `out` (created; existing files of the same names
/// are replaced), named `ENV_epNNNN.mp4`.
pub fn bag_videos(bag: &Path, out: &Path, select: &Selection) -> Result<VideoReport, ExportError> {
    std::fs::create_dir_all(out).map_err(at(out))?;
    let mut files = Vec::new();
    let steps = episodes(bag, |e| {
        if select.wants(&e) && !e.steps.is_empty() {
            let path = out.join(format!("{}_ep{:04}.mp4", e.env, e.episode));
            let frames = episode_video(&e, &path)?;
            files.push((path, frames));
        }
        Ok(())
    })?;
    Ok(VideoReport { steps, files })
}

/// One frame of an episode: the Observation and its caption.
struct Shot<'a> {
    obs: &'a Observation,
    caption: String,
}

/// Writes the video of `e` to `path`; returns its frame count.
pub fn episode_video(e: &Episode, path: &Path) -> Result<usize, ExportError> {
    let eval = e.result.as_ref().is_some_and(|r| r.eval);
    let mut shots: Vec<Shot> = e
        .steps
        .iter()
        .map(|s| Shot {
            obs: &s.obs,
            caption: format!(
                "{} ep {}  step {}  reward {}  {}",
                e.env,
                e.episode,
                s.t.step,
                s.t.reward,
                if eval { "eval" } else { command_source_name(s.t.action.source) }
            ),
        })
        .collect();
    if let Some(last) = e.steps.last().and_then(|s| s.last.as_ref()) {
        let end = match &e.result {
            Some(r) if r.success => "success",
            Some(_) => "failure",
            None => "end",
        };
        shots.push(Shot { obs: last, caption: format!("{} ep {}  step {}  {end}", e.env, e.episode, last.step) });
    }
    let first = shots[0].obs;
    let bad = |o: &Observation, reason: String| ExportError::Frame { env: o.env.clone(), seq: o.seq, reason };
    let (h, w) = (first.height, first.width);
    if h == 0 || w == 0 {
        return Err(bad(first, "carries no image".into()));
    }
    let fps = episode_fps(e);
    let mut decoded = Vec::with_capacity(shots.len());
    for s in &shots {
        if (s.obs.height, s.obs.width) != (h, w) {
            return Err(bad(s.obs, format!("{}x{} px in an episode of {h}x{w} px frames", s.obs.height, s.obs.width)));
        }
        let color = s.obs.color_rgb8().map_err(|err| bad(s.obs, err.to_string()))?;
        let depth = s.obs.depth_m().map_err(|err| bad(s.obs, err.to_string()))?;
        decoded.push((color, depth));
    }
    let (lo, hi) = decoded
        .iter()
        .flat_map(|(_, d)| d.iter().copied().filter(|x| x.is_finite()))
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
    let layout = Layout::new(h, w);
    let mut mp4 = Mp4Writer::create(path, layout.width, layout.height, fps)?;
    for (s, (color, depth)) in shots.iter().zip(&decoded) {
        let frame = layout
            .compose(color, depth, (lo, hi), &s.caption)
            .map_err(|reason| ExportError::Encode { path: path.to_path_buf(), reason })?;
        mp4.frame(&frame)?;
    }
    mp4.finish()?;
    Ok(shots.len())
}

/// Frames per second of an episode's simulated time: one over the time between an Observation and
/// the next (the Transition's stamp is the next one's); 1 when the stamps say nothing.
fn episode_fps(e: &Episode) -> u32 {
    let s = &e.steps[0];
    let dt = s.t.header.stamp.as_nanos() - s.obs.header.stamp.as_nanos();
    if dt > 0 { (1e9 / dt as f64).round().clamp(1.0, 1000.0) as u32 } else { 1 }
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
                let d = equiarm_train::plot::viridis((depth[p] - lo) as f64 / span);
                let row = y * fw * 3;
                out[row + 3 * x..row + 3 * x + 3].copy_from_slice(c);
                let xd = w * k + x;
                out[row + 3 * xd..row + 3 * xd + 3].copy_from_slice(&d);
            }
        }
        let top = h * k * fw * 3;
        let caption_h = self.height - (h * k) as u32;
        equiarm_train::plot::caption(&mut out[top..], self.width, caption_h, caption, caption_h * 7 / 10)
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
    fn create(path: &Path, width: u32, height: u32, fps: u32) -> Result<Self, ExportError> {
        let enc = |reason: String| ExportError::Encode { path: path.to_path_buf(), reason };
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

    fn frame(&mut self, rgb: &[u8]) -> Result<(), ExportError> {
        let path = self.path.clone();
        let enc = |reason: String| ExportError::Encode { path: path.clone(), reason };
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

    fn finish(mut self) -> Result<(), ExportError> {
        let path = self.path.clone();
        let boxes = self
            .muxer
            .finalize()
            .map_err(|e| ExportError::Encode { path: path.clone(), reason: format!("MP4: {e}") })?;
        for (offset, bytes) in boxes.offset_and_bytes_pairs() {
            self.file.seek(SeekFrom::Start(offset)).and_then(|_| self.file.write_all(bytes)).map_err(at(&path))?;
        }
        self.file.flush().map_err(at(&path))?;
        Ok(())
    }
}
