"""The line files that ship with trackenv (schema: :mod:`trackenv.envs.line_file`).

``EXAMPLE`` is the example line: a synthetic 20 km main line of 100 sections of 200 m with a station and its
switches, two bridges with transition zones, two level crossings, two cuttings known to be wet, a freight
branch joining at the station and five years of recording-car runs, made by trackenv's own engine::

    import gymnasium as gym
    import trackenv
    from trackenv.lines import EXAMPLE

    env = gym.make("trackenv/TampingLine-v0", line=EXAMPLE)

``EXAMPLE_NETWORK`` is the example network file: the example line and a synthetic 6 km freight branch without a
measured history (``example_branch.yaml``), served by one tamping machine (:mod:`trackenv.envs.network_file`).
"""

from pathlib import Path

#: The example line's file (its sections and history CSV files lie beside it).
EXAMPLE = Path(__file__).resolve().parent / "example.yaml"

#: The example network's file (its line files lie beside it).
EXAMPLE_NETWORK = Path(__file__).resolve().parent / "example_network.yaml"

__all__ = ["EXAMPLE", "EXAMPLE_NETWORK"]
