"""The rule family of each problem, looked up by its config's type: a harness asks for the rules of the config
it has and never switches on which problem that is."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from trackenv.envs.config import TampingEnvConfig
from trackenv.envs.line_config import LineConfig

from .line import LINE_HEURISTICS, line_tuned_params
from .tamping import HEURISTICS, tuned_params

#: config type -> (rule classes by name, the shipped tuned parameters by rule name)
_FAMILIES: dict[type, tuple[dict[str, Any], Callable[[], dict[str, dict[str, Any]]]]] = {
    TampingEnvConfig: (HEURISTICS, tuned_params),
    LineConfig: (LINE_HEURISTICS, line_tuned_params),
}


def _family(config: Any) -> tuple[dict[str, Any], Callable[[], dict[str, dict[str, Any]]]]:
    try:
        return _FAMILIES[type(config)]
    except KeyError:
        known = [t.__name__ for t in _FAMILIES]
        raise ValueError(f"config must be one of {known}, got {type(config).__name__}") from None


def rules_for(config: Any) -> dict[str, Any]:
    """The rule classes of ``config``'s problem, by name."""
    return _family(config)[0]


def tuned_params_for(config: Any) -> dict[str, dict[str, Any]]:
    """The shipped tuned parameters of ``config``'s rules, by rule name ({} where none ship)."""
    return _family(config)[1]()
