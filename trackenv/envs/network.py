"""A network of lines that share one tamping machine: its configuration (:class:`NetworkConfig`) and its episode
engine (:class:`NetworkBatch`), a thin layer over the one line engine.

The network's lines are rows of the line engine, :class:`~trackenv.envs.line_episode.LineBatch`: one engine per
distinct line config (:func:`line_groups`; one for a network of one config, whose network ``b``'s line ``l`` is
row ``b·L + l``, L = ``n_lines``), every line a draw of its :class:`~trackenv.envs.line_config.LineConfig` with
its own traffic, register, rates and wet spots. The layer adds only what the shared machine changes: which
line's requests are worked, the move between lines and its cost, and the stacked observation and info. The
physics, the tamping, the masks, the capacity and budget rules and the costs are the line engine's.

**The machine.** It is on one line at a time (line ``start_line`` at the start of every episode). A step's
requests (``MultiBinary(Σ sections)``, line ``l``'s sections at ``line_offsets[l] .. line_offsets[l + 1] − 1``
of :class:`NetworkConfig`: ``l·S .. l·S + S − 1`` on lines of one config of S sections) are counted per line,
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

__all__ = ["NETWORK_COST_KEYS", "NetworkBatch", "NetworkConfig", "NetworkState", "line_groups", "line_seeds",
           "network_observation_space"]

#: the network's own cost part, beside the lines' parts in ``info["costs"]``
MOVE_COST_KEY = "move"
NETWORK_COST_KEYS = (*LineConfig.cost_keys(), MOVE_COST_KEY)


@dataclass(frozen=True)
class NetworkConfig:
    """A network of ``n_lines`` lines that share one tamping machine. Costs in k€.

    * ``line_config``: the config of every line (a :class:`~trackenv.envs.line_config.LineConfig`, a dict of its
      fields, or a preset name of :data:`~trackenv.envs.line_config.SCENARIOS`; default ``"default"``, the
      12-section line), or a list of them, one per line (lines of their own: each a line file's config, say,
      with its own sections, lengths, speeds and traffic); each line draws its own episode from its config.
      Lines of a list share the calendar (``steps_per_year``, ``horizon_years``) and the observation's keys
      (``profiles``, ``contact_sensor``, ``choices``); a list whose configs are all equal is stored as the one
      config;
    * ``n_lines``: lines in the network (1-16; default 3 **[assumption]**: a regional maintenance area of a
      few lines served by one tamper; with a list of configs, its length, and another number is an error);
    * ``capacity``: sections the machine tamps per step on the line it is on (one line per step; at most that
      line's sections, in that line's ``section_length_m``; None: each line's own ``capacity``, 6 on the
      default line: one quarter's nights of a tamper at 0.5-2.2 km per working hour). It replaces the line
      configs' ``capacity`` (cut to a line's sections where it has fewer; above every line's, an error; a line
      file's own ``capacity``, its possessions, stays that line's) in the stored line configs, so
      ``replace(capacity=None)`` afterwards keeps the replaced values (give the line configs again for their own);
    * ``move_cost``: moving the machine to another line (10 k€ **[assumption]**: a transfer run of the tamper
      and its crew over the network, of the order of a possession's call-out); the move takes the step in which
      it is asked (no tamping anywhere in that step);
    * ``start_line``: the line the machine is on at the start of every episode (default 0).

    The horizon, calendar and economics of each line are its line config's. Bad values raise ValueError naming
    the field and its range; an unknown key (:meth:`from_dict`, :meth:`replace`) raises naming it."""

    #: the action parameterisations a learner may use on the network: its own (one flag per section of every line)
    agent_action_types: ClassVar[tuple[str, ...]] = ("multibinary",)

    n_lines: int = None  # type: ignore[assignment]  # None: 3, or the length of a list of line configs
    line_config: Any = "default"
    capacity: int | None = None
    move_cost: float = 10.0
    start_line: int = 0

    def __post_init__(self) -> None:
        lines = _line_configs(self.line_config)
        if self.n_lines is None:
            object.__setattr__(self, "n_lines", len(lines) if isinstance(self.line_config, (list, tuple)) else 3)
        check_int_field(self, "n_lines", low=1, high=16)
        if isinstance(self.line_config, (list, tuple)) and len(lines) != self.n_lines:
            raise ValueError(f"n_lines={self.n_lines!r} but line_config lists {len(lines)} line configs: give one "
                             f"per line, or leave n_lines out")
        if self.capacity is None and all(line == lines[0] for line in lines):
            object.__setattr__(self, "capacity", lines[0].capacity)
        if self.capacity is not None:
            check_int_field(self, "capacity", low=1, high=max(line.n_sections for line in lines))
            lines = tuple(line if line.line is not None and line.line.capacity is not None  # a file's own stays
                          else line.replace(capacity=min(self.capacity, line.n_sections)) for line in lines)
        _check_alike(lines)
        object.__setattr__(self, "line_config", lines[0] if all(line == lines[0] for line in lines) else lines)
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
        other key a field of the line configs (``horizon_years=1.0``) applied to every line's config."""
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
            given = mine.get("line_config", config.line_config)
            lines = _replaced(_line_configs(given), line_changes)
            mine["line_config"] = lines if isinstance(given, (list, tuple)) else lines[0]
        return config.replace(**mine) if mine else config

    def replace(self, **changes: Any) -> NetworkConfig:
        """A copy with some fields changed (validated). A new ``line_config`` brings its own capacity (and a list
        of them its own number of lines) unless ``capacity`` (``n_lines``) is given too."""
        base = {f.name: getattr(self, f.name) for f in fields(self)}
        if "line_config" in changes and "capacity" not in changes:
            base["capacity"] = None
        if isinstance(changes.get("line_config"), (list, tuple)) and "n_lines" not in changes:
            base["n_lines"] = None
        return self.from_dict({**base, **changes})

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly: the network's fields, the line config as its own dict, or a list of them (:meth:`from_dict`
        reads it)."""
        lines = [line.to_dict() for line in self.line_configs]
        return {**{f.name: getattr(self, f.name) for f in fields(self)},
                "line_config": lines if self.mixed else lines[0]}

    @classmethod
    def cost_keys(cls) -> tuple[str, ...]:
        """The parts of ``info["costs"]``: the line's, and ``move``."""
        return NETWORK_COST_KEYS

    @property
    def mixed(self) -> bool:
        """Whether the lines have configs of their own (``line_config`` a tuple), not one config for all."""
        return isinstance(self.line_config, tuple)

    @property
    def line_configs(self) -> tuple[LineConfig, ...]:
        """(n_lines,) each line's config, in line order."""
        return self.line_config if self.mixed else (self.line_config,) * self.n_lines

    @property
    def line_sections(self) -> tuple[int, ...]:
        """(n_lines,) each line's number of sections: line ``l``'s sections are the action's entries
        ``line_offsets[l] .. line_offsets[l + 1] − 1``."""
        return tuple(line.n_sections for line in self.line_configs)

    @property
    def line_offsets(self) -> tuple[int, ...]:
        """(n_lines + 1,) where each line's sections start in the action (and in per-section observation keys)."""
        return (0, *np.cumsum(self.line_sections).tolist())

    @property
    def sections_per_line(self) -> int:
        """Sections of every line, where the lines have one config (ValueError on a network of lines of their
        own: :attr:`line_sections`)."""
        if self.mixed:
            raise ValueError("the lines of this network have configs of their own: see line_sections")
        return self.line_config.n_sections

    @property
    def n_sections(self) -> int:
        """Sections of the whole network: the length of the action."""
        return sum(self.line_sections)

    @property
    def horizon_steps(self) -> int:
        return self.line_configs[0].horizon_steps

    @property
    def horizon_years(self) -> float:
        return self.line_configs[0].horizon_years

    @property
    def steps_per_year(self) -> int:
        return self.line_configs[0].steps_per_year


