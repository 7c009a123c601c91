//! The experiment's pieces end to end at toy sizes: the dataset file round-trips and refuses
//! damaged input naming the pair; the bound is 0.625 on invert-label data and 1 on clean data; a
//! trained C8 network's prediction is invariant to rotating both images by 90° (and a CNN's is not),
//! also as `rotest invariance` measures it.

mod common;

use std::path::PathBuf;

use equiarm_nn::burn::tensor::{Device, Tensor, TensorData};
use equiarm_nn::init::Init;
use equiarm_nn::nets::{NetConfig, RotCnnNet, RotEquiNet};
use equiarm_rotest::RotestError;
use equiarm_rotest::bound::dataset_bound;
use equiarm_rotest::dataset::{Dataset, FILE_NAME};
use equiarm_rotest::generate::generate;
use equiarm_rotest::train::{self, Classifier, ClassifierKind, RotestConfig, Samples, rotate};
use equiarm_sim::rotest::{Corruptions, PairConfig};

fn scratch(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("rotest_experiment").join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn data(setting: &str, size: usize, pairs: usize, seed: u64) -> Dataset {
    let cfg = PairConfig { size, supersample: 1, corruptions: Corruptions::parse(setting).unwrap() };
    generate(&cfg, pairs, seed).unwrap()
}

#[test]
fn dataset_file_round_trips_and_damage_is_reported_naming_the_pair() {
    let ds = data("grid", 16, 6, 1);
    let dir = scratch("roundtrip");
    let path = ds.write(&dir).unwrap();
    let back = Dataset::read(&dir, None).unwrap();
    assert_eq!(back.pairs, ds.pairs);
    assert_eq!(back.header.pairs, ds.header.pairs);
    assert_eq!(back.header.corrupt, "grid");
    assert_eq!(Dataset::read_header(&path).unwrap().pairs, ds.header.pairs);
    assert_eq!(Dataset::read(&path, Some(2)).unwrap().pairs, ds.pairs[..2].to_vec());

    // a flipped byte inside the last pair's chunk
    let mut bytes = std::fs::read(&path).unwrap();
    let last = back.header.chunks.last().copied().unwrap();
    let body = bytes.len() - (last.offset + last.len) as usize;
    let at = body + last.offset as usize + last.len as usize / 2;
    bytes[at] ^= 0xff;
    let bad = dir.join("damaged.rotest");
    std::fs::write(&bad, &bytes).unwrap();
    let e = Dataset::read(&bad, None).unwrap_err();
    assert!(matches!(e, RotestError::Format { .. }), "{e}");
    assert!(e.to_string().contains("pair 5") && e.to_string().contains("damaged.rotest"), "{e}");

    // truncated, and not a dataset at all
    let ok = std::fs::read(&path).unwrap();
    std::fs::write(&bad, &ok[..ok.len() - 10]).unwrap();
    let e = Dataset::read(&bad, None).unwrap_err().to_string();
    assert!(e.contains("pair 5") && e.contains("truncated"), "{e}");
    // bytes after the last chunk
    std::fs::write(&bad, [&ok[..], b"tail"].concat()).unwrap();
    let e = Dataset::read_header(&bad).unwrap_err().to_string();
    assert!(e.contains("4 bytes after the last chunk"), "{e}");
    std::fs::write(&bad, b"{\"hello\": 1}").unwrap();
    assert!(Dataset::read(&bad, None).unwrap_err().to_string().contains("not a rotation-estimation dataset"));
    let e = Dataset::read(&dir.join("missing").join(FILE_NAME), None).unwrap_err();
    assert!(matches!(e, RotestError::Io { .. }), "{e}");
}

/// Issue 61: a header pointing every pair at the same chunk (a small input whose pairs would each
/// decompress it again) is refused before anything is decompressed.
#[test]
fn a_header_reusing_one_chunk_for_many_pairs_is_refused() {
    let ds = data("none", 8, 3, 4);
    let dir = scratch("reused_chunk");
    let path = ds.write(&dir).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let n = u64::from_le_bytes(bytes[12..20].try_into().unwrap()) as usize;
    let mut header: equiarm_rotest::dataset::Header = serde_json::from_slice(&bytes[20..20 + n]).unwrap();
    let first = header.chunks[0];
    header.chunks = vec![first; 3];
    let json = serde_json::to_vec(&header).unwrap();
    let body = &bytes[20 + n..];
    let forged = [&bytes[..12], &(json.len() as u64).to_le_bytes()[..], &json, body].concat();
    let bad = dir.join("forged.rotest");
    std::fs::write(&bad, forged).unwrap();
    for e in [Dataset::read(&bad, None).unwrap_err(), Dataset::read_header(&bad).unwrap_err()] {
        assert!(e.to_string().contains("pair 1: chunk at byte 0 after the header"), "{e}");
    }
}

#[test]
fn the_bound_is_0_625_on_invert_label_and_1_on_clean_data() {
    let inv = data("condition_reverse", 8, 40, 2);
    let b = dataset_bound(&inv.header.pairs, &Corruptions::parse(&inv.header.corrupt).unwrap());
    assert_eq!(b.uniform_rotation, 0.625);
    assert!(b.drawn < 1.0 && b.drawn >= 0.5, "{}", b.drawn);
    // the drawn-label bound: 1 for pairs with idx 0 or 4, 0.5 for the others
    let expect = inv.header.pairs.iter().map(|m| if m.idx % 4 == 0 { 1.0 } else { 0.5 }).sum::<f64>() / 40.0;
    assert!((b.drawn - expect).abs() < 1e-12);
    for setting in ["none", "side,reflect"] {
        let clean = data(setting, 8, 10, 3);
        let b = dataset_bound(&clean.header.pairs, &Corruptions::parse(setting).unwrap());
        assert_eq!((b.uniform_rotation, b.drawn), (1.0, 1.0), "{setting}");
    }
}

#[test]
fn training_options_out_of_their_domain_name_the_flag() {
    let mut c = RotestConfig::paper(ClassifierKind::Cnn, 10, 0);
    c.img_trans = 11;
    assert!(c.validate().unwrap_err().to_string().contains("--img-trans"));
    let c = RotestConfig { input: 48, ..RotestConfig::paper(ClassifierKind::Cnn, 10, 0) };
    assert!(c.validate().unwrap_err().to_string().contains("--input"));
    let c = RotestConfig::paper(ClassifierKind::Cnn, 1700, 0);
    assert!(train::split(2000, &c).unwrap_err().to_string().contains("--train-pairs"));
    let [a, b, t] = train::split(2000, &RotestConfig::paper(ClassifierKind::Cnn, 100, 0)).unwrap();
    assert_eq!((a.len(), b.len(), t.len()), (100, 200, 200));
    let mut all: Vec<usize> = a.iter().chain(&b).chain(&t).copied().collect();
    all.sort();
    all.dedup();
    assert_eq!(all.len(), 500, "the three parts are disjoint");
}

#[test]
fn rotations_by_90_are_exact_and_the_augmentation_adds_seven_copies_per_pair() {
    let side = 5;
    let img: Vec<f32> = (0..2 * side * side).map(|v| v as f32).collect();
    let mut x = img.clone();
    for _ in 0..4 {
        x = rotate(&x, 2, side, 2);
    }
    assert_eq!(x, img);
    // 90° counter-clockwise as displayed: the top-right pixel goes to the top-left
    let r = rotate(&img, 2, side, 2);
    assert_eq!(r[0], img[side - 1]);
    // 45° twice is 90° up to interpolation (the centre pixel is exact)
    let c = side * side / 2;
    let r45 = rotate(&rotate(&img, 2, side, 1), 2, side, 1);
    assert!((r45[c] - r[c]).abs() < 1e-4);
    // rotating at the stored resolution then downsampling by 2 equals downsampling then rotating
    // (up to float rounding) for multiples of 90°
    let ds = data("none", 38, 3, 4);
    let small = Samples::from_dataset(&ds, &[0, 1, 2], 19).unwrap();
    let n = 8 * 19 * 19;
    for k in [2, 4, 6] {
        let r = Samples::from_dataset_rotated(&ds, &[0, 1, 2], 19, k).unwrap();
        for i in 0..3 {
            let expect = rotate(&small.x[i * n..(i + 1) * n], 8, 19, k);
            let err = expect.iter().zip(&r.x[i * n..(i + 1) * n]).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
            assert!(err < 1e-5, "k {k} pair {i}: {err}");
        }
    }
    let copies = Samples::rotated_copies(&ds, &[0, 2], 19).unwrap();
    assert_eq!(copies.len(), 2 * 7);
    assert_eq!(copies.y, [small.y[0], small.y[2]].repeat(7));
}

fn rot90_batch(x: &Tensor<4>) -> Tensor<4> {
    // counter-clockwise as displayed, over (H, W), all 8 channels (both images) together
    x.clone().swap_dims(2, 3).flip([2])
}

fn values(t: Tensor<2>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().unwrap()
}

use common::tiny;

#[test]
fn a_trained_c8_net_predicts_the_same_class_for_both_images_rotated_by_90_degrees() {
    let ds = data("none", 19, 24, 5);
    let out = scratch("train_equi");
    let cfg = RotestConfig { min_epochs: 2, max_epochs: 2, lr: 1e-3, ..tiny(ClassifierKind::Equi, 16, 0) };
    let rec = train::run(&ds, &cfg, &Device::flex(), &out, &mut |_| {}).unwrap();
    assert_eq!(rec.history.len(), 2);
    assert!(rec.history.iter().all(|e| e.loss.is_finite()));
    let saved: train::RotestRecord = serde_json::from_slice(&std::fs::read(out.join("run.json")).unwrap()).unwrap();
    assert_eq!(saved, rec);

    let dev = Device::flex();
    let ncfg = NetConfig::new(8, 16, 8);
    let fresh = RotEquiNet::new(&ncfg, &Init::new(0), &dev).unwrap();
    let net = equiarm_nn::checkpoint::load(
        RotEquiNet::new(&ncfg, &Init::new(0), &dev).unwrap(),
        &out.join("best.safetensors"),
    )
    .unwrap();
    let s = Samples::from_dataset(&ds, &(0..24).collect::<Vec<_>>(), 19).unwrap();
    // all 24 pairs, centre crop 16 of 19
    let n = 8 * 19 * 19;
    let mut crop = Vec::new();
    for i in 0..24 {
        for ch in 0..8 {
            for r in 1..17 {
                let o = i * n + ch * 19 * 19 + r * 19 + 1;
                crop.extend_from_slice(&s.x[o..o + 16]);
            }
        }
    }
    let x = Tensor::<4>::from_data(TensorData::new(crop, [24, 8, 16, 16]), &dev);
    let trained = values(net.logits(x.clone()));
    assert_ne!(trained, values(fresh.logits(x.clone())), "the checkpoint holds trained weights");
    let mut xr = x.clone();
    for _ in 0..3 {
        xr = rot90_batch(&xr);
        let rotated = values(net.logits(xr.clone()));
        let scale = trained.iter().map(|v| v.abs()).fold(0.0f32, f32::max).max(1e-6);
        let err = trained.iter().zip(&rotated).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max) / scale;
        assert!(err < 1e-4, "logits change by {err} (relative) under a 90° rotation");
        assert_eq!(train::argmax_rows(net.logits(xr.clone())), train::argmax_rows(net.logits(x.clone())));
    }
    // `rotest invariance` measures this checkpoint on the run's own test split: unrotated, it finds
    // the run's test accuracy; under 90°, 180° and 270° it finds every prediction unchanged
    let (back, agreement) = train::run_agreement(&ds, &out, &dev, false).unwrap();
    assert_eq!(back, rec);
    assert_eq!(agreement.len(), 8);
    for k in [0, 2, 4, 6] {
        let (unchanged, acc) = agreement[k];
        assert_eq!(unchanged, 1.0, "{}°: {unchanged}", 45 * k);
        assert!((acc - rec.test_acc).abs() < 1e-9, "{}°: accuracy {acc}, the run's {}", 45 * k, rec.test_acc);
    }
    assert!(agreement.iter().all(|&(u, a)| (0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&a)));
    // the CNN has no such symmetry: the same check fails for it
    let cnn = RotCnnNet::new(&ncfg, &Init::new(0), &dev).unwrap();
    let (a, b) = (values(cnn.logits(x.clone())), values(cnn.logits(rot90_batch(&x))));
    let scale = a.iter().map(|v| v.abs()).fold(0.0f32, f32::max);
    let err = a.iter().zip(&b).map(|(p, q)| (p - q).abs()).fold(0.0f32, f32::max) / scale;
    assert!(err > 1e-3, "a CNN is not invariant: {err}");
}

