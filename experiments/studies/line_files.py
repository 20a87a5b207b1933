"""Line files made and checked with the engine itself: measured histories synthesised by running a line whose
true rates are known (:func:`synthesize_history`), the check that the history fit recovers those rates
(:func:`fit_recovery`), and the example line that ships with trackenv (:func:`example_line`,
``python experiments/line_example.py``).
"""

from __future__ import annotations

import csv
import datetime as dt
import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from trackenv.envs.line import TampingLine
from trackenv.envs.line_config import LineConfig
from trackenv.envs.line_file import HISTORY_COLUMNS, SECTION_COLUMNS, LineDescription, Measurement, Section
from trackenv.envs.line_fit import history_fit, line_overrides, roughness


def synthesize_history(line: LineDescription, *, years: float, seed: int,
                       tamp_at: Mapping[str, Sequence[int]] | None = None, tamp_above_mm: float | None = None,
                       measurement_interval: int = 2, **config: Any) -> tuple[LineDescription, np.ndarray]:
    """Run ``line`` (its sections' state at the start, their true ``rate_factor`` where given) in the engine for
    ``years`` from episode ``seed``, tamping each section at the steps ``tamp_at[id]`` and whenever its last
    measured SD is at least ``tamp_above_mm`` (None: never), with a recording-car run
    every ``measurement_interval`` steps (and at the start); ``config``: further :class:`LineConfig` fields.
    Returns the line as its files would describe it at the end: ``as_of`` moved on by ``years``, each
    section's years since tamping and tampings since renewal then, no rate factor, and the measured history
    (SD and mean-to-peak with the recording car's error) appended to its own; and the roughness of each
    section's drawn rate field (:func:`~trackenv.envs.line_fit.roughness`, tamping damage out)."""
    c = LineConfig(line=line, horizon_years=years, measurement_interval=measurement_interval,
                   capacity=line.n_sections, min_steps_between_tampings=0, **config)
    env = TampingLine(c)
    obs, _ = env.reset(seed=seed)
    field = roughness(env.engine.get_state(0).rows["base_rate"])
    start = dt.date.fromisoformat(line.as_of)
    ids = [s.id for s in line.sections]
    tamp_at = tamp_at or {}
    steps = c.horizon_steps

    def day(step: int) -> str:
        return (start + dt.timedelta(days=round(step * 365.25 / c.steps_per_year))).isoformat()

    history = list(line.history) + _runs(ids, day(0), obs)
    for step in range(steps):
        action = np.array([step in tamp_at.get(i, ()) for i in ids], dtype=np.int8)
        if tamp_above_mm is not None:
            action |= (obs["section_sd"] >= tamp_above_mm).astype(np.int8)
        obs, *_ = env.step(action)
        if (step + 1) % measurement_interval == 0:
            history += _runs(ids, day(step + 1), obs)
    history.sort(key=lambda m: (ids.index(m.section), m.date))
    sections = tuple(replace(s, years_since_tamping=round(float(y) * c.steps_per_year) / c.steps_per_year,
                             tampings_since_renewal=int(n), rate_factor=None)
                     for s, y, n in zip(line.sections, obs["years_since_tamping"], obs["tampings_since_renewal"],
                                        strict=True))
    return replace(line, as_of=day(steps), sections=sections, history=tuple(history)), field


def _runs(ids: list[str], date: str, obs: dict[str, np.ndarray]) -> list[Measurement]:
    """One recording-car run: the observation's measured SD and mean-to-peak, rounded to 0.01 mm as a car reports
    them (the mean-to-peak at least the SD, as on real track: the engine's error model, Gaussian on each, can
    put a small peak under its SD)."""
    return [Measurement(section=i, date=date, sd_mm=round(float(sd), 2), peak_mm=round(max(float(pk), float(sd)), 2))
            for i, sd, pk in zip(ids, obs["section_sd"], obs["section_peak"], strict=True)]


