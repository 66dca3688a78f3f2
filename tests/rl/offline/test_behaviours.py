"""The behaviour policies' checkpoints: an ``epsilon-greedy`` log acts only with an agent of the twin it logs on."""

import dataclasses

import pytest
import torch

from dtradar_rl.agents.checkpoints import WrongTwinError, save_checkpoint
from dtradar_rl.agents.policy import QNetwork
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.task.observations import Normalizer, build_observations
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import config_for

SMALL = "synthetic-10x8"


def _memoryless(path, trained_on, normalizer):
    """A memoryless (``tuned``) checkpoint recording ``trained_on`` as its twin, observing with ``normalizer``."""
    names = build_observations(trained_on, "neighbors", normalizer).names
    torch.manual_seed(0)
    scene, variant = trained_on.name.split("/")
    cfg = dataclasses.replace(config_for("tuned", scene=scene, variant=variant), hidden=(8,))
    return save_checkpoint(path, QNetwork(len(names), (8,)), cfg, normalizer, names, trained_on)


def test_an_epsilon_greedy_log_with_a_memoryless_checkpoint_of_another_twin_is_refused_naming_both_twins(
    root, tmp_path, monkeypatch
):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    blueprint = load_dataset(f"{SMALL}/blueprint")
    cfg = LogConfig(
        scene=SMALL, behaviour="epsilon-greedy", steps=120, num_envs=12, max_steps=15, minari=False, verbose=False
    )
    # fine-tuned on the dynamic twin from the blueprint agent, as `make adapt` does: the blueprint's normaliser
    adapted = _memoryless(
        tmp_path / "adapted" / "model.pt", load_dataset(f"{SMALL}/dynamic"), Normalizer.fit(blueprint)
    )
    other = load_dataset("synthetic-12x8/blueprint")  # another scene, its own normaliser
    elsewhere = _memoryless(tmp_path / "other" / "model.pt", other, Normalizer.fit(other))
    for ckpt, trained in ((adapted, f"{SMALL}/dynamic"), (elsewhere, "synthetic-12x8/blueprint")):
        with pytest.raises(WrongTwinError, match=f"trained on {trained}, not on {SMALL}/blueprint") as e:
            log_dataset(dataclasses.replace(cfg, checkpoint=str(ckpt)), blueprint)
        assert "how to fix" in str(e.value) and trained.split("/")[0] in e.value.hint
    assert not list((root / "logged").rglob("meta.json")), "nothing was logged"
