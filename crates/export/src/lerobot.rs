//! A bag as a LeRobotDataset v3.0 directory (`equiarm bag export BAG --format lerobot OUT`), laid out
//! and typed as LeRobot's own writer does, so `LeRobotDataset(repo_id, root=OUT)` loads it:
//!
//! - `data/chunk-000/file-000.parquet` (a new file past [`DATA_FILE_MB`] MB, a new chunk every
//!   [`CHUNKS_SIZE`] files; Snappy; one row group per episode): one row per step ([`crate::steps`]),
//!   episodes contiguous and numbered from 0 in the order they are written;
//! - `meta/info.json` (`codebase_version` `v3.0`, the features below, fps = 1 / the simulated step),
//!   `meta/episodes/chunk-000/file-000.parquet` (one row per episode: its tasks, length, data file and
//!   row range, and the bag's env and episode index), `meta/tasks.parquet` (the task names, as pandas
//!   writes a frame indexed by task) and `meta/stats.json` (min, max, mean, std, count and the
//!   quantiles q01 … q99 of every feature; the depth without quantiles).
//!
//! The features: `observation.image` (the colour frame, a lossless PNG in LeRobot's image struct
//! `{bytes, path}`), `observation.depth` (metres, float32 `[H, W]`: the Observation's half floats
//! exactly), `observation.state` (`holding`: 1 when the gripper holds an object), `action` (the
//! normalised action `p, dx, dy, dz, dtheta` in [-1, 1], as the learner sees it), `next.reward`,
//! `next.done` (the episode ended by success or an invalid state), `next.truncated` (by the step
//! limit), `next.success` (true on the last step of a successful episode), `action_source`
//! (`expert`, `policy`, `random`, `teleop`, or `eval` for evaluation episodes, so demonstrations can
//! be filtered), and LeRobot's `timestamp` (frame_index / fps), `frame_index`, `episode_index`,
//! `index` and `task_index`.

use std::collections::BTreeMap;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow_array::builder::{BinaryBuilder, ListBuilder, StringBuilder};
use arrow_array::{
    ArrayRef, BooleanArray, FixedSizeListArray, Float32Array, Int64Array, RecordBatch, StringArray, StructArray,
};
use arrow_schema::{DataType, Field, Fields, Schema};
use equiarm_msgs::command_source_name;
use equiarm_types::files::at;
use parquet::arrow::ArrowWriter;
use parquet::basic::Compression;
use parquet::file::properties::WriterProperties;
use serde_json::{Value, json};

use crate::ExportError;
use crate::steps::{Episode, StepReport, episodes};

/// LeRobot's dataset format version written.
pub const CODEBASE_VERSION: &str = "v3.0";
/// Files per chunk directory (LeRobot's default).
pub const CHUNKS_SIZE: u32 = 1000;
/// A data file is closed once it holds this many MB (LeRobot's default).
pub const DATA_FILE_MB: usize = 100;
/// The normalised action's dimensions, in order.
pub const ACTION_NAMES: [&str; 5] = ["p", "dx", "dy", "dz", "dtheta"];

/// What an export wrote.
#[derive(Clone, Debug)]
pub struct LeRobotReport {
    /// What reading the bag found.
    pub steps: StepReport,
    /// Rows (frames) written.
    pub frames: u64,
    /// Episodes written.
    pub episodes: u64,
    /// The task names, by task index.
    pub tasks: Vec<String>,
    /// Frames per second of simulated time.
    pub fps: u32,
    /// Image height and width.
    pub size: (u32, u32),
    /// The data files written.
    pub data_files: Vec<PathBuf>,
}

/// Writes the steps of `bag` into the new directory `out` (refused if it exists and is not empty).
pub fn export(bag: &Path, out: &Path) -> Result<LeRobotReport, ExportError> {
    if std::fs::read_dir(out).is_ok_and(|mut d| d.next().is_some()) {
        return Err(ExportError::OutExists(out.to_path_buf()));
    }
    let mut w = Writer { out: out.to_path_buf(), ..Writer::default() };
    let steps = episodes(bag, |e| w.episode(e))?;
    if w.frames == 0 {
        return Err(ExportError::NoSteps(bag.to_path_buf()));
    }
    w.finish(steps)
}

