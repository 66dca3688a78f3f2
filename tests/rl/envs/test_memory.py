import numpy as np
import pytest
import torch

from dtradar_rl.envs.memory import MemoryGymEnv, MemoryLayout, MemoryNavEnv
from dtradar_rl.task.observations import OBS_DIMS, Normalizer
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import config_for


@pytest.fixture(scope="module")
def dyn():
    return load_dataset("synthetic-12x8/dynamic")


@pytest.mark.parametrize(("bumps", "visits"), [(False, False), (True, False), (False, True), (True, True)])
def test_memory_agents_in_the_batched_env_agree_step_for_step_with_the_gymnasium_env(dyn, bumps, visits):
    norm, n, steps = Normalizer.fit(dyn), 12, 30
    kw = {
        "reward": "geodesic",
        "normalizer": norm,
        "max_steps": steps,
        "memory_radius": 3,
        "memory_bumps": bumps,
        "memory_visits": visits,
    }
    batched = MemoryNavEnv.from_dataset(dyn, n, **kw)
    envs = [MemoryGymEnv(dyn, **kw) for _ in range(n)]
    rng = np.random.default_rng(0)
    pairs = envs[0].mdp.sample_pairs(n, rng)
    batched.reset_where(torch.ones(n, dtype=torch.bool), starts=pairs[:, 0], targets=pairs[:, 1])
    first = np.stack(
        [e.reset(options={"start": e.mdp.xy(s), "target": e.mdp.xy(t)})[0] for e, (s, t) in zip(envs, pairs)]
    )
    np.testing.assert_allclose(batched.observe().numpy(), first, rtol=1e-6)
    done = np.zeros(n, bool)
    for _ in range(steps):
        actions = rng.integers(0, 4, n)
        obs_b, rew_b, term_b, trunc_b, _ = batched.step(torch.as_tensor(actions))
        for i, e in enumerate(envs):
            if done[i]:
                continue
            o, r, te, tr, _ = e.step(actions[i])
            np.testing.assert_allclose(obs_b[i].numpy(), o, rtol=1e-6)
            assert rew_b[i].item() == pytest.approx(r, abs=1e-5)
            assert (bool(term_b[i]), bool(trunc_b[i])) == (te, tr)
            done[i] = te or tr
    assert done.all()


def test_the_memory_window_keeps_an_obstacle_sensed_earlier_after_the_robot_moves_away():
    ds = load_dataset("synthetic-12x8/blueprint")
    env = MemoryGymEnv(ds, memory_radius=3, max_steps=50)
    blocked = env.mdp.blocked
    # a wall cell with two free cells on one side: stand beside it, then step away from it
    iy, ix, side_x = next(
        (int(y), int(x), sx)
        for y, x in np.argwhere(blocked)
        for sx in (-1, 1)
        if 0 <= x + 2 * sx < env.mdp.nx and not blocked[y, x + sx] and not blocked[y, x + 2 * sx]
    )
    start, away = (ix + side_x, iy), (0 if side_x < 0 else 1)
    target = next(
        (x, y)
        for y in range(env.mdp.ny)
        for x in range(env.mdp.nx)
        if not blocked[y, x] and (x, y) != start and env.mdp.connected(env.mdp.cell(*start), env.mdp.cell(x, y))
    )
    obs, _ = env.reset(options={"start": start, "target": target})
    obs, _, _, _, info = env.step(away)
    assert not info["collision"]
    lay, base = env.layout, OBS_DIMS["neighbors"]
    r, side = lay.radius, 2 * lay.radius + 1
    (x, y), dx = info["cell"], ix - info["cell"][0]
    assert abs(dx) == 2 and y == iy
    assert obs[base + r * side + dx + r] == 1.0  # sensed: the wall, now out of reach
    assert obs[base + side * side + r * side + (start[0] - x) + r] == 1.0  # visited: where it stood


def test_the_memory_preset_is_robust_plus_a_memory_window_and_needs_neighbour_observations():
    cfg = config_for("memory", scene="synthetic")
    assert cfg.memory_radius == 5 and cfg.aug_obstacles == config_for("robust").aug_obstacles
    with pytest.raises(ValueError, match="--memory-radius needs --obs neighbors"):
        config_for("memory", scene="synthetic", obs="goal")
    assert MemoryLayout(12, 8, 5).dim == 2 * 11 * 11


