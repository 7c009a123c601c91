//! Episode videos of a bag (`equiarm bag video BAG --out DIR`): one MP4 per episode
//! ([`equiarm_train::video`]), one frame per step plus the episode's last frame, at the simulated
//! rate (fps = 1 / the simulated step, as the stamps say), each captioned with the env and episode,
//! the step, its reward and who chose its action (`expert`, `policy`, `random`, `teleop`; `eval`
//! for evaluation episodes), and on the last frame whether the episode succeeded.

use std::path::{Path, PathBuf};

use equiarm_msgs::command_source_name;
use equiarm_msgs::msg::Observation;
use equiarm_types::files::at;

use equiarm_train::video::{self, Frame};

use crate::ExportError;
use crate::steps::{Episode, StepReport, episodes};

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
    let mut frames = Vec::with_capacity(shots.len());
    for s in &shots {
        if (s.obs.height, s.obs.width) != (h, w) {
            return Err(bad(s.obs, format!("{}x{} px in an episode of {h}x{w} px frames", s.obs.height, s.obs.width)));
        }
        let color = s.obs.color_rgb8().map_err(|err| bad(s.obs, err.to_string()))?;
        let depth = s.obs.depth_m().map_err(|err| bad(s.obs, err.to_string()))?;
        frames.push(Frame { color, depth, caption: s.caption.clone() });
    }
    video::write(path, &frames, (h, w), episode_fps(e))?;
    Ok(shots.len())
}

/// Frames per second of an episode's simulated time: one over the time between an Observation and
/// the next (the Transition's stamp is the next one's); 1 when the stamps say nothing.
fn episode_fps(e: &Episode) -> u32 {
    let s = &e.steps[0];
    let dt = s.t.header.stamp.as_nanos() - s.obs.header.stamp.as_nanos();
    if dt > 0 { (1e9 / dt as f64).round().clamp(1.0, 1000.0) as u32 } else { 1 }
}
