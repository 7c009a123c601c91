//! `equiarm sim`'s options: flags override the env config, and a bad task, view or corruption is
//! refused by the parser naming the value and the choices.

use clap::Parser;
use equiarm_nodes::sim::{SimArgs, env_config};
use equiarm_types::TaskKind;

#[derive(Parser)]
struct Cli {
    #[command(flatten)]
    args: SimArgs,
}

fn parse(a: &[&str]) -> Result<SimArgs, clap::Error> {
    Cli::try_parse_from(std::iter::once("sim").chain(a.iter().copied())).map(|c| c.args)
}

fn args(a: &[&str]) -> SimArgs {
    parse(a).unwrap()
}

#[test]
fn flags_override_the_preset_and_bad_names_list_the_choices() {
    let cfg = env_config(&args(&["--task", "drawer_opening", "--view", "angle30", "--resolution", "96"])).unwrap();
    assert_eq!(cfg.task, TaskKind::DrawerOpening);
    assert_eq!((cfg.camera.elevation_deg, cfg.camera.width, cfg.camera.height), (30.0, 96, 96));
    let e = parse(&["--task", "stacking"]).unwrap_err().to_string();
    assert!(e.contains("'stacking'") && e.contains("block_in_bowl"), "{e}");
    let e = parse(&["--view", "top"]).unwrap_err().to_string();
    assert!(e.contains("angle90"), "{e}");
}

#[test]
fn corrupt_sets_the_corruptions_and_a_bad_name_is_named() {
    assert_eq!(env_config(&args(&[])).unwrap().corruption, Default::default());
    let c = env_config(&args(&["--corrupt", "random_reflection,gripper_only"])).unwrap().corruption;
    assert!(c.random_reflection && c.gripper_only && !c.occlusion_projection, "{c:?}");
    assert_eq!(env_config(&args(&["--corrupt", "none"])).unwrap().corruption, Default::default());
    let e = parse(&["--corrupt", "mirror"]).unwrap_err().to_string();
    assert!(e.contains("--corrupt") && e.contains("`mirror`") && e.contains("random_reflection"), "{e}");
}