/// The frame geometry and clock fixed by the first episode.
#[derive(Clone, Copy, Debug)]
struct Shape {
    height: u32,
    width: u32,
    fps: u32,
}

/// One open data file.
struct DataFile {
    path: PathBuf,
    chunk: u32,
    file: u32,
    writer: ArrowWriter<File>,
}

/// One row of `meta/episodes`.
struct EpisodeRow {
    task: String,
    length: u64,
    chunk: u32,
    file: u32,
    from: u64,
    env: String,
    env_episode: u32,
}

#[derive(Default)]
struct Writer {
    out: PathBuf,
    shape: Option<Shape>,
    data: Option<DataFile>,
    next_file: (u32, u32),
    data_files: Vec<PathBuf>,
    frames: u64,
    episodes: Vec<EpisodeRow>,
    tasks: BTreeMap<String, i64>,
    stats: Stats,
}

/// The columns of one episode.
#[derive(Default)]
struct Columns {
    png: Vec<Vec<u8>>,
    png_name: Vec<String>,
    depth: Vec<f32>,
    holding: Vec<f32>,
    action: Vec<f32>,
    reward: Vec<f32>,
    done: Vec<bool>,
    truncated: Vec<bool>,
    success: Vec<bool>,
    source: Vec<&'static str>,
    timestamp: Vec<f32>,
    frame_index: Vec<i64>,
    index: Vec<i64>,
}

impl Writer {
    fn episode(&mut self, e: Episode) -> Result<(), ExportError> {
        if e.steps.is_empty() {
            return Ok(());
        }
        let shape = match self.shape {
            Some(s) => s,
            None => *self.shape.insert(shape_of(&e)?),
        };
        let task =
            e.result.as_ref().map(|r| r.task.clone()).filter(|t| !t.is_empty()).unwrap_or_else(|| "unknown".into());
        let n_tasks = self.tasks.len() as i64;
        let task_index = *self.tasks.entry(task.clone()).or_insert(n_tasks);
        let episode_index = self.episodes.len() as i64;
        let eval = e.result.as_ref().is_some_and(|r| r.eval);
        let success = e.result.as_ref().is_some_and(|r| r.success);
        let last = e.steps.len() - 1;
        let mut c = Columns::default();
        for (k, s) in e.steps.iter().enumerate() {
            let (o, t) = (&s.obs, &s.t);
            let bad = |reason: String| ExportError::Frame { env: o.env.clone(), seq: o.seq, reason };
            if (o.height, o.width) != (shape.height, shape.width) {
                return Err(bad(format!(
                    "{}x{} px, while the first frame exported was {}x{}",
                    o.height, o.width, shape.height, shape.width
                )));
            }
            let color = o.color_rgb8().map_err(|e| bad(e.to_string()))?;
            let depth = o.depth_m().map_err(|e| bad(e.to_string()))?;
            self.stats.frame(&color, &depth);
            c.png.push(png(&color, shape, &self.out)?);
            c.png_name.push(format!("frame-{k:06}.png"));
            c.depth.extend_from_slice(&depth);
            let action = equiarm_train::policy::action_of(&t.action).to_normalized();
            c.action.extend_from_slice(&action);
            c.holding.push(o.holding as u8 as f32);
            c.reward.push(t.reward);
            c.done.push(t.done);
            c.truncated.push(t.timeout);
            c.success.push(success && k == last);
            c.source.push(if eval { "eval" } else { command_source_name(t.action.source) });
            c.timestamp.push(k as f32 / shape.fps as f32);
            c.frame_index.push(k as i64);
            c.index.push((self.frames + k as u64) as i64);
        }
        let n = e.steps.len();
        let batch = self.batch(&c, shape, episode_index, task_index)?;
        self.stats.rows(&c, n, episode_index, task_index);
        let data = self.data_file()?;
        let (chunk, file) = (data.chunk, data.file);
        let path = data.path.clone();
        let enc = |e: parquet::errors::ParquetError| ExportError::Encode { path: path.clone(), reason: e.to_string() };
        data.writer.write(&batch).map_err(enc)?;
        data.writer.flush().map_err(enc)?; // one row group per episode
        if data.writer.bytes_written() > DATA_FILE_MB << 20 {
            self.close_data()?;
        }
        self.episodes.push(EpisodeRow {
            task,
            length: n as u64,
            chunk,
            file,
            from: self.frames,
            env: e.env,
            env_episode: e.episode,
        });
        self.frames += n as u64;
        Ok(())
    }

