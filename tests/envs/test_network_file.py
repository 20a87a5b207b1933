"""Network files: the example network loads and runs, and every fault of a network file is refused naming the file
and the key."""

import shutil
from pathlib import Path

import numpy as np
import pytest

from trackenv.envs.line_file import LineFileError, load_line
from trackenv.envs.network_env import TampingNetwork
from trackenv.envs.network_file import load_network, load_network_or_none
from trackenv.lines import EXAMPLE, EXAMPLE_NETWORK


def test_the_example_network_is_its_line_files_and_runs():
    network = load_network(EXAMPLE_NETWORK)
    assert [line.name for line in network.lines] == [load_line(EXAMPLE).name, "Example Branch Line (synthetic)"]
    assert network.start_line == 0 and network.capacity is None and network.as_of == "2026-01-01"
    config = network.config(horizon_years=0.5)
    assert config.mixed and config.line_sections == (100, 30) and config.horizon_steps == 2
    assert [line.line for line in config.line_configs] == list(network.lines)
    env = TampingNetwork(config)
    obs, _ = env.reset(seed=0)
    assert obs["section_sd"].shape == (130,)
    _, reward, *_ = env.step(np.zeros(130, dtype=np.int8))
    assert np.isfinite(reward) and reward < 0


def _folder(tmp_path: Path, text: str) -> Path:
    for name in ("example.yaml", "example_sections.csv", "example_history.csv", "example_branch.yaml",
                 "example_branch_sections.csv"):
        shutil.copy(EXAMPLE.parent / name, tmp_path / name)
    path = tmp_path / "network.yaml"
    path.write_text(text, encoding="utf-8")
    return path


GOOD = "name: N\nlines:\n  - example.yaml\n  - example_branch.yaml\n"


@pytest.mark.parametrize("text, message", [
    ("name: N\n", "missing key 'lines'"),
    ("name: N\nlines: []\n", "lines: must be a list of line files"),
    ("name: N\nlines: example.yaml\n", "lines: must be a list of line files"),
    ("name: N\nlines:\n  - example.yaml\n  - ./example.yaml\n", r"lines\[1\]: './example.yaml' is listed twice"),
    ("name: N\nlines:\n  - nowhere.yaml\n",
     r"lines\[0\] \('nowhere.yaml', relative to the network file\): no such line file"),
    (GOOD + "machine_on: main\n", "machine_on: 'main' is neither a listed line file"),
    (GOOD + "capacity: 0\n", r"capacity: 0 is outside \[1, 100\] sections"),
    (GOOD + "capacity: 600\n", r"capacity: 600 is outside \[1, 100\] sections .*it counts sections a step, not metres"),
    (GOOD + "move_cost: -1\n", r"move_cost: -1 k€ is outside"),
    (GOOD + "move_cost: 10000\n", r"move_cost: 10000 k€ is outside \[0, 1000\] k€; give it in k€"),
    ("name: N\nas_of: 2026-01-01\ntraffic: {}\nsections: s.csv\n", "a line file .*not a network file"),
    (GOOD + "mashine_on: example.yaml\n", "did you mean 'machine_on'"),
])
def test_faults_of_a_network_file_name_the_key(tmp_path, text, message):
    path = _folder(tmp_path, text)
    with pytest.raises(LineFileError, match=message):
        load_network(path).config()


def test_a_network_file_given_as_a_line_file_is_named(tmp_path):
    import gymnasium as gym

    path = _folder(tmp_path, GOOD)
    with pytest.raises(LineFileError, match="a network file .*not a line file: plan it with trackenv plan"):
        load_line(path)
    with pytest.raises(ValueError, match="a network file"):
        gym.make("trackenv/TampingLine-v0", line=str(path))


def test_the_lines_keep_their_files_name_through_a_config():
    """A line's description keeps its source through the network's config (a capacity given rebuilds each line's
    config), so what the plan says names the file, not a dict."""
    import dataclasses

    config = dataclasses.replace(load_network(EXAMPLE_NETWORK), capacity=3).config()
    assert [Path(line.line.source).name for line in config.line_configs] == ["example.yaml", "example_branch.yaml"]


def test_the_machine_is_on_the_line_named_by_file_or_by_name(tmp_path):
    assert load_network(_folder(tmp_path, GOOD + "machine_on: example_branch.yaml\n")).start_line == 1
    path = _folder(tmp_path, GOOD + "machine_on: Example Branch Line (synthetic)\n")
    assert load_network(path).config().start_line == 1


