"""Reproduce section 4 of the paper: the settlement loop on the seed track, with and without a stiffness
change.

Two scenarios, each ``iterations`` iterations of ``cycles_per_iteration`` axle passes at 80 km/h on
:meth:`Track.seed` (the paper's Table 3):

* **A** (the paper's Fig. 10): uniform ballast. The settlement should come out homogeneous along the track
  and the contact force nearly constant.
* **B** (the paper's Fig. 11): the ballast 10 % stiffer from sleeper 40 (24 m) on. Settlement and contact
  force should concentrate around 24 m and grow from iteration to iteration.

The vehicle defaults to ``Wheelset(mass=1800.0, static_load=100e3)``, a loaded wheelset (108.8 kN static
wheel load): the paper's contact stiffness belongs to a wheel load of that order (see the physics notes), and
the bare 1800 kg wheelset of its Table 4 loads the track with only 8.8 kN.

:func:`reproduce_paper` writes ``paper.json`` (profiles per iteration and summary figures) and two figures
like the paper's Fig. 10 and Fig. 11, and returns the summary; :func:`format_summary` renders it in a few
lines.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from trackenv.degradation import DegradationHistory, TrackDegradation
from trackenv.physics._checks import check_int, check_scalar, check_speed
from trackenv.physics.settlement import HettlerLaw
from trackenv.physics.timestep import DT_REFERENCE_S
from trackenv.physics.track import Track
from trackenv.physics.vehicle import Wheelset

__all__ = ["reproduce_paper", "format_summary", "scenario_tracks", "STIFFNESS_CHANGE_SLEEPER", "END_SLEEPERS"]

STIFFNESS_CHANGE_SLEEPER = 40  # scenario B: ballast 10 % stiffer from this sleeper on (24 m on Track.seed)
STIFFNESS_FACTOR = 1.10
#: Rail elements per sleeper bay for the paper's scenarios: with the linear reading the loop's u40 - u39 after
#: 6 x 50 000 cycles is 0.335 mm at 2 elements, 0.253 at 4, 0.245 at 8 and 16 (dt-converged at 1e-4 s), so 8
#: is converged within 1 %; the cubic reading is within 5 % already at 2 (0.196 vs 0.189 mm).
PAPER_ELEMENTS_PER_BAY = 8
END_SLEEPERS = 3  # sleepers at each end left out of scenario A's uniformity figure ("away from the ends")

FIGURE_FILES = {"A": "fig10_uniform_ballast.png", "B": "fig11_stiffer_ballast_from_24m.png"}
DESCRIPTIONS = {"A": "uniform ballast (paper Fig. 10)",
                "B": f"ballast {STIFFNESS_FACTOR - 1:.0%} stiffer from sleeper {STIFFNESS_CHANGE_SLEEPER} "
                     "(paper Fig. 11)"}


def scenario_tracks(elements_per_bay: int = 2) -> dict[str, Track]:
    """The two tracks of section 4: ``{"A": uniform seed track, "B": ballast +10 % from sleeper 40}``."""
    seed = Track.seed(elements_per_bay=elements_per_bay)
    return {"A": seed,
            "B": seed.scaled(ballast_stiffness=STIFFNESS_FACTOR, from_sleeper=STIFFNESS_CHANGE_SLEEPER)}


# ---------------------------------------------------------------------------------------------- summaries
def _uniformity(history: DegradationHistory) -> dict:
    """Scenario A's figures: how uniform the final settlement and contact force are away from the ends."""
    u = history.settlement[-1]
    n = u.size
    inner = slice(END_SLEEPERS, n - END_SLEEPERS)
    ui = u[inner]
    fi = history.contact_force[-1][inner]
    mean = float(ui.mean())
    return {
        "interior_sleepers": [END_SLEEPERS, n - END_SLEEPERS - 1],
        "final_settlement_mean_mm": mean * 1e3,
        "final_settlement_min_mm": float(ui.min()) * 1e3,
        "final_settlement_max_mm": float(ui.max()) * 1e3,
        # (max - min) / mean over the interior sleepers, as a fraction
        "final_settlement_spread": float((ui.max() - ui.min()) / mean) if mean > 0 else float("nan"),
        "final_contact_force_spread": float((fi.max() - fi.min()) / fi.mean()),
    }