/// With a learning rate too small to change any prediction, validation accuracy never improves after
/// epoch 1: training stops `patience` epochs later, but not before `min_epochs`, and reports the
/// test accuracy of epoch 1.
#[test]
fn early_stopping_waits_for_patience_after_min_epochs_and_reports_the_best_epoch() {
    let ds = data("none", 19, 16, 6);
    for (min_epochs, expect) in [(2, 3), (5, 5)] {
        let cfg =
            RotestConfig { lr: 1e-12, min_epochs, patience: 2, max_epochs: 50, ..tiny(ClassifierKind::Cnn, 8, 1) };
        let rec = train::run(&ds, &cfg, &Device::flex(), &scratch(&format!("stop{min_epochs}")), &mut |_| {}).unwrap();
        assert_eq!(rec.history.len(), expect, "min_epochs {min_epochs}");
        assert!(rec.history.iter().all(|e| e.val_acc == rec.history[0].val_acc));
        assert_eq!((rec.best_epoch, Some(rec.test_acc)), (1, rec.history[0].test_acc));
        // the test split is evaluated only when validation improves: here in epoch 1 only
        assert!(rec.history[1..].iter().all(|e| e.test_acc.is_none()));
    }
}

/// `rotest grid` at toy sizes over `root/data` (one setting, `none`, N = 4) into `root/runs`, its
/// report into `root/report`.
fn tiny_grid(
    root: &std::path::Path,
    variants: Vec<equiarm_rotest::cli::ClassifierVariant>,
    seeds: Vec<u64>,
) -> equiarm_rotest::cli::RotestCommand {
    equiarm_rotest::cli::RotestCommand::Grid(grid_args(root, variants, seeds))
}

