//! Env contracts: determinism (same seed and actions ⇒ byte-identical observations, also through
//! VecEnv's parallel stepping), rejection of bad actions, the corruptions, and the expert planners'
//! success rate (CI version of the 95/100 acceptance: ≥ 19 of 20 per task, images off to stay fast).

use equiarm_sim::{Action, Corruption, Env, EnvConfig, SimError, TaskKind, VecEnv};

fn run(cfg: &EnvConfig, seed: u64, steps: usize) -> Vec<equiarm_sim::Observation> {
    let mut env = Env::new(cfg.clone()).unwrap();
    let mut obs = vec![env.reset(seed).unwrap()];
    for k in 0..steps {
        // The expert's action, perturbed deterministically so the run is not only the planner's.
        let mut a = obs.last().unwrap().expert_action;
        a.dx += 0.01 * ((k % 3) as f32 - 1.0);
        let r = env.step(&a).unwrap();
        obs.push(r.observation);
        if r.done {
            break;
        }
    }
    obs
}

#[test]
fn same_seed_and_actions_give_byte_identical_observations() {
    for task in [TaskKind::BlockPicking, TaskKind::DrawerOpening] {
        let cfg = EnvConfig::new(task);
        let a = run(&cfg, 5, 8);
        let b = run(&cfg, 5, 8);
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.color, y.color);
            assert_eq!(
                x.depth.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                y.depth.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
            );
            assert_eq!(x.segmentation, y.segmentation);
            assert_eq!(x.holding, y.holding);
            assert_eq!(x.expert_action, y.expert_action);
        }
        let c = run(&cfg, 6, 0);
        assert_ne!(a[0].color, c[0].color, "another seed gives another scene");
    }
}

#[test]
fn vec_env_matches_sequential_envs() {
    let cfg = EnvConfig::new(TaskKind::BlockPushing);
    let mut venv = VecEnv::new(cfg.clone(), 3).unwrap();
    let seeds = [1, 2, 3];
    let mut obs = venv.reset(&seeds).unwrap();
    for _ in 0..3 {
        let actions: Vec<Action> = obs.iter().map(|o| o.expert_action).collect();
        obs = venv.step(&actions).unwrap().into_iter().map(|r| r.observation).collect();
    }
    for (k, seed) in seeds.iter().enumerate() {
        let mut env = Env::new(cfg.clone()).unwrap();
        let mut o = env.reset(*seed).unwrap();
        for _ in 0..3 {
            o = env.step(&o.expert_action).unwrap().observation;
        }
        assert_eq!(o, obs[k]);
    }
}

#[test]
fn bad_actions_and_unreset_env_are_errors() {
    let mut env = Env::new(EnvConfig::new(TaskKind::BlockPicking)).unwrap();
    assert!(matches!(env.step(&Action::default()), Err(SimError::NotReset)));
    env.reset(0).unwrap();
    let bad = Action { dx: f32::NAN, ..Action::default() };
    assert!(matches!(env.step(&bad), Err(SimError::Action(_))));
    let inf = Action { dtheta: f32::INFINITY, ..Action::default() };
    assert!(env.step(&inf).is_err());
    // Out-of-range values are clipped, as in the paper: a huge dz moves 5 cm at most.
    let o = env.step(&Action { open_ratio: 7.0, dz: -3.0, ..Action::default() }).unwrap().observation;
    assert!((o.tcp[2] - 0.15).abs() < 1e-5, "tcp z {}", o.tcp[2]);
}

#[test]
fn an_ended_episode_refuses_more_steps_until_reset() {
    let mut cfg = EnvConfig::new(TaskKind::BlockPulling);
    cfg.max_steps = 2;
    let mut env = Env::new(cfg).unwrap();
    env.reset(0).unwrap();
    assert!(!env.step(&Action::default()).unwrap().done);
    let last = env.step(&Action::default()).unwrap();
    assert!(last.done && last.info.timeout);
    // No reward, step count or state change after the end: the caller must reset.
    assert!(matches!(env.step(&Action::default()), Err(SimError::EpisodeOver { steps: 2 })));
    env.reset(1).unwrap();
    assert!(env.step(&Action::default()).is_ok());
}