    fn batch(
        &self,
        c: &Columns,
        shape: Shape,
        episode_index: i64,
        task_index: i64,
    ) -> Result<RecordBatch, ExportError> {
        let n = c.reward.len();
        let (h, w) = (shape.height as i32, shape.width as i32);
        let mut bytes = BinaryBuilder::new();
        let mut names = StringBuilder::new();
        for (b, p) in c.png.iter().zip(&c.png_name) {
            bytes.append_value(b);
            names.append_value(p);
        }
        let image = StructArray::new(
            image_fields(),
            vec![Arc::new(bytes.finish()) as ArrayRef, Arc::new(names.finish())],
            None,
        );
        let row =
            FixedSizeListArray::new(item(DataType::Float32), w, Arc::new(Float32Array::from(c.depth.clone())), None);
        let depth = FixedSizeListArray::new(item(depth_row_type(w)), h, Arc::new(row), None);
        let action =
            FixedSizeListArray::new(item(DataType::Float32), 5, Arc::new(Float32Array::from(c.action.clone())), None);
        let columns: Vec<ArrayRef> = vec![
            Arc::new(image),
            Arc::new(depth),
            Arc::new(Float32Array::from(c.holding.clone())),
            Arc::new(action),
            Arc::new(Float32Array::from(c.reward.clone())),
            Arc::new(BooleanArray::from(c.done.clone())),
            Arc::new(BooleanArray::from(c.truncated.clone())),
            Arc::new(BooleanArray::from(c.success.clone())),
            Arc::new(StringArray::from(c.source.clone())),
            Arc::new(Float32Array::from(c.timestamp.clone())),
            Arc::new(Int64Array::from(c.frame_index.clone())),
            Arc::new(Int64Array::from(vec![episode_index; n])),
            Arc::new(Int64Array::from(c.index.clone())),
            Arc::new(Int64Array::from(vec![task_index; n])),
        ];
        RecordBatch::try_new(data_schema(shape), columns)
            .map_err(|e| ExportError::Encode { path: self.out.clone(), reason: e.to_string() })
    }

    /// The data file to append to, opened (with its directory) when there is none.
    fn data_file(&mut self) -> Result<&mut DataFile, ExportError> {
        if self.data.is_none() {
            let (chunk, file) = self.next_file;
            let dir = self.out.join(format!("data/chunk-{chunk:03}"));
            std::fs::create_dir_all(&dir).map_err(at(&dir))?;
            let path = dir.join(format!("file-{file:03}.parquet"));
            let f = File::create(&path).map_err(at(&path))?;
            let shape = self.shape.expect("the shape is known before the first row");
            let writer = ArrowWriter::try_new(f, data_schema(shape), Some(props()))
                .map_err(|e| ExportError::Encode { path: path.clone(), reason: e.to_string() })?;
            self.next_file = if file + 1 == CHUNKS_SIZE { (chunk + 1, 0) } else { (chunk, file + 1) };
            self.data_files.push(path.clone());
            self.data = Some(DataFile { path, chunk, file, writer });
        }
        Ok(self.data.as_mut().expect("opened above"))
    }

    fn close_data(&mut self) -> Result<(), ExportError> {
        if let Some(d) = self.data.take() {
            d.writer.close().map_err(|e| ExportError::Encode { path: d.path.clone(), reason: e.to_string() })?;
        }
        Ok(())
    }

    fn finish(mut self, steps: StepReport) -> Result<LeRobotReport, ExportError> {
        self.close_data()?;
        let shape = self.shape.expect("rows were written");
        let meta = self.out.join("meta");
        self.write_episodes(&meta)?;
        let tasks: Vec<String> = {
            let mut t: Vec<(&String, &i64)> = self.tasks.iter().collect();
            t.sort_by_key(|(_, i)| **i);
            t.into_iter().map(|(n, _)| n.clone()).collect()
        };
        write_tasks(&meta.join("tasks.parquet"), &tasks)?;
        let info = info_json(shape, self.frames, self.episodes.len(), tasks.len());
        write_json(&meta.join("info.json"), &info)?;
        write_json(&meta.join("stats.json"), &self.stats.json(shape))?;
        Ok(LeRobotReport {
            steps,
            frames: self.frames,
            episodes: self.episodes.len() as u64,
            tasks,
            fps: shape.fps,
            size: (shape.height, shape.width),
            data_files: self.data_files,
        })
    }