/// The options of [`tiny_grid`] (what `rotest status` takes too): one epoch a run.
fn grid_args(
    root: &std::path::Path,
    variants: Vec<equiarm_rotest::cli::ClassifierVariant>,
    seeds: Vec<u64>,
) -> equiarm_rotest::grid::GridArgs {
    common::grid_args(root, variants, seeds, 1)
}

/// `rotest grid --variants cnn` trains the CNN alone, writes the report, and skips the run the
/// second time; an empty list of variants is refused naming the flag.
#[test]
fn the_grid_trains_only_the_variants_named_and_skips_finished_runs() {
    use equiarm_rotest::cli::{ClassifierVariant, run};
    let root = scratch("grid_variants");
    data("none", 19, 12, 7).write(&root.join("data").join("none")).unwrap();
    let grid = |variants: Vec<ClassifierVariant>| tiny_grid(&root, variants, vec![0]);
    assert_eq!(run(grid(vec![ClassifierVariant::Cnn]), &|| false).unwrap(), 0);
    let runs = root.join("runs").join("none");
    let cnn = runs.join("cnn").join("4").join("s0").join("run.json");
    assert!(cnn.is_file());
    assert!(!runs.join("equi").exists() && !runs.join("cnn+trans").exists());
    let table = std::fs::read_to_string(root.join("report").join("rotest.md")).unwrap();
    assert!(table.contains("| none | 4 |"), "{table}");
    let written = std::fs::metadata(&cnn).unwrap().modified().unwrap();
    run(grid(vec![ClassifierVariant::Cnn]), &|| false).unwrap();
    assert_eq!(std::fs::metadata(&cnn).unwrap().modified().unwrap(), written, "a finished run was trained again");
    let err = run(grid(vec![]), &|| false).unwrap_err().to_string();
    assert!(err.contains("--variants"), "{err}");
}