#[test]
fn random_reflection_mirrors_the_clean_image() {
    let clean = run(&EnvConfig::new(TaskKind::BlockPushing), 2, 5);
    let mut cfg = EnvConfig::new(TaskKind::BlockPushing);
    cfg.corruption = Corruption { random_reflection: true, ..Default::default() };
    let refl = run(&cfg, 2, 5);
    let (w, h) = (clean[0].width, clean[0].height);
    let mut kinds = std::collections::HashSet::new();
    for (c, r) in clean.iter().zip(&refl) {
        let mut found = None;
        for (k, (cols, rows)) in [(false, false), (true, false), (false, true), (true, true)].into_iter().enumerate() {
            let mut img = c.segmentation.clone();
            equiarm_sim::corrupt::reflect(&mut img, 1, w, h, cols, rows);
            if img == r.segmentation {
                found = Some(k);
            }
        }
        kinds.insert(found.expect("a reflected observation is one of the four flips of the clean one"));
    }
    assert!(kinds.len() >= 2, "reflections should vary: {kinds:?}");
}

#[test]
fn occlusion_projection_is_a_height_map_around_the_gripper() {
    let mut cfg = EnvConfig::new(TaskKind::BlockPicking);
    cfg.corruption = Corruption { occlusion_projection: true, ..Default::default() };
    let mut env = Env::new(cfg).unwrap();
    let o = env.reset(4).unwrap();
    let missing = o.depth.iter().filter(|&&v| v == equiarm_sim::corrupt::MISSING).count();
    let zero = o.depth.iter().filter(|&&v| v == 0.0).count();
    // The table is 0.2 m below the gripper at reset; the cube top 0.15 m.
    let table = o.depth.iter().filter(|&&v| (v - 0.2).abs() < 2e-3).count();
    let cube = o.depth.iter().filter(|&&v| (v - 0.15).abs() < 3e-3).count();
    println!("missing {missing} zero {zero} table {table} cube {cube}");
    assert!(zero > 0 && table > o.depth.len() / 4 && cube > 20);
    assert!(o.color.iter().all(|&c| c == 0));
}

#[test]
fn expert_planners_succeed_in_19_of_20_episodes() {
    for task in TaskKind::ALL {
        let mut cfg = EnvConfig::new(task);
        cfg.render = false;
        let mut env = Env::new(cfg).unwrap();
        let mut ok = 0;
        for seed in 1000..1020 {
            ok += env.run_expert_episode(seed).unwrap().info.success as u32;
        }
        println!("{}: {ok}/20", task.name());
        assert!(ok >= 19, "{}: expert succeeded in {ok}/20", task.name());
    }
}

/// The sim steps at 1/120 s; a run at 240 Hz guards that the experts do not depend on the coarse
/// step.
#[test]
fn experts_also_succeed_at_240_hz() {
    for task in [TaskKind::BlockPicking, TaskKind::BlockPushing, TaskKind::BlockInBowl] {
        let mut cfg = EnvConfig::new(task);
        cfg.render = false;
        cfg.params.dt = 1.0 / 240.0;
        cfg.params.substeps *= 2;
        cfg.params.settle_substeps *= 2;
        cfg.params.grip_substeps *= 2;
        cfg.params.reset_settle_substeps *= 2;
        let mut env = Env::new(cfg).unwrap();
        let mut ok = 0;
        for seed in 0..10 {
            ok += env.run_expert_episode(seed).unwrap().info.success as u32;
        }
        println!("{} at 240 Hz: {ok}/10", task.name());
        assert!(ok >= 9, "{} at 240 Hz: {ok}/10", task.name());
    }
}

#[test]
fn holding_flag_follows_the_grasp() {
    let mut cfg = EnvConfig::new(TaskKind::BlockPicking);
    cfg.render = false;
    let mut env = Env::new(cfg).unwrap();
    let mut obs = env.reset(8).unwrap();
    assert!(!obs.holding, "an open gripper in the air holds nothing");
    let mut held_at = None;
    loop {
        let r = env.step(&obs.expert_action).unwrap();
        obs = r.observation;
        if obs.holding && held_at.is_none() {
            held_at = Some(obs.step);
            assert!(obs.open_ratio < 0.8 && obs.open_ratio > 0.5, "jaw around a 5 cm cube: {}", obs.open_ratio);
        }
        if r.done {
            assert!(r.info.success);
            break;
        }
    }
    assert!(held_at.is_some(), "the expert grasped the cube");
    // The same episode again, up to the step before it succeeded (the cube lifted and held; an ended
    // episode refuses more steps): opening the jaw there drops the cube.
    let last = obs.step;
    let mut obs = env.reset(8).unwrap();
    while obs.step + 1 < last {
        let r = env.step(&obs.expert_action).unwrap();
        assert!(!r.done, "the replayed episode ended early");
        obs = r.observation;
    }
    assert!(obs.holding, "the cube is held the step before success");
    let r = env.step(&Action { open_ratio: 1.0, ..Action::default() }).unwrap();
    let o = if r.done {
        r.observation
    } else {
        env.step(&Action { open_ratio: 1.0, ..Action::default() }).map(|r| r.observation).unwrap_or(r.observation)
    };
    assert!(!o.holding, "still holding after the jaw opened");
}

