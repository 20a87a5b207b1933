"""The planning state API: a snapshot of one env's episode that restores it exactly.

``state = env.get_state()`` and ``env.set_state(state)`` on every trackenv env (and ``vec.get_state(i)`` /
``vec.set_state(i, state)`` on the native vector envs, with the same snapshots) make rollouts, tree search and
counterfactuals cheap: restore a state and step on, and the env replays bit for bit what it did from that
state, for any actions. A snapshot copies the episode's mutable arrays and shares what never changes within an
episode (the track objects), so it costs a few hundred kilobytes and well under a millisecond for the default
line. Snapshots are picklable and independent of the env they came from: stepping the env does not change a
snapshot, and a snapshot can be restored any number of times, into the env it came from, another env of the
same config, or a row of a vector env of that config.

A snapshot holds the env generator's state too, so a ``reset()`` without a seed after ``set_state`` draws the
episode that the source env would have drawn next.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True, eq=False)
class EnvState:
    """One env's episode at one step (see the module docstring).

    * ``config``: the config of the env it came from; ``set_state`` refuses a snapshot of another config;
    * ``episode``: the engine's snapshot of the episode (its arrays are private copies: never mutate them);
    * ``rng_state``: the env generator's ``bit_generator.state``;
    * ``last_info``: the info of the step (or reset) that led to this state, as the env returned it.
    """

    config: Any
    episode: Any
    rng_state: dict
    last_info: dict


def snapshot(config: Any, episode: Any, rng: np.random.Generator, last_info: dict) -> EnvState:
    """An :class:`EnvState` of ``episode`` (already a private copy) with copies of the generator state and info."""
    return EnvState(config, episode, copy.deepcopy(dict(rng.bit_generator.state)), copy.deepcopy(last_info))


def checked(state: Any, config: Any) -> EnvState:
    """``state`` if it is an :class:`EnvState` of ``config``; else ValueError saying why."""
    if not isinstance(state, EnvState):
        raise ValueError(f"state must be an EnvState from get_state(), got {type(state).__name__}")
    if state.config is not config and state.config != config:
        raise ValueError("state comes from an env of another config; set_state needs the config it was taken with")
    return state
