//! Each domain word has one spelling: Display, FromStr, serde and clap agree on it for every value,
//! aliases parse, unknown words are refused with the list of names, and the stored forms of earlier
//! configs still load.

use clap::ValueEnum;
use equiarm_types::{
    Action, Augmentation, AugmentationKind, Corruption, CorruptionKind, ModelKind, ParseError, TaskKind, ViewPreset,
};

/// Display, FromStr, serde and clap give and take the same name for every value of `T`.
fn one_spelling<T>(all: &[T], names: &str)
where
    T: Copy + PartialEq + std::fmt::Debug + std::fmt::Display + std::str::FromStr<Err = ParseError>,
    T: serde::Serialize + serde::de::DeserializeOwned + ValueEnum,
{
    let mut listed = Vec::new();
    for &v in all {
        let name = v.to_string();
        assert_eq!(name.parse::<T>().unwrap(), v);
        assert_eq!(serde_json::to_string(&v).unwrap(), format!("\"{name}\""));
        assert_eq!(serde_json::from_str::<T>(&format!("\"{name}\"")).unwrap(), v);
        assert_eq!(v.to_possible_value().unwrap().get_name(), name);
        assert_eq!(<T as ValueEnum>::from_str(&name, false).unwrap(), v, "clap parses {name}");
        listed.push(name);
    }
    assert_eq!(listed.join(", "), names);
    let err = "no_such_word".parse::<T>().unwrap_err().to_string();
    assert!(err.contains("no_such_word") && err.contains(names), "{err}");
    assert!(serde_json::from_str::<T>("\"no_such_word\"").unwrap_err().to_string().contains(names));
}

#[test]
fn every_named_value_has_one_spelling() {
    one_spelling(&TaskKind::ALL, &TaskKind::names());
    one_spelling(&ViewPreset::ALL, &ViewPreset::names());
    one_spelling(&ModelKind::ALL, &ModelKind::names());
    one_spelling(&CorruptionKind::ALL, &CorruptionKind::names());
    one_spelling(&AugmentationKind::ALL, &AugmentationKind::names());
    assert_eq!(TaskKind::names(), "block_pulling, block_pushing, block_picking, drawer_opening, block_in_bowl");
    assert_eq!(ModelKind::names(), "equi, cnn, sen, ferm");
}

#[test]
fn aliases_parse_to_the_same_value() {
    assert_eq!("close_loop_block_in_bowl".parse::<TaskKind>().unwrap(), TaskKind::BlockInBowl);
    assert_eq!(TaskKind::BlockInBowl.bulletarm_name(), "close_loop_block_in_bowl");
    assert_eq!("equi_d4".parse::<ModelKind>().unwrap(), ModelKind::Equi);
    assert_eq!(<ModelKind as ValueEnum>::from_str("equi_d4", false).unwrap(), ModelKind::Equi);
    assert_eq!(TaskKind::select("all").unwrap(), TaskKind::ALL.to_vec());
    assert!(TaskKind::select("pulling").unwrap_err().to_string().ends_with("block_in_bowl or all"));
}

#[test]
fn per_task_facts_are_the_papers() {
    let demos: Vec<usize> = TaskKind::ALL.iter().map(|t| t.paper_demos()).collect();
    assert_eq!(demos, [20, 20, 50, 50, 100]);
    let updates: Vec<u64> = TaskKind::ALL.iter().map(|t| t.paper_updates()).collect();
    assert_eq!(updates, [5000, 5000, 5000, 5000, 10_000]);
    assert!(TaskKind::ALL.iter().all(|t| t.paper_episode_steps() == 50));
}

#[test]
fn corruption_sets_read_in_any_order_and_write_one_way() {
    let c: Corruption = "gripper_only, random_reflection".parse().unwrap();
    assert_eq!(c, Corruption::of(&[CorruptionKind::RandomReflection, CorruptionKind::GripperOnly]));
    assert_eq!(c.to_string(), "random_reflection,gripper_only");
    assert_eq!("none".parse::<Corruption>().unwrap(), Corruption::NONE);
    assert_eq!(Corruption::NONE.to_string(), "none");
    for k in CorruptionKind::ALL {
        let one = Corruption::of(&[k]);
        assert_eq!(one.to_string().parse::<Corruption>().unwrap(), one);
        assert_eq!(one.kinds(), vec![k]);
    }
    let err = "random_reflect".parse::<Corruption>().unwrap_err().to_string();
    assert!(err.contains("random_reflect") && err.contains("gripper_only"), "{err}");
    let err = "gripper_only,gripper_only".parse::<Corruption>().unwrap_err().to_string();
    assert!(err.contains("named twice"), "{err}");
    // serde: the text form, and the map of flags that env configs held before it.
    assert_eq!(serde_json::to_string(&c).unwrap(), "\"random_reflection,gripper_only\"");
    assert_eq!(serde_json::from_str::<Corruption>("\"random_reflection,gripper_only\"").unwrap(), c);
    let flags = r#"{"random_reflection": true, "gripper_only": true}"#;
    assert_eq!(serde_json::from_str::<Corruption>(flags).unwrap(), c);
    assert!(serde_json::from_str::<Corruption>(r#"{"random_reflect": true}"#).is_err());
}

#[test]
fn augmentations_keep_their_config_form() {
    for (a, json) in [
        (Augmentation::Rad, "\"rad\""),
        (Augmentation::Center, "\"center\""),
        (Augmentation::PAPER_DRQ, r#"{"drq":{"k":2,"m":2}}"#),
    ] {
        assert_eq!(serde_json::to_string(&a).unwrap(), json);
        assert_eq!(serde_json::from_str::<Augmentation>(json).unwrap(), a);
        assert_eq!(Augmentation::from(a.kind()), a);
    }
}

#[test]
fn actions_normalise_both_ways() {
    let a = Action::new(1.0, 0.05, -0.025, 0.0, std::f32::consts::FRAC_PI_8);
    let u = a.to_normalized();
    assert_eq!(u, [1.0, 1.0, -0.5, 0.0, 0.5]);
    assert_eq!(Action::from_normalized(u), a);
    assert_eq!(Action::from_normalized([2.0, -3.0, 0.0, 0.0, 0.0]), Action::new(1.0, -0.05, 0.0, 0.0, 0.0));
    assert!(!Action::new(f32::NAN, 0.0, 0.0, 0.0, 0.0).is_finite());
}

#[test]
fn a_huge_unknown_word_makes_a_short_message() {
    let word = "x".repeat(1_000_000);
    let err = word.parse::<TaskKind>().unwrap_err().to_string();
    assert!(err.len() < 400, "{} bytes", err.len());
}
