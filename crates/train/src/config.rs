//! The checks of a [`TrainConfig`] that need the simulator: the episode step limit. [`check`] is
//! [`TrainConfig::validate`] (the learner's fields) plus these; everything that runs a config (the
//! in-process loop, the nodes, the command line) calls it. The task, camera and corruption are
//! typed (`equiarm_types`): a name that is none of them is refused when the config is read.

use equiarm_sac::config::{ConfigError, TrainConfig};

/// Largest episode step limit accepted (the paper: 50): the simulator's.
pub const MAX_EPISODE_STEPS: u32 = equiarm_sim::env::MAX_EPISODE_STEPS;

/// Check every field of `cfg`; the error names the field and the fix.
pub fn check(cfg: &TrainConfig) -> Result<(), ConfigError> {
    let err = |field: &'static str, message: String| Err(ConfigError { field, message });
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
    use equiarm_types::TaskKind;

    #[test]
    fn every_preset_of_every_task_passes() {
        for task in TaskKind::ALL {
            for p in equiarm_sac::config::Preset::ALL {
                check(&TrainConfig::preset(p, task)).unwrap();
            }
        }
    }

    #[test]
    fn simulator_names_and_limits_are_checked_naming_the_field() {
        // Names are types: a config naming no task, view or corruption is not read at all.
        for (field, json, named) in [
            ("task", r#"{"task": "block_pullin"}"#, "block_in_bowl"),
            ("view", r#"{"view": "sideways"}"#, "angle90"),
            ("corruption", r#"{"corruption": "random_reflection,mirror"}"#, "`mirror`"),
        ] {
            let e = serde_json::from_str::<TrainConfig>(json).unwrap_err().to_string();
            assert!(e.contains(named) && e.contains(field), "{field}: {e}");
        }
        let c = TrainConfig { max_episode_steps: u32::MAX, ..TrainConfig::reduced(TaskKind::BlockPulling) };
        let e = check(&c).unwrap_err();
        assert_eq!(e.field, "max_episode_steps");
        assert!(e.message.contains("above"), "{e}");
        // The learner's own fields are checked too.
        let mut c = TrainConfig::reduced(TaskKind::BlockPulling);
        c.agent.input_size = 60;
        assert_eq!(check(&c).unwrap_err().field, "agent.input_size");
    }
}
