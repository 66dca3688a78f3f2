"""On a twin with two transmitters the batched torch env and the gymnasium env agree step for step (plain, with the
wider ring, with memory), the gymnasium checker passes, and noise and obstacle augmentation keep the layout."""

import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env

from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.memory import MemoryGymEnv, MemoryNavEnv, flag_columns
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.task.observations import Normalizer, obs_dim, tx_names

STEPS = 30


def _pairs(env, n, seed=0):
    return env.mdp.sample_pairs(n, np.random.default_rng(seed))


def _agree(batched, envs, pairs, seed):
    xy = batched.mdp.xy
    batched.reset_where(torch.ones(len(envs), dtype=torch.bool), starts=pairs[:, 0], targets=pairs[:, 1])
    first = np.stack([e.reset(options={"start": xy(s), "target": xy(t)})[0] for e, (s, t) in zip(envs, pairs)])
    np.testing.assert_allclose(batched.observe().numpy(), first, rtol=1e-6)
    rng = np.random.default_rng(seed)
    done = np.zeros(len(envs), bool)
    for _ in range(STEPS):
        actions = rng.integers(0, 4, len(envs))
        obs_b, rew_b, term_b, trunc_b, info_b = batched.step(torch.as_tensor(actions))
        for i, e in enumerate(envs):
            if done[i]:
                continue
            o, r, te, tr, info = e.step(actions[i])
            np.testing.assert_allclose(obs_b[i].numpy(), o, rtol=1e-6)
            assert rew_b[i].item() == pytest.approx(r, rel=1e-5, abs=1e-5)
            assert (bool(term_b[i]), bool(trunc_b[i]), bool(info_b["collision"][i])) == (te, tr, info["collision"])
            done[i] = te or tr
    assert done.all()


@pytest.mark.parametrize(
    "obs,radius,fast", [("goal", 1, True), ("neighbors", 1, True), ("neighbors", 1, False), ("neighbors", 2, True)]
)
def test_batched_and_gymnasium_envs_agree_step_for_step_on_a_twin_with_two_transmitters(two_tx, obs, radius, fast):
    norm = Normalizer.fit(two_tx)
    kw = dict(obs=obs, reward="geodesic", normalizer=norm, max_steps=STEPS, sense_radius=radius)
    n = 16
    batched = BatchedNavEnv.from_dataset(two_tx, n, seed=3, fast_path=fast, **kw)
    assert batched.obs_dim == obs_dim(obs, 2, radius)
    envs = [DtradarNavEnv(two_tx, **kw) for _ in range(n)]
    _agree(batched, envs, _pairs(batched, n), seed=0)


def test_memory_envs_agree_step_for_step_on_a_twin_with_two_transmitters(two_tx):
    norm = Normalizer.fit(two_tx)
    kw = dict(reward="geodesic", normalizer=norm, max_steps=STEPS, memory_radius=2, memory_bumps=True)
    n = 12
    batched = MemoryNavEnv.from_dataset(two_tx, n, seed=1, memory_visits=True, **kw)
    envs = [MemoryGymEnv(two_tx, memory_visits=True, **kw) for _ in range(n)]
    _agree(batched, envs, _pairs(batched, n, seed=1), seed=2)


def test_the_gymnasium_env_of_a_twin_with_two_transmitters_passes_the_checker(two_tx):
    env = DtradarNavEnv(two_tx, obs="neighbors")
    check_env(env, skip_render_check=True)
    assert env.observation_space.shape == (obs_dim("neighbors", 2),)


def test_noise_and_augmented_obstacles_keep_the_further_transmitters_columns(two_tx):
    norm = Normalizer.fit(two_tx)
    env = BatchedNavEnv.from_dataset(two_tx, 64, obs="neighbors", normalizer=norm, noise="realistic", seed=0)
    names = env.obs_table.names
    cols = [names.index(c) for c in tx_names(1)]
    obs = env.reset()
    heard = torch.as_tensor(env.obs_table.heard_by[:, 1])[env.cell]
    assert torch.equal(obs[:, cols[-1]], heard.float())  # the flag is not perturbed
    assert bool((obs[heard][:, cols[:-1]] != env.cell_part[env.cell][heard][:, cols[:-1]]).any(1).all())
    assert torch.all(obs[~heard][:, cols[:-1]] == 0)
    aug = BatchedNavEnv.from_dataset(two_tx, 64, obs="neighbors", normalizer=norm, aug_obstacles=3, seed=0)
    o = aug.reset()
    hidden = aug.extra.gather(1, aug.next_cell[aug.cell])
    assert hidden.any() and torch.all(o[:, flag_columns()][hidden] == 0)
    # the robot's own cell is never an extra obstacle: its transmitter-1 columns are the table's
    assert torch.equal(o[:, cols], aug.cell_part[aug.cell][:, cols])


def test_the_memory_senses_a_street_heard_only_from_the_second_transmitter_as_free(two_tx):
    env = MemoryNavEnv.from_dataset(two_tx, 1, normalizer=Normalizer.fit(two_tx), memory_radius=1)
    heard, mdp = env.obs_table.heard_by, env.mdp
    only_tx1 = np.flatnonzero(heard[:, 1] & ~heard[:, 0])
    silent = np.flatnonzero(mdp.free.ravel() & ~heard.any(1))
    assert only_tx1.size and silent.size
    names = env.obs_names
    for cell, sensed in ((only_tx1, 0.0), (silent, 1.0)):
        # a free cell next to one of them, and the window column of that neighbour
        start, a = next(
            (int(s), a) for s in np.flatnonzero(mdp.free.ravel()) for a in range(4) if mdp.next_cell[s, a] in cell
        )
        target = next(int(t) for t in mdp.pair_cells() if t != start and mdp.connected(t, start))
        env.reset_where(torch.ones(1, dtype=torch.bool), starts=[start], targets=[target])
        dx, dy = ((-1, 0), (1, 0), (0, -1), (0, 1))[a]
        assert env.observe()[0, names.index(f"sensed[{dx:+d},{dy:+d}]")].item() == sensed
