//! The five close-loop tasks (docs/paper.md §3.3) and the facts the paper gives per task.

crate::named_enum! {
    /// A manipulation task. Named `block_pulling` … `block_in_bowl`; BulletArm's environment names
    /// (`close_loop_block_pulling`, …) are accepted as aliases.
    pub enum TaskKind: "task" {
        /// Pull one flat block into the other: success when the two blocks are within 2 mm of each other.
        BlockPulling = "block_pulling" | "close_loop_block_pulling",
        /// Push the cube onto the goal square: success when their centres are closer than 0.05 m in xy.
        BlockPushing = "block_pushing" | "close_loop_block_pushing",
        /// Pick the cube up: success when it is held and the TCP is higher than 0.15 m.
        BlockPicking = "block_picking" | "close_loop_block_picking",
        /// Open the drawer: success when it is pulled out of the cabinet by more than 0.15 m.
        DrawerOpening = "drawer_opening" | "close_loop_drawer_opening",
        /// Put the cube into the bowl: success when the cube touches the bowl within 0.03 m of its
        /// centre in xy and the bowl is tilted less than 20°.
        BlockInBowl = "block_in_bowl" | "close_loop_block_in_bowl",
    }
}

/// The paper's episode step limit, the same for every task (docs/paper.md §3.3).
pub const PAPER_EPISODE_STEPS: u32 = 50;

impl TaskKind {
    /// The tasks a command-line word names: `all` is every task, any other word the one task it
    /// names; an unknown word is an error that lists the names.
    pub fn select(word: &str) -> Result<Vec<Self>, crate::ParseError> {
        if word.trim() == "all" {
            return Ok(Self::ALL.to_vec());
        }
        match Self::from_name(word.trim()) {
            Some(t) => Ok(vec![t]),
            None => Err(crate::ParseError::unknown("task", word, format!("{} or all", Self::names()))),
        }
    }

    /// BulletArm's name of the task's environment (`close_loop_block_pulling`, …).
    pub fn bulletarm_name(self) -> String {
        format!("close_loop_{}", self.name())
    }

    /// Successful expert episodes the paper preloads into the replay (docs/paper.md §2).
    pub fn paper_demos(self) -> usize {
        match self {
            TaskKind::BlockPulling | TaskKind::BlockPushing => 20,
            TaskKind::BlockPicking | TaskKind::DrawerOpening => 50,
            TaskKind::BlockInBowl => 100,
        }
    }

    /// Gradient updates the paper trains for (docs/paper.md §2).
    pub fn paper_updates(self) -> u64 {
        match self {
            TaskKind::BlockInBowl => 10_000,
            _ => 5_000,
        }
    }

    /// The paper's episode step limit ([`PAPER_EPISODE_STEPS`] for every task).
    pub fn paper_episode_steps(self) -> u32 {
        PAPER_EPISODE_STEPS
    }

    /// Objects the task places besides the gripper (BulletArm's `num_objects`): two blocks for
    /// pulling, the cube for pushing and picking, the drawer's cabinet for opening, the cube and the
    /// bowl for block in bowl.
    pub fn object_count(self) -> usize {
        match self {
            TaskKind::BlockPulling | TaskKind::BlockInBowl => 2,
            TaskKind::BlockPushing | TaskKind::BlockPicking | TaskKind::DrawerOpening => 1,
        }
    }
}
