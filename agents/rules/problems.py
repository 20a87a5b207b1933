"""The rules of a config and their shipped tuned parameters: one rule family serves every preset, and the rules
that use the choices (:mod:`.choices`) join it where the config enables more than tamping; the tuned parameters
are per preset (tuned on its training seeds by ``trackenv evaluate --env ID --retune``, or for the choice
scenarios by ``experiments/choices_compare.py --tune``), and a config that is no shipped preset gets those of
the default line."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from trackenv.envs.line_config import SCENARIOS, LineConfig, scenario

from .choices import CHOICE_RULES
from .line import LINE_HEURISTICS, LINE_TUNED_FILE, line_tuned_params
from .model_predictive import ModelPredictive

_HERE = Path(__file__).resolve().parent
#: preset name -> the file of its tuned parameters
TUNED_FILES: dict[str, Path] = {
    "default": LINE_TUNED_FILE,
    "track60": _HERE / "track60_tuned_heuristics.json",
    "choices": _HERE / "choices_tuned_heuristics.json",
    "wet": _HERE / "wet_tuned_heuristics.json",
    "defects": _HERE / "defects_tuned_heuristics.json",
}


def rules_for(config: Any) -> dict[str, Any]:
    """The rule classes by name: the tamping rules on every config, and the rules that use the choices
    (:data:`~.choices.CHOICE_RULES`) where the config enables more than tamping."""
    if not isinstance(config, LineConfig):
        raise ValueError(f"config must be a LineConfig, got {type(config).__name__}")
    if tuple(config.choices) == ("tamp",):
        return LINE_HEURISTICS
    return every_rule()


def every_rule() -> dict[str, Any]:
    """Every rule class by name: the tamping rules and the rules that use the choices."""
    return {**LINE_HEURISTICS, **CHOICE_RULES}


#: the planners a learner may take as its advisor besides the rules, by name: no members of the tuned family (their
#: defaults were chosen on training episodes), each bound to the configs it can plan
PLANNERS: dict[str, Any] = {ModelPredictive.name: ModelPredictive}


def advisor_rules() -> dict[str, Any]:
    """Every policy class a learner may take as its advisor, by name: the rules and the planners."""
    return {**every_rule(), **PLANNERS}


def main_rule(config: LineConfig) -> str:
    """The name of ``config``'s main rule, the one comparisons on it run: the choice rule where it enables more
    than tamping, else the grouped threshold."""
    return "grouped-threshold" if tuple(config.choices) == ("tamp",) else "choice-threshold"


#: fields that say how a line's passes are computed, not what the line is, at their presets' values
_HOW_COMPUTED = {"engine": "classic", "pass_reuse_tolerance_m": 0.0}


def as_preset(config: LineConfig) -> LineConfig:
    """``config`` as a shipped preset would be written if it is one: a 10-year horizon, and the fields that say
    how its passes are computed (the engine, pass reuse) at the presets' values. A preset stays the same line,
    with the same tuned parameters and id, over any horizon and either engine."""
    return computed_as_presets(config).replace(horizon_years=10.0)


def computed_as_presets(config: LineConfig) -> LineConfig:
    """``config`` with its passes computed as every preset computes them (the classic engine, every pass
    computed): the same line, the config of every saved result."""
    return config.replace(**_HOW_COMPUTED)


def preset_of(config: LineConfig) -> str | None:
    """The name of the shipped preset (:data:`~trackenv.envs.line_config.SCENARIOS`) that ``config`` is, over any
    horizon and either engine (:func:`as_preset`); None for any other line."""
    plain = as_preset(config)
    return next((name for name in SCENARIOS if plain == scenario(name)), None)


def tuned_file_for(config: LineConfig) -> Path:
    """The tuned-parameter file of ``config``: its preset's where it is a shipped preset (:func:`preset_of`) with
    one, else the default line's."""
    path = TUNED_FILES.get(preset_of(config) or "")
    return path if path is not None and path.exists() else LINE_TUNED_FILE


def tuned_params_for(config: Any) -> dict[str, dict[str, Any]]:
    """The shipped tuned parameters of ``config``'s rules, by rule name ({} where none ship)."""
    rules_for(config)
    return line_tuned_params(tuned_file_for(config))


def tuned_rule(config: Any, name: str, *, require_tuned: bool = False) -> Any:
    """The rule ``name`` of ``config``'s family (:func:`rules_for`) with ``config``'s shipped tuned parameters
    (:func:`tuned_params_for`), not yet bound to the config's calendar. Where none ship for it, the rule's own
    defaults, or ValueError with ``require_tuned`` (a comparison that must run the tuned rule, not a stand-in).
    An unknown ``name`` is a ValueError naming the family's rules."""
    family = rules_for(config)
    if name not in family:
        raise ValueError(f"rule must be one of {sorted(family)}, got {name!r}")
    tuned = tuned_params_for(config)
    if require_tuned and name not in tuned:
        raise ValueError(f"rule {name!r}: no tuned parameters ship for this config ({tuned_file_for(config).name} "
                         f"holds {sorted(tuned)})")
    return family[name](**tuned.get(name, {}))
