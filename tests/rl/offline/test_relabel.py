"""Goal relabelling of logged datasets: relabelled steps are the steps the env gives for the new goal, the mix is a
checked probability distribution, own targets reproduce the log, and training on relabelled data runs and is
recorded."""

import json

import numpy as np
import pytest
import torch

from dtradar_data.core.errors import InvalidSettingError, SchemaMismatchError, UnknownNameError
from dtradar_rl.cli import main
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.offline.config import ALGORITHMS, OfflineConfig
from dtradar_rl.offline.formats import to_mdp_dataset
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.policy import load_offline_policy
from dtradar_rl.offline.relabel import AUTO_MIXES, FALLBACK, FUTURE, MIXES, NEXT, OWN, RANDOM, RelabelConfig
from dtradar_rl.offline.relabelled_sampler import relabelled_sampler
from dtradar_rl.offline.relabeller import relabel, relabelled_mdp_dataset, relabeller
from dtradar_rl.offline.trainer import fast_sampling, train_offline
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.twins import load_dataset

SMALL = "synthetic-12x8"
LOG = dict(scene=SMALL, num_envs=16, max_steps=20, seed=3, minari=False, verbose=False)
MIX = RelabelConfig(own=0.1, future=0.4, random=0.3, next=0.2, seed=5)


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """A data root of this module, with the small twin and its logs (one per reward)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DTRADAR_DATA_ROOT", str(tmp_path_factory.mktemp("root")))
        twin = load_dataset(f"{SMALL}/blueprint")
        logs = {
            reward: log_dataset(LogConfig(**LOG, behaviour="noisy-shortest", steps=2_000, reward=reward), twin)
            for reward in ("geodesic", "euclidean", "scaled", "paper")
        }
        yield twin, logs


def _env_steps(twin, logged, cells, actions, goals):
    """What the batched env that logs gives for each (cell, action, goal), all robots stepped at once."""
    env = BatchedNavEnv.from_dataset(
        twin,
        len(cells),
        obs=logged.meta["observations"]["preset"],
        normalizer=Normalizer.from_dict(logged.meta["normalizer"]),
        reward=logged.meta["settings"]["reward"],
        max_steps=50,
    )
    env.reset_where(torch.ones(len(cells), dtype=torch.bool), torch.as_tensor(cells), torch.as_tensor(goals))
    obs = env.observe().numpy()
    next_obs, reward, term, _, _ = env.step(torch.as_tensor(actions))
    return obs, next_obs.numpy(), reward.numpy(), term.numpy()


@pytest.mark.parametrize("reward", ["geodesic", "euclidean", "scaled", "paper"])
def test_relabelled_observations_rewards_and_terminals_are_those_the_env_gives_for_the_new_goal(store, reward):
    twin, logs = store
    r = relabel(logs[reward], MIX, twin).columns
    assert {OWN, FUTURE, RANDOM, NEXT} <= set(r["source"].tolist()) - {FALLBACK}
    assert r["terminated"].any() and not r["terminated"].all()
    # the batched env that logged: every relabelled step, bit for bit
    obs, next_obs, rew, term = _env_steps(twin, logs[reward], r["cell"], r["action"], r["goal"])
    np.testing.assert_array_equal(r["obs"], obs)
    np.testing.assert_array_equal(r["next_obs"], next_obs)
    np.testing.assert_array_equal(r["reward"], rew)
    np.testing.assert_array_equal(r["terminated"], term)
    # a fresh gymnasium env from the cell towards the goal (it computes in float64: equal for the integer rewards
    # of geodesic and paper, within float32 rounding for the square roots and divisions of the others)
    env = DtradarNavEnv(
        twin, obs="neighbors", reward=reward, normalizer=Normalizer.from_dict(logs[reward].meta["normalizer"])
    )
    xy = lambda c: tuple(int(v) for v in env.mdp.xy(int(c)))  # noqa: E731
    for i in np.random.default_rng(0).choice(len(r["action"]), 150, replace=False):
        o, _ = env.reset(options={"start": xy(r["cell"][i]), "target": xy(r["goal"][i])})
        o2, rw, te, _, _ = env.step(int(r["action"][i]))
        np.testing.assert_array_equal(o, r["obs"][i])
        np.testing.assert_array_equal(o2, r["next_obs"][i])
        assert te == r["terminated"][i]
        if reward in ("geodesic", "paper"):
            assert rw == r["reward"][i]
        else:
            assert rw == pytest.approx(float(r["reward"][i]), rel=1e-6, abs=1e-6)


def test_own_target_probability_one_reproduces_the_logged_transitions_exactly(store):
    twin, logs = store
    for logged in logs.values():
        a = logged.arrays()
        r = relabel(logged, RelabelConfig(), twin).columns
        assert (r["source"] == OWN).all() and np.array_equal(r["goal"], a["target"])
        for mine, theirs in (("obs", "obs"), ("next_obs", "next_obs"), ("reward", "reward"), ("terminated",) * 2):
            np.testing.assert_array_equal(r[mine], a[theirs], err_msg=mine)
            assert r[mine].dtype == a[theirs].dtype


def test_an_own_target_sampler_draws_the_same_minibatches_as_the_trainers_flat_sampler(store):
    twin, logs = store
    mdp = to_mdp_dataset(logs["geodesic"])
    flat = fast_sampling(mdp)
    own = relabelled_sampler(mdp, relabeller(logs["geodesic"], twin), RelabelConfig(seed=9))
    for _ in range(3):
        np.random.seed(11)
        b1 = flat.sample_transition_batch(64)
        np.random.seed(11)
        b2 = own.sample_transition_batch(64)
        for k in ("observations", "actions", "rewards", "next_observations", "next_actions", "terminals"):
            np.testing.assert_array_equal(getattr(b1, k), getattr(b2, k), err_msg=k)
    assert own.counts[OWN] == 3 * 64


def test_goals_come_from_where_the_mix_says_and_never_are_the_robots_own_cell(store):
    twin, logs = store
    logged = logs["geodesic"]
    rl = relabeller(logged, twin)
    mix = RelabelConfig(own=0.0, future=0.4, random=0.3, next=0.3, discount=0.8, seed=1)
    r = relabel(logged, mix, twin).columns
    cell, goal, src = r["cell"], r["goal"], r["source"]
    assert not (goal == cell).any()
    assert (goal[src == FALLBACK] == rl.target[src == FALLBACK]).all()
    nxt = rl.next
    for i in np.flatnonzero(src == FUTURE):  # a cell this episode reaches later
        assert goal[i] in nxt[i : rl.last[i] + 1]
    assert (goal[src == NEXT] == nxt[src == NEXT]).all()
    comp = rl.mdp.component
    assert (comp[goal[src == RANDOM]] == comp[cell[src == RANDOM]]).all()
    shares = np.bincount(src, minlength=5) / len(src)
    assert shares[FUTURE] + shares[FALLBACK] + shares[NEXT] == pytest.approx(0.7, abs=0.05)
    assert shares[RANDOM] == pytest.approx(0.3, abs=0.05)
    again = relabel(logged, mix, twin).columns
    assert np.array_equal(again["goal"], goal)  # the seed fixes the goals
    # discount 0: the future goal is the next cell
    zero = relabel(logged, RelabelConfig(own=0.0, future=1.0, discount=0.0), twin).columns
    moved = zero["source"] == FUTURE
    assert np.array_equal(zero["goal"][moved], nxt[moved]) and (zero["terminated"][moved]).all()


def test_the_relabelled_d3rlpy_dataset_holds_one_episode_per_step(store):
    twin, logs = store
    r = relabel(logs["geodesic"], MIX, twin).columns
    mdp = relabelled_mdp_dataset(logs["geodesic"], MIX, twin)
    assert mdp.transition_count == len(r["action"]) == len(mdp.episodes)
    for i in np.random.default_rng(1).choice(len(r["action"]), 40, replace=False):
        ep = mdp.episodes[i]
        assert ep.transition_count == 1 and ep.terminated == bool(r["terminated"][i])
        np.testing.assert_array_equal(ep.observations[0], r["obs"][i])
        assert ep.actions[0, 0] == r["action"][i] and ep.rewards[0, 0] == r["reward"][i]
        if not ep.terminated:
            np.testing.assert_array_equal(ep.observations[1], r["next_obs"][i])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"own": 0.5, "future": 0.3}, "sum to 1, got 0.8"),
        ({"own": 0.6, "future": 0.6}, "sum to 1, got 1.2"),
        ({"own": 1.2, "future": -0.2}, r"'own' must be a finite number in \[0, 1\], got 1.2"),
        ({"own": 0.5, "future": -0.5, "next": 1.0}, r"'future' must be a finite number in \[0, 1\], got -0.5"),
        ({"own": float("nan")}, r"'own' must be a finite number in \[0, 1\], got nan"),
        ({"own": 0.0, "random": float("inf")}, r"'random' must be a finite number in \[0, 1\], got inf"),
        ({"own": 0.0, "future": 1.0, "next": -float("inf")}, r"'next' must be .* got -inf"),
        ({"discount": 1.0}, "--relabel-discount must be in"),
    ],
)
def test_probabilities_that_are_not_a_distribution_are_refused_with_what_to_fix(kwargs, match):
    with pytest.raises(InvalidSettingError, match=match) as exc:
        RelabelConfig(**kwargs)
    assert exc.value.hint
    if "sum to 1" not in match and "discount" not in match:  # a value alone: the whole mix is named with it
        assert "(the mix: own=" in exc.value.message and "next=" in exc.value.message


def test_a_benchmark_refuses_a_relabel_mix_that_is_not_a_distribution_when_it_is_made(root, tmp_path, capsys):
    from dtradar_rl.experiments.offline_bench_config import OfflineBenchConfig

    for mix, match in (("own=0.2", "sum to 1, got 0.2"), ("own=nan,future=1", "'own' must be a finite number")):
        with pytest.raises(ConfigError, match=match):
            OfflineBenchConfig(relabel=mix)  # made, not yet validated: nothing of the benchmark ran
    assert OfflineBenchConfig(algorithms=("cqll",)).relabel == "auto", "an unknown algorithm is validate()'s to name"
    out = tmp_path / "bench"
    assert main(["offline-bench", "--scene", SMALL, "--relabel", "own=0.5,future=inf", "--out", str(out)]) == 2
    assert "'future' must be a finite number in [0, 1], got inf" in capsys.readouterr().err
    assert not out.exists() and not root.exists(), "refused before anything was logged or written"


def test_a_relabel_mix_on_the_command_line_is_parsed_and_a_bad_one_is_one_error_line(capsys):
    assert OfflineConfig(relabel="future").relabel_config() == RelabelConfig(own=0.0, future=1.0)
    cfg = OfflineConfig(relabel="own=0.5, random=0.5", relabel_discount=0.5, seed=4).relabel_config()
    assert (cfg.own, cfg.random, cfg.discount, cfg.seed) == (0.5, 0.5, 0.5, 4)
    assert all(RelabelConfig.parse(m) for m in MIXES)
    for algorithm, mix in AUTO_MIXES.items():  # auto: the algorithm's own mix
        auto = OfflineConfig(algorithm=algorithm, relabel="auto").relabel_config()
        assert auto == RelabelConfig.parse(mix) and not auto.is_identity
    assert set(AUTO_MIXES) == set(ALGORITHMS)
    with pytest.raises(UnknownNameError, match="did you mean 'cql'"):
        OfflineConfig(algorithm="cq", relabel="auto").validate()
    with pytest.raises(ConfigError, match="sum to 1"):
        OfflineConfig(relabel="future=0.5")
    with pytest.raises(UnknownNameError, match="did you mean 'future'"):
        OfflineConfig(relabel="futur=1")
    with pytest.raises(UnknownNameError, match="unknown relabel mix 'ogbnch'; did you mean 'ogbench'"):
        OfflineConfig(relabel="ogbnch")
    with pytest.raises(ConfigError, match="not a number"):
        OfflineConfig(relabel="own=half,future=0.5")
    with pytest.raises(UnknownNameError, match="unknown relabel resampling 'epoch'"):
        OfflineConfig(relabel="future", relabel_resample="epoch")
    assert main(["offline", "--scene", SMALL, "--relabel", "own=0.5,next=-0.5,future=1"]) == 2
    assert "relabel probability 'next' must be a finite number in [0, 1], got -0.5" in capsys.readouterr().err


def test_a_quick_training_with_relabelling_runs_end_to_end_and_its_config_records_the_mix(store, tmp_path, capsys):
    twin, logs = store
    out = tmp_path / "gcbc"
    args = ["offline", "--scene", SMALL, "--logged", logs["geodesic"].name, "--algorithm", "bc", "--relabel", "future"]
    args += ["--relabel-discount", "0.8", "--n-steps", "40", "--batch-size", "32", "--hidden", "16", "--pairs", "20"]
    args += ["--threads", "1", "--no-latency", "--out", str(out), "--no-verbose"]
    assert main(args) == 0
    assert f"bc: {SMALL}/blueprint -> {SMALL}/dynamic" in capsys.readouterr().out
    meta = json.loads((out / "config.json").read_text())
    assert meta["config"]["relabel"] == "future" and meta["config"]["relabel_discount"] == 0.8
    rec = meta["relabel"]
    assert (rec["future"], rec["own"], rec["discount"], rec["seed"], rec["resample"]) == (1.0, 0.0, 0.8, 0, "batch")
    assert rec["drawn"] == 40 * 32 and rec["shares"]["future"] + rec["shares"]["fallback"] == pytest.approx(1.0)
    policy = load_offline_policy(out)
    assert policy.config.relabel_config() == RelabelConfig(own=0.0, future=1.0, discount=0.8)
    assert json.loads((out / "results.json").read_text())["results"]


@pytest.mark.parametrize("algorithm", sorted(ALGORITHMS))
def test_every_algorithm_trains_on_relabelled_minibatches(store, tmp_path, algorithm):
    twin, logs = store
    cfg = OfflineConfig(
        scene=SMALL,
        logged=logs["geodesic"].name,
        algorithm=algorithm,
        relabel="ogbench",
        relabel_resample="run" if algorithm in ("dqn", "bc") else "batch",
        n_steps=10,
        batch_size=16,
        hidden=(8,),
        eval_variants=(),
        threads=1,
        verbose=False,
        out=str(tmp_path / algorithm),
    )
    result = train_offline(cfg, dataset=twin)
    assert len(result.losses) == 10 and all(np.isfinite(v) for row in result.losses for v in row.values())
    assert result.logged["relabel"]["drawn"] == 10 * 16


def test_the_default_relabels_by_algorithm_and_a_config_saved_before_it_reads_as_none():
    assert OfflineConfig().relabel == "auto"
    assert OfflineConfig(algorithm="cql").relabel_config() == RelabelConfig.parse("own-next")
    assert OfflineConfig(algorithm="dqn").relabel_config() == RelabelConfig.parse("ogbench")
    old = {k: v for k, v in OfflineConfig(algorithm="bc").to_dict().items() if not k.startswith("relabel")}
    assert OfflineConfig.from_dict(old).relabel == "none"


def test_the_default_trains_on_the_logged_targets_where_a_log_cannot_be_relabelled(store, tmp_path, capsys):
    twin, _ = store
    logged = log_dataset(LogConfig(**LOG, behaviour="random", steps=400, obs="paper"), twin)
    common = dict(scene=SMALL, logged=logged.name, obs="paper", algorithm="bc", n_steps=5, batch_size=16)
    common.update(hidden=(8,), eval_variants=(), threads=1, verbose=True)
    result = train_offline(OfflineConfig(**common, out=str(tmp_path / "auto")), dataset=twin)
    assert "auto does not apply (the 'paper' observation has no target)" in capsys.readouterr().out
    assert "relabel" not in result.logged and len(result.losses) == 5
    with pytest.raises(SchemaMismatchError, match="no target"):  # a mix named explicitly is refused
        train_offline(OfflineConfig(**common, relabel="future", out=str(tmp_path / "future")), dataset=twin)