def _localisation(history: DegradationHistory, change_m: float) -> dict:
    """Scenario B's figures: where the largest differential settlement and the largest contact-force increase
    (vs the first iteration) sit, how far from the stiffness change, and how they grow per iteration."""
    x = history.sleeper_positions
    u = history.settlement
    diff = np.abs(np.diff(u, axis=1))  # (iterations, n - 1): |u[k+1] - u[k]|, located midway between them
    k_diff = diff.argmax(axis=1)
    x_diff = 0.5 * (x[k_diff] + x[k_diff + 1])
    d_max = diff.max(axis=1)
    inc = history.contact_force - history.contact_force[0]
    k_inc = inc.argmax(axis=1)
    inc_max = inc.max(axis=1)
    inc_loc: list[float | None] = [None] + [float(x[k]) for k in k_inc[1:]]  # none for the reference itself
    growth_diff = np.diff(d_max)
    growth_inc = np.diff(inc_max)
    return {
        "stiffness_change_m": change_m,
        # largest |u[k+1] - u[k]| per iteration, where it is (midway between the two sleepers), and its growth
        "max_differential_settlement_mm": (d_max * 1e3).tolist(),
        "max_differential_settlement_location_m": x_diff.tolist(),
        "max_differential_settlement_sleepers": [[int(k), int(k) + 1] for k in k_diff],
        "max_differential_settlement_growth_mm": (growth_diff * 1e3).tolist(),
        "differential_settlement_location_m": float(x_diff[-1]),
        "differential_settlement_distance_m": float(abs(x_diff[-1] - change_m)),
        "differential_settlement_grows": bool(np.all(growth_diff[1:] > 0)) if d_max.size > 2 else None,
        # largest increase of the contact-force profile over iteration 1's, per iteration
        "max_contact_force_increase_kN": (inc_max / 1e3).tolist(),
        "max_contact_force_increase_location_m": inc_loc,
        "max_contact_force_increase_growth_kN": (growth_inc / 1e3).tolist(),
        "contact_force_increase_location_m": inc_loc[-1],
        "contact_force_increase_distance_m": None if inc_loc[-1] is None else abs(inc_loc[-1] - change_m),
        "contact_force_increase_grows": bool(np.all(growth_inc[1:] > 0)) if inc_max.size > 2 else None,
    }


def _scenario_record(history: DegradationHistory, passes: int) -> tuple[dict, dict]:
    """(profiles for paper.json, common summary figures) of one scenario."""
    profiles = {
        "sleeper_positions_m": history.sleeper_positions.tolist(),
        "cycles": history.cycles.tolist(),
        "settlement_mm": (history.settlement * 1e3).tolist(),
        "contact_force_kN": (history.contact_force / 1e3).tolist(),
        "max_contact_force_kN": (history.max_contact_force / 1e3).tolist(),
        "sleeper_force_kN": (history.sleeper_force / 1e3).tolist(),
        "passes": history.passes.tolist(),
    }
    summary = {
        "final_settlement_mean_mm": float(history.settlement[-1].mean()) * 1e3,
        "final_settlement_range_mm": [float(history.settlement[-1].min()) * 1e3,
                                      float(history.settlement[-1].max()) * 1e3],
        "max_contact_force_kN": profiles["max_contact_force_kN"],
        "dynamic_passes": passes,
    }
    return profiles, summary


# ---------------------------------------------------------------------------------------------- figures
def _plot(history: DegradationHistory, path: Path, title: str, static_load_kN: float,
          change_m: float | None) -> None:
    """Two panels like the paper's Fig. 10/11: (a) settlement and (b) contact force along the track, one line
    per iteration on a colour ramp; a dashed line marks the stiffness change when there is one."""
    import matplotlib
    from matplotlib.figure import Figure  # drawn without pyplot: no global state, the user's backend untouched
    from matplotlib.ticker import ScalarFormatter

    x = history.sleeper_positions
    u_mm = history.settlement * 1e3
    f_kn = history.contact_force / 1e3
    cycles = history.cycles
    n_it = u_mm.shape[0]
    cmap = matplotlib.colormaps["viridis"]
    colours = [cmap(0.9 * i / max(n_it - 1, 1)) for i in range(n_it)]

    fig = Figure(figsize=(8.0, 7.0), layout="constrained")
    ax_u, ax_f = fig.subplots(2, 1, sharex=True)
    for i in range(n_it):
        label = f"iteration {i + 1} (N = {cycles[i]:,.0f})"
        ax_u.plot(x, u_mm[i], color=colours[i], lw=1.4, label=label)
        ax_f.plot(x, f_kn[i], color=colours[i], lw=1.4, marker=".", ms=3, label=label)
    ax_f.axhline(static_load_kN, color="0.5", ls=":", lw=1.0,
                 label=f"static wheel load {static_load_kN:.1f} kN")
    for ax in (ax_u, ax_f):
        if change_m is not None:
            ax.axvline(change_m, color="tab:red", ls="--", lw=1.0,
                       label=f"ballast +{STIFFNESS_FACTOR - 1:.0%} from {change_m:g} m")
        ax.grid(alpha=0.3)
        fmt = ScalarFormatter(useOffset=False)
        ax.yaxis.set_major_formatter(fmt)
    ax_u.invert_yaxis()  # settlement is downward: draw it going down, as the rail does
    ax_u.set_ylabel("settlement [mm] (downward)")
    ax_u.set_title("(a) rail settlement per iteration", loc="left", fontsize=10)
    ax_f.set_ylabel("peak contact force per sleeper bay [kN]")
    ax_f.set_xlabel("position along the track [m]")
    ax_f.set_title("(b) wheel/rail contact force of the pass driving each iteration", loc="left", fontsize=10)
    ax_u.legend(fontsize=7, ncol=2 if n_it > 4 else 1, loc="best")
    handles, labels = ax_f.get_legend_handles_labels()
    keep = [i for i, lb in enumerate(labels) if not lb.startswith("iteration")]
    ax_f.legend([handles[i] for i in keep], [labels[i] for i in keep], fontsize=7, loc="best")
    ax_f.set_xlim(x[0], x[-1])
    fig.suptitle(title, fontsize=11)
    fig.savefig(path, dpi=120)


