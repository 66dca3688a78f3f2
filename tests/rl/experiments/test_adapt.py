import json

import pytest

from dtradar_rl.experiments.adapt import AdaptConfig, adapt, first_time_at
from dtradar_rl.task.config import ConfigError
from dtradar_rl.train.config import config_for
from dtradar_rl.train.dqn import train


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_a_tiny_adapt_run_fine_tunes_a_blueprint_agent_and_compares_it_with_training_from_scratch(tmp_path):
    cfg = config_for(
        "memory",
        scene="synthetic-12x8",
        total_env_steps=400,
        num_envs=16,
        learning_starts=100,
        memory_radius=2,
        out=str(tmp_path / "dqn"),
        verbose=False,
        threads=1,
    )
    ckpt = train(cfg).checkpoint
    result = adapt(
        AdaptConfig(
            scene="synthetic-12x8",
            checkpoint=str(ckpt),
            seconds=0.4,
            eval_every_s=0.4,
            pairs=10,
            learning_starts=64,
            out=str(tmp_path / "adapt"),
            verbose=False,
            threads=1,
        )
    )
    curves = result.curves
    assert set(curves) == {"finetune", "finetune-dqn", "scratch"}
    assert curves["finetune"][0]["train_s"] == 0.0 and curves["finetune"][-1]["train_s"] >= 0.4
    assert curves["scratch"][-1]["train_s"] >= 0.4
    for name in ("curve.png", "curve.csv", "adapt.md", "adapt.json"):
        assert (tmp_path / "adapt" / name).is_file()
    saved = json.loads((tmp_path / "adapt" / "adapt.json").read_text())
    assert saved["curves"]["finetune"] == curves["finetune"]


def test_first_time_at_reads_the_curve():
    rows = [{"train_s": 0.0, "success_rate": 0.8}, {"train_s": 2.0, "success_rate": 0.99}]
    assert first_time_at(rows, 0.99) == 2.0 and first_time_at(rows, 1.0) is None


def test_adapting_a_checkpoint_without_the_geodesic_reward_asks_for_plain_fine_tuning(tmp_path):
    cfg = config_for(
        "tuned",
        scene="synthetic-12x8",
        reward="scaled",
        total_env_steps=200,
        num_envs=8,
        learning_starts=50,
        out=str(tmp_path / "dqn"),
        verbose=False,
        threads=1,
    )
    ckpt = train(cfg).checkpoint
    with pytest.raises(ConfigError, match="expert-weight 0"):
        adapt(AdaptConfig(scene="synthetic-12x8", checkpoint=str(ckpt), seconds=0.2, out=str(tmp_path / "a")))
    result = adapt(
        AdaptConfig(
            scene="synthetic-12x8",
            checkpoint=str(ckpt),
            seconds=0.2,
            eval_every_s=0.2,
            pairs=5,
            learning_starts=16,
            expert_weight=0.0,
            scratch=False,
            verbose=False,
            threads=1,
            out=str(tmp_path / "a"),
        )
    )
    assert set(result.curves) == {"finetune"}


def test_adapting_to_a_twin_traced_with_another_radio_is_refused_and_other_ray_tracing_settings_are_warned_about(
    root, tmp_path
):
    import dataclasses

    import numpy as np

    from dtradar_data.pipeline.synthetic import synthetic_dataset
    from dtradar_data.store import writing
    from dtradar_rl.agents.checkpoints import WrongTwinError, save_checkpoint
    from dtradar_rl.agents.policy import QNetwork
    from dtradar_rl.task.observations import Normalizer, build_observations
    from dtradar_rl.task.twins import load_dataset

    rt = {"frequency_hz": 2.4e9, "max_depth": 5, "samples_per_src": 10_000, "rx_pattern": "dipole", "solver": "x"}
    blocked = np.zeros((6, 10), bool)
    blocked[2:4, 4] = True

    def store(variant, version, **changed):
        ds = synthetic_dataset(10, 6, blocked, name=f"cubicle/{variant}")
        writing.write_version(ds.name, version, ds.table, {**ds.meta, "rt": {**rt, **changed}, "licence": "CC0-1.0"})
        return load_dataset(ds.name)

    blueprint = store("blueprint", "0123456789abcdef")
    norm = Normalizer.fit(blueprint)
    names = build_observations(blueprint, "neighbors", norm).names
    cfg = dataclasses.replace(config_for("tuned", scene="cubicle"), hidden=(8,))
    ckpt = save_checkpoint(tmp_path / "bp" / "model.pt", QNetwork(len(names), (8,)), cfg, norm, names, blueprint)
    run = dict(scene="cubicle", checkpoint=str(ckpt), seconds=0.2, eval_every_s=0.2, pairs=5, learning_starts=16)
    run.update(plain=False, scratch=False, verbose=False, threads=1, out=str(tmp_path / "adapt"))

    store("dynamic", "1111111111111111", frequency_hz=5.8e9, solver="y")  # another radio: refused, nothing written
    with pytest.raises(WrongTwinError, match="--rt.frequency-hz 2.4e\\+09 there, 5.8e\\+09 here") as e:
        adapt(AdaptConfig(**run))
    assert "--rt.frequency-hz 2.4e+09" in e.value.hint and not (tmp_path / "adapt").exists()

    store("dynamic", "2222222222222222", samples_per_src=1_000)  # traced more coarsely: can be meant, warned about
    with pytest.warns(UserWarning, match="--rt.samples-per-src 10000 there, 1000 here"):
        adapt(AdaptConfig(**run))
    saved = json.loads((tmp_path / "adapt" / "adapt.json").read_text())
    assert saved["rt_differences"] == {"samples_per_src": [10_000, 1_000]}
