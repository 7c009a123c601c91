//! The fuzz targets: one per external input of equiarm. Each builds its seeds (valid inputs made
//! with the project's own writers) and a harness that feeds one input to the code under test.
//!
//! A harness fails by panicking. Besides the panics of the code under test, some harnesses check
//! a property that must hold for every accepted input (a decoded message re-encodes to the same
//! bytes, an accepted number lies in the flag's range, a recovered bag reads back complete) and
//! panic when it does not.

use std::marker::PhantomData;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use equiarm_msgs::{RosMessage, builtin_interfaces::Time, cdr};

use crate::mutate::Shape;
use equiarm_types::OBS_PLANES;

/// A target could not be set up (its seeds or its harness).
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    /// Reading or writing a scratch file failed (the file, and the cause).
    #[error(transparent)]
    Io(#[from] equiarm_types::files::FileError),
    /// The project's own code refused to make a seed or the state a harness needs.
    #[error("{what}: {message}")]
    Project {
        /// What was being made.
        what: &'static str,
        /// The error it gave.
        message: String,
    },
}

impl SetupError {
    fn project(what: &'static str) -> impl FnOnce(&dyn std::fmt::Display) -> SetupError {
        move |e| SetupError::Project { what, message: e.to_string() }
    }
}

/// Feeds inputs to the code under test; fails by panicking.
pub trait Harness {
    /// Runs one input; says whether the code under test accepted it (returned `Ok`).
    fn run(&mut self, input: &[u8]) -> bool;
}

/// One fuzz target.
#[derive(Clone)]
pub struct Target {
    /// Its name on the command line.
    pub name: &'static str,
    /// What it feeds and to what.
    pub about: &'static str,
    /// How its inputs are shaped.
    pub shape: Shape,
    /// Longest input it is given, bytes.
    pub max_len: usize,
    /// Tokens of its format for text mutations.
    pub dictionary: &'static [&'static str],
    seeds: fn(&Path) -> Result<Vec<Vec<u8>>, SetupError>,
    harness: fn(&Path) -> Result<Box<dyn Harness>, SetupError>,
}

impl Target {
    /// Its seeds, built in the scratch directory `scratch` (the same every time).
    pub fn seeds(&self, scratch: &Path) -> Result<Vec<Vec<u8>>, SetupError> {
        (self.seeds)(scratch)
    }

    /// A harness working in the scratch directory `scratch`.
    pub fn harness(&self, scratch: &Path) -> Result<Box<dyn Harness>, SetupError> {
        (self.harness)(scratch)
    }
}

/// Every target, in the order `all` runs them.
pub fn all() -> Vec<Target> {
    let mut t = cdr_targets();
    t.extend([
        Target {
            name: "bag_read",
            about: "an MCAP file written by equiarm_bag::Writer: Reader::open, for_each (strict and salvage), info",
            shape: Shape::Binary,
            max_len: 1 << 16,
            dictionary: &[],
            seeds: bag_seeds,
            harness: |s| Ok(Box::new(BagRead { scratch: s.to_path_buf() })),
        },
        Target {
            name: "bag_recover",
            about: "an MCAP file given to equiarm_bag::recover; the recovered bag must read back complete",
            shape: Shape::Binary,
            max_len: 1 << 16,
            dictionary: &[],
            seeds: bag_seeds,
            harness: |s| Ok(Box::new(BagRecover { scratch: s.to_path_buf() })),
        },
        Target {
            name: "env_config",
            about: "EnvConfig JSON (the sim node's --config): serde_json, then Env::with_assets's validation",
            shape: Shape::Text,
            max_len: 1 << 14,
            dictionary: ENV_CONFIG_WORDS,
            seeds: env_config_seeds,
            harness: |_| {
                let assets = equiarm_sim::Assets::bundled().map_err(|e| SetupError::project("bundled assets")(&e))?;
                Ok(Box::new(EnvConfigHarness { assets: Arc::new(assets) }))
            },
        },
        Target {
            name: "train_config",
            about: "TrainConfig JSON: TrainConfig::from_json, then equiarm_train::config::check; accepted configs round-trip",
            shape: Shape::Text,
            max_len: 1 << 14,
            dictionary: TRAIN_CONFIG_WORDS,
            seeds: train_config_seeds,
            harness: |_| Ok(Box::new(TrainConfigHarness)),
        },
        Target {
            name: "weights",
            about: "safetensors actor weights (a PolicyWeights payload): equiarm_nn::checkpoint::load_bytes into a small EquiActor",
            shape: Shape::Binary,
            max_len: 1 << 20,
            dictionary: &[],
            seeds: weights_seeds,
            harness: |_| Ok(Box::new(WeightsHarness { actor: small_actor()? })),
        },
        Target {
            name: "tensorfile",
            about: "an optimiser-state file: equiarm_sac::tensorfile::read",
            shape: Shape::Binary,
            max_len: 1 << 16,
            dictionary: &[],
            seeds: tensorfile_seeds,
            harness: |s| Ok(Box::new(TensorFileHarness { path: s.join("state.safetensors") })),
        },
        Target {
            name: "resume",
            about: "a checkpoint directory of a tiny config with one file mutated: Learner::resume",
            shape: Shape::Binary,
            max_len: 1 << 20,
            dictionary: &[],
            seeds: resume_seeds,
            harness: resume_harness,
        },
        Target {
            name: "urdf",
            about: "a URDF file: equiarm_sim::assets::load_urdf (parse and validate)",
            shape: Shape::Text,
            max_len: 1 << 14,
            dictionary: URDF_WORDS,
            seeds: |_| Ok(URDFS.iter().map(|u| u.as_bytes().to_vec()).collect()),
            harness: |s| Ok(Box::new(UrdfHarness { path: s.join("fuzz.urdf") })),
        },
        Target {
            name: "cli_values",
            about: "command-line numbers: the equiarm_nodes::cli_values parsers (first byte picks the parser); accepted values lie in range",
            shape: Shape::Text,
            max_len: 64,
            dictionary: &[" ", "\t", "+", "_", "0x", "e", "E", "."],
            seeds: cli_seeds,
            harness: |_| Ok(Box::new(CliHarness)),
        },
        Target {
            name: "bag_metadata",
            about: "a bag's metadata.yaml beside a small intact bag: Reader::info's check of it (aliases refused unexpanded)",
            shape: Shape::Text,
            max_len: 1 << 14,
            dictionary: &["&a ", "*a", "version: ", "message_count: ", "relative_file_paths:", "- ", "[", "{", "\n  "],
            seeds: |s| {
                let dir = small_bag(&s.join("seed").join("bag"))?;
                // (an alias-using file is no seed: seeds must be accepted; the dictionary brings aliases)
                Ok(vec![std::fs::read(dir.join("metadata.yaml")).map_err(equiarm_types::files::at(&dir))?])
            },
            harness: |s| Ok(Box::new(BagMetadata { dir: small_bag(&s.join("read").join("bag"))? })),
        },
        Target {
            name: "obs_frame",
            about: "an Observation's stated sides and planes (u16 height, u16 width, u16 split, then bytes): policy::frame_of_size for 19 px",
            shape: Shape::Binary,
            max_len: 1 << 12,
            dictionary: &[],
            seeds: |_| obs_frame_seeds(),
            harness: |_| Ok(Box::new(ObsFrame)),
        },
        Target {
            name: "grid_toml",
            about: "an experiment grid file: equiarm_experiment::grid::Grid::parse, then each run's config",
            shape: Shape::Text,
            max_len: 1 << 14,
            dictionary: &["tasks = ", "variants = ", "views = ", "corruptions = ", "seeds = ", "[updates]", "[config]", "heldout_episodes = "],
            seeds: |_| Ok(GRIDS.iter().map(|g| g.as_bytes().to_vec()).collect()),
            harness: |_| Ok(Box::new(GridToml)),
        },
        Target {
            name: "rotest_dataset",
            about: "a rotation-estimation dataset (a whole `pairs.rotest`, or its JSON header, a NUL and the chunks): Dataset::read and read_header agree",
            shape: Shape::Text,
            max_len: 1 << 14,
            dictionary: &["\"size\":", "\"pairs\":", "\"chunks\":", "\"offset\":", "\"len\":", "\"label\":", "\"idx\":", "1024", "{", "}", "[", "]", ","],
            seeds: rotest_seeds,
            harness: |s| Ok(Box::new(RotestDataset { path: s.join("pairs.rotest") })),
        },
    ]);
    t
}