/// BulletArm's floor (pybullet's `plane.urdf`) has 1 m tiles: in the default oblique view of the
/// workspace, a row through the middle of the image crosses one tile edge, at the centre column
/// (world y = 0), light blue on the left (y < 0) and white on the right. Pybullet's TinyRenderer gives
/// (162, 186, 224) and (239, 239, 239) there at 152 px, with the edge at column 76.
#[test]
fn floor_is_bulletarm_plane_one_metre_tiles() {
    let mut env = Env::new(EnvConfig::new(TaskKind::BlockPulling)).unwrap();
    let o = env.reset(5).unwrap();
    let n = o.width;
    let table = env.segmentation_names().iter().position(|s| s == "table").unwrap() as u16;
    let row = n / 2;
    let px = |c: usize| {
        let i = row * n + c;
        (o.segmentation[i] == table).then(|| [o.color[i * 3], o.color[i * 3 + 1], o.color[i * 3 + 2]])
    };
    let (left, right) = (px(4).unwrap(), px(n - 5).unwrap());
    let near = |a: [u8; 3], b: [u8; 3]| a.iter().zip(b).all(|(x, y)| (*x as i32 - y as i32).abs() <= 12);
    assert!(near(left, [162, 186, 224]), "left of the y = 0 edge {left:?}");
    assert!(near(right, [239, 239, 239]), "right of the y = 0 edge {right:?}");
    let floor: Vec<(usize, [u8; 3])> = (0..n).filter_map(|c| px(c).map(|p| (c, p))).collect();
    let edges: Vec<usize> = floor.windows(2).filter(|w| w[0].1 != w[1].1).map(|w| w[1].0).collect();
    assert_eq!(edges.len(), 1, "one tile edge on the middle row, found at columns {edges:?}");
    assert!(edges[0].abs_diff(n / 2) <= 1, "the edge is at column {} of {n}", edges[0]);
}

#[test]
fn gripper_only_scene_has_a_plain_floor() {
    let floor_colours = |gripper_only: bool| {
        let mut cfg = EnvConfig::new(TaskKind::BlockPicking);
        cfg.corruption.gripper_only = gripper_only;
        let mut env = Env::new(cfg).unwrap();
        let o = env.reset(0).unwrap();
        let table = env.segmentation_names().iter().position(|n| n == "table").unwrap() as u16;
        let mut colours = std::collections::HashSet::new();
        for (i, s) in o.segmentation.iter().enumerate() {
            if *s == table {
                colours.insert([o.color[i * 3], o.color[i * 3 + 1], o.color[i * 3 + 2]]);
            }
        }
        colours.len()
    };
    assert_eq!(floor_colours(false), 2, "default: two checker colours (flat shading)");
    assert_eq!(floor_colours(true), 1, "gripper-only: one plain colour");
}

/// Issue 58: the arm is drawn only. With it and without it the episode is the same (the same
/// gripper, objects and segmentation ids), and the frames differ exactly where the arm is seen; it
/// covers part of the image (the paper's top rows) and is gone in the gripper-only scene.
#[test]
fn the_arm_changes_the_frames_only_where_it_is_seen() {
    use equiarm_sim::env::ArmView;
    for task in [TaskKind::BlockPulling, TaskKind::BlockPicking] {
        let scene = |arm: ArmView, gripper_only: bool| {
            let mut cfg = EnvConfig::new(task);
            cfg.arm = arm;
            cfg.corruption.gripper_only = gripper_only;
            let mut env = Env::new(cfg.clone()).unwrap();
            env.reset(3).unwrap();
            (run(&cfg, 3, 12), env.segmentation_names().to_vec())
        };
        let (with, names) = scene(ArmView::Visible, false);
        let (without, names_without) = scene(ArmView::Hidden, false);
        assert_eq!(names[..names_without.len()], names_without[..], "{task}: the other ids are unchanged");
        assert!(names[names_without.len()..].iter().all(|n| n.starts_with("arm/")), "{names:?}");
        assert_eq!(with.len(), without.len(), "{task}: the same episode");
        let mut arm_pixels = 0;
        for (a, b) in with.iter().zip(&without) {
            assert_eq!((a.tcp, a.holding, a.expert_action), (b.tcp, b.holding, b.expert_action), "{task}");
            for i in 0..a.segmentation.len() {
                let is_arm = names[a.segmentation[i] as usize].starts_with("arm/");
                arm_pixels += is_arm as usize;
                let same = a.segmentation[i] == b.segmentation[i]
                    && a.depth[i] == b.depth[i]
                    && a.color[i * 3..i * 3 + 3] == b.color[i * 3..i * 3 + 3];
                assert!(is_arm || same, "{task} step {}: pixel {i} differs outside the arm", a.step);
            }
        }
        let share = arm_pixels as f64 / (with.len() * with[0].segmentation.len()) as f64;
        assert!(share > 0.01 && share < 0.5, "{task}: the arm covers {share} of the frames");
        let (gripper_only, names) = scene(ArmView::Visible, true);
        assert!(!names.iter().any(|n| n.starts_with("arm/")), "{task}: no arm in the gripper-only scene");
        assert_eq!(gripper_only.len(), without.len());
    }
}