@pytest.mark.parametrize("written", ["./example_branch.yaml", "../{folder}/example_branch.yaml",
                                     "{folder_path}/example_branch.yaml"])
def test_machine_on_matches_a_listed_file_as_a_path_from_the_network_files_folder(tmp_path, written):
    """``machine_on: ./example_branch.yaml`` (or any path to the file, from the network file's folder) is the listed
    ``example_branch.yaml``: it was refused as naming no line, since it matched only as written."""
    text = written.format(folder=tmp_path.name, folder_path=tmp_path)
    assert load_network(_folder(tmp_path, GOOD + f"machine_on: {text}\n")).start_line == 1
    with pytest.raises(LineFileError, match=r"machine_on: './example_branch.csv' is neither a listed line file"):
        load_network(_folder(tmp_path, GOOD + "machine_on: ./example_branch.csv\n"))


def test_load_network_or_none_loads_a_network_file_and_leaves_anything_else(tmp_path):
    """A network file is loaded as :func:`load_network` loads it, its faults named as it names them; a line file,
    or a file that is not YAML, is None (the line's loader names its faults)."""
    assert load_network_or_none(EXAMPLE_NETWORK) == load_network(EXAMPLE_NETWORK)
    assert load_network_or_none(EXAMPLE) is None
    path = _folder(tmp_path, GOOD + "mashine_on: example.yaml\n")
    with pytest.raises(LineFileError, match="unknown key 'mashine_on'; did you mean 'machine_on'"):
        load_network_or_none(path)
    path.write_text("name: [unclosed\n")
    assert load_network_or_none(path) is None and load_network_or_none(tmp_path / "nowhere.yaml") is None


def test_lines_dated_more_than_a_step_apart_are_refused(tmp_path):
    path = _folder(tmp_path, GOOD)
    branch = tmp_path / "example_branch.yaml"
    branch.write_text(branch.read_text().replace("as_of: 2026-01-01", "as_of: 2026-05-01"))
    with pytest.raises(LineFileError, match=r"lines\[0\] .*as_of 2026-01-01 is 120 days before the network's latest "
                                            r"\(2026-05-01, lines\[1\]: .*example_branch.yaml\)"):
        load_network(path).config()
    branch.write_text(branch.read_text().replace("as_of: 2026-05-01", "as_of: 2026-02-01"))
    assert load_network(path).config().n_lines == 2  # within a quarter: they step together from 2026-02-01
    # up to 92 days (the longest calendar quarter, 1 October to 1 January) is one step; a day more is not
    branch.write_text(branch.read_text().replace("as_of: 2026-02-01", "as_of: 2026-04-03"))
    assert load_network(path).config().n_lines == 2
    branch.write_text(branch.read_text().replace("as_of: 2026-04-03", "as_of: 2026-04-04"))
    with pytest.raises(LineFileError, match="is 93 days before .* within one step \\(92 days\\)"):
        load_network(path).config()


@pytest.mark.parametrize("field, where", [("move_cost", "move_cost: 20, in k€"),
                                          ("start_line", "machine_on"), ("n_lines", "lines: the line files")])
def test_the_networks_own_fields_are_not_taken_as_line_fields(tmp_path, field, where):
    """``trackenv plan NETWORK.yaml --set move_cost=20`` passes the field to the lines' configs: one error saying
    where the network file sets it (it was LineConfig's TypeError, a traceback)."""
    network = load_network(_folder(tmp_path, GOOD))
    with pytest.raises(ValueError, match=rf"^{field} is the network's, not a line's: set it in the network file "
                                         rf".*\({where}"):
        network.config(**{field: 2})


def test_a_line_field_given_as_its_default_still_conflicts_with_the_file(tmp_path):
    """The file sets speed_kmh; a --set of another value is refused even where it is the field's default (100 km/h
    was ignored silently while the plan said it had changed)."""
    network = load_network(_folder(tmp_path, GOOD))
    speed = network.lines[0].speed_kmh
    assert speed != 100.0
    with pytest.raises(LineFileError, match=rf"speed_kmh=100.0 conflicts with the line file .*, which sets it to "
                                            rf"{speed!r}: leave it out"):
        network.config(speed_kmh=100.0)
    from trackenv.envs import scenario

    assert scenario("default", line=network.lines[0], speed_kmh=speed).speed_kmh == speed  # the file's: taken
