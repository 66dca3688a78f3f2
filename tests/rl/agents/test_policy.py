"""The greedy policy: loop escape takes a seeded random move only where the robot keeps coming back, and the
default preset is the one the CLI and the README name."""

import subprocess
import sys
from pathlib import Path

import pytest
import torch

from dtradar_rl.agents.policy import Policy, QNetwork
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import DEFAULT_PRESET, PRESETS, config_for


class Fixed(QNetwork):
    """Always prefers move 1."""

    def __init__(self, dim):
        super().__init__(dim, (1,))

    def forward(self, x):
        return torch.tensor([0.0, 1.0, 0.0, 0.0]).expand(x.shape[0], 4)


def policy(escape_after):
    ds = load_dataset("synthetic-12x8/blueprint")
    cfg = config_for("memory-escape", scene="synthetic-12x8", escape_after=escape_after)
    return Policy(Fixed(8), cfg, Normalizer.fit(ds), "neighbors", {})


def test_loop_escape_moves_at_random_only_from_cells_visited_often_enough_and_repeats_with_the_seed():
    obs = torch.zeros(400, 8)
    obs[:200, -1] = 2.0  # visits_here: 2 earlier stands
    obs[200:, -1] = 1.0
    p = policy(2)
    p.env_for(load_dataset("synthetic-12x8/blueprint"), 1)  # restarts the escape generator
    a = p.act(obs)
    assert (a[200:] == 1).all()  # not stuck: greedy
    assert set(a[:200].tolist()) == {0, 1, 2, 3}  # stuck: uniform random moves
    p.env_for(load_dataset("synthetic-12x8/blueprint"), 1)
    assert torch.equal(p.act(obs), a)  # seeded
    assert (policy(0).act(obs) == 1).all()  # escape off


def test_a_default_agent_observes_its_visit_count_last_where_the_escape_reads_it():
    ds = load_dataset("synthetic-12x8/blueprint")
    cfg = config_for(scene="synthetic-12x8")
    env = Policy(Fixed(8), cfg, Normalizer.fit(ds), "neighbors", {}).env_for(ds, 2)
    assert env.obs_names[-1] == "visits_here" and env.obs_dim == len(env.obs_names)
    env.reset()
    assert (env.observe()[:, -1] == 0).all()


def test_loop_escape_needs_the_visit_counts():
    with pytest.raises(ConfigError, match="--memory-visits"):
        config_for("memory", escape_after=2)


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_the_default_preset_is_named_in_the_train_help_and_the_readme():
    assert DEFAULT_PRESET in PRESETS and config_for().preset == DEFAULT_PRESET
    out = subprocess.run([sys.executable, "-m", "dtradar_rl", "train", "--help"], capture_output=True, text=True)
    assert out.returncode == 0 and DEFAULT_PRESET in out.stdout
    text = " ".join(out.stdout.replace("│", " ").split())  # the help's box and line wrapping removed
    assert f"--preset {DEFAULT_PRESET}" in text or f"(default: {DEFAULT_PRESET})" in text
    readme = (Path(__file__).parents[3] / "README.md").read_text()
    assert f"`{DEFAULT_PRESET}`" in readme
