"""The heuristic maintenance rules: :mod:`.tamping` for Tamping-v0 (the 60 m track), :mod:`.line` for TampingLine;
their tuned parameters ship beside them (``tuned_heuristics.json``, ``line_tuned_heuristics.json``)."""

from .line import (
    LINE_HEURISTICS,
    LINE_TUNED_FILE,
    BudgetedWorstFirst,
    GroupedThreshold,
    LineNoMaintenance,
    RegisterPeriodic,
    SectionThreshold,
    UniformPeriodic,
    line_tuned_params,
    planner_view,
    stale_measurement,
)
from .problems import rules_for, tuned_params_for
from .tamping import (
    HEURISTICS,
    TUNED_PARAMS_FILE,
    Campaign,
    DefectThreshold,
    Heuristic,
    NoMaintenance,
    Periodic,
    RandomPolicy,
    SDThreshold,
    WorstFirst,
    make_policy,
    tuned_params,
)

__all__ = [
    # Tamping-v0 (.tamping)
    "HEURISTICS", "TUNED_PARAMS_FILE", "Campaign", "DefectThreshold", "Heuristic", "NoMaintenance", "Periodic",
    "RandomPolicy", "SDThreshold", "WorstFirst", "make_policy", "tuned_params",
    # TampingLine (.line)
    "LINE_HEURISTICS", "LINE_TUNED_FILE", "BudgetedWorstFirst", "GroupedThreshold", "LineNoMaintenance",
    "RegisterPeriodic", "SectionThreshold", "UniformPeriodic", "line_tuned_params", "planner_view",
    "stale_measurement",
    # either problem, by its config
    "rules_for", "tuned_params_for",
]