    fn write_episodes(&self, meta: &Path) -> Result<(), ExportError> {
        let dir = meta.join("episodes/chunk-000");
        std::fs::create_dir_all(&dir).map_err(at(&dir))?;
        let path = dir.join("file-000.parquet");
        let e = &self.episodes;
        let int = |f: &dyn Fn(usize, &EpisodeRow) -> i64| -> ArrayRef {
            Arc::new(Int64Array::from(e.iter().enumerate().map(|(i, r)| f(i, r)).collect::<Vec<_>>()))
        };
        let mut tasks = ListBuilder::new(StringBuilder::new());
        for r in e {
            tasks.values().append_value(&r.task);
            tasks.append(true);
        }
        let tasks = tasks.finish();
        let columns: Vec<(&str, ArrayRef)> = vec![
            ("episode_index", int(&|i, _| i as i64)),
            ("tasks", Arc::new(tasks)),
            ("length", int(&|_, r| r.length as i64)),
            ("data/chunk_index", int(&|_, r| r.chunk as i64)),
            ("data/file_index", int(&|_, r| r.file as i64)),
            ("dataset_from_index", int(&|_, r| r.from as i64)),
            ("dataset_to_index", int(&|_, r| (r.from + r.length) as i64)),
            ("meta/episodes/chunk_index", int(&|_, _| 0)),
            ("meta/episodes/file_index", int(&|_, _| 0)),
            ("env", Arc::new(StringArray::from(e.iter().map(|r| r.env.as_str()).collect::<Vec<_>>()))),
            ("env_episode", int(&|_, r| r.env_episode as i64)),
        ];
        write_table(&path, columns, None)
    }
}

/// Height, width and fps from an episode's first step (fps: one over the simulated time between an
/// Observation and the next, which the Transition's stamp gives).
fn shape_of(e: &Episode) -> Result<Shape, ExportError> {
    let s = &e.steps[0];
    let dt_ns = s.t.header.stamp.as_nanos() - s.obs.header.stamp.as_nanos();
    let bad = |reason: String| ExportError::Frame { env: s.obs.env.clone(), seq: s.obs.seq, reason };
    if s.obs.height == 0 || s.obs.width == 0 {
        return Err(bad("carries no image".into()));
    }
    if dt_ns <= 0 {
        return Err(bad(format!("the next frame is stamped {dt_ns} ns after it: no frame rate")));
    }
    let fps = (1e9 / dt_ns as f64).round().max(1.0) as u32;
    Ok(Shape { height: s.obs.height, width: s.obs.width, fps })
}

fn png(rgb: &[u8], shape: Shape, out: &Path) -> Result<Vec<u8>, ExportError> {
    let mut buf = Vec::new();
    image::codecs::png::PngEncoder::new(&mut buf)
        .write_image(rgb, shape.width, shape.height, image::ExtendedColorType::Rgb8)
        .map_err(|e| ExportError::Encode { path: out.to_path_buf(), reason: format!("PNG: {e}") })?;
    Ok(buf)
}

use image::ImageEncoder as _;

fn item(t: DataType) -> Arc<Field> {
    Arc::new(Field::new("item", t, true))
}

fn depth_row_type(width: i32) -> DataType {
    DataType::FixedSizeList(item(DataType::Float32), width)
}

fn image_fields() -> Fields {
    Fields::from(vec![Field::new("bytes", DataType::Binary, true), Field::new("path", DataType::Utf8, true)])
}

