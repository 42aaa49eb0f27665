"""The sets of "Beyond the paper": the variants of each question, the folders of results/beyond that hold them,
the command task's set and seeds, the condition-dropout sets; read by every module of the report."""

BASELINES = ("ppo", "pgg_g1.1")


# The behaviour-cloned nulls of the tables' agents (pgg_utils/bc_null.py, results/beyond/bc_null/run.sh): their
# folder, and the suffix that keys a fitted null's cells beside the same agents' own null in `means`.
BC_FOLDER, BC = "bc_null", " null=bc"


# The sets of the variant that clones the rollout's actions while it trains (results/beyond/bc_train/<task>).
BC_TRAIN_FOLDER = "bc_train"


# The ids of paper.BEYOND_VARIANTS by family (those with --null-bc-coef, {goal}, --guidance-schedule), as
# reproduce.grid_variants names them; tests/test_reproduce.py checks them against it.
CLONING_VARIANTS = {"pgg_g1.1_bc0.1"}


GOAL_VARIANTS = {"pgg_g1.1_goal"}


SCHEDULE_VARIANTS = {"pgg_g1to1.2", "pgg_adaptive1.1_kl0.04"}


# The command task's set (results/beyond/command/run_all.sh): its folder, its variants in the report's order with
# the null branch each is guided by, and its seeds. Its sweeps are read apart from the tasks' folders: its tests
# are a family of their own and never enter the other questions' Holm families.
COMMAND_FOLDER = "command"


COMMAND_VARIANTS = {"pgg_g1.1_null17": "command null", "pgg_g1.1": "state null", "ppo": "untrained null"}


COMMAND_NULL = "pgg_g1.1_null17"


COMMAND_SEEDS = 5


COMMAND_ENV = "paper_study.cheetah_velocity:HalfCheetahVelocity-v0"


# The sets that drop the condition (goal or command) in training, classifier-free guidance's recipe
# (results/beyond/condition_dropout/run_all.sh): their folder, and their variants with the set each is compared with.
DROPOUT_FOLDER = "condition_dropout"


DROPOUT_VARIANTS = {"pgg_drop0.1_goal": "Reacher-v4", "pgg_drop0.1_null17": "command"}


# Every variant of paper.BEYOND_VARIANTS: those the report compares with BASELINES.
BEYOND_VARIANT_IDS = SCHEDULE_VARIANTS | GOAL_VARIANTS | CLONING_VARIANTS | {COMMAND_NULL} | set(DROPOUT_VARIANTS)


SETS_APART = (BC_FOLDER, COMMAND_FOLDER, DROPOUT_FOLDER)  # folders of results/beyond that are not a task's


COLLAPSE_FRACTION = 0.5


GOAL_ENV = "Reacher-v4"


COMMAND_DROPOUT = next(v for v, folder in DROPOUT_VARIANTS.items() if folder == COMMAND_FOLDER)


GOAL_DROPOUT = next(v for v, folder in DROPOUT_VARIANTS.items() if folder == GOAL_ENV)


# Each task's variants in the tables' order, with the null each is guided by.
COMMAND_SET = {COMMAND_DROPOUT: "command dropped", COMMAND_NULL: "command null", "pgg_g1.1": "state null",
               "ppo": "untrained null"}  # fmt: skip


GOAL_SET = {GOAL_DROPOUT: "goal dropped", "pgg_g1.1_goal": "goal null", "pgg_g1.1": "state null",
            "ppo": "untrained null"}  # fmt: skip
