"""Pictures of an episode of the engine (:class:`~trackenv.envs.line_episode.LineBatch`): the level and
contact-force profiles along a segment of several sections, the 60 m track (:func:`segment_frame`), and the
sections of a line with their measured and true geometry (:func:`line_frame`), each with its limits and
tampings.

Drawn with matplotlib's pyplot-free API (a :class:`~matplotlib.figure.Figure` on its own Agg canvas): no global
figure registry and no ``matplotlib.use``, so rendering never changes the backend of the user's process.
"""

from __future__ import annotations

import numpy as np


def segment_frame(batch, line: int, info: dict) -> np.ndarray:
    """An RGB array (H, W, 3) of the first segment of line ``line`` of a
    :class:`~trackenv.envs.line_episode.LineBatch`: its level and D1 level along the track with the alert and
    immediate-action limits and each section's SD (sections tamped this step shaded), and the largest
    wheel/rail force over each sleeper bay in the step's passes."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    c = batch.config
    seg = batch.segments(line).start
    x = np.arange(c.n_sleepers) * 0.6
    sections = batch.section_of_sleeper
    sd = info.get("section_sd_m", np.zeros(c.n_sections))
    lim = batch.limits
    fig = Figure(figsize=(8, 5), dpi=80)
    canvas = FigureCanvasAgg(fig)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    ax1.plot(x, batch.level[seg] * 1e3, color="0.5", lw=1, label="level")
    ax1.plot(x, batch.d1[seg] * 1e3, color="C0", lw=1.5, label="D1 (3-25 m)")
    for sign in (-1, 1):
        ax1.axhline(sign * lim.alert_m * 1e3, color="orange", ls="--", lw=0.8)
        ax1.axhline(sign * lim.immediate_action_m * 1e3, color="red", ls="--", lw=0.8)
    # section boundaries midway between the last sleeper of one section and the first of the next [m]
    edges = np.interp(np.flatnonzero(np.diff(sections)) + 0.5, np.arange(x.size), x)
    tamped = info.get("tamped_sections", np.zeros(c.n_sections, dtype=bool))
    for s in range(batch.K):
        idx = np.flatnonzero(sections == s)
        if tamped[s]:
            ax1.axvspan(x[idx[0]], x[idx[-1]], color="green", alpha=0.15)
        ax1.text(x[idx].mean(), ax1.get_ylim()[1] * 0.9, f"SD {sd[s] * 1e3:.2f}", ha="center", fontsize=7)
    for e in edges:
        for ax in (ax1, ax2):
            ax.axvline(e, color="k", lw=0.5, alpha=0.4)
    ax1.invert_yaxis()
    ax1.set_ylabel("level [mm] (down +)")
    ax1.legend(loc="lower right", fontsize=7)
    ax1.set_title(f"year {batch.step[line] / c.steps_per_year:.2f}   cost {info.get('cost', 0.0):.2f} k€")
    ax2.plot(x, batch.contact_profile[seg] / 1e3, color="C3")
    ax2.set_ylabel("contact force [kN]")
    ax2.set_xlabel("position along the track [m]")
    fig.tight_layout()
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def line_frame(batch, line: int, info: dict) -> np.ndarray:
    """An RGB array (H, W, 3) of line ``line`` of a :class:`~trackenv.envs.line_episode.LineBatch`: per section
    the true SD and D1 mean-to-peak (bars, from the physics) and the last measured ones (dots, what the planner
    sees), against the SD alert limit and the mean-to-peak alert, intervention and immediate-action limits (of
    each section's speed band);
    sections tamped this step (``info["tamped_sections"]``) shaded, known zones of the register labelled; the title
    starts with ``info["frame_label"]`` where there is one (the network: which line)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    c = batch.config
    r = batch.rows(line)
    x = np.arange(c.n_sections)
    def lim(name: str) -> np.ndarray:  # each section's, of its speed band
        return batch.section_limits(name)[r]

    tamped = info.get("tamped_sections", np.zeros(c.n_sections, dtype=bool))
    fig = Figure(figsize=(8, 5), dpi=80)
    canvas = FigureCanvasAgg(fig)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    panels = (
        (ax1, batch.sd[r], batch.measured_sd[r], "SD of D1 [mm]", ((lim("sd_alert_m"), "orange", "SD alert"),)),
        (ax2, batch.peak[r], batch.measured_peak[r], "D1 mean-to-peak [mm]",
         ((lim("alert_m"), "orange", "alert"), (lim("intervention_m"), "C1", "intervention"),
          (lim("immediate_action_m"), "red", "immediate action"))),
    )
    for ax, true_m, measured_m, label, limits in panels:
        for s in np.flatnonzero(tamped):
            ax.axvspan(s - 0.5, s + 0.5, color="green", alpha=0.15)
        ax.bar(x, true_m * 1e3, width=0.6, color="0.6", label="true")
        ax.plot(x, measured_m * 1e3, "o", color="C0", ms=5, label="measured")
        for value_m, color, name in limits:
            if (value_m == value_m[0]).all():
                ax.axhline(value_m[0] * 1e3, color=color, ls="--", lw=0.8, label=name)
            else:  # sections of several speed bands: each section's limit
                ax.step(x, value_m * 1e3, where="mid", color=color, ls="--", lw=0.8, label=name)
        ax.set_ylabel(label)
        ax.legend(loc="upper left", fontsize=7, ncol=3)
    zone = {1: "transition", 2: "switch"}
    ax2.set_xticks(x, [f"{s}\n{zone.get(int(batch.register[r][s]), '')}" for s in x], fontsize=7)
    ax2.set_xlabel("section (shaded: tamped this step)")
    step = int(batch.step[line])
    ax1.set_title(f"{info.get('frame_label', '')}year {step / c.steps_per_year:.2f}   step cost "
                  f"{info.get('cost', 0.0):.1f} k€")
    fig.tight_layout()
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()
