"""Pictures: the level and contact-force profiles of an episode, its sections, limits and tampings.

Drawn with matplotlib's pyplot-free API (a :class:`~matplotlib.figure.Figure` on its own Agg canvas): no global
figure registry and no ``matplotlib.use``, so rendering never changes the backend of the user's process.
"""

from __future__ import annotations

import numpy as np


def episode_frame(ep, info: dict) -> np.ndarray:
    """An RGB array (H, W, 3) of the current state of a tamping episode."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    c = ep.config
    x = ep.sim.track.sleeper_positions
    d1, sd, peak = ep.quality()
    lim = c.quality_limits.for_speed(c.speed)
    fig = Figure(figsize=(8, 5), dpi=80)
    canvas = FigureCanvasAgg(fig)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    ax1.plot(x, ep.sim.level * 1e3, color="0.5", lw=1, label="level")
    ax1.plot(x, d1 * 1e3, color="C0", lw=1.5, label="D1 (3-25 m)")
    for sign in (-1, 1):
        ax1.axhline(sign * lim.alert_m * 1e3, color="orange", ls="--", lw=0.8)
        ax1.axhline(sign * lim.immediate_action_m * 1e3, color="red", ls="--", lw=0.8)
    # section boundaries midway between the last sleeper of one section and the first of the next [m]
    edges = np.interp(np.flatnonzero(np.diff(ep.sections)) + 0.5, np.arange(x.size), x)
    tamped = info.get("tamped_sections", np.zeros(c.n_sections, dtype=bool))
    for s in range(c.n_sections):
        idx = np.flatnonzero(ep.sections == s)
        if tamped[s]:
            ax1.axvspan(x[idx[0]], x[idx[-1]], color="green", alpha=0.15)
        ax1.text(x[idx].mean(), ax1.get_ylim()[1] * 0.9, f"SD {sd[s] * 1e3:.2f}", ha="center", fontsize=7)
    for e in edges:
        for ax in (ax1, ax2):
            ax.axvline(e, color="k", lw=0.5, alpha=0.4)
    ax1.invert_yaxis()
    ax1.set_ylabel("level [mm] (down +)")
    ax1.legend(loc="lower right", fontsize=7)
    ax1.set_title(f"year {ep.step_count / c.steps_per_year:.2f}   cost {info.get('cost', 0.0):.2f} k€")
    ax2.plot(x, ep.contact_force / 1e3, color="C3")
    ax2.set_ylabel("contact force [kN]")
    ax2.set_xlabel("position along the track [m]")
    fig.tight_layout()
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()
