//! The checks of a [`TrainConfig`] that need the simulator: the task and camera names and the
//! episode step limit. [`check`] is [`TrainConfig::validate`] (the learner's fields) plus these;
//! everything that runs a config (the in-process loop, the nodes, the command line) calls it.

use equiarm_sac::config::{ConfigError, TrainConfig};
use equiarm_sim::env::Corruption;
use equiarm_sim::{TaskKind, ViewPreset};

/// Largest episode step limit accepted (the paper: 50): the simulator's.
pub const MAX_EPISODE_STEPS: u32 = equiarm_sim::env::MAX_EPISODE_STEPS;

/// Check every field of `cfg`; the error names the field and the fix.
pub fn check(cfg: &TrainConfig) -> Result<(), ConfigError> {
    let err = |field: &'static str, message: String| Err(ConfigError { field, message });
    if TaskKind::from_name(&cfg.task).is_none() {
        let names: Vec<&str> = TaskKind::ALL.iter().map(|t| t.name()).collect();
        return err("task", format!("unknown task `{}`: use {}", cfg.task, names.join(", ")));
    }
    if ViewPreset::from_name(&cfg.view).is_none() {
        return err("view", format!("unknown camera preset `{}` (e.g. side, angle15 … angle90)", cfg.view));
    }
    if let Err(e) = Corruption::parse(&cfg.corruption) {
        let message = match e {
            equiarm_sim::SimError::Config { message, .. } => message,
            other => other.to_string(),
        };
        return err("corruption", message);
    }
    if cfg.max_episode_steps > MAX_EPISODE_STEPS {
        return err(
            "max_episode_steps",
            format!("{} is above {MAX_EPISODE_STEPS} (the paper's limit is 50)", cfg.max_episode_steps),
        );
    }
    cfg.validate()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_preset_of_every_task_passes() {
        for task in TaskKind::ALL {
            for p in equiarm_sac::config::Preset::ALL {
                check(&TrainConfig::preset(p, task.name())).unwrap();
            }
        }
    }

    #[test]
    fn simulator_names_and_limits_are_checked_naming_the_field() {
        let c = TrainConfig::reduced("block_pullin");
        let e = check(&c).unwrap_err();
        assert_eq!(e.field, "task");
        assert!(e.message.contains("block_pulling") && e.message.contains("block_in_bowl"), "{e}");
        let c = TrainConfig { view: "sideways".into(), ..TrainConfig::reduced("block_pulling") };
        assert_eq!(check(&c).unwrap_err().field, "view");
        let c = TrainConfig { corruption: "random_reflection,mirror".into(), ..TrainConfig::reduced("block_pulling") };
        let e = check(&c).unwrap_err();
        assert_eq!(e.field, "corruption");
        assert!(e.message.contains("`mirror`"), "{}", e.message);
        let c = TrainConfig { max_episode_steps: u32::MAX, ..TrainConfig::reduced("block_pulling") };
        let e = check(&c).unwrap_err();
        assert_eq!(e.field, "max_episode_steps");
        assert!(e.message.contains("above"), "{e}");
        // The learner's own fields are checked too.
        let mut c = TrainConfig::reduced("block_pulling");
        c.agent.input_size = 60;
        assert_eq!(check(&c).unwrap_err().field, "agent.input_size");
    }
}