/// Asked to stop (SIGINT/SIGTERM in `equiarm rotest grid`) once its first run has finished, the
/// grid starts no other, writes no report and returns the stopped status; the same command then
/// trains only the runs left and writes the report. `rotest status` says where each run stands:
/// finished here, unfinished (a directory without `run.json`), not started, or archived in the
/// report.
#[test]
fn a_stopped_grid_keeps_its_finished_runs_and_the_same_command_continues() {
    use equiarm_rotest::cli::{ClassifierVariant, run};
    use equiarm_rotest::grid::status;
    use equiarm_train::STOPPED_EXIT;
    let root = scratch("grid_stop");
    data("none", 19, 12, 7).write(&root.join("data").join("none")).unwrap();
    let seed_dir = |s: u64| root.join("runs").join("none").join("cnn").join("4").join(format!("s{s}"));
    // the stop comes when seed 0 has finished, before seed 1 starts (one run at a time)
    let stop = || seed_dir(0).join("run.json").is_file();
    let grid = || tiny_grid(&root, vec![ClassifierVariant::Cnn], vec![0, 1, 2]);
    assert_eq!(run(grid(), &stop).unwrap(), STOPPED_EXIT);
    assert!(seed_dir(0).join("run.json").is_file());
    assert!(!seed_dir(1).exists() && !seed_dir(2).exists(), "a run was started after the stop");
    assert!(!root.join("report").exists(), "a stopped grid wrote a report");
    std::fs::create_dir_all(seed_dir(1)).unwrap();
    let args = grid_args(&root, vec![ClassifierVariant::Cnn], vec![0, 1, 2]);
    let text = status(&args).unwrap();
    assert!(text.contains("none: 1 finished here, 0 archived in "), "{text}");
    assert!(text.contains(", 1 unfinished (cut short, or in training now), 1 not started\n"), "{text}");
    assert!(text.contains("all 3 runs: 1 finished here, 0 archived in "), "{text}");
    assert!(text.contains(&format!("unfinished, no checkpoint: {}\n", seed_dir(1).display())), "{text}");
    assert!(text.contains(&format!("not started: {}\n", seed_dir(2).display())), "{text}");
    // a setting named twice is one setting
    let twice = equiarm_rotest::grid::GridArgs { settings: "none;none".into(), ..args.clone() };
    assert_eq!(twice.plan().unwrap().len(), 3);
    let written = std::fs::metadata(seed_dir(0).join("run.json")).unwrap().modified().unwrap();
    assert_eq!(run(grid(), &|| false).unwrap(), 0);
    assert!(seed_dir(1).join("run.json").is_file() && seed_dir(2).join("run.json").is_file());
    assert_eq!(std::fs::metadata(seed_dir(0).join("run.json")).unwrap().modified().unwrap(), written);
    let table = std::fs::read_to_string(root.join("report").join("rotest.md")).unwrap();
    assert!(table.lines().any(|l| l.starts_with("| none | 4 |") && l.ends_with("(3) |")), "{table}");
    // on another machine (no runs directory) the report's archive holds them all
    std::fs::remove_dir_all(root.join("runs")).unwrap();
    let text = status(&args).unwrap();
    assert!(text.contains("all 3 runs: 0 finished here, 3 archived in "), "{text}");
    assert!(text.contains(", 0 unfinished (cut short, or in training now), 0 not started\n"), "{text}");
}