/// The data files' columns, in [`FEATURES`] order.
fn data_schema(shape: Shape) -> Arc<Schema> {
    let (h, w) = (shape.height as i32, shape.width as i32);
    let types = [
        DataType::Struct(image_fields()),
        DataType::FixedSizeList(item(depth_row_type(w)), h),
        DataType::Float32,
        DataType::FixedSizeList(item(DataType::Float32), 5),
        DataType::Float32,
        DataType::Boolean,
        DataType::Boolean,
        DataType::Boolean,
        DataType::Utf8,
        DataType::Float32,
        DataType::Int64,
        DataType::Int64,
        DataType::Int64,
        DataType::Int64,
    ];
    Arc::new(Schema::new(FEATURES.iter().zip(types).map(|(name, t)| Field::new(*name, t, true)).collect::<Vec<_>>()))
}

/// Feature names, in column order.
const FEATURES: [&str; 14] = [
    "observation.image",
    "observation.depth",
    "observation.state",
    "action",
    "next.reward",
    "next.done",
    "next.truncated",
    "next.success",
    "action_source",
    "timestamp",
    "frame_index",
    "episode_index",
    "index",
    "task_index",
];

fn props() -> WriterProperties {
    WriterProperties::builder().set_compression(Compression::SNAPPY).build()
}

/// `meta/info.json`'s features.
fn features_json(shape: Shape) -> Value {
    let (h, w) = (shape.height, shape.width);
    let scalar = |dtype: &str| json!({"dtype": dtype, "shape": [1], "names": null});
    json!({
        "observation.image": {"dtype": "image", "shape": [h, w, 3], "names": ["height", "width", "channels"]},
        "observation.depth": {"dtype": "float32", "shape": [h, w], "names": ["height", "width"]},
        "observation.state": {"dtype": "float32", "shape": [1], "names": ["holding"]},
        "action": {"dtype": "float32", "shape": [5], "names": ACTION_NAMES},
        "next.reward": scalar("float32"),
        "next.done": scalar("bool"),
        "next.truncated": scalar("bool"),
        "next.success": scalar("bool"),
        "action_source": scalar("string"),
        "timestamp": scalar("float32"),
        "frame_index": scalar("int64"),
        "episode_index": scalar("int64"),
        "index": scalar("int64"),
        "task_index": scalar("int64"),
    })
}

fn info_json(shape: Shape, frames: u64, episodes: usize, tasks: usize) -> Value {
    json!({
        "codebase_version": CODEBASE_VERSION,
        "robot_type": "equiarm_gripper",
        "total_episodes": episodes,
        "total_frames": frames,
        "total_tasks": tasks,
        "chunks_size": CHUNKS_SIZE,
        "data_files_size_in_mb": DATA_FILE_MB,
        "video_files_size_in_mb": 200,
        "fps": shape.fps,
        "splits": {"train": format!("0:{episodes}")},
        "data_path": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
        "video_path": null,
        "features": features_json(shape),
    })
}

fn write_json(path: &Path, v: &Value) -> Result<(), ExportError> {
    let text = serde_json::to_string_pretty(v).expect("JSON values serialise");
    std::fs::write(path, text + "\n").map_err(at(path))?;
    Ok(())
}

/// `meta/tasks.parquet` as pandas writes a frame `task_index` indexed by `task`: LeRobot reads the
/// task back as the index (pandas' schema metadata says which column that is).
fn write_tasks(path: &Path, tasks: &[String]) -> Result<(), ExportError> {
    let columns: Vec<(&str, ArrayRef)> = vec![
        ("task_index", Arc::new(Int64Array::from((0..tasks.len() as i64).collect::<Vec<_>>()))),
        ("task", Arc::new(StringArray::from(tasks.to_vec()))),
    ];
    let pandas = json!({
        "index_columns": ["task"],
        "column_indexes": [{"name": null, "field_name": null, "pandas_type": "unicode", "numpy_type": "object",
                            "metadata": {"encoding": "UTF-8"}}],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64", "metadata": null},
            {"name": "task", "field_name": "task", "pandas_type": "unicode", "numpy_type": "object", "metadata": null},
        ],
        "creator": {"library": "equiarm", "version": env!("CARGO_PKG_VERSION")},
        "pandas_version": "2.2.0",
    });
    write_table(path, columns, Some(("pandas", pandas.to_string())))
}