# ---------------------------------------------------------------------------------------------- main entry
def reproduce_paper(out_dir: str | Path = "results/paper", iterations: int = 6,
                    cycles_per_iteration: float = 50_000, speed: float = 80 / 3.6, vehicle=None,
                    make_plots: bool = True, progress: bool = True, law=None, interpolation: str = "linear",
                    elements_per_bay: int = PAPER_ELEMENTS_PER_BAY) -> dict:
    """Run the paper's two scenarios (section 4), write ``paper.json`` and the figures, return the summary.

    ``out_dir``: output folder (created); ``iterations`` of ``cycles_per_iteration`` axle passes each at
    ``speed`` [m/s]; ``vehicle`` defaults to ``Wheelset(mass=1800.0, static_load=100e3)``; ``law`` to
    :class:`HettlerLaw`; ``progress``: a tqdm bar over the iterations on stderr; ``interpolation``: how the
    per-sleeper settlement becomes the next pass's rail level, default "linear", the paper's reading (GENSYS
    reads a two-column table of position and displacement), or "cubic" (see :class:`TrackDegradation`);
    ``elements_per_bay``: rail mesh, default :data:`PAPER_ELEMENTS_PER_BAY`, where the loop has converged
    for the linear reading (a kinked profile needs a finer mesh than a smooth one).

    ``paper.json`` holds, per scenario, the settlement [mm], contact-force profile [kN] (peak per sleeper bay)
    and sleeper force [kN] per iteration, the peak contact force per iteration and the summary figures. The
    returned dict is ``paper.json`` without the per-iteration profiles: ``settings``, ``A`` and ``B``
    (``description``, ``wall_time_s``, ``summary``), ``files`` and ``wall_time_s``.

    Summary figures. A: the spread (max - min) / mean of the final settlement over the sleepers
    ``END_SLEEPERS .. n - 1 - END_SLEEPERS``. B: where the largest differential settlement |u[k+1] - u[k]|
    (located midway between the two sleepers) and the largest increase of the contact-force profile over
    iteration 1's sit, their distance from the stiffness change at 24 m, their values per iteration and
    their growth.
    """
    iterations = check_int("iterations", iterations, low=1, high=10_000)
    cycles_per_iteration = check_scalar("cycles_per_iteration", cycles_per_iteration, low=1.0, high=1e9)
    speed = check_speed(speed)
    vehicle = Wheelset(mass=1800.0, static_load=100e3) if vehicle is None else vehicle
    law = HettlerLaw() if law is None else law
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)

    tracks = scenario_tracks(elements_per_bay)
    change_m = float(tracks["B"].sleeper_positions[STIFFNESS_CHANGE_SLEEPER])
    sims = {name: TrackDegradation(tr, vehicle, law=law, cycles_per_iteration=cycles_per_iteration,
                                   speed=speed, interpolation=interpolation, dt=DT_REFERENCE_S)
            for name, tr in tracks.items()}
    static_load = float(np.max(sims["A"].system.static_wheel_loads))
    law_params = law.to_dict() if hasattr(law, "to_dict") else {}
    settings = {
        "track": "Track.seed() (paper Table 3: 51 sleepers at 0.6 m)",
        "vehicle": repr(vehicle),
        "static_wheel_load_kN": static_load / 1e3,
        "law": {"name": getattr(law, "name", type(law).__name__), **law_params},
        "iterations": iterations,
        "cycles_per_iteration": cycles_per_iteration,
        "speed_m_per_s": speed,
        "speed_km_per_h": speed * 3.6,
        "stiffness_change_m": change_m,
        "stiffness_change_sleeper": STIFFNESS_CHANGE_SLEEPER,
        "stiffness_factor": STIFFNESS_FACTOR,
        "interpolation": interpolation,
        "elements_per_bay": tracks["A"].elements_per_bay,
    }

    from tqdm.auto import tqdm

    t_all = time.perf_counter()
    full: dict = {"settings": settings}
    with tqdm(total=2 * iterations, desc="paper", unit="it", disable=not progress, leave=True) as bar:
        for name, sim in sims.items():
            bar.set_description(f"scenario {name}")

            def tick(i: int, rec, _bar=bar) -> None:
                _bar.update(1)
                _bar.set_postfix(max_F=f"{rec.max_contact_force / 1e3:.2f} kN",
                                 u_mean=f"{rec.settlement.mean() * 1e3:.3f} mm")

            t0 = time.perf_counter()
            history = sim.run(iterations, progress=tick)
            wall = time.perf_counter() - t0
            profiles, summary = _scenario_record(history, int(history.passes.sum()))
            summary.update(_uniformity(history) if name == "A" else _localisation(history, change_m))
            full[name] = {"description": DESCRIPTIONS[name], "wall_time_s": wall, "summary": summary,
                          **profiles}
            if make_plots:
                title = (f"Scenario {name}: {DESCRIPTIONS[name]}: {iterations} × {cycles_per_iteration:,.0f} "
                         f"cycles at {speed * 3.6:.0f} km/h")
                _plot(history, out / FIGURE_FILES[name], title, static_load / 1e3,
                      change_m if name == "B" else None)

    files = {"json": str(out / "paper.json")}
    if make_plots:
        files.update({f"figure_{name}": str(out / fn) for name, fn in FIGURE_FILES.items()})
    full["files"] = files
    full["wall_time_s"] = time.perf_counter() - t_all
    (out / "paper.json").write_text(json.dumps(_finite(full), indent=1))
    keep = ("description", "wall_time_s", "summary")
    return _finite({"settings": settings, "A": {k: full["A"][k] for k in keep},
                    "B": {k: full["B"][k] for k in keep}, "files": files, "wall_time_s": full["wall_time_s"]})


