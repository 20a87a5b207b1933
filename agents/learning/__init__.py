"""The learners: PPO on the 60 m track, Tamping-v1 (:mod:`.tamping`), the per-section policy of TampingLine
(:mod:`.line_policy`)
trained by counterfactual policy iteration (:mod:`.line`, :mod:`.line_counterfactual`), imitation of the rules
(:mod:`.imitation`), stable-baselines3's view of the native vector envs (:mod:`.sb3_vec`), the action
parameterisations (:mod:`.actions`), the training settings (:mod:`.settings`) and the checkpoints a killed run
resumes from (:mod:`.checkpoint`). The hyper-parameters (``hyperparams/ppo.yml``) and the shipped models
(``pretrained/``) live beside them.

The names below load on first use: most of these modules import stable-baselines3 and torch, which take
seconds to import and are an optional extra (``trackenv[rl]``), so importing this package imports neither.
"""

from __future__ import annotations

import importlib
from typing import Any

#: public name -> the module of this package that defines it
_EXPORTS: dict[str, str] = {
    **dict.fromkeys(["ACTION_TYPES", "RANKED", "RANKED_CHOICES", "VEC_ACTION_TYPES", "agent_action_space",
                     "check_action_type", "env_action_type", "ranked_to_choices", "ranked_to_sections"], "actions"),
    **dict.fromkeys(["ADVISOR_FEATURES", "CHOICE_FEATURES", "FEATURES", "FEATURE_CLIP", "FRESH_SD_MM",
                     "LEARNABLE_CHOICES", "LineAgent", "choice_open", "compose_choices", "is_choice_rule", "may_tamp",
                     "n_features", "remember_work", "section_features", "tamping_codes"], "line_policy"),
    **dict.fromkeys(["flipped_choices", "line_forks", "marginal_possession", "section_counterfactuals"],
                    "line_counterfactual"),
    **dict.fromkeys(["SectionAgentsVecEnv", "TampingSB3VecEnv", "VecScaleReward", "make_vec_env", "observation_keys",
                     "filter_observation"], "sb3_vec"),
    **dict.fromkeys(["teacher_policy", "teacher_to_agent_actions", "collect_demonstrations", "return_scale",
                     "fit_policy", "fit_choices", "warm_start"], "imitation"),
    **dict.fromkeys(["DEFAULT_ENV_ID", "DEFAULT_EVAL_SEEDS", "DEFAULT_HYPERPARAMS", "DEFAULT_PRETRAINED",
                     "DEFAULT_TRAIN_SEED", "NormalizedPolicy", "ZooSchema", "export_policy", "from_zoo",
                     "load_hyperparams", "load_trained", "make_progress_callback", "single_torch_thread",
                     "stats_path", "train"], "tamping"),
    **dict.fromkeys(["AlgoSettings", "LineSettings", "TampingSettings", "TrainingSettings"], "settings"),
    **dict.fromkeys(["DEFAULT_CHOICE_PRETRAINED", "DEFAULT_LINE_PRETRAINED", "LINE_ENV_ID", "LINE_ZOO",
                     "export_line_policy", "line_meta_path", "load_line_trained", "train_line"], "line"),
}

__all__ = [  # = sorted(_EXPORTS) (a test keeps them equal), written out for linters and editors
    "ACTION_TYPES", "ADVISOR_FEATURES", "AlgoSettings", "CHOICE_FEATURES", "DEFAULT_CHOICE_PRETRAINED",
    "DEFAULT_ENV_ID", "DEFAULT_EVAL_SEEDS", "DEFAULT_HYPERPARAMS", "DEFAULT_LINE_PRETRAINED", "DEFAULT_PRETRAINED",
    "DEFAULT_TRAIN_SEED", "FEATURES", "FEATURE_CLIP", "FRESH_SD_MM", "LEARNABLE_CHOICES", "LINE_ENV_ID", "LINE_ZOO",
    "LineAgent", "LineSettings", "NormalizedPolicy", "RANKED", "RANKED_CHOICES", "SectionAgentsVecEnv",
    "TampingSB3VecEnv", "TampingSettings", "TrainingSettings", "VEC_ACTION_TYPES", "VecScaleReward", "ZooSchema",
    "agent_action_space", "check_action_type", "choice_open", "collect_demonstrations", "compose_choices",
    "env_action_type", "export_line_policy", "export_policy", "filter_observation", "fit_choices", "fit_policy",
    "flipped_choices", "from_zoo", "is_choice_rule", "line_forks", "line_meta_path", "load_hyperparams",
    "load_line_trained", "load_trained", "make_progress_callback", "make_vec_env", "marginal_possession", "may_tamp",
    "n_features",
    "observation_keys", "ranked_to_choices", "ranked_to_sections", "remember_work", "return_scale",
    "section_counterfactuals", "section_features", "single_torch_thread", "stats_path", "tamping_codes",
    "teacher_policy", "teacher_to_agent_actions", "train", "train_line", "warm_start",
]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value  # once loaded, a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))