def test_a_tiny_memory_agent_trains_saves_and_evaluates(tmp_path):
    from dtradar_rl.evaluation.evaluate import evaluate
    from dtradar_rl.train.dqn import train
    from dtradar_rl.train.saved_runs import load_policy

    cfg = config_for(
        "memory",
        scene="synthetic-12x8",
        total_env_steps=1_000,
        num_envs=16,
        learning_starts=200,
        memory_radius=2,
        out=str(tmp_path),
        verbose=False,
        threads=1,
    )
    result = train(cfg)
    policy = load_policy(result.checkpoint)
    metrics, _ = evaluate(policy, load_dataset("synthetic-12x8/dynamic"), pairs=10)
    assert 0.0 <= metrics.success_rate <= 1.0 and metrics.latency_ms > 0


def test_the_bump_map_marks_the_cell_a_failed_move_aimed_at_and_only_that():
    ds = load_dataset("synthetic-12x8/blueprint")
    env = MemoryGymEnv(ds, memory_radius=2, memory_bumps=True, max_steps=50)
    assert env.layout.channels[-1] == "bumped" and env.observation_space.shape[0] == OBS_DIMS["neighbors"] + 3 * 25
    blocked = env.mdp.blocked
    iy, ix, a = next(
        (int(y), int(x) - 1, 1)  # stand left of a wall cell, move X+ into it
        for y, x in np.argwhere(blocked)
        if x >= 1 and not blocked[y, x - 1]
    )
    target = next((int(x), int(y)) for y, x in np.argwhere(~blocked) if (x, y) != (ix, iy))
    obs, _ = env.reset(options={"start": (ix, iy), "target": target})
    bump = slice(OBS_DIMS["neighbors"] + 2 * 25, None)
    assert obs[bump].sum() == 0
    obs, _, _, _, info = env.step(a)
    assert info["collision"] and obs[bump].sum() == 1
    assert obs[bump].reshape(5, 5)[2, 3] == 1  # the window's centre row, one cell towards +x


def test_visits_here_counts_the_earlier_stands_on_the_current_cell_in_this_episode():
    ds = load_dataset("synthetic-12x8/blueprint")
    env = MemoryGymEnv(ds, memory_radius=2, memory_visits=True, max_steps=50)
    free = np.argwhere(~env.mdp.blocked)
    (y, x) = next((int(y), int(x)) for y, x in free if x + 1 < env.mdp.nx and not env.mdp.blocked[y, x + 1])
    target = next((int(tx), int(ty)) for ty, tx in free if (tx, ty) not in ((x, y), (x + 1, y)))
    obs, _ = env.reset(options={"start": (x, y), "target": target})
    seen = [obs[-1]]
    for a in (1, 0, 1, 0):  # X+, X-, X+, X-: back and forth between two cells
        obs, *_ = env.step(a)
        seen.append(obs[-1])
    assert seen == [0, 0, 1, 1, 2] and env.layout.names[-1] == "visits_here"
    obs, _ = env.reset(options={"start": (x, y), "target": target})
    assert obs[-1] == 0  # a new episode forgets


def test_memory_state_restored_by_setattr_as_a_resumed_run_does_gives_the_same_observations(dyn, tmp_path):
    kw = {"normalizer": Normalizer.fit(dyn), "memory_radius": 3, "memory_bumps": True, "memory_visits": True}
    a, b = MemoryNavEnv.from_dataset(dyn, 5, seed=1, **kw), MemoryNavEnv.from_dataset(dyn, 5, seed=2, **kw)
    a.reset()
    gen = torch.Generator().manual_seed(0)
    for _ in range(12):
        a.step(torch.randint(4, (5,), generator=gen))
    torch.save({k: getattr(a, k) for k in a.state_keys}, tmp_path / "state.pt")  # what a training checkpoint saves
    b.reset()
    for k, v in torch.load(tmp_path / "state.pt").items():
        setattr(b, k, v)
    assert torch.equal(a.observe(), b.observe())
    actions = torch.randint(4, (5,), generator=gen)
    assert torch.equal(a.step(actions)[0], b.step(actions)[0])
    assert all(torch.equal(getattr(a, k), getattr(b, k)) for k in a.state_keys)