def _finite(obj):
    """The object with non-finite floats replaced by None, so that the JSON is standard."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def _fmt_list(values, fmt: str) -> str:
    return ", ".join("–" if v is None else format(v, fmt) for v in values)


def format_summary(d: dict) -> str:
    """A few human-readable lines from the dict :func:`reproduce_paper` returns (or ``paper.json``)."""
    s = d["settings"]
    a, b = d["A"]["summary"], d["B"]["summary"]
    lines = [
        f"Paper section 4: {s['iterations']} × {s['cycles_per_iteration']:,.0f} cycles at "
        f"{s['speed_km_per_h']:.0f} km/h, {s['vehicle']} ({s['static_wheel_load_kN']:.1f} kN static), "
        f"law {s['law']['name']}, {s.get('interpolation', 'cubic')} settlement between sleepers, "
        f"{s.get('elements_per_bay', 2)} elements per bay",
        f"A {d['A']['description']}: final settlement {a['final_settlement_min_mm']:.4f}–"
        f"{a['final_settlement_max_mm']:.4f} mm over sleepers {a['interior_sleepers'][0]}–"
        f"{a['interior_sleepers'][1]}, spread {100 * a['final_settlement_spread']:.2g} % of the mean; "
        f"contact-force spread {100 * a['final_contact_force_spread']:.2g} %",
        f"  max contact force per iteration [kN]: {_fmt_list(a['max_contact_force_kN'], '.2f')}",
        f"B {d['B']['description']}: final settlement {b['final_settlement_range_mm'][0]:.4f}–"
        f"{b['final_settlement_range_mm'][1]:.4f} mm",
        f"  largest differential settlement at {b['differential_settlement_location_m']:.2f} m "
        f"({b['differential_settlement_distance_m']:.2f} m from {b['stiffness_change_m']:g} m), "
        f"per iteration [mm]: {_fmt_list(b['max_differential_settlement_mm'], '.4f')}",
    ]
    loc = b["contact_force_increase_location_m"]
    where = "–" if loc is None else f"{loc:.2f} m ({b['contact_force_increase_distance_m']:.2f} m away)"
    lines += [
        f"  largest contact-force increase over iteration 1 at {where}, per iteration [kN]: "
        f"{_fmt_list(b['max_contact_force_increase_kN'], '.4f')}",
        f"  max contact force per iteration [kN]: {_fmt_list(b['max_contact_force_kN'], '.2f')}",
        f"wall time: A {d['A']['wall_time_s']:.2f} s, B {d['B']['wall_time_s']:.2f} s, total "
        f"{d['wall_time_s']:.2f} s; files: {', '.join(d['files'].values())}",
    ]
    return "\n".join(lines)
