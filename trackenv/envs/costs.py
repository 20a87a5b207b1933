"""What a section's track quality costs in one step: one function, per section, for every problem.

A problem's step cost is its interventions (possession or mobilisation, tamping, renewal) plus, for every
section, a **geometry** cost ∝ (SD / SD_alert)² per section-year (poor ride, faster wear of track and vehicles)
and a fixed cost per step for each quality class it is in (alert, intervention limit — a speed restriction —,
immediate action — a closure). The problem's config names its class costs (``class_costs``); the env sums the
sections for its reward, and the per-section parts credit each section with its own costs.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np


def section_quality_costs(sd_m: np.ndarray, section_class: np.ndarray, *, sd_alert_m: float | np.ndarray,
                          geometry_cost_per_section_year: float | np.ndarray, steps_per_year: int,
                          class_costs: Mapping[str, tuple[int, float]]) -> dict[str, np.ndarray]:
    """The step's quality costs per section (k€, arrays shaped like ``sd_m``): ``"geometry"`` =
    ``geometry_cost_per_section_year / steps_per_year · (sd_m / sd_alert_m)²`` (the SD alert and the geometry
    cost one for all, or per section: its speed band's, its length's), and for each ``name: (cls, cost)`` of
    ``class_costs`` the cost where ``section_class == cls`` (0 OK, 1 alert, 2 intervention, 3 immediate action:
    :func:`trackenv.physics.geometry.classify`)."""
    parts = {"geometry": geometry_cost_per_section_year / steps_per_year * (sd_m / sd_alert_m) ** 2}
    for name, (cls, cost) in class_costs.items():
        parts[name] = cost * (section_class == cls)
    return parts