// ---------------------------------------------------------------------------------------------
// Files and frames from outside (issue 61)

/// Two small datasets, each as a whole file and as header, NUL, chunks (the form whose length
/// prefix the harness writes, so that mutations of the header reach the checks behind it).
fn rotest_seeds(scratch: &Path) -> Result<Vec<Vec<u8>>, SetupError> {
    use equiarm_rotest::dataset::Dataset;
    use equiarm_sim::rotest::{Corruptions, PairConfig};
    let mut out = Vec::new();
    for (setting, seed) in [("none", 1), ("condition_reverse", 2)] {
        let corruptions = Corruptions::parse(setting).map_err(|e| SetupError::project("a seed's setting")(&e))?;
        let cfg = PairConfig { size: 8, supersample: 1, corruptions };
        let ds = equiarm_rotest::generate::generate(&cfg, 2, seed)
            .map_err(|e| SetupError::project("generating a seed dataset")(&e))?;
        let path = ds.write(&scratch.join(setting)).map_err(|e| SetupError::project("writing a seed dataset")(&e))?;
        let file = std::fs::read(&path).map_err(equiarm_types::files::at(&path))?;
        Dataset::read(&path, None).map_err(|e| SetupError::project("reading a seed dataset")(&e))?;
        let n = u64::from_le_bytes(file[12..20].try_into().expect("8 bytes")) as usize;
        out.push([&file[20..20 + n], &[0u8][..], &file[20 + n..]].concat());
        out.push(file);
    }
    Ok(out)
}

struct RotestDataset {
    path: PathBuf,
}

impl Harness for RotestDataset {
    fn run(&mut self, input: &[u8]) -> bool {
        use equiarm_rotest::dataset::{Dataset, MAGIC, VERSION};
        let file = match input.iter().position(|&b| b == 0) {
            Some(nul) if !input.starts_with(MAGIC) => {
                let (header, data) = (&input[..nul], &input[nul + 1..]);
                [&MAGIC[..], &VERSION.to_le_bytes(), &(header.len() as u64).to_le_bytes(), header, data].concat()
            }
            _ => input.to_vec(),
        };
        std::fs::write(&self.path, &file).expect("writing the input file");
        let header = Dataset::read_header(&self.path);
        match Dataset::read(&self.path, None) {
            Ok(ds) => {
                let header =
                    header.unwrap_or_else(|e| panic!("read accepts a dataset whose header read_header refuses: {e}"));
                assert_eq!(header.pairs, ds.header.pairs, "read and read_header give other pairs");
                assert_eq!(ds.pairs.len(), ds.header.pairs.len(), "one stored pair per header pair");
                true
            }
            Err(_) => false,
        }
    }
}

/// A finished bag of 6 commands on one topic in `dir` (made afresh), with its metadata.yaml.
fn small_bag(dir: &Path) -> Result<PathBuf, SetupError> {
    use equiarm_bag::{TopicInfo, Writer, WriterOptions};
    let bag = |e: &dyn std::fmt::Display| SetupError::Project { what: "writing the small bag", message: e.to_string() };
    let _ = std::fs::remove_dir_all(dir);
    let mut w = Writer::create(dir, WriterOptions::default()).map_err(|e| bag(&e))?;
    let qos = [equiarm_bag::qos::OfferedQos::reliable(10)];
    let id = w
        .add_topic(TopicInfo::of::<equiarm_msgs::msg::GripperCommand>("/env0/gripper_cmd", &qos))
        .map_err(|e| bag(&e))?;
    for k in 0..6u64 {
        let data = cdr::encode(&command()).map_err(|e| bag(&e))?;
        w.write(id, 1_700_000_000_000_000_000 + k, 1_700_000_000_000_000_000 + k, &data).map_err(|e| bag(&e))?;
    }
    Ok(w.finish().map_err(|e| bag(&e))?.dir)
}

struct BagMetadata {
    dir: PathBuf,
}