def fit_recovery(n_sections: int = 24, seeds: Sequence[int] = (1,), years: float = 5.0, rate_sigma: float = 0.5,
                 measurement_interval: int = 2, truth_seed: int = 0, sd_noise_mm: float = 0.1,
                 previous_cycle_years: float = 3.0) -> dict[str, Any]:
    """Draw true rate factors from the engine's prior (lognormal, log-SD ``rate_sigma``), synthesise each
    episode's history of plain sections last tamped ``previous_cycle_years`` before its start, tamped at its
    start and measured every ``measurement_interval``
    steps for ``years`` by a recording car with error ``sd_noise_mm``, fit, and compare with each section's true
    effective rate (its factor times its drawn field's roughness over the typical one: what the fit estimates):
    the 80 % intervals' coverage of the truth, the correlation of the log posterior medians with the log truth,
    and their RMS log error against that of the prior median (what a section without history gets)."""
    rng = np.random.default_rng(truth_seed)
    truth, median, p10, p90, residual = [], [], [], [], []
    for seed in seeds:
        k = np.exp(rate_sigma * rng.standard_normal(n_sections) - rate_sigma**2 / 2)
        line = plain_line(n_sections, rate_factors=list(k), years_since_tamping=previous_cycle_years)
        measured, field = synthesize_history(line, years=years, seed=seed,
                                             tamp_at={s.id: [0] for s in line.sections},
                                             measurement_interval=measurement_interval, wet_spot_probability=0.0,
                                             rate_sigma=rate_sigma, sd_noise_mm=sd_noise_mm)
        config = LineConfig(line=measured, rate_sigma=rate_sigma, sd_noise_mm=sd_noise_mm)
        fit = history_fit(config)
        typical = line_overrides(config).roughness
        truth += list(field / typical)  # the effective rate: the factor times the field's roughness
        median += [f.rate_factor for f in fit.sections]
        p10 += [f.rate_p10 for f in fit.sections]
        p90 += [f.rate_p90 for f in fit.sections]
        residual += [f.residual_mm for f in fit.sections]
    t, m = np.log(truth), np.log(median)
    prior = -rate_sigma**2 / 2
    return {
        "sections": len(truth), "years": years, "measurements_per_section": int(years * 4 / measurement_interval),
        "coverage_80": float(np.mean((np.array(p10) <= truth) & (np.array(truth) <= np.array(p90)))),
        "correlation_log": float(np.corrcoef(t, m)[0, 1]),
        "rms_log_error": float(np.sqrt(np.mean((m - t) ** 2))),
        "rms_log_error_prior": float(np.sqrt(np.mean((prior - t) ** 2))),
        "median_ratio": float(np.median(np.exp(m - t))),
        "median_residual_mm": float(np.median(residual)),
    }


def plain_line(n_sections: int, *, rate_factors: Sequence[float] | None = None, years_since_tamping: float = 0.0,
               tampings_since_renewal: int = 0, annual_mgt: float = 15.0, as_of: str = "2023-01-01",
               ) -> LineDescription:
    """A line of ``n_sections`` plain 200 m sections (the default line's traffic), for tests and studies."""
    rates: Sequence[float | None] = [None] * n_sections if rate_factors is None else [float(k) for k in rate_factors]
    sections = tuple(Section(id=f"S{j + 1:03d}", length_m=200.0, register="plain", wet=False, annual_mgt=annual_mgt,
                             speed_kmh=100.0, freight_share=0.4, years_since_tamping=years_since_tamping,
                             tampings_since_renewal=tampings_since_renewal, rate_factor=rates[j])
                     for j in range(n_sections))
    return LineDescription(name="plain test line", as_of=as_of, speed_kmh=100.0, annual_mgt=annual_mgt,
                           freight_share=0.4, freight_axle_load_t=22.5, sections=sections)


