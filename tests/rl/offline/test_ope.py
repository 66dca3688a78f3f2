"""Off-policy evaluation beside the truth: FQE's estimate from logged data and the value measured on the twin; and
the trainer's fast settings that FQE shares (the vectorised minibatch sampler, d3rlpy's logging off), which must
train the very same weights as d3rlpy's defaults."""

import numpy as np
import pytest
import torch

from dtradar_rl.envs.memory import batched_env
from dtradar_rl.offline.config import OfflineConfig
from dtradar_rl.offline.formats import import_d3rlpy, to_mdp_dataset
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.ope import episode_starts, fqe_estimate, initial_observations, true_value
from dtradar_rl.offline.trainer import fast_sampling, fit, make_algorithm, train_offline
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.twins import load_dataset

TINY = "synthetic-8x6"
X_PLUS = 1  # action index of the move X+


@pytest.fixture(scope="module")
def tiny():
    return load_dataset(f"{TINY}/blueprint")


class AlwaysXPlus:
    """A hand-made policy: the move X+ for every robot, whatever it observes."""

    def __init__(self, ds):
        self.normalizer = Normalizer.fit(ds)

    def env_for(self, ds, num_envs, **kwargs):
        return batched_env(ds, num_envs, obs="neighbors", normalizer=self.normalizer, **kwargs)

    def act(self, obs, shield=False):
        return torch.full(obs.shape[:-1], X_PLUS, dtype=torch.long)


def two_steps_right_then_a_wall(ds):
    """A start two X+ moves from its target along a shortest path, and a start whose X+ move hits an obstacle."""
    mdp = GridMDP.from_dataset(ds)
    free = np.flatnonzero(~np.asarray(ds.blocked, bool).ravel())
    along = None
    for c in free:
        c1 = mdp.next_cell[c, X_PLUS]
        c2 = mdp.next_cell[c1, X_PLUS]
        if c1 != c and c2 != c1 and mdp.bfs_distances(c2)[c] == 2:
            along = (int(c), int(c2))
            break
    wall = next(int(c) for c in free if mdp.collides[c, X_PLUS])
    target = next(int(c) for c in free if c != wall and mdp.bfs_distances(int(c))[wall] > 0)
    assert along is not None
    return along, (wall, target)


def test_the_true_value_is_the_discounted_return_worked_out_by_hand(tiny):
    policy = AlwaysXPlus(tiny)
    along, wall = two_steps_right_then_a_wall(tiny)
    gamma = 0.5
    # geodesic reward: +1 for a step along a shortest path, +1 more on reaching the target, then nothing
    assert true_value(policy, tiny, np.array([along]), gamma=gamma) == pytest.approx(1 + gamma * 2)
    # every move into the obstacle: -1, until the 5-step limit cuts the episode
    assert true_value(policy, tiny, np.array([wall]), gamma=gamma, max_steps=5) == pytest.approx(
        -sum(gamma**t for t in range(5))
    )
    # the mean over pairs, and a discount of 1 is the plain return
    both = true_value(policy, tiny, np.array([along, wall]), gamma=1.0, max_steps=5)
    assert both == pytest.approx(((1 + 2) + (-5)) / 2)
    with pytest.raises(ValueError, match="gamma"):
        true_value(policy, tiny, np.array([along]), gamma=0.0)


class AlwaysXPlusFullTable(AlwaysXPlus):
    """The same policy in an env whose shaped-reward table holds every free cell as a target."""

    def env_for(self, ds, num_envs, **kwargs):
        kwargs.pop("target_pool", None)
        return super().env_for(ds, num_envs, **kwargs)


def test_the_true_value_does_not_depend_on_which_targets_the_reward_table_holds(tiny):
    pairs = GridMDP.from_dataset(tiny).sample_pairs(24, np.random.default_rng(3))
    got = true_value(AlwaysXPlus(tiny), tiny, pairs, gamma=0.9, max_steps=12)
    assert got == true_value(AlwaysXPlusFullTable(tiny), tiny, pairs, gamma=0.9, max_steps=12)