#[test]
fn config_round_trips_through_json_and_rejects_unknown_keys() {
    let mut cfg = EnvConfig::new(TaskKind::DrawerOpening);
    cfg.camera = equiarm_sim::ViewPreset::Angle30.into();
    cfg.corruption.random_reflection = true;
    let text = serde_json::to_string(&cfg).unwrap();
    let back: EnvConfig = serde_json::from_str(&text).unwrap();
    assert_eq!(back, cfg);
    let partial: EnvConfig = serde_json::from_str(r#"{"task": "block_in_bowl", "params": {"substeps": 30}}"#).unwrap();
    assert_eq!(partial.task, TaskKind::BlockInBowl);
    assert_eq!(partial.params.substeps, 30);
    assert_eq!(partial.params.dt, equiarm_sim::SimParams::default().dt);
    let err = serde_json::from_str::<EnvConfig>(r#"{"task": "block_picking", "params": {"substep": 3}}"#).unwrap_err();
    assert!(err.to_string().contains("substep"), "{err}");
}

/// Dynamic bodies heavier than the fingers (the task's objects), as (x, y, z).
fn objects(env: &Env) -> Vec<[f32; 3]> {
    let scene = env.scene().unwrap();
    scene
        .physics
        .bodies
        .iter()
        .filter(|(_, b)| b.is_dynamic() && b.mass() > 0.3)
        .map(|(_, b)| {
            let t = b.translation();
            [t.x, t.y, t.z]
        })
        .collect()
}

#[test]
fn descending_onto_a_block_stops_on_top_and_leaves_it_in_place() {
    // The palm is kinematic: pressed down onto a flat block (5 cm tall) it used to push the
    // block into the table until the solver shot it sideways, often out of the workspace.
    let mut cfg = EnvConfig::new(TaskKind::BlockPulling);
    cfg.render = false;
    let mut env = Env::new(cfg).unwrap();
    for seed in 0..3 {
        let mut o = env.reset(seed).unwrap();
        let block = objects(&env)[0];
        // Above the block centre, jaw half open (its 3.75 cm gap is narrower than the block).
        for _ in 0..8 {
            let a = Action::new(0.5, block[0] - o.tcp[0], block[1] - o.tcp[1], 0.0, 0.0);
            o = env.step(&a).unwrap().observation;
        }
        let mut r = None;
        for _ in 0..6 {
            let s = env.step(&Action::new(0.5, 0.0, 0.0, -0.05, 0.0)).unwrap();
            assert!(!s.info.invalid, "seed {seed}: the block left the workspace");
            r = Some(s);
        }
        let o = r.unwrap().observation;
        let after = objects(&env)[0];
        let moved = ((after[0] - block[0]).powi(2) + (after[1] - block[1]).powi(2)).sqrt();
        assert!(moved < 0.01, "seed {seed}: block moved {moved} m: {block:?} -> {after:?}");
        assert!((after[2] - block[2]).abs() < 0.003, "seed {seed}: block height {} -> {}", block[2], after[2]);
        // The finger bottoms (1 cm below the TCP) rest on the block's top face (z = 0.05), not
        // at the floor clamp (TCP z 0.01).
        let bottoms = o.tcp[2] - 0.01;
        assert!((0.047..0.055).contains(&bottoms), "seed {seed}: finger bottoms at z {bottoms}");
    }
}
