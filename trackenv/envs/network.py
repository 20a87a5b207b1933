"""A network of lines that share one tamping machine: its configuration (:class:`NetworkConfig`) and its episode
engine (:class:`NetworkBatch`), a thin layer over the one line engine.

The network's lines are rows of one :class:`~trackenv.envs.line_episode.LineBatch` (network ``b``'s line ``l``
is row ``b·L + l``, L = ``n_lines``), every line a draw of the same :class:`~trackenv.envs.line_config.LineConfig`
with its own traffic, register, rates and wet spots. The layer adds only what the shared machine changes: which
line's requests are worked, the move between lines and its cost, and the stacked observation and info. The
physics, the tamping, the masks, the capacity and budget rules and the costs are the line engine's.

**The machine.** It is on one line at a time (line ``start_line`` at the start of every episode). A step's
requests (``MultiBinary(n_lines · S)``, line ``l``'s sections at ``l·S .. l·S + S − 1``) are counted per line,
masked sections left out. The machine's *destination* is the line with the most requested sections; a tie
with the machine's own line keeps it there, a tie between other lines goes to the lowest index. If the
destination is the machine's line, its requests are worked as on a plain line (at most ``capacity``
sections, the worst measured first: the line's clipping rule and ``info["clipped"]``) and the other lines'
requests are dropped. Otherwise the machine moves: no section is tamped anywhere this step, the move costs
``move_cost``, and from the next step on the machine is on its destination and works there if asked again.
Traffic, settlement and quality costs run on every line every step. ``info["dropped_requests"]`` counts, per
line, the requested unmasked sections that were not tamped (the machine moving, another line than the
machine's, or over the capacity or the annual budget: then ``info["clipped"]`` too).

**Seeding.** A network's lines are drawn at reset from generators derived from the network's generator
(:func:`line_seeds`: one 63-bit seed per line, in line order), so a network episode is a deterministic function
of the network's seed and its actions; with one line, the line is the plain line of seed ``line_seeds(rng, 1)[0]``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces

from ..physics._checks import check_field, check_int_field
from .common import observation_space
from .line_config import LineConfig
from .line_episode import LineBatch, LineState, line_observation_bounds, line_observation_space

__all__ = ["NETWORK_COST_KEYS", "NetworkBatch", "NetworkConfig", "NetworkState", "line_seeds",
           "network_observation_space"]

#: the network's own cost part, beside the lines' parts in ``info["costs"]``
MOVE_COST_KEY = "move"
NETWORK_COST_KEYS = (*LineConfig.cost_keys(), MOVE_COST_KEY)


@dataclass(frozen=True)
class NetworkConfig:
    """A network of ``n_lines`` lines of one line config that share one tamping machine. Costs in k€.

    * ``n_lines``: lines in the network (1-16; default 3 **[assumption]**: a regional maintenance area of a
      few lines served by one tamper);
    * ``line_config``: the config of every line (a :class:`~trackenv.envs.line_config.LineConfig`, a dict of its
      fields, or a preset name of :data:`~trackenv.envs.line_config.SCENARIOS`; default ``"default"``, the
      12-section line); each line draws its own episode from it;
    * ``capacity``: sections the machine tamps per step over the whole network (one line per step; at most a
      line's sections; None: the line config's ``capacity``, 6 on the default line: one quarter's nights of a
      tamper at 0.5-2.2 km per working hour). It replaces the line config's ``capacity``;
    * ``move_cost``: moving the machine to another line (10 k€ **[assumption]**: a transfer run of the tamper
      and its crew over the network, of the order of a possession's call-out); the move takes the step in which
      it is asked (no tamping anywhere in that step);
    * ``start_line``: the line the machine is on at the start of every episode (default 0).

    The horizon, calendar and economics of each line are the line config's. Bad values raise ValueError naming
    the field and its range; an unknown key (:meth:`from_dict`, :meth:`replace`) raises naming it."""

    #: the action parameterisations a learner may use on the network: its own (one flag per section of every line)
    agent_action_types: ClassVar[tuple[str, ...]] = ("multibinary",)

    n_lines: int = 3
    line_config: Any = "default"
    capacity: int | None = None
    move_cost: float = 10.0
    start_line: int = 0

    def __post_init__(self) -> None:
        check_int_field(self, "n_lines", low=1, high=16)
        line = _line_config(self.line_config)
        if self.capacity is None:
            object.__setattr__(self, "capacity", line.capacity)
        check_int_field(self, "capacity", low=1, high=line.n_sections)
        object.__setattr__(self, "line_config", line.replace(capacity=self.capacity))
        check_field(self, "move_cost", low=0.0, high=1e6)
        check_int_field(self, "start_line", low=0, high=self.n_lines - 1)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> NetworkConfig:
        """Build from a dict; an unknown key raises ValueError naming it."""
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"unknown NetworkConfig key(s) {sorted(unknown)}; known: {sorted(known)}")
        return cls(**d)

    @classmethod
    def coerce(cls, config: NetworkConfig | dict | None, **overrides: Any) -> NetworkConfig:
        """A config from None (defaults), a dict or a config, with ``overrides``: NetworkConfig fields, and any
        other key a field of the line config (``horizon_years=1.0``) applied to ``line_config``."""
        if config is None:
            config = cls()
        elif isinstance(config, dict):
            config = cls.from_dict(config)
        elif not isinstance(config, cls):
            raise ValueError(f"config must be a NetworkConfig or a dict, got {type(config).__name__}")
        own = {f.name for f in fields(cls)}
        mine = {k: v for k, v in overrides.items() if k in own}
        line_changes = {k: v for k, v in overrides.items() if k not in own}
        if line_changes:
            line = _line_config(mine.get("line_config", config.line_config))
            mine["line_config"] = line.replace(**line_changes)
        return config.replace(**mine) if mine else config

    def replace(self, **changes: Any) -> NetworkConfig:
        """A copy with some fields changed (validated). A new ``line_config`` brings its own capacity unless
        ``capacity`` is given too."""
        base = {f.name: getattr(self, f.name) for f in fields(self)}
        if "line_config" in changes and "capacity" not in changes:
            base["capacity"] = None
        return self.from_dict({**base, **changes})

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly: the network's fields, the line config as its own dict (:meth:`from_dict` reads it)."""
        return {**{f.name: getattr(self, f.name) for f in fields(self)}, "line_config": self.line_config.to_dict()}

    @classmethod
    def cost_keys(cls) -> tuple[str, ...]:
        """The parts of ``info["costs"]``: the line's, and ``move``."""
        return NETWORK_COST_KEYS

    @property
    def sections_per_line(self) -> int:
        return self.line_config.n_sections

    @property
    def n_sections(self) -> int:
        """Sections of the whole network: the length of the action."""
        return self.n_lines * self.line_config.n_sections

    @property
    def horizon_steps(self) -> int:
        return self.line_config.horizon_steps

    @property
    def horizon_years(self) -> float:
        return self.line_config.horizon_years

    @property
    def steps_per_year(self) -> int:
        return self.line_config.steps_per_year


def _line_config(value: Any) -> LineConfig:
    """``line_config`` as a LineConfig (a config, a dict of its fields or a preset name), else ValueError."""
    if not isinstance(value, (LineConfig, dict, str)):
        raise ValueError(f"line_config must be a LineConfig, a dict of its fields or a preset name, got "
                         f"{type(value).__name__}")
    try:
        return LineConfig.coerce(value)
    except ValueError as exc:
        raise ValueError(f"line_config: {exc}") from None


def line_seeds(rng: np.random.Generator, n_lines: int) -> list[int]:
    """The seeds of a network's lines for one episode, drawn from the network's generator ``rng`` (which moves
    on, so the next episode's lines differ)."""
    return [int(s) for s in rng.integers(0, 2**63 - 1, size=n_lines, dtype=np.int64)]


def network_observation_space(config: NetworkConfig) -> spaces.Dict:
    """The Dict space of the network's observation: each key of the line's observation stacked over the lines
    (per-section keys (n_lines · S,), per-line keys (n_lines,), ``time`` (1,) shared, profiles (n_lines · R, n)),
    with the line's bounds; and ``machine_line``, the machine's line one-hot (n_lines,)."""
    line_space = line_observation_space(config.line_config).spaces
    bounds = {**line_observation_bounds(config.line_config), "machine_line": (0.0, 1.0)}
    shapes = {key: _stacked_shape(key, tuple(line_space[key].shape or ()), config.n_lines) for key in line_space}
    return observation_space(bounds, {**shapes, "machine_line": (config.n_lines,)})


def _stacked_shape(key: str, shape: tuple[int, ...], n_lines: int) -> tuple[int, ...]:
    if key == "time":
        return shape
    if shape == (1,):
        return (n_lines,)
    return (n_lines * shape[0], *shape[1:])


@dataclass(frozen=True, eq=False)
class NetworkState:
    """One network's episode: each line's :class:`~trackenv.envs.line_episode.LineState` and the machine's line."""

    lines: tuple[LineState, ...]
    machine_line: int


#: how the lines' scalar info values combine into the network's (any other scalar: an (n_lines,) array)
_COMBINE: dict[str, Callable[[list], Any]] = {
    "immediate_action_exceedances": sum, "observation_clipped": sum, "clipped": any, "max_contact_force_N": max,
    "year": lambda values: values[0]}


class NetworkBatch:
    """``n_networks`` network episodes of one :class:`NetworkConfig`, their lines the rows of one
    :class:`~trackenv.envs.line_episode.LineBatch` (network ``b``'s line ``l``: row ``b·L + l``). It offers the
    env layer the engine API of the line (:meth:`start`, :meth:`advance`, :meth:`observation`,
    :meth:`observations`, :meth:`reset_info`, :meth:`allowed`, :meth:`step_count`, :meth:`get_state`,
    :meth:`set_state`, :meth:`frame`), per network; the rules of the shared machine are in the module
    docstring."""

    def __init__(self, config: NetworkConfig, n_networks: int) -> None:
        self.config = config
        self.n_networks = int(n_networks)
        self.L = config.n_lines
        self.S = config.sections_per_line
        self.lines = LineBatch(config.line_config, self.n_networks * self.L)
        self.machine = np.full(self.n_networks, config.start_line, dtype=np.int64)
        self._line_keys = list(line_observation_space(config.line_config).spaces)

    def rows(self, b: int) -> range:
        """The line rows of network ``b``."""
        return range(b * self.L, (b + 1) * self.L)

    # ------------------------------------------------------------------ episodes
    def start(self, networks: list[int], rngs: list[np.random.Generator]) -> None:
        """New episodes for ``networks``, each line drawn from a generator seeded by :func:`line_seeds` of its
        network's generator ``rngs[b]``; the machine on ``start_line``."""
        line_rngs: list[Any] = [None] * (self.n_networks * self.L)
        rows = []
        for b in networks:
            for row, seed in zip(self.rows(b), line_seeds(rngs[b], self.L), strict=True):
                line_rngs[row] = np.random.default_rng(seed)
                rows.append(row)
        self.lines.start(rows, line_rngs)
        self.machine[networks] = self.config.start_line

    def destination(self, requested: np.ndarray) -> np.ndarray:
        """(n_networks,) the line each machine goes to for ``requested`` (n_networks, L) sections asked per line:
        the most asked; a tie with the machine's line keeps it, a tie between others goes to the lowest index."""
        best = requested.max(axis=1)
        here = requested[np.arange(self.n_networks), self.machine]
        return np.where(here == best, self.machine, requested.argmax(axis=1))

    def advance(self, want: np.ndarray, networks: list[int], rngs: list[np.random.Generator],
                resetting: list[int] = ()) -> tuple[np.ndarray, np.ndarray, dict[int, dict]]:  # type: ignore[assignment]
        """One step of ``networks``, which ask to tamp ``want`` (n_networks, n_lines · S) bool: the machine's line
        worked or the machine moved (module docstring), every line's traffic and costs; then new episodes in
        ``resetting``. Returns rewards, truncation flags (n_networks,; 0 and False for networks not stepped) and
        each stepped network's info."""
        N, L, S = self.n_networks, self.L, self.S
        stepped = np.zeros(N, dtype=bool)
        stepped[networks] = True
        asked = want.reshape(N, L, S) & stepped[:, None, None] & self.lines.allowed().reshape(N, L, S)
        requested = asked.sum(axis=2)
        target = self.destination(requested)
        moving = stepped & (target != self.machine)
        working = (np.arange(L)[None, :] == self.machine[:, None]) & ~moving[:, None]
        worked = asked & working[:, :, None]
        line_rows = [row for b in networks for row in self.rows(b)]
        rewards, truncated, line_infos = self.lines.advance(worked.reshape(N * L, S), line_rows, [])
        self.machine = np.where(moving, target, self.machine)
        move = np.where(moving, self.config.move_cost, 0.0)
        totals = np.where(stepped, rewards.reshape(N, L).sum(axis=1) - move, 0.0)
        infos = {}
        for b in networks:
            mine = [line_infos[row] for row in self.rows(b)]
            tamped = np.array([info["tamped_sections"].sum() for info in mine])
            infos[b] = self.info(b, mine, bool(moving[b]), requested[b], requested[b] - tamped)
        if resetting:
            self.start(list(resetting), rngs)
        return totals, np.asarray(truncated.reshape(N, L).all(axis=1)), infos

    def allowed(self) -> np.ndarray:
        """(n_networks, n_lines · S) the sections that may be tamped now (the line's mask). A True on a line the
        machine is not on means a request there counts towards moving the machine."""
        return self.lines.allowed().reshape(self.n_networks, self.L * self.S)

    def step_count(self, b: int) -> int:
        """Steps network ``b`` has taken in its episode (its lines step together)."""
        return self.lines.step_count(b * self.L)

    # ------------------------------------------------------------------ observation and info
    def observation(self, b: int) -> dict[str, np.ndarray]:
        """Network ``b``'s observation (:func:`network_observation_space`)."""
        per_line = [self.lines.observation(row) for row in self.rows(b)]
        out = {key: per_line[0][key] if key == "time" else np.concatenate([o[key] for o in per_line])
               for key in self._line_keys}
        out["machine_line"] = (np.arange(self.L) == self.machine[b]).astype(np.float32)
        return out

    def observations(self, keys) -> dict[str, np.ndarray]:
        """Every network's :meth:`observation`, stacked (n_networks, ...) under ``keys``."""
        obs = [self.observation(b) for b in range(self.n_networks)]
        return {k: np.stack([o[k] for o in obs]) for k in keys}

    def reset_info(self, b: int) -> dict:
        """Network ``b``'s info at the start of its episode (no costs, nothing asked)."""
        none = np.zeros(self.L, dtype=np.int64)
        return self.info(b, [self.lines.reset_info(row) for row in self.rows(b)], False, none, none)

    def info(self, b: int, line_infos: list[dict], moved: bool, requested: np.ndarray, dropped: np.ndarray) -> dict:
        """Network ``b``'s step info: ``costs`` (each part summed over the lines, and ``move``) and ``cost``
        (their sum = −reward), ``line_costs`` (n_lines,) each line's cost and ``line_cost_parts`` (part ->
        (n_lines,)), ``machine_line`` (after the step), ``moved``, ``requested_sections`` and
        ``dropped_requests`` (n_lines,); then the lines' own keys, per-section arrays concatenated in the
        action's order (n_lines · S,), counts by name summed (``choices``) and scalars combined (counts summed,
        ``clipped`` any, the largest contact force, the year; any other as an (n_lines,) array)."""
        move = self.config.move_cost if moved else 0.0
        parts = {k: float(sum(info["costs"][k] for info in line_infos)) for k in line_infos[0]["costs"]}
        parts[MOVE_COST_KEY] = float(move)
        out: dict[str, Any] = {
            "costs": parts,
            "cost": float(sum(parts.values())),
            "line_costs": np.array([info["cost"] for info in line_infos]),
            "line_cost_parts": {k: np.array([info["costs"][k] for info in line_infos]) for k in line_infos[0]["costs"]},
            "machine_line": int(self.machine[b]),
            "moved": bool(moved),
            "requested_sections": np.asarray(requested, dtype=np.int64).copy(),
            "dropped_requests": np.asarray(dropped, dtype=np.int64).copy(),
        }
        for key, value in line_infos[0].items():
            if key in ("costs", "cost"):
                continue
            values = [info[key] for info in line_infos]
            if isinstance(value, np.ndarray):
                out[key] = np.concatenate(values)
            elif isinstance(value, dict):  # counts by name (``choices``): summed over the lines
                out[key] = {name: sum(v[name] for v in values) for name in value}
            elif key in _COMBINE:
                out[key] = type(value)(_COMBINE[key](values))
            else:
                out[key] = np.array(values)
        return out

    # ------------------------------------------------------------------ planning state, rendering
    def get_state(self, b: int) -> NetworkState:
        """A copy of network ``b``'s episode: :meth:`set_state` restores it exactly."""
        return NetworkState(tuple(self.lines.get_state(row) for row in self.rows(b)), int(self.machine[b]))

    def set_state(self, b: int, state: NetworkState) -> None:
        """Make network ``b`` continue from ``state`` (:meth:`get_state` of a batch of this config)."""
        for row, line in zip(self.rows(b), state.lines, strict=True):
            self.lines.set_state(row, line)
        self.machine[b] = state.machine_line

    def frame(self, b: int, last_info: dict) -> np.ndarray:
        """An RGB picture of the line network ``b``'s machine is on (:meth:`LineBatch.frame`), from its part of
        the network's ``last_info``: titled with that line's number and its own step cost."""
        line = int(self.machine[b])
        S = self.S
        mine = {k: v[line * S:(line + 1) * S] if isinstance(v, np.ndarray) and v.shape[:1] == (self.L * S,) else v
                for k, v in last_info.items()}
        if "line_costs" in last_info:  # the title's cost: that line's, not the network's
            mine["cost"] = float(last_info["line_costs"][line])
        mine["frame_label"] = f"line {line} (the machine's; lines 0-{self.L - 1})   "
        return self.lines.frame(b * self.L + line, mine)