/// Regression (issue 61): `rotest bound` read a dataset's header without the checks training makes,
/// and printed a bound of 1.0000 for a dataset `rotest train` refuses. Every reader of the header now
/// checks it as training does.
#[test]
fn the_bound_refuses_a_header_that_training_refuses() {
    let ds = data("none", 16, 4, 2);
    let dir = scratch("bad_header");
    let path = ds.write(&dir).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let n = u64::from_le_bytes(bytes[12..20].try_into().unwrap()) as usize;
    let mut header: serde_json::Value = serde_json::from_slice(&bytes[20..20 + n]).unwrap();
    header["pairs"][1]["label"] = 9.into();
    let json = serde_json::to_vec(&header).unwrap();
    let mut damaged = bytes[..12].to_vec();
    damaged.extend_from_slice(&(json.len() as u64).to_le_bytes());
    damaged.extend_from_slice(&json);
    damaged.extend_from_slice(&bytes[20 + n..]);
    std::fs::write(&path, &damaged).unwrap();
    let from_training = Dataset::read(&dir, None).unwrap_err().to_string();
    let from_bound = Dataset::read_header(&dir).unwrap_err().to_string();
    assert!(from_training.contains("pair 1: label or rotation outside 0..8"), "{from_training}");
    assert_eq!(from_bound, from_training, "both readers refuse it alike");
}
