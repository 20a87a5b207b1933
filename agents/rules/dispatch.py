"""Where the network's one tamping machine goes when the lines' policies disagree: a dispatch by the value of the
work each line asks for (:class:`ValueDispatch`), the option of :class:`~.network.NetworkRule`.

Why. Counting requests (the env's own destination, and the network rule's default) treats every requested section
alike and keeps the machine on a line while that line asks for anything: it can tamp sections that could wait
while another line's sections stand at the intervention or immediate-action limit, where each step costs a speed
restriction or a closure. The value of a section's tamping now is what it costs each step it is left as it is.

**A section's value** (:func:`section_cost_rates`, k€ per step): the line's quality cost of the section's
projected state (:func:`~.line.projected_geometry`: the measured SD and mean-to-peak carried on at their growth
over the measurement's age and ``lead_years`` more, since a section waits at least the step it takes the machine
to come): the geometry cost ``geometry_cost_per_section_year / steps_per_year · (SD / SD alert)²`` plus the cost
of its quality class (the alert, speed-restriction or immediate-action cost of the line, against the limits of
the section's speed band). A line's value is the sum over the sections its policy asks for.

**The choice** (:meth:`ValueDispatch.target`): while the machine's line asks for work, the machine stays unless
another line's requests are worth more than the machine's line's by ``switch_margin`` (k€ per step: a move costs
``move_cost``, a step without tamping and, likely, the way back; the margin keeps the machine from shuttling);
when its line asks for nothing, it goes to the line whose requests are worth most. The network rule then passes
on the requests of the chosen line only, so the env's count of requests sends the machine there.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from trackenv.physics._checks import check_field

from .line import projected_geometry

__all__ = ["ValueDispatch", "section_cost_rates"]

#: metres per millimetre: the limits are in metres, the observation in millimetres
_MM = 1e-3


def section_cost_rates(obs: Mapping[str, Any], line_config: Any, lead_years: float = 0.0) -> np.ndarray:
    """(batch, S) k€ per step: the quality cost the line ``line_config``
    (:class:`~trackenv.envs.line_config.LineConfig`) charges each section of the batched line observation
    ``obs`` in its projected state ``lead_years`` after now (:func:`~.line.projected_geometry`): the geometry
    cost (per metre of the section) and the cost of the quality class of its projected mean-to-peak against the
    limits of its speed band (:func:`trackenv.envs.costs.section_quality_costs`, read with the planner's
    projection in place of the true state)."""
    from trackenv.envs.costs import section_quality_costs
    from trackenv.physics.geometry import classify

    c = line_config
    _, sd_mm, peak_mm = projected_geometry(obs, lead_years)
    bands = [c.quality_limits.for_speed(v / 3.6) for v in c.section_values("speed_kmh")]
    section_class = np.stack([classify(peak_mm[:, j] * _MM, band) for j, band in enumerate(bands)], axis=1)
    parts = section_quality_costs(
        sd_mm * _MM, section_class, sd_alert_m=np.array([band.sd_alert_m for band in bands]),
        geometry_cost_per_section_year=c.geometry_cost_per_section_year * c.length_factors,
        steps_per_year=c.steps_per_year, class_costs=c.class_costs)
    return np.asarray(sum(parts.values()))


@dataclass(frozen=True)
class ValueDispatch:
    """The dispatch by value (module docstring). ``switch_margin``: k€ per step by which another line's requests
    must be worth more than those of the machine's line to take the machine from work there (0-1e4);
    ``lead_years``: how far past the measurement's age each section is projected (0-5 years). The defaults were
    chosen on training episodes (the documentation's network page)."""

    switch_margin: float = 60.0
    lead_years: float = 0.0

    def __post_init__(self) -> None:
        check_field(self, "switch_margin", low=0.0, high=1e4)
        check_field(self, "lead_years", low=0.0, high=5.0)

    def params(self) -> dict[str, float]:
        return asdict(self)

    def line_values(self, line_obs: Mapping[str, Any], want: np.ndarray, line_config: Any) -> np.ndarray:
        """(n, L) k€ per step: the value of each line's requests ``want`` (n, L, S) bool, from the network's
        lines' batched observation ``line_obs`` (n · L, S) (:func:`~.network.line_view`)."""
        rates = section_cost_rates(line_obs, line_config, self.lead_years).reshape(want.shape)
        return np.where(want, rates, 0.0).sum(axis=2)

    def target(self, values: np.ndarray, asked: np.ndarray, here: np.ndarray, move_cost: float = 0.0) -> np.ndarray:
        """(n,) the line whose requests the machine serves: ``values`` (n, L) of the lines' requests, ``asked``
        (n, L) whether a line asks for any work, ``here`` (n,) the machine's line. It stays on a line that asks
        unless another's requests are worth more by ``switch_margin`` or by the network's ``move_cost`` (k€),
        whichever is larger; from a line that asks for nothing it goes to the asking line worth most (the lowest
        index of equals; its own line where none asks), and where the move costs more than the margin, only if
        that line's requests are worth more than the move. So a move dearer than the margin is weighed; on the
        shipped networks (10 k€ against 60) it is not."""
        rows = np.arange(values.shape[0])
        worth = np.where(asked, values, -np.inf)
        best = worth.argmax(axis=1)
        busy = asked[rows, here]
        leave = worth[rows, best] > values[rows, here] + max(self.switch_margin, move_cost)
        worth_moving = asked.any(axis=1) & ((move_cost <= self.switch_margin) | (worth[rows, best] > move_cost))
        go = np.where(busy, leave, worth_moving)
        return np.where(go, best, here)
