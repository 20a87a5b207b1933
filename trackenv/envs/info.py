"""The step's ``info`` dict: the keys every trackenv env reports, built in one place (each env adds its own)."""

from __future__ import annotations

from typing import Any

import numpy as np


def step_info(parts: dict[str, float], tamped: np.ndarray, sd_m: np.ndarray, peak_m: np.ndarray,
              section_class: np.ndarray, year: float, max_contact_force_n: float, **extra: Any) -> dict:
    """The info of a step (or of a reset, with zero costs and nothing tamped): the cost parts (k€) and their sum
    (= −reward), the sections tamped, the true quality per section in mm and m (SD and mean-to-peak of the D1
    level), the EN 13848-5 style class per section and the count at the immediate-action limit, the time
    [years] at the end of the step, the largest wheel/rail force of the step [N]; then ``extra``."""
    return {
        "costs": parts,
        "cost": float(sum(parts.values())),
        "tamped_sections": np.array(tamped, dtype=bool),
        "section_sd_mm": sd_m * 1e3,
        "section_peak_mm": peak_m * 1e3,
        "section_sd_m": sd_m.copy(),
        "section_peak_m": peak_m.copy(),
        "section_class": section_class.copy(),
        "immediate_action_exceedances": int(np.sum(section_class == 3)),
        "year": float(year),
        "max_contact_force_N": float(max_contact_force_n),
        **extra,
    }