/// One Parquet file of `columns` (one row group), with a schema metadata entry.
fn write_table(path: &Path, columns: Vec<(&str, ArrayRef)>, meta: Option<(&str, String)>) -> Result<(), ExportError> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(at(dir))?;
    }
    let enc = |reason: String| ExportError::Encode { path: path.to_path_buf(), reason };
    let fields: Vec<Field> = columns.iter().map(|(n, a)| Field::new(*n, a.data_type().clone(), true)).collect();
    let mut schema = Schema::new(fields);
    if let Some((k, v)) = meta {
        schema = schema.with_metadata(std::collections::HashMap::from([(k.to_string(), v)]));
    }
    let batch = RecordBatch::try_new(Arc::new(schema), columns.into_iter().map(|(_, a)| a).collect())
        .map_err(|e| enc(e.to_string()))?;
    let f = File::create(path).map_err(at(path))?;
    let mut w = ArrowWriter::try_new(f, batch.schema(), Some(props())).map_err(|e| enc(e.to_string()))?;
    w.write(&batch).map_err(|e| enc(e.to_string()))?;
    w.close().map_err(|e| enc(e.to_string()))?;
    Ok(())
}

/// Per-feature statistics, as LeRobot computes them (images per channel in [0, 1]).
#[derive(Default)]
struct Stats {
    /// Colour histogram per channel (exact quantiles of 8-bit values): 256 counts each.
    color: [Vec<u64>; 3],
    /// Depth per pixel: min, max, sum, sum of squares.
    depth: Vec<[f64; 4]>,
    frames: u64,
    /// Every value of the non-image features, per feature and dimension.
    values: BTreeMap<&'static str, Vec<Vec<f64>>>,
}

impl Stats {
    fn frame(&mut self, rgb: &[u8], depth: &[f32]) {
        for h in &mut self.color {
            h.resize(256, 0);
        }
        for px in rgb.chunks_exact(3) {
            for (c, &v) in px.iter().enumerate() {
                self.color[c][v as usize] += 1;
            }
        }
        if self.depth.is_empty() {
            self.depth = vec![[f64::INFINITY, f64::NEG_INFINITY, 0.0, 0.0]; depth.len()];
        }
        for (s, &d) in self.depth.iter_mut().zip(depth) {
            let d = d as f64;
            *s = [s[0].min(d), s[1].max(d), s[2] + d, s[3] + d * d];
        }
        self.frames += 1;
    }