def write_line(line: LineDescription, folder: Path, stem: str, *, header: str = "") -> Path:
    """Write ``line`` as files: ``stem``.yaml (with ``header`` as its opening comment), ``stem``_sections.csv
    and, with a history, ``stem``_history.csv. Returns the YAML's path."""
    folder.mkdir(parents=True, exist_ok=True)
    d = line.to_dict()
    sections_file, history_file = f"{stem}_sections.csv", f"{stem}_history.csv"
    for key in ("speed_kmh", "freight_share"):  # a column that only repeats the line's is left out
        if all(row[key] == d["traffic"][key] for row in d["sections"]):
            for row in d["sections"]:
                del row[key]
    _write_csv(folder / sections_file, SECTION_COLUMNS, d["sections"])
    lines = [f"# {row}" if row else "#" for row in header.splitlines()]
    lines += [f"name: {d['name']}"]
    if d.get("description"):
        lines += ["description: " + yaml.safe_dump(d["description"], width=10_000).strip().removesuffix("...").strip()]
    lines += [f"as_of: {d['as_of']}", "traffic:"]
    lines += [f"  {k}: {v:g}" for k, v in d["traffic"].items()]
    lines += [f"sections: {sections_file}"]
    if d["history"]:
        _write_csv(folder / history_file, HISTORY_COLUMNS, d["history"])
        lines += [f"history: {history_file}"]
    path = folder / f"{stem}.yaml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _write_csv(path: Path, columns: Mapping[str, Any], rows: list[dict[str, Any]]) -> None:
    used = [c for c in columns if any(c in r for r in rows)]
    with path.open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(used)
        for r in rows:
            w.writerow([_cell(r.get(c)) for c in used])


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.2f}".rstrip("0").rstrip(".") if not math.isnan(value) else ""
    return str(value)


#: The example line (``trackenv/lines/example.yaml``): 100 sections, most of 200 m. Zones by section number
#: (1-based).
EXAMPLE_STATION = (47, 48, 49, 50, 51)  # a station with switches at both throats (47, 48, 51)
EXAMPLE_STATION_SPEED_KMH = 80.0  # through the station's switches, against 120 km/h on the line
EXAMPLE_SWITCHES = (47, 48, 51, 35, 88)  # and two level crossings
EXAMPLE_BRIDGES = (22, 78)  # each with a transition zone on both approaches
EXAMPLE_WET = (12, 13, 14, 15, 63, 64, 65, 66)  # two cuttings known to be wet
EXAMPLE_BRANCH_FROM = 49  # a freight branch joins at the station: more traffic from here on, half of it freight
#: Traffic before / from the branch: MGT a year and freight share (the branch adds 6 MGT, nearly all freight:
#: (18 × 0.35 + 6) / 24 ≈ 0.5) **[assumption]**.
EXAMPLE_TRAFFIC = ((18.0, 0.35), (24.0, 0.5))
#: Sections of other lengths than 200 m (the bridges' own sections, and two longer plain ones): the line stays
#: 20 km.
EXAMPLE_LENGTHS_M = {22: 150.0, 78: 150.0, 30: 250.0, 90: 250.0}
#: Tamping cycles [years] by class in the example's past (a railway's usual order: switches and transitions
#: most often) **[assumption]**.
EXAMPLE_CYCLES = {"plain": 5.0, "wet": 3.0, "transition": 2.0, "switch_or_crossing": 1.5}
#: ... or when the last measured SD reached this [mm] (condition-based, whichever comes first) **[assumption]**.
EXAMPLE_TAMP_ABOVE_MM = 2.5


