"""Scoring policies: the harness (:mod:`.harness`: episodes on the native vector envs), its statistics
(:mod:`.statistics`), grid tuning of the rules (:mod:`.tuning`), the comparison of policies on any preset
(:mod:`.line_compare`), figures (:mod:`.reporting`), the per-section
hindsight bound of the line (:mod:`.line_hindsight`), the leaderboard over the suite (:mod:`.leaderboard`) and the
Ray executor (:mod:`.distributed`)."""

from .distributed import RayExecutor
from .harness import (
    TEST_SEEDS,
    TRAIN_SEEDS,
    EvaluationResult,
    bind_policy,
    evaluate_many,
    evaluate_one,
    evaluate_policy,  # noqa: F401  (the deprecated name of evaluate_one, kept where it was)
    policy_name,
    policy_params,
    record_episode,
    run_episodes,
)
from .leaderboard import (
    DEFAULT_SEEDS,
    DEFAULT_SUITE,
    bound_unavailable,
    episode_bounds,
    format_leaderboard,
    normalised_score,
    run_leaderboard,
)
from .line_compare import (
    SECTION_CLASSES,
    class_breakdown,
    env_config,
    format_line_table,
    line_comparison,
    parse_seeds,
    plot_line_episode,
    run_calibration,
    scenario_of,
)
from .line_hindsight import (
    RECORDING_DESIGNS,
    TrueStateRule,
    hindsight_bound,
    hindsight_bounds,
    recorded_rule_schedules,
    replay,
    replay_schedules,
    replay_sections,
    room_summary,
    saved_schedules,
    schedule_from_rows,
    schedule_rows,
)
from .reporting import plot_comparison
from .statistics import N_BOOTSTRAP, bootstrap_ci, paired_difference
from .tuning import tune, tune_many

__all__ = [
    # the harness (.harness) and its statistics (.statistics)
    "TEST_SEEDS", "TRAIN_SEEDS", "EvaluationResult", "bind_policy", "evaluate_many", "evaluate_one", "policy_name",
    "policy_params", "record_episode", "run_episodes", "N_BOOTSTRAP", "bootstrap_ci", "paired_difference",
    # tuning, reports, the executor
    "tune", "tune_many", "plot_comparison", "RayExecutor",
    # the comparison of policies on a preset (.line_compare)
    "SECTION_CLASSES", "class_breakdown", "format_line_table",
    "line_comparison", "parse_seeds", "plot_line_episode", "run_calibration", "env_config",
    "scenario_of",
    # the line's hindsight bound (.line_hindsight)
    "RECORDING_DESIGNS", "TrueStateRule", "hindsight_bound", "hindsight_bounds", "recorded_rule_schedules",
    "replay", "replay_schedules", "replay_sections", "room_summary", "saved_schedules", "schedule_from_rows",
    "schedule_rows",
    # the leaderboard (.leaderboard)
    "DEFAULT_SEEDS", "DEFAULT_SUITE", "bound_unavailable", "episode_bounds", "format_leaderboard",
    "normalised_score", "run_leaderboard",
]