    fn rows(&mut self, c: &Columns, n: usize, episode_index: i64, task_index: i64) {
        let mut push = |name: &'static str, dims: usize, vals: &mut dyn Iterator<Item = f64>| {
            let v = self.values.entry(name).or_insert_with(|| vec![Vec::new(); dims]);
            for (i, x) in vals.enumerate() {
                v[i % dims].push(x);
            }
        };
        push("observation.state", 1, &mut c.holding.iter().map(|&x| x as f64));
        push("action", 5, &mut c.action.iter().map(|&x| x as f64));
        push("next.reward", 1, &mut c.reward.iter().map(|&x| x as f64));
        push("next.done", 1, &mut c.done.iter().map(|&x| x as u8 as f64));
        push("next.truncated", 1, &mut c.truncated.iter().map(|&x| x as u8 as f64));
        push("next.success", 1, &mut c.success.iter().map(|&x| x as u8 as f64));
        push("timestamp", 1, &mut c.timestamp.iter().map(|&x| x as f64));
        push("frame_index", 1, &mut c.frame_index.iter().map(|&x| x as f64));
        push("episode_index", 1, &mut std::iter::repeat_n(episode_index as f64, n));
        push("index", 1, &mut c.index.iter().map(|&x| x as f64));
        push("task_index", 1, &mut std::iter::repeat_n(task_index as f64, n));
    }

    fn json(&self, shape: Shape) -> Value {
        let mut out = serde_json::Map::new();
        for (name, dims) in &self.values {
            let per_dim: Vec<Summary> = dims.iter().map(|v| Summary::of(v.clone())).collect();
            let stat = |f: &dyn Fn(&Summary) -> f64, per_dim: &[Summary]| -> Value {
                Value::from(per_dim.iter().map(f).collect::<Vec<_>>())
            };
            let mut m = serde_json::Map::new();
            m.insert("min".into(), stat(&|s| s.min, &per_dim));
            m.insert("max".into(), stat(&|s| s.max, &per_dim));
            m.insert("mean".into(), stat(&|s| s.mean, &per_dim));
            m.insert("std".into(), stat(&|s| s.std, &per_dim));
            m.insert("count".into(), json!([dims.first().map_or(0, Vec::len)]));
            for (k, q) in QUANTILES {
                m.insert(k.into(), stat(&|s| s.quantile(q), &per_dim));
            }
            out.insert(name.to_string(), Value::Object(m));
        }
        out.insert("observation.image".into(), self.color_json());
        out.insert("observation.depth".into(), self.depth_json(shape));
        Value::Object(out)
    }

    fn color_json(&self) -> Value {
        let per_channel = |f: &dyn Fn(&[u64]) -> f64| -> Value {
            Value::from(self.color.iter().map(|h| vec![vec![f(h)]]).collect::<Vec<_>>())
        };
        let count = |h: &[u64]| h.iter().sum::<u64>() as f64;
        let mean = |h: &[u64]| h.iter().enumerate().map(|(v, &n)| v as f64 * n as f64).sum::<f64>() / count(h) / 255.0;
        let std = |h: &[u64]| {
            let m = mean(h) * 255.0;
            let var = h.iter().enumerate().map(|(v, &n)| (v as f64 - m).powi(2) * n as f64).sum::<f64>() / count(h);
            var.sqrt() / 255.0
        };
        let quantile = |h: &[u64], q: f64| {
            let want = q * count(h);
            let mut seen = 0.0;
            for (v, &n) in h.iter().enumerate() {
                seen += n as f64;
                if seen >= want {
                    return v as f64 / 255.0;
                }
            }
            1.0
        };
        let mut m = serde_json::Map::new();
        m.insert("min".into(), per_channel(&|h| h.iter().position(|&n| n > 0).unwrap_or(0) as f64 / 255.0));
        m.insert("max".into(), per_channel(&|h| h.iter().rposition(|&n| n > 0).unwrap_or(0) as f64 / 255.0));
        m.insert("mean".into(), per_channel(&mean));
        m.insert("std".into(), per_channel(&std));
        m.insert("count".into(), json!([self.frames]));
        for (k, q) in QUANTILES {
            m.insert(k.into(), per_channel(&|h| quantile(h, q)));
        }
        Value::Object(m)
    }

    fn depth_json(&self, shape: Shape) -> Value {
        let n = self.frames as f64;
        let grid = |f: &dyn Fn(&[f64; 4]) -> f64| -> Value {
            Value::from(
                self.depth
                    .chunks(shape.width as usize)
                    .map(|row| row.iter().map(f).collect::<Vec<_>>())
                    .collect::<Vec<_>>(),
            )
        };
        let mean = |s: &[f64; 4]| s[2] / n;
        let mut m = serde_json::Map::new();
        m.insert("min".into(), grid(&|s| s[0]));
        m.insert("max".into(), grid(&|s| s[1]));
        m.insert("mean".into(), grid(&mean));
        m.insert("std".into(), grid(&|s| (s[3] / n - mean(s).powi(2)).max(0.0).sqrt()));
        m.insert("count".into(), json!([self.frames]));
        Value::Object(m)
    }
}

/// LeRobot's quantiles and their keys.
const QUANTILES: [(&str, f64); 5] = [("q01", 0.01), ("q10", 0.10), ("q50", 0.50), ("q90", 0.90), ("q99", 0.99)];

/// Min, max, mean, population std and quantiles of one dimension's values.
struct Summary {
    sorted: Vec<f64>,
    min: f64,
    max: f64,
    mean: f64,
    std: f64,
}

impl Summary {
    fn of(mut v: Vec<f64>) -> Self {
        v.sort_by(f64::total_cmp);
        let n = v.len().max(1) as f64;
        let mean = v.iter().sum::<f64>() / n;
        let std = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
        Self { min: v.first().copied().unwrap_or(0.0), max: v.last().copied().unwrap_or(0.0), mean, std, sorted: v }
    }

    /// Linear interpolation between the closest ranks (numpy's default).
    fn quantile(&self, q: f64) -> f64 {
        if self.sorted.is_empty() {
            return 0.0;
        }
        let pos = q * (self.sorted.len() - 1) as f64;
        let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
        self.sorted[lo] + (self.sorted[hi] - self.sorted[lo]) * (pos - lo as f64)
    }
}
