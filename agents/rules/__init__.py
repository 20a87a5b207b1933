"""The heuristic maintenance rules (:mod:`.line`; the base class and the random baseline in :mod:`.base`), the rules
that use every choice of a track manager (:mod:`.choices`), the network's wrapper of them (:mod:`.network`), the
model-predictive planner of a line measured every step (:mod:`.model_predictive`, no member of the tuned family), and
their tuned parameters per preset, shipped beside them (:mod:`.problems`: ``line_tuned_heuristics.json`` for the
default line, ``track60_tuned_heuristics.json`` for the 60 m track)."""

from .base import Heuristic, RandomPolicy, as_batch
from .choices import CHOICE_RULES, ChoiceThreshold, ChoiceThresholdNoLooking, ChoiceThresholdSpotOnly
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
from .model_predictive import ModelPredictive
from .network import NetworkRule
from .problems import TUNED_FILES, rules_for, tuned_params_for, tuned_rule

__all__ = [
    "Heuristic", "RandomPolicy", "as_batch",
    "CHOICE_RULES", "ChoiceThreshold", "ChoiceThresholdNoLooking", "ChoiceThresholdSpotOnly",
    "LINE_HEURISTICS", "LINE_TUNED_FILE", "BudgetedWorstFirst", "GroupedThreshold", "LineNoMaintenance",
    "RegisterPeriodic", "SectionThreshold", "UniformPeriodic", "line_tuned_params", "planner_view",
    "stale_measurement",
    "ModelPredictive", "NetworkRule", "TUNED_FILES", "rules_for", "tuned_params_for", "tuned_rule",
]