impl Harness for BagMetadata {
    fn run(&mut self, input: &[u8]) -> bool {
        let path = self.dir.join("metadata.yaml");
        std::fs::write(&path, input).expect("writing the input file");
        let reader = equiarm_bag::Reader::open(&self.dir).expect("the small bag opens");
        let info = reader.info().expect("the small bag reads");
        info.metadata.is_some_and(|m| m.ok())
    }
}

/// The side the `obs_frame` target's reader takes.
const FRAME_SIDE: usize = 19;

fn obs_frame_seeds() -> Result<Vec<Vec<u8>>, SetupError> {
    let mut out = Vec::new();
    // (seeds must be accepted: frames of the side read; the mutations change the sides)
    let side = FRAME_SIDE as u32;
    for step in [7, 0] {
        let n = (side * side) as usize;
        let mut o = equiarm_msgs::msg::Observation::default();
        let color: Vec<u8> = (0..n * 3).map(|i| (i * step % 251) as u8).collect();
        let depth: Vec<f32> = (0..n).map(|i| 0.2 + i as f32 / 1000.0).collect();
        o.set_frame(side, side, &color, &depth).map_err(|e| SetupError::project("compressing a seed frame")(&e))?;
        let mut bytes = Vec::new();
        for v in [side as u16, side as u16, o.color.len() as u16] {
            bytes.extend(v.to_le_bytes());
        }
        bytes.extend(&o.color);
        bytes.extend(&o.depth);
        out.push(bytes);
    }
    Ok(out)
}

struct ObsFrame;

impl Harness for ObsFrame {
    fn run(&mut self, input: &[u8]) -> bool {
        let Some((head, planes)) = input.split_at_checked(6) else { return false };
        let n = |i: usize| u16::from_le_bytes([head[i], head[i + 1]]) as usize;
        let (color, depth) = planes.split_at(n(4).min(planes.len()));
        let o = equiarm_msgs::msg::Observation {
            height: n(0) as u32,
            width: n(2) as u32,
            color: color.to_vec(),
            depth: depth.to_vec(),
            ..Default::default()
        };
        equiarm_train::policy::frame_of_size(&o, FRAME_SIDE).is_ok()
    }
}

/// The repository's grid files, the seeds of `grid_toml`.
const GRIDS: &[&str] = &[
    include_str!("../../experiments/tasks.toml"),
    include_str!("../../experiments/baselines.toml"),
    include_str!("../../experiments/view_angle.toml"),
    include_str!("../../experiments/reflection.toml"),
    include_str!("../../experiments/bf16_check.toml"),
    include_str!("../../experiments/arm.toml"),
];

struct GridToml;

impl Harness for GridToml {
    fn run(&mut self, input: &[u8]) -> bool {
        use equiarm_experiment::grid::Grid;
        let Ok(text) = std::str::from_utf8(input) else { return false };
        let Ok(grid) = Grid::parse(Path::new("fuzz.toml"), text) else { return false };
        grid.cells().iter().all(|c| grid.config(c).is_ok())
    }
}

/// A target that fails on purpose, for testing the runner (not in [`all`]): its seeds are run
/// first and unmutated, `ok` passes, `panic` panics, `abort` aborts the process, `alloc` asks for
/// 1 TiB (beyond the worker's memory limit) and `hang` never returns.
pub fn selftest() -> Vec<Target> {
    vec![Target {
        name: "selftest",
        about: "fails on purpose (tests of the runner)",
        shape: Shape::Binary,
        max_len: 16,
        dictionary: &[],
        seeds: |_| Ok(["ok", "panic", "abort", "alloc", "hang"].iter().map(|s| s.as_bytes().to_vec()).collect()),
        harness: |_| Ok(Box::new(SelfTest)),
    }]
}

struct SelfTest;