def _line_config(value: Any) -> LineConfig:
    """``line_config`` as a LineConfig (a config, a dict of its fields or a preset name), else ValueError."""
    if not isinstance(value, (LineConfig, dict, str)):
        raise ValueError(f"line_config must be a LineConfig, a dict of its fields or a preset name, or a list of "
                         f"them (one per line), got {type(value).__name__}")
    try:
        return LineConfig.coerce(value)
    except ValueError as exc:
        raise ValueError(f"line_config: {exc}") from None


def _line_configs(value: Any) -> tuple[LineConfig, ...]:
    """``line_config`` as the tuple of the configs it gives (one, or one per line), else ValueError."""
    if not isinstance(value, (list, tuple)):
        return (_line_config(value),)
    if not value:
        raise ValueError("line_config: an empty list (give one line config per line)")
    out = []
    for i, item in enumerate(value):
        try:
            out.append(_line_config(item))
        except ValueError as exc:
            raise ValueError(f"line_config[{i}]: {str(exc).removeprefix('line_config: ')}") from None
    return tuple(out)


def _replaced(lines: tuple[LineConfig, ...], changes: dict[str, Any]) -> list[LineConfig]:
    """Each of ``lines`` with ``changes``; a line that refuses them (a field its line file sets, say) is named in
    the ValueError by its index and its name, since the lines of a network may come from several files."""
    out = []
    for i, line in enumerate(lines):
        try:
            out.append(line.replace(**changes))
        except ValueError as exc:
            where = f" ({line.line.name})" if line.line is not None else ""  # the message names its file
            raise ValueError(f"line_config[{i}]{where}: {exc}") from None
    return out