def example_line(seed: int = 2026, history_years: float = 5.0) -> tuple[LineDescription, dict[str, Any]]:
    """The example line that ships with trackenv, made by the engine: its sections and their state five years
    before ``as_of`` (drawn from ``seed``), true rate factors drawn as the engine draws them (lognormal with
    log-SD 0.5, AR(1) along the line over 600 m; clipped to 0.4-2), then ``history_years`` run in the engine with
    the past's tamping (:data:`EXAMPLE_CYCLES`, :data:`EXAMPLE_TAMP_ABOVE_MM`) and a recording car twice a
    year. Returns the line as its files
    describe it at ``as_of`` (2026-01-01; no rate factors) and the truth: per section its true effective rate
    (the factor times its drawn field's roughness over the class's typical one, what the fit estimates)."""
    rng = np.random.default_rng(seed)
    n = 100
    lengths = [EXAMPLE_LENGTHS_M.get(j, 200.0) for j in range(1, n + 1)]
    z = np.empty(n)
    z[0] = rng.standard_normal()
    for j in range(1, n):  # AR(1) over the distance between the sections' centres
        rho = math.exp(-(lengths[j - 1] + lengths[j]) / 2 / 600.0)
        z[j] = rho * z[j - 1] + math.sqrt(1 - rho * rho) * rng.standard_normal()
    rates = np.clip(np.exp(0.5 * z - 0.125), 0.4, 2.0)  # no extreme sections in an example
    transitions = {b + d for b in EXAMPLE_BRIDGES for d in (-1, 1)}
    sections = []
    for j in range(1, n + 1):
        register = ("switch_or_crossing" if j in EXAMPLE_SWITCHES else "transition" if j in transitions
                    else "plain")
        kind = "wet" if j in EXAMPLE_WET else register
        cycle = EXAMPLE_CYCLES[kind]
        mgt, share = EXAMPLE_TRAFFIC[j >= EXAMPLE_BRANCH_FROM]
        sections.append(Section(
            id=f"S{j:03d}", length_m=lengths[j - 1], register=register, wet=j in EXAMPLE_WET, annual_mgt=mgt,
            speed_kmh=EXAMPLE_STATION_SPEED_KMH if j in EXAMPLE_STATION else 120.0, freight_share=share,
            years_since_tamping=round(float(rng.uniform(0.0, cycle)) * 4) / 4,
            tampings_since_renewal=int(rng.integers(0, 4)), rate_factor=float(rates[j - 1])))
    start = LineDescription(name="Example Valley Line (synthetic)", as_of="2021-01-01", speed_kmh=120.0,
                            annual_mgt=18.0, freight_share=0.35, freight_axle_load_t=22.5, sections=tuple(sections),
                            description="A synthetic 20 km main line made by trackenv's engine: a "
                                        "station with switches passed at 80 km/h, two bridges with transition "
                                        "zones, two level crossings, two cuttings known to be wet, a freight "
                                        "branch joining at the station (6 MGT a year more from there on, nearly "
                                        "all of it freight: half the tonnage), sections of 150-250 m, five years "
                                        "of recording-car runs twice a year.")
    steps = int(round(history_years * 4))
    tamp_at = {}
    for s in sections:
        cycle = EXAMPLE_CYCLES["wet" if s.wet else s.register]
        tamp_at[s.id] = [step for step in range(steps) if (s.years_since_tamping + step / 4) % cycle < 0.25 - 1e-9
                         and s.years_since_tamping + step / 4 >= cycle - 1e-9]
    line, field = synthesize_history(start, years=history_years, seed=seed, tamp_at=tamp_at,
                                     tamp_above_mm=EXAMPLE_TAMP_ABOVE_MM, measurement_interval=2,
                                     wet_spot_probability=0.0)
    typical = _typical_roughness(line)
    truth = {s.id: float(f / t) if not math.isnan(t) else math.nan
             for s, f, t in zip(line.sections, field, typical, strict=True)}
    return line, {"rate_factor": dict(zip([s.id for s in sections], map(float, rates), strict=True)),
                  "effective_rate": truth}


def _typical_roughness(line: LineDescription) -> np.ndarray:
    return line_overrides(LineConfig(line=line)).roughness