impl Harness for SelfTest {
    fn run(&mut self, input: &[u8]) -> bool {
        match input {
            b"panic" => panic!("selftest panics"),
            b"abort" => std::process::abort(),
            b"alloc" => std::hint::black_box(vec![1u8; 1 << 40]).len() > 1,
            b"hang" => loop {
                std::thread::sleep(std::time::Duration::from_millis(100));
            },
            _ => true,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// CDR

/// Realistic values of a message type, beside its default, for seeds.
trait Samples: RosMessage {
    fn samples() -> Vec<Self>;
    /// What readers do next with an accepted message, beyond decoding it (default: nothing).
    fn read_further(&self) {}
}

struct Cdr<M>(PhantomData<M>);

impl<M: Samples> Harness for Cdr<M> {
    fn run(&mut self, input: &[u8]) -> bool {
        if let Ok(m) = cdr::decode::<M>(input) {
            m.read_further();
            let a = cdr::encode(&m).unwrap_or_else(|e| panic!("a decoded {} does not encode: {e}", M::TYPE_NAME));
            let again =
                cdr::decode::<M>(&a).unwrap_or_else(|e| panic!("a re-encoded {} does not decode: {e}", M::TYPE_NAME));
            let b = cdr::encode(&again).unwrap_or_else(|e| panic!("{}: {e}", M::TYPE_NAME));
            assert!(a == b, "{}: decode and encode do not round-trip", M::TYPE_NAME);
            return true;
        }
        false
    }
}

fn cdr_seeds<M: Samples>() -> Result<Vec<Vec<u8>>, SetupError> {
    let mut out = Vec::new();
    for m in std::iter::once(M::default()).chain(M::samples()) {
        out.push(cdr::encode(&m).map_err(|e| SetupError::project("encoding a seed message")(&e))?);
    }
    Ok(out)
}

macro_rules! cdr_targets {
    ($($name:literal => $ty:ty),* $(,)?) => {
        /// The CDR decoding targets, one per message type.
        fn cdr_targets() -> Vec<Target> {
            vec![$(Target {
                name: $name,
                about: concat!("CDR bytes decoded as ", stringify!($ty), ": equiarm_msgs::cdr::decode; accepted bytes round-trip"),
                shape: Shape::Binary,
                max_len: 1 << 14,
                dictionary: &[],
                seeds: |_| cdr_seeds::<$ty>(),
                harness: |_| Ok(Box::new(Cdr::<$ty>(PhantomData))),
            }),*]
        }

        /// The ROS type name each CDR target decodes, by target name.
        pub fn cdr_type_names() -> Vec<(&'static str, &'static str)> {
            vec![$(($name, <$ty as RosMessage>::TYPE_NAME)),*]
        }
    };
}

cdr_targets! {
    "cdr_time" => equiarm_msgs::builtin_interfaces::Time,
    "cdr_clock" => equiarm_msgs::rosgraph_msgs::Clock,
    "cdr_header" => equiarm_msgs::std_msgs::Header,
    "cdr_region_of_interest" => equiarm_msgs::sensor_msgs::RegionOfInterest,
    "cdr_image" => equiarm_msgs::sensor_msgs::Image,
    "cdr_camera_info" => equiarm_msgs::sensor_msgs::CameraInfo,
    "cdr_vector3" => equiarm_msgs::geometry_msgs::Vector3,
    "cdr_quaternion" => equiarm_msgs::geometry_msgs::Quaternion,
    "cdr_transform" => equiarm_msgs::geometry_msgs::Transform,
    "cdr_transform_stamped" => equiarm_msgs::geometry_msgs::TransformStamped,
    "cdr_tf_message" => equiarm_msgs::tf2_msgs::TFMessage,
    "cdr_gripper_command" => equiarm_msgs::msg::GripperCommand,
    "cdr_observation" => equiarm_msgs::msg::Observation,
    "cdr_transition" => equiarm_msgs::msg::Transition,
    "cdr_episode_result" => equiarm_msgs::msg::EpisodeResult,
    "cdr_trainer_status" => equiarm_msgs::msg::TrainerStatus,
    "cdr_policy_weights" => equiarm_msgs::msg::PolicyWeights,
}

fn stamp() -> Time {
    Time { sec: 1_764_000_000, nanosec: 123_456_789 }
}

fn header() -> equiarm_msgs::std_msgs::Header {
    equiarm_msgs::std_msgs::Header::new(stamp(), "world")
}

fn image(encoding: &str, w: u32, h: u32, bytes_per_px: u32) -> equiarm_msgs::sensor_msgs::Image {
    equiarm_msgs::sensor_msgs::Image {
        header: header(),
        height: h,
        width: w,
        encoding: encoding.into(),
        is_bigendian: 0,
        step: w * bytes_per_px,
        data: (0..w * h * bytes_per_px).map(|i| (i * 37 % 251) as u8).collect(),
    }
}

fn command() -> equiarm_msgs::msg::GripperCommand {
    equiarm_msgs::msg::GripperCommand {
        header: header(),
        obs_seq: 41,
        open_ratio: 0.5,
        dx: 0.01,
        dy: -0.02,
        dz: 0.005,
        dtheta: 0.3,
        source: equiarm_msgs::msg::GripperCommand::SOURCE_EXPERT,
    }
}

impl Samples for Time {
    fn samples() -> Vec<Self> {
        vec![stamp(), Time { sec: -1, nanosec: 999_999_999 }]
    }
}

impl Samples for equiarm_msgs::rosgraph_msgs::Clock {
    fn samples() -> Vec<Self> {
        vec![Self { clock: stamp() }]
    }
}

impl Samples for equiarm_msgs::std_msgs::Header {
    fn samples() -> Vec<Self> {
        vec![header(), Self::new(stamp(), "camera_side_rgbd_optical_frame")]
    }
}

fn transform(child: &str, x: f64) -> equiarm_msgs::geometry_msgs::TransformStamped {
    use equiarm_msgs::geometry_msgs::{Quaternion, Transform, Vector3};
    let rotation = Quaternion { x: 0.0, y: 0.0, z: 0.38268343236508984, w: 0.9238795325112867 };
    let transform = Transform { translation: Vector3 { x, y: -0.1, z: 0.05 }, rotation };
    equiarm_msgs::geometry_msgs::TransformStamped { header: header(), child_frame_id: child.into(), transform }
}

impl Samples for equiarm_msgs::geometry_msgs::Vector3 {
    fn samples() -> Vec<Self> {
        vec![transform("a", 0.5).transform.translation]
    }
}

impl Samples for equiarm_msgs::geometry_msgs::Quaternion {
    fn samples() -> Vec<Self> {
        vec![transform("a", 0.5).transform.rotation]
    }
}

impl Samples for equiarm_msgs::geometry_msgs::Transform {
    fn samples() -> Vec<Self> {
        vec![transform("a", 0.5).transform]
    }
}

impl Samples for equiarm_msgs::geometry_msgs::TransformStamped {
    fn samples() -> Vec<Self> {
        vec![transform("env0/gripper", 0.5)]
    }
}

impl Samples for equiarm_msgs::tf2_msgs::TFMessage {
    fn samples() -> Vec<Self> {
        vec![Self { transforms: vec![transform("camera_optical_frame", 0.7), transform("env0/gripper", 0.4)] }]
    }
}

impl Samples for equiarm_msgs::sensor_msgs::RegionOfInterest {
    fn samples() -> Vec<Self> {
        vec![Self { x_offset: 4, y_offset: 8, height: 32, width: 32, do_rectify: true }]
    }
}

impl Samples for equiarm_msgs::sensor_msgs::Image {
    fn samples() -> Vec<Self> {
        vec![image("rgb8", 4, 4, 3), image("32FC1", 4, 4, 4)]
    }
}

impl Samples for equiarm_msgs::sensor_msgs::CameraInfo {
    fn samples() -> Vec<Self> {
        vec![Self {
            header: header(),
            height: 152,
            width: 152,
            distortion_model: "plumb_bob".into(),
            d: vec![0.0; 5],
            k: [183.0, 0.0, 76.0, 0.0, 183.0, 76.0, 0.0, 0.0, 1.0],
            r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            p: [183.0, 0.0, 76.0, 0.0, 0.0, 183.0, 76.0, 0.0, 0.0, 0.0, 1.0, 0.0],
            binning_x: 0,
            binning_y: 0,
            roi: Default::default(),
        }]
    }
}

impl Samples for equiarm_msgs::msg::GripperCommand {
    fn samples() -> Vec<Self> {
        vec![command()]
    }
}

impl Samples for equiarm_msgs::msg::Observation {
    fn samples() -> Vec<Self> {
        vec![Self {
            header: header(),
            seq: 41,
            env: "env0".into(),
            episode: 3,
            step: 7,
            height: 4,
            width: 4,
            color: zstd::bulk::compress(&image("rgb8", 4, 4, 3).data, 1).expect("compressing a seed"),
            depth: zstd::bulk::compress(&image("16FC1", 4, 4, 2).data, 1).expect("compressing a seed"),
            holding: true,
            expert_action: command(),
            terminal: false,
        }]
    }

    /// The frame is read as the policy and the trainer read it (its planes decompressed and checked);
    /// a bad one is an error, never a panic or an allocation beyond the sides it claims.
    fn read_further(&self) {
        let _ = self.color_rgb8();
        let _ = self.depth_f16();
    }
}

impl Samples for equiarm_msgs::msg::Transition {
    fn samples() -> Vec<Self> {
        vec![Self {
            header: header(),
            env: "env0".into(),
            episode: 3,
            step: 7,
            obs_seq: 41,
            next_obs_seq: 42,
            action: command(),
            reward: 1.0,
            done: true,
            timeout: false,
            expert: true,
        }]
    }
}

impl Samples for equiarm_msgs::msg::EpisodeResult {
    fn samples() -> Vec<Self> {
        vec![Self {
            header: header(),
            env: "env1".into(),
            task: "block_pulling".into(),
            seed: 1_000_003,
            episode: 12,
            steps: 17,
            success: true,
            ret: 1.0,
            discounted_return: 0.85,
            expert: false,
            eval: true,
        }]
    }
}

impl Samples for equiarm_msgs::msg::TrainerStatus {
    fn samples() -> Vec<Self> {
        vec![Self {
            header: header(),
            updates: 1250,
            transitions: 30_000,
            buffer_size: 30_000,
            expert_transitions: 1000,
            critic_loss: 0.02,
            actor_loss: -1.5,
            alpha: 0.01,
            updates_per_s: 2.5,
            transitions_per_s: 40.0,
            last_eval_return: f32::NAN,
            last_eval_success_rate: f32::NAN,
            last_eval_episodes: 0,
        }]
    }
}

impl Samples for equiarm_msgs::msg::PolicyWeights {
    fn samples() -> Vec<Self> {
        vec![Self {
            header: header(),
            run_id: "20261202-072100-s0".into(),
            version: 3,
            updates: 500,
            model: "equi".into(),
            format: "safetensors".into(),
            data: (0..200u32).map(|i| (i * 13 % 256) as u8).collect(),
        }]
    }
}

// ---------------------------------------------------------------------------------------------
// Bags

/// Small bags in each compression, one left unfinished (a killed recorder), each as the bytes of
/// its single `.mcap` file.
fn bag_seeds(scratch: &Path) -> Result<Vec<Vec<u8>>, SetupError> {
    use equiarm_bag::{Compression, TopicInfo, Writer, WriterOptions};
    use equiarm_msgs::msg::{GripperCommand, Observation, Transition};
    let bag = |e: &dyn std::fmt::Display| SetupError::Project { what: "writing a seed bag", message: e.to_string() };
    let mut out = Vec::new();
    let cases =
        [(Compression::None, true), (Compression::Zstd, true), (Compression::Lz4, true), (Compression::None, false)];
    for (i, (compression, finish)) in cases.into_iter().enumerate() {
        let dir = scratch.join(format!("seed_bag{i}"));
        if dir.exists() {
            std::fs::remove_dir_all(&dir).map_err(equiarm_types::files::at(&dir))?;
        }
        let opts = WriterOptions { compression, chunk_size: 600, zstd_level: 1, ..WriterOptions::default() };
        let mut w = Writer::create(&dir, opts).map_err(|e| bag(&e))?;
        let obs = w.add_topic(TopicInfo::of::<Observation>("/env0/observation", &[])).map_err(|e| bag(&e))?;
        let cmd = w.add_topic(TopicInfo::of::<GripperCommand>("/env0/command", &[])).map_err(|e| bag(&e))?;
        let tr = w.add_topic(TopicInfo::of::<Transition>("/transitions", &[])).map_err(|e| bag(&e))?;
        let t0 = 1_764_000_000_000_000_000u64;
        for k in 0..4u64 {
            let t = t0 + k * 100_000_000;
            let mut o = <Observation as Samples>::samples().remove(0);
            o.seq = k;
            let mut c = command();
            c.obs_seq = k;
            let mut x = <Transition as Samples>::samples().remove(0);
            x.obs_seq = k;
            for (topic, data) in [(obs, cdr::encode(&o)), (cmd, cdr::encode(&c)), (tr, cdr::encode(&x))] {
                let data = data.map_err(|e| bag(&e))?;
                w.write(topic, t, t, &data).map_err(|e| bag(&e))?;
            }
        }
        if finish {
            w.finish().map_err(|e| bag(&e))?;
        } else {
            w.flush().map_err(|e| bag(&e))?;
            drop(w);
        }
        let file = std::fs::read_dir(&dir)
            .map_err(equiarm_types::files::at(&dir))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .find(|p| p.extension().is_some_and(|x| x == "mcap"))
            .ok_or_else(|| SetupError::Project { what: "writing a seed bag", message: "no .mcap file".into() })?;
        out.push(std::fs::read(&file).map_err(equiarm_types::files::at(&file))?);
    }
    Ok(out)
}

struct BagRead {
    scratch: PathBuf,
}

impl Harness for BagRead {
    fn run(&mut self, input: &[u8]) -> bool {
        use equiarm_bag::{ReadMode, Reader};
        let path = self.scratch.join("in.mcap");
        std::fs::write(&path, input).expect("writing the input file");
        let Ok(reader) = Reader::open(&path) else { return false };
        for mode in [ReadMode::Strict, ReadMode::Salvage] {
            let _ = reader.for_each(mode, |m| {
                // what bag play and eval do with a message: look at its bytes
                std::hint::black_box(m.data.len() + m.topic.len());
                Ok::<(), std::convert::Infallible>(())
            });
        }
        reader.info().is_ok()
    }
}

struct BagRecover {
    scratch: PathBuf,
}

impl Harness for BagRecover {
    fn run(&mut self, input: &[u8]) -> bool {
        use equiarm_bag::{Compression, ReadMode, Reader, WriterOptions};
        let path = self.scratch.join("in.mcap");
        std::fs::write(&path, input).expect("writing the input file");
        let out = self.scratch.join("recovered");
        if out.exists() {
            std::fs::remove_dir_all(&out).expect("removing the last output");
        }
        let opts = WriterOptions { compression: Compression::None, ..WriterOptions::default() };
        let Ok(report) = equiarm_bag::recover(&path, &out, opts) else { return false };
        // what recover wrote must read back whole, with every message it says it kept
        let reader = Reader::open(&out).unwrap_or_else(|e| panic!("the recovered bag does not open: {e}"));
        let read = reader
            .for_each(ReadMode::Strict, |_| Ok::<(), std::convert::Infallible>(()))
            .unwrap_or_else(|e| panic!("the recovered bag does not read: {e}"));
        let Ok(read) = read;
        assert_eq!(read.messages, report.summary.messages, "the recovered bag holds another number of messages");
        true
    }
}

// ---------------------------------------------------------------------------------------------
// Configs

const ENV_CONFIG_WORDS: &[&str] = &[
    "\"task\"",
    "\"camera\"",
    "\"params\"",
    "\"corruption\"",
    "\"max_steps\"",
    "\"render\"",
    "\"width\"",
    "\"height\"",
    "\"block_picking\"",
    "\"drawer_opening\"",
    "\"random_reflection\"",
];

fn env_config_seeds(_: &Path) -> Result<Vec<Vec<u8>>, SetupError> {
    use equiarm_sim::{EnvConfig, TaskKind, ViewPreset};
    let mut configs: Vec<EnvConfig> = TaskKind::ALL.iter().map(|&t| EnvConfig::new(t)).collect();
    for (i, preset) in ViewPreset::ALL.iter().enumerate() {
        let mut c = EnvConfig::new(TaskKind::ALL[i % TaskKind::ALL.len()]);
        c.camera = (*preset).into();
        c.corruption.random_reflection = i % 2 == 0;
        c.corruption.occlusion_projection = i % 3 == 0;
        c.render = i % 4 != 3;
        configs.push(c);
    }
    let mut out: Vec<Vec<u8>> = Vec::new();
    for c in &configs {
        out.push(serde_json::to_vec_pretty(c).map_err(|e| SetupError::project("writing EnvConfig JSON")(&e))?);
    }
    out.push(b"{}".to_vec());
    out.push(br#"{"task": "block_pulling", "max_steps": 50}"#.to_vec());
    Ok(out)
}

struct EnvConfigHarness {
    assets: Arc<equiarm_sim::Assets>,
}

impl Harness for EnvConfigHarness {
    fn run(&mut self, input: &[u8]) -> bool {
        let Ok(text) = std::str::from_utf8(input) else { return false };
        let Ok(cfg) = serde_json::from_str::<equiarm_sim::EnvConfig>(text) else { return false };
        equiarm_sim::Env::with_assets(cfg, self.assets.clone()).is_ok()
    }
}

const TRAIN_CONFIG_WORDS: &[&str] = &[
    "\"batch_size\"",
    "\"num_envs\"",
    "\"image_size\"",
    "\"hidden\"",
    "\"input_size\"",
    "\"capacity\"",
    "\"total_updates\"",
    "\"training_starts\"",
    "\"lr_final\"",
    "\"augmentation\"",
    "{\"drq\": {\"k\": 2, \"m\": 2}}",
    "\"center\"",
    "\"cnn\"",
    "\"sen\"",
];

fn train_config_seeds(_: &Path) -> Result<Vec<Vec<u8>>, SetupError> {
    use equiarm_sac::config::{Augmentation, Preset, TrainConfig};
    let mut configs = Vec::new();
    for (i, task) in equiarm_sim::TaskKind::ALL.iter().enumerate() {
        let preset = Preset::ALL[i % Preset::ALL.len()];
        configs.push(TrainConfig::preset(preset, *task));
    }
    let mut drq = TrainConfig::reduced(equiarm_types::TaskKind::BlockPulling);
    drq.augmentation = Augmentation::PAPER_DRQ;
    drq.agent.lr_final = Some(1e-4);
    configs.push(drq);
    let mut out = Vec::new();
    for c in &configs {
        out.push(serde_json::to_vec_pretty(c).map_err(|e| SetupError::project("writing TrainConfig JSON")(&e))?);
    }
    Ok(out)
}

struct TrainConfigHarness;

impl Harness for TrainConfigHarness {
    fn run(&mut self, input: &[u8]) -> bool {
        use equiarm_sac::config::TrainConfig;
        let Ok(text) = std::str::from_utf8(input) else { return false };
        let Ok(cfg) = TrainConfig::from_json(text) else { return false };
        if equiarm_train::config::check(&cfg).is_err() {
            return false;
        }
        {
            // an accepted config is what a checkpoint's manifest stores and a resume compares
            let again = serde_json::to_string(&cfg).expect("an accepted TrainConfig serialises");
            let back = TrainConfig::from_json(&again)
                .unwrap_or_else(|e| panic!("an accepted TrainConfig does not read back: {e}"));
            assert!(back == cfg, "an accepted TrainConfig reads back different: {again}");
        }
        true
    }
}

// ---------------------------------------------------------------------------------------------
// Weights, optimiser state, checkpoints

fn small_actor() -> Result<equiarm_nn::nets::EquiActor, SetupError> {
    use equiarm_nn::{
        init::Init,
        nets::{EquiActor, NetConfig},
    };
    let cfg = NetConfig::new(8, 8, OBS_PLANES);
    EquiActor::new(&cfg, &Init::new(1), &equiarm_nn::device::cpu())
        .map_err(|e| SetupError::project("building the actor")(&e))
}

fn weights_seeds(_: &Path) -> Result<Vec<Vec<u8>>, SetupError> {
    let actor = small_actor()?;
    let bytes = equiarm_nn::checkpoint::to_bytes(&actor).map_err(|e| SetupError::project("saving the actor")(&e))?;
    Ok(vec![bytes])
}

struct WeightsHarness {
    actor: equiarm_nn::nets::EquiActor,
}

impl Harness for WeightsHarness {
    fn run(&mut self, input: &[u8]) -> bool {
        equiarm_nn::checkpoint::load_bytes(self.actor.clone(), input.to_vec(), "fuzz input").is_ok()
    }
}

fn tensorfile_seeds(scratch: &Path) -> Result<Vec<Vec<u8>>, SetupError> {
    let path = scratch.join("seed.safetensors");
    let tensors = vec![
        ("m.enc.convs.0.weight.0".to_string(), vec![2, 3], vec![0.5, -1.0, 2.0, 0.0, -0.0, 1e-3]),
        ("v.enc.convs.0.weight.0".to_string(), vec![2, 3], vec![1e-6; 6]),
        ("m.head.bias.0".to_string(), vec![4], vec![0.25; 4]),
        ("empty".to_string(), vec![0, 2], vec![]),
    ];
    let meta = [("step".to_string(), "42".to_string()), ("lr".to_string(), "0.003".to_string())];
    equiarm_sac::tensorfile::write(&path, &tensors, &meta)?;
    let one = std::fs::read(&path).map_err(equiarm_types::files::at(&path))?;
    equiarm_sac::tensorfile::write(&path, &tensors[..1], &[])?;
    let two = std::fs::read(&path).map_err(equiarm_types::files::at(&path))?;
    Ok(vec![one, two])
}

struct TensorFileHarness {
    path: PathBuf,
}

impl Harness for TensorFileHarness {
    fn run(&mut self, input: &[u8]) -> bool {
        std::fs::write(&self.path, input).expect("writing the input file");
        equiarm_sac::tensorfile::read(&self.path).is_ok()
    }
}

/// The checkpoint's files in a fixed order; an input's first byte picks one (modulo the count,
/// plus one more slot: the replay file's body before compression, compressed by the harness, so
/// mutations reach the replay parser behind zstd's checksum).
const CHECKPOINT_FILES: [&str; 9] = [
    "actor.safetensors",
    "actor_optim.safetensors",
    "agent.json",
    "critic.safetensors",
    "critic_optim.safetensors",
    "critic_target.safetensors",
    "learner.json",
    "manifest.json",
    "replay.bin.zst",
];
const REPLAY_BODY: usize = CHECKPOINT_FILES.len();
/// `replay.bin.zst` starts with 8 magic bytes and a 4-byte version, then one zstd stream.
const REPLAY_HEAD: usize = 12;

fn tiny_config() -> equiarm_sac::config::TrainConfig {
    let mut cfg = equiarm_sac::config::TrainConfig::reduced(equiarm_types::TaskKind::BlockPulling);
    cfg.image_size = 10;
    cfg.agent.input_size = 8;
    cfg.agent.hidden = 8;
    cfg.batch_size = 2;
    cfg.replay.capacity = 16;
    cfg.training_starts = 2;
    cfg
}

fn tiny_learner() -> Result<equiarm_sac::learner::Learner, SetupError> {
    use equiarm_sac::{frame::StoredFrame, replay::Stored};
    let cfg = tiny_config();
    let s = cfg.image_size;
    let mut learner =
        equiarm_sac::learner::Learner::new(cfg).map_err(|e| SetupError::project("building the learner")(&e))?;
    let frame = |k: usize| {
        let color: Vec<u8> = (0..s * s * 3).map(|i| ((i + k) * 7 % 256) as u8).collect();
        let depth: Vec<f32> = (0..s * s).map(|i| 0.5 + (i % 5) as f32 * 0.01).collect();
        StoredFrame::new(s, color, &depth, k.is_multiple_of(2)).map(Arc::new)
    };
    for k in 0..3 {
        let t = Stored {
            obs: frame(k).map_err(|e| SetupError::project("a replay frame")(&e))?,
            next_obs: frame(k + 1).map_err(|e| SetupError::project("a replay frame")(&e))?,
            action: [0.5, 0.1, -0.1, 0.0, 0.2],
            reward: if k == 2 { 1.0 } else { 0.0 },
            done: k == 2,
            expert: k == 0,
        };
        learner.push(t).map_err(|e| SetupError::project("filling the replay")(&e))?;
    }
    Ok(learner)
}

fn resume_seeds(scratch: &Path) -> Result<Vec<Vec<u8>>, SetupError> {
    let dir = scratch.join("seed_checkpoint");
    tiny_learner()?.save(&dir).map_err(|e| SetupError::project("saving the checkpoint")(&e))?;
    let mut out = Vec::new();
    for (i, name) in CHECKPOINT_FILES.iter().enumerate() {
        let path = dir.join(name);
        let mut seed = vec![i as u8];
        seed.extend(std::fs::read(&path).map_err(equiarm_types::files::at(&path))?);
        out.push(seed);
    }
    let replay = &out[REPLAY_BODY - 1][1..];
    let body = zstd::decode_all(&replay[REPLAY_HEAD.min(replay.len())..])
        .map_err(equiarm_types::files::at(&dir.join("replay.bin.zst")))?;
    let mut seed = vec![REPLAY_BODY as u8];
    seed.extend_from_slice(&replay[..REPLAY_HEAD]);
    seed.extend(body);
    out.push(seed);
    Ok(out)
}

struct Resume {
    learner: equiarm_sac::learner::Learner,
    dir: PathBuf,
    originals: Vec<Vec<u8>>,
    changed: Option<usize>,
}

fn resume_harness(scratch: &Path) -> Result<Box<dyn Harness>, SetupError> {
    let seeds = resume_seeds(scratch)?;
    let dir = scratch.join("checkpoint");
    std::fs::create_dir_all(&dir).map_err(equiarm_types::files::at(&dir))?;
    let originals: Vec<Vec<u8>> = seeds.iter().take(CHECKPOINT_FILES.len()).map(|s| s[1..].to_vec()).collect();
    for (name, bytes) in CHECKPOINT_FILES.iter().zip(&originals) {
        let path = dir.join(name);
        std::fs::write(&path, bytes).map_err(equiarm_types::files::at(&path))?;
    }
    Ok(Box::new(Resume { learner: tiny_learner()?, dir, originals, changed: None }))
}

impl Harness for Resume {
    fn run(&mut self, input: &[u8]) -> bool {
        let Some((&which, content)) = input.split_first() else { return false };
        if let Some(i) = self.changed.take() {
            std::fs::write(self.dir.join(CHECKPOINT_FILES[i]), &self.originals[i])
                .expect("restoring a checkpoint file");
        }
        let which = which as usize % (CHECKPOINT_FILES.len() + 1);
        let (file, bytes) = if which == REPLAY_BODY {
            let split = REPLAY_HEAD.min(content.len());
            let mut bytes = content[..split].to_vec();
            bytes.extend(zstd::encode_all(&content[split..], 1).expect("compressing in memory"));
            (REPLAY_BODY - 1, bytes)
        } else {
            (which, content.to_vec())
        };
        std::fs::write(self.dir.join(CHECKPOINT_FILES[file]), bytes).expect("writing the input file");
        self.changed = Some(file);
        self.learner.resume(&self.dir).is_ok()
    }
}

// ---------------------------------------------------------------------------------------------
// URDF

const URDFS: [&str; 6] = [
    include_str!("../../urdf/gripper.urdf"),
    include_str!("../../urdf/cube.urdf"),
    include_str!("../../urdf/flat_block.urdf"),
    include_str!("../../urdf/table.urdf"),
    include_str!("../../urdf/drawer.urdf"),
    include_str!("../../urdf/bowl.urdf"),
];

const URDF_WORDS: &[&str] = &[
    "<link name=\"l\">",
    "</link>",
    "<joint name=\"j\" type=\"prismatic\">",
    "type=\"revolute\"",
    "type=\"fixed\"",
    "</joint>",
    "<parent link=\"l\"/>",
    "<child link=\"l\"/>",
    "<limit lower=\"0\" upper=\"1\" effort=\"1\" velocity=\"1\"/>",
    "<inertial>",
    "<mass value=\"",
    "<inertia ixx=\"1\" ixy=\"0\" ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"1\"/>",
    "<origin xyz=\"0 0 0\" rpy=\"0 0 0\"/>",
    "<geometry>",
    "<box size=\"",
    "<cylinder radius=\"1\" length=\"1\"/>",
    "<sphere radius=\"",
    "<mesh filename=\"",
    "<collision>",
    "<visual>",
    "<material name=\"m\">",
    "<color rgba=\"",
    "<axis xyz=\"",
    "<!--",
    "-->",
    "&amp;",
    "<![CDATA[",
];

struct UrdfHarness {
    path: PathBuf,
}

impl Harness for UrdfHarness {
    fn run(&mut self, input: &[u8]) -> bool {
        std::fs::write(&self.path, input).expect("writing the input file");
        equiarm_sim::assets::load_urdf(&self.path).is_ok()
    }
}

// ---------------------------------------------------------------------------------------------
// Command-line numbers

/// The parsers, in the order an input's first byte picks them (modulo the count).
const CLI_PARSERS: [&str; 8] =
    ["seconds", "whole_seconds", "millis", "millis_or_zero", "rate", "steps", "positive_steps", "bounded 3..=17"];

fn cli_seeds(_: &Path) -> Result<Vec<Vec<u8>>, SetupError> {
    let values = ["2.5", "60", "250", "0", "1.5", "100", "1", "5"];
    Ok(values
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let mut s = vec![i as u8];
            s.extend_from_slice(v.as_bytes());
            s
        })
        .collect())
}

struct CliHarness;

impl Harness for CliHarness {
    fn run(&mut self, input: &[u8]) -> bool {
        use equiarm_nodes::cli_values as cv;
        let Some((&which, text)) = input.split_first() else { return false };
        // clap hands the parsers UTF-8 only
        let Ok(s) = std::str::from_utf8(text) else { return false };
        let which = which as usize % CLI_PARSERS.len();
        let in_range = match which {
            0 => cv::seconds(s).map(|v| v > 0.0 && v <= cv::MAX_SECONDS),
            1 => cv::whole_seconds(s).map(|v| (1..=cv::MAX_SECONDS as u64).contains(&v)),
            2 => cv::millis(s).map(|v| (1..=cv::MAX_MILLIS).contains(&v)),
            3 => cv::millis_or_zero(s).map(|v| v <= cv::MAX_MILLIS),
            4 => cv::rate(s).map(|v| (0.0..=cv::MAX_RATE).contains(&v)),
            5 => cv::steps(s).map(|v| v <= cv::MAX_STEPS),
            6 => cv::positive_steps(s).map(|v| (1..=cv::MAX_STEPS).contains(&v)),
            _ => cv::bounded(s, "steps", 3, 17).map(|v| (3..=17).contains(&v)),
        };
        match in_range {
            Ok(ok) => {
                assert!(ok, "{} accepted {s:?} outside its range", CLI_PARSERS[which]);
                true
            }
            Err(e) => {
                // the message says why: out of which range, or not a number of which kind
                let m = e.to_string();
                assert!(
                    m.contains(" is outside ") || m.contains(" is not a "),
                    "{} refused {s:?} saying {m:?}",
                    CLI_PARSERS[which]
                );
                false
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_message_type_has_a_cdr_target() {
        let covered: Vec<&str> = cdr_type_names().into_iter().map(|(_, t)| t).collect();
        for t in equiarm_msgs::ALL_TYPES {
            assert!(covered.contains(&t.type_name), "no CDR target decodes {}", t.type_name);
        }
        let names: Vec<&str> = all().iter().map(|t| t.name).collect();
        for (target, _) in cdr_type_names() {
            assert!(names.contains(&target), "{target} is not in all()");
        }
    }

    #[test]
    fn target_names_are_unique() {
        let mut names: Vec<&str> = all().iter().map(|t| t.name).collect();
        names.sort();
        let n = names.len();
        names.dedup();
        assert_eq!(names.len(), n);
    }

    #[test]
    fn every_target_accepts_its_own_seeds() {
        let scratch = tempfile::tempdir().unwrap();
        for t in all() {
            let seeds = t.seeds(scratch.path()).unwrap();
            assert!(!seeds.is_empty(), "{}", t.name);
            // seeds are built the same way every time: the parent rebuilds inputs from them
            assert_eq!(seeds, t.seeds(scratch.path()).unwrap(), "{}: seeds differ between builds", t.name);
            let mut h = t.harness(scratch.path()).unwrap();
            for (i, s) in seeds.iter().enumerate() {
                assert!(h.run(s), "{}: seed {i} refused", t.name);
            }
        }
    }
}