def _check_alike(lines: tuple[LineConfig, ...]) -> None:
    """Lines of one network step together and stack their observations: ValueError naming the first line whose
    calendar or observation keys differ from line 0's."""
    first = lines[0]
    for i, line in enumerate(lines[1:], start=1):
        for name in ("steps_per_year", "horizon_steps"):
            if getattr(line, name) != getattr(first, name):
                raise ValueError(f"line_config[{i}]: {name}={getattr(line, name)!r} differs from line 0's "
                                 f"{getattr(first, name)!r}: the lines of a network step together")
        if set(line_observation_bounds(line)) != set(line_observation_bounds(first)):
            raise ValueError(f"line_config[{i}]: its observation has other keys than line 0's (profiles, "
                             f"contact_sensor and choices must agree)")
        if line.profiles and line.n_sleepers != first.n_sleepers:
            raise ValueError(f"line_config[{i}]: segment_length_m={line.segment_length_m!r} differs from line 0's "
                             f"{first.segment_length_m!r}: with profiles the lines' profiles are stacked")


def line_groups(config: NetworkConfig) -> list[tuple[LineConfig, list[int]]]:
    """The network's distinct line configs, each with its lines (in the order of first appearance): one group of
    every line for a network of one line config."""
    groups: list[tuple[LineConfig, list[int]]] = []
    for line, line_config in enumerate(config.line_configs):
        for known, members in groups:
            if known == line_config:
                members.append(line)
                break
        else:
            groups.append((line_config, [line]))
    return groups


def line_seeds(rng: np.random.Generator, n_lines: int) -> list[int]:
    """The seeds of a network's lines for one episode, drawn from the network's generator ``rng`` (which moves
    on, so the next episode's lines differ)."""
    return [int(s) for s in rng.integers(0, 2**63 - 1, size=n_lines, dtype=np.int64)]


def network_observation_space(config: NetworkConfig) -> spaces.Dict:
    """The Dict space of the network's observation: each key of the lines' observation stacked over the lines
    (per-section keys (Σ sections,) in the action's order, per-line keys (n_lines,), ``time`` (1,) shared,
    profiles (Σ segments, n)), with the widest of the lines' bounds; and ``machine_line``, the machine's line
    one-hot (n_lines,)."""
    lines = config.line_configs
    spaces_ = [line_observation_space(line).spaces for line in lines]
    line_bounds = [line_observation_bounds(line) for line in lines]
    bounds = {key: (min(b[key][0] for b in line_bounds), max(b[key][1] for b in line_bounds))
              for key in line_bounds[0]}
    shapes = {key: _stacked_shape(key, [tuple(s[key].shape or ()) for s in spaces_]) for key in spaces_[0]}
    return observation_space({**bounds, "machine_line": (0.0, 1.0)}, {**shapes, "machine_line": (len(lines),)})


def _stacked_shape(key: str, shapes: list[tuple[int, ...]]) -> tuple[int, ...]:
    """The shape of a key of the lines' observations (``shapes``, one per line) stacked over the lines."""
    if key == "time":
        return shapes[0]
    if shapes[0] == (1,):
        return (len(shapes),)
    return (sum(shape[0] for shape in shapes), *shapes[0][1:])


@dataclass(frozen=True, eq=False)
class NetworkState:
    """One network's episode: each line's :class:`~trackenv.envs.line_episode.LineState` and the machine's line."""

    lines: tuple[LineState, ...]
    machine_line: int


#: how the lines' scalar info values combine into the network's (any other scalar: an (n_lines,) array)
_COMBINE: dict[str, Callable[[list], Any]] = {
    "immediate_action_exceedances": sum, "observation_clipped": sum, "clipped": any, "max_contact_force_N": max,
    "beyond_validity": any,
    "year": lambda values: values[0]}


