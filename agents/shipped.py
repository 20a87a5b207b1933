"""The shipped line agents by the names every command and table gives them, and their files.

Kept free of imports beyond the standard library: the command line reads these names and paths for every command,
and loading a policy (torch, stable-baselines3) waits until one is asked for."""

from __future__ import annotations

from pathlib import Path

PRETRAINED = Path(__file__).resolve().parent / "learning" / "pretrained"
#: a network over section features trained by counterfactual policy iteration, with the tuned grouped threshold
#: as its advisor; tamping only (its file format is stable-baselines3's, hence "ppo" in the file name)
LINE_AGENT_NAME = "cpi-agent"
LINE_PRETRAINED_FILE = PRETRAINED / "ppo_tamping_line.zip"
#: the same kind of network trained with the choice rule as advisor, for the lines with every choice: its
#: tamping from the network, the other choices from the choice rule
CHOICE_AGENT_NAME = "cpi-choice-agent"
CHOICE_PRETRAINED_FILE = PRETRAINED / "cpi_choice_line.zip"
#: the same kind of network trained on the 60 m track (``trackenv/Tamping-v1``, six sections on one physics segment:
#: each decision priced by forking the whole line), with the model-predictive planner as advisor (whose SD history
#: is the agent's recurrent state); it runs where that planner can plan, a line measured every step without error
#: (``experiments/train_line.py --scenario track60 --advisor model-predictive --export`` writes it)
TRACK60_AGENT_NAME = "cpi-track60-agent"
TRACK60_PRETRAINED_FILE = PRETRAINED / "cpi_track60.zip"
#: name -> file of every shipped line agent
SHIPPED_AGENTS: dict[str, Path] = {LINE_AGENT_NAME: LINE_PRETRAINED_FILE, CHOICE_AGENT_NAME: CHOICE_PRETRAINED_FILE,
                                   TRACK60_AGENT_NAME: TRACK60_PRETRAINED_FILE}