def _bc(tmp_path, logged, name):
    cfg = OfflineConfig(
        scene=TINY,
        algorithm="bc",
        n_steps=300,
        batch_size=64,
        hidden=(64, 64),
        lr=3e-3,
        eval_variants=(),
        threads=1,
        verbose=False,
        out=str(tmp_path / name),
    )
    return train_offline(cfg, dataset=logged).policy


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_fqe_is_finite_and_ranks_bc_on_expert_like_data_above_bc_on_random_moves_as_the_twin_does(root, tmp_path, tiny):
    torch.set_num_threads(1)
    log = {"scene": TINY, "num_envs": 16, "steps": 3_000, "max_steps": 20, "minari": False, "verbose": False}
    mixed = log_dataset(LogConfig(**log, behaviour="noisy-shortest", shortest_prob=0.5), tiny)
    random_log = log_dataset(LogConfig(**log, behaviour="random"), tiny)
    good, bad = _bc(tmp_path, mixed, "good"), _bc(tmp_path, random_log, "bad")

    starts = episode_starts(mixed)
    data = to_mdp_dataset(mixed)
    assert len(starts) == len(initial_observations(data)) == mixed.meta["stats"]["episodes"]
    # the rollouts start where the logged episodes started: the same first observations
    env = good.env_for(tiny, len(starts), reward="geodesic", max_steps=20)
    env.reset_where(torch.ones(len(starts), dtype=torch.bool), starts=starts[:, 0], targets=starts[:, 1])
    np.testing.assert_allclose(env.observe().numpy(), initial_observations(data), atol=1e-6)

    kw = {"n_steps": 300, "seed": 0, "gamma": 0.5, "batch_size": 64, "hidden": (64, 64), "learning_rate": 1e-3}
    est = {k: fqe_estimate(p, data, target_update_interval=20, **kw) for k, p in (("good", good), ("bad", bad))}
    truth = {k: true_value(p, tiny, starts, gamma=0.5, max_steps=20) for k, p in (("good", good), ("bad", bad))}
    assert all(np.isfinite(v) for v in est.values()), est
    assert truth["good"] > truth["bad"] + 0.5, truth
    assert est["good"] > est["bad"] + 0.5, (est, truth)
    # the same seed gives the same estimate; the algorithm itself is accepted as well as its policy
    assert fqe_estimate(good.algo, data, target_update_interval=20, **kw) == est["good"]


def _weights(algo):
    mods = algo.impl.modules.get_torch_modules()
    return {f"{m}.{k}": t.clone() for m in sorted(mods) for k, t in mods[m].state_dict().items()}


def test_the_fast_trainer_settings_train_the_same_weights_as_d3rlpys_defaults_for_the_same_seed(root, tmp_path, tiny):
    d3rlpy = import_d3rlpy()
    torch.set_num_threads(1)
    log = LogConfig(scene=TINY, behaviour="random", steps=800, num_envs=16, max_steps=20, minari=False, verbose=False)
    data = to_mdp_dataset(log_dataset(log, tiny))

    # the same minibatches, and building the fast sampler draws nothing from numpy's generator
    np.random.seed(5)
    fast = fast_sampling(data)
    a = np.random.randint(1000)
    np.random.seed(5)
    assert np.random.randint(1000) == a and fast is not data
    for seed, size in ((5, 64), (6, 4096)):  # the large batch holds terminal transitions (zero next observation)
        np.random.seed(seed)
        slow_batch = data.sample_transition_batch(size)
        np.random.seed(seed)
        fast_batch = fast.sample_transition_batch(size)
        for k in ("observations", "actions", "rewards", "next_observations", "next_actions", "terminals", "intervals"):
            got, want = getattr(fast_batch, k), getattr(slow_batch, k)
            assert got.dtype == want.dtype and np.array_equal(got, want), k
    assert fast_batch.terminals.any()

    for name in ("cql", "bc"):
        cfg = OfflineConfig(algorithm=name, batch_size=32, hidden=(16,))
        d3rlpy.seed(3)
        defaults = make_algorithm(cfg)  # d3rlpy's fit: file logger, progress bar, timestamped folder, saves
        for _ in defaults.fitter(
            data,
            n_steps=40,
            n_steps_per_epoch=10,
            logger_adapter=d3rlpy.logging.FileAdapterFactory(root_dir=str(tmp_path / "d3rlpy_logs")),
        ):
            pass
        d3rlpy.seed(3)
        ours = make_algorithm(cfg)
        losses = fit(ours, data, 40)
        assert len(losses) == 10 and losses[-1]["step"] == 40
        want, got = _weights(defaults), _weights(ours)
        assert want.keys() == got.keys() and all(torch.equal(want[k], got[k]) for k in want), name