class NetworkBatch:
    """``n_networks`` network episodes of one :class:`NetworkConfig`, their lines rows of the line engine: one
    :class:`~trackenv.envs.line_episode.LineBatch` per distinct line config (:attr:`groups`; one for a network of
    one line config), whose row ``b·G + k`` is network ``b``'s ``k``-th line of that config (G lines of it). It
    offers the env layer the engine API of the line (:meth:`start`, :meth:`advance`, :meth:`observation`,
    :meth:`observations`, :meth:`reset_info`, :meth:`allowed`, :meth:`step_count`, :meth:`get_state`,
    :meth:`set_state`, :meth:`frame`), per network; the rules of the shared machine are in the module
    docstring."""

    def __init__(self, config: NetworkConfig, n_networks: int) -> None:
        self.config = config
        self.n_networks = int(n_networks)
        self.L = config.n_lines
        self.offsets = np.asarray(config.line_offsets)
        self.sections = np.asarray(config.line_sections)
        #: (LineBatch, the network's lines it holds) per distinct line config (:func:`line_groups`)
        self.groups = [(LineBatch(line_config, self.n_networks * len(members)), members)
                       for line_config, members in line_groups(config)]
        #: line ``l`` of every network: (its group, its place in the group)
        self._place = {line: (g, k) for g, (_, members) in enumerate(self.groups) for k, line in enumerate(members)}
        self.machine = np.full(self.n_networks, config.start_line, dtype=np.int64)
        self._line_keys = list(line_observation_space(config.line_configs[0]).spaces)

    def row(self, b: int, line: int) -> tuple[LineBatch, int]:
        """Network ``b``'s ``line``: the line engine that holds it and its row there."""
        g, k = self._place[line]
        batch, members = self.groups[g]
        return batch, b * len(members) + k

    def _per_line(self, b: int) -> list[tuple[LineBatch, int]]:
        return [self.row(b, line) for line in range(self.L)]

    def _line_slices(self, values: np.ndarray) -> list[np.ndarray]:
        """``values`` (n, Σ sections) split into each line's (n, sections of the line)."""
        return [values[:, self.offsets[line]:self.offsets[line + 1]] for line in range(self.L)]

    # ------------------------------------------------------------------ episodes
    def start(self, networks: list[int], rngs: list[np.random.Generator]) -> None:
        """New episodes for ``networks``, each line drawn from a generator seeded by :func:`line_seeds` of its
        network's generator ``rngs[b]``; the machine on ``start_line``."""
        starts: list[tuple[list[int], list[Any]]] = [([], [None] * batch.n_lines) for batch, _ in self.groups]
        for b in networks:
            for line, seed in enumerate(line_seeds(rngs[b], self.L)):
                g, _ = self._place[line]
                _, row = self.row(b, line)
                starts[g][0].append(row)
                starts[g][1][row] = np.random.default_rng(seed)
        for (batch, _), (rows, line_rngs) in zip(self.groups, starts, strict=True):
            batch.start(sorted(rows), line_rngs)
        self.machine[networks] = self.config.start_line

    def destination(self, requested: np.ndarray) -> np.ndarray:
        """(n_networks,) the line each machine goes to for ``requested`` (n_networks, L) sections asked per line:
        the most asked; a tie with the machine's line keeps it, a tie between others goes to the lowest index."""
        best = requested.max(axis=1)
        here = requested[np.arange(self.n_networks), self.machine]
        return np.where(here == best, self.machine, requested.argmax(axis=1))

    def advance(self, want: np.ndarray, networks: list[int], rngs: list[np.random.Generator],
                resetting: list[int] = ()) -> tuple[np.ndarray, np.ndarray, dict[int, dict]]:  # type: ignore[assignment]
        """One step of ``networks``, which ask to tamp ``want`` (n_networks, Σ sections) bool: the machine's line
        worked or the machine moved (module docstring), every line's traffic and costs; then new episodes in
        ``resetting``. Returns rewards, truncation flags (n_networks,; 0 and False for networks not stepped) and
        each stepped network's info."""
        N, L = self.n_networks, self.L
        stepped = np.zeros(N, dtype=bool)
        stepped[networks] = True
        asked = np.asarray(want, dtype=bool).reshape(N, -1) & stepped[:, None] & self.allowed()
        requested = np.add.reduceat(asked, self.offsets[:-1], axis=1)
        target = self.destination(requested)
        moving = stepped & (target != self.machine)
        working = (np.arange(L)[None, :] == self.machine[:, None]) & ~moving[:, None]
        worked = self._line_slices(asked & np.repeat(working, self.sections, axis=1))
        rewards, truncated = np.zeros((N, L)), np.zeros((N, L), dtype=bool)
        line_infos: dict[tuple[int, int], dict] = {}
        for batch, members in self.groups:
            G = len(members)
            rows = [b * G + k for b in networks for k in range(G)]
            group_want = np.stack([worked[line] for line in members], axis=1).reshape(N * G, -1)
            group_rewards, group_truncated, infos = batch.advance(group_want, rows, [])
            rewards[:, members] = group_rewards.reshape(N, G)
            truncated[:, members] = np.asarray(group_truncated).reshape(N, G)
            line_infos.update({(row // G, members[row % G]): info for row, info in infos.items()})
        self.machine = np.where(moving, target, self.machine)
        move = np.where(moving, self.config.move_cost, 0.0)
        totals = np.where(stepped, rewards.sum(axis=1) - move, 0.0)
        infos = {}
        for b in networks:
            mine = [line_infos[b, line] for line in range(L)]
            tamped = np.array([info["tamped_sections"].sum() for info in mine])
            infos[b] = self.info(b, mine, bool(moving[b]), requested[b], requested[b] - tamped)
        if resetting:
            self.start(list(resetting), rngs)
        return totals, np.asarray(truncated.all(axis=1)), infos

    def allowed(self) -> np.ndarray:
        """(n_networks, Σ sections) the sections that may be tamped now (the line's mask). A True on a line the
        machine is not on means a request there counts towards moving the machine."""
        return self._per_section(LineBatch.allowed)

    def renewing(self) -> np.ndarray:
        """(n_networks, Σ sections) whether a section's next tamping is a ballast renewal
        (:meth:`LineBatch.renewing`)."""
        return self._per_section(LineBatch.renewing)

    def _per_section(self, of_lines: Callable[[LineBatch], np.ndarray]) -> np.ndarray:
        """(n_networks, Σ sections) in the action's order: ``of_lines(batch)`` (per section of its rows) of each
        line engine, placed at its lines."""
        out: np.ndarray | None = None
        for batch, members in self.groups:
            values = np.asarray(of_lines(batch)).reshape(self.n_networks, len(members), -1)
            if out is None:
                out = np.zeros((self.n_networks, int(self.offsets[-1])), dtype=values.dtype)
            for k, line in enumerate(members):
                out[:, self.offsets[line]:self.offsets[line + 1]] = values[:, k]
        assert out is not None  # a network has a line
        return out

    def step_count(self, b: int) -> int:
        """Steps network ``b`` has taken in its episode (its lines step together)."""
        batch, row = self.row(b, 0)
        return batch.step_count(row)

    # ------------------------------------------------------------------ observation and info
    def observation(self, b: int) -> dict[str, np.ndarray]:
        """Network ``b``'s observation (:func:`network_observation_space`)."""
        per_line = [batch.observation(row) for batch, row in self._per_line(b)]
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
        return self.info(b, [batch.reset_info(row) for batch, row in self._per_line(b)], False, none, none)

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
            "cost": float(sum(info["cost"] for info in line_infos) + move),  # summed as the reward is: = −reward
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
        return NetworkState(tuple(batch.get_state(row) for batch, row in self._per_line(b)), int(self.machine[b]))

    def set_state(self, b: int, state: NetworkState) -> None:
        """Make network ``b`` continue from ``state`` (:meth:`get_state` of a batch of this config)."""
        for (batch, row), line in zip(self._per_line(b), state.lines, strict=True):
            batch.set_state(row, line)
        self.machine[b] = state.machine_line

    def frame(self, b: int, last_info: dict) -> np.ndarray:
        """An RGB picture of the line network ``b``'s machine is on (:meth:`LineBatch.frame`), from its part of
        the network's ``last_info``: titled with that line's number and its own step cost."""
        line = int(self.machine[b])
        first, end = self.offsets[line], self.offsets[line + 1]
        total = int(self.offsets[-1])
        mine = {k: v[first:end] if isinstance(v, np.ndarray) and v.shape[:1] == (total,) else v
                for k, v in last_info.items()}
        if "line_costs" in last_info:  # the title's cost: that line's, not the network's
            mine["cost"] = float(last_info["line_costs"][line])
        mine["frame_label"] = f"line {line} (the machine's; lines 0-{self.L - 1})   "
        batch, row = self.row(b, line)
        return batch.frame(row, mine)
