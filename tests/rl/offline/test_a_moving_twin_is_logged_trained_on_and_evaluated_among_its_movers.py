"""A log on a moving twin (``<scene>/moving/<behaviour>``): ``python -m dtradar_rl log --variant moving`` rolls the
behaviour out among the movers, keeps every step's snapshot in the meta (checked step by step against the MDP in
time), carries the card's section, trains an offline agent memoryless on it and evaluates it on the moving twin; what
cannot apply there is refused, typed, naming what works. A tiny synthetic moving twin stored as ``synth/moving``."""

import json
from types import SimpleNamespace

import numpy as np
import pytest

import dtradar_data
from dtradar_data.core.errors import DatasetNotFoundError
from dtradar_data.core.ids import LoggedId, parse_logged_id
from dtradar_data.pipeline.synthetic import synthetic_moving_dataset
from dtradar_data.store import writing
from dtradar_rl.cli import main
from dtradar_rl.offline import checkpoint_twin
from dtradar_rl.offline.behaviours import BehaviourSpec
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.moving_logs import MovingLogError, step_snapshots
from dtradar_rl.offline.trainer import OfflineConfig, train_offline
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.observations import Normalizer

TWIN = "synth/moving"
LOG = ["--scene", "synth", "--variant", "moving", "--steps", "480", "--num-envs", "12", "--no-verbose"]


@pytest.fixture()
def moving_twin(root):
    ds = synthetic_moving_dataset(8, 6, name=TWIN)
    writing.write_version(TWIN, "0123456789abcdef", ds.table, {**ds.meta, "scene_spec": {"title": "Synthetic"}})
    return dtradar_data.load(TWIN)


def test_a_logged_id_may_sit_on_the_moving_twin():
    assert parse_logged_id("cubicle/moving/expert@v0") == LoggedId("cubicle", "moving", "expert", "v0")


def test_log_on_the_moving_twin_keeps_every_steps_snapshot_and_trains_and_evaluates_there(moving_twin, tmp_path):
    assert main(["log", *LOG, "--behaviour", "expert"]) == 0
    logged = dtradar_data.load(f"{TWIN}/expert")
    assert logged.name == "synth/moving/expert" and logged.meta["parent"] == TWIN
    moving = logged.meta["moving"]
    assert moving["snapshots"] == moving_twin.snapshots and moving["movers"] == moving_twin.meta["moving"]["movers"]
    # every logged step follows the MDP in time from the snapshot the meta gives it, bumps into movers included
    a = logged.arrays()
    t = step_snapshots(logged)
    mdp = GridMDP.from_dataset(moving_twin)
    for i in range(len(t)):
        nxt, t1, *_ = mdp.step_at(int(a["cell"][i]), int(t[i]), int(a["action"][i]))
        if i + 1 < len(t) and a["episode"][i + 1] == a["episode"][i]:
            assert (a["cell"][i + 1], t[i + 1]) == (nxt, t1), f"step {i}"
    assert set(np.unique(a["action"])) <= {0, 1, 2, 3}, "the four moves: no wait action"
    assert "### Logged among movers" in (logged.path / "README.md").read_text()
    assert logged.meta["score"]["episodes"]["normalized"] > 50  # the SPL in time of an expert's episodes

    cfg = OfflineConfig(
        scene="synth", variant="moving", behaviour="expert", transitions=480, num_envs=12, algorithm="bcq",
        n_steps=40, pairs=10, latency=False, verbose=False, out=str(tmp_path / "run"),
    )  # fmt: skip
    result = train_offline(cfg)
    assert result.logged["source"] == f"{logged.name}@{logged.version}"
    saved = json.loads((result.out_dir / "config.json").read_text())
    assert saved["obs"]["senses"] == "none"  # bcq's auto is the memory window, which cannot be rebuilt among movers
    evaluated = {row["dataset"] for row in result.rows}
    assert evaluated == {TWIN}, "evaluated among its movers (the static twins are not built here)"
    assert "mover_collisions" in result.rows[0]


def test_what_cannot_apply_on_a_moving_twin_is_refused_before_anything_is_logged(moving_twin, monkeypatch):
    with pytest.raises(MovingLogError, match="--minari-memory on the moving twin synth/moving") as e:
        log_dataset(LogConfig(scene="synth", variant="moving", behaviour="expert", steps=48, minari_memory=True))
    assert "every dataset family" in e.value.hint

    # a checkpoint of `make train VARIANT=moving` (the wait action, the clock) cannot act in a log
    normalizer = Normalizer.fit(moving_twin)
    trained = dict(memory_radius=0, sense_radius=1, obs_preset="neighbors", normalizer=normalizer)
    for wait, clock in [(True, "none"), (False, "sincos")]:
        policy = SimpleNamespace(config=SimpleNamespace(preset="tuned"), wait_action=wait, clock=clock, **trained)
        monkeypatch.setattr(checkpoint_twin, "load_policy", lambda path, device, p=policy: p)
        monkeypatch.setattr(checkpoint_twin, "check_logs_on_its_twin", lambda *a: None)
        spec = BehaviourSpec("epsilon-greedy", checkpoint="runs/synth/dqn-moving/model.pt")
        with pytest.raises(ConfigError, match="wait action" if wait else "clock") as e:
            checkpoint_twin.checkpoint_policy(spec, "neighbors", normalizer, ds=moving_twin)
        assert "--wait-action" in e.value.hint and "dataset family" in e.value.hint


def test_a_moving_twin_not_built_here_is_named_with_its_build_not_refused_as_a_variant(root, capsys):
    assert main(["log", "--scene", "cubicle", "--variant", "moving", "--behaviour", "expert"]) == 2
    err = capsys.readouterr().err
    assert "cubicle/moving" in err and "unknown variant" not in err, err
    with pytest.raises(DatasetNotFoundError):
        log_dataset(LogConfig(scene="cubicle", variant="moving", behaviour="expert"))
