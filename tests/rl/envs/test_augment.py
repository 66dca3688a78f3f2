"""Obstacle augmentation of the batched env (domain randomisation): off = unchanged, on = extra obstacles that act
and read exactly like blocked cells of a ray-traced table, with starts and targets kept free and connected."""

import numpy as np
import pytest
import torch

from dtradar_data.core.errors import InvalidCoordinatesError, UnknownNameError
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.twins import load_dataset, synthetic_blocked
from dtradar_rl.train.config import PRESETS, config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.train.saved_runs import load_policy

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def synth():
    return load_dataset("synthetic/blueprint")


def twin_with(extra: np.ndarray):
    """The synthetic 42 x 18 twin with ``extra`` cells blocked too. Its radio features are free-space line of sight,
    independent of obstacles, so this is exactly the table a re-traced twin with those obstacles would have."""
    blocked = synthetic_blocked(42, 18, "blueprint") | extra.reshape(18, 42)
    return synthetic_dataset(
        42, 18, blocked, cell_m=0.25, tx=(42 * 0.25 / 2, 18 * 0.25 / 2, 3.0), name="synthetic/augmented"
    )


def aug_env(ds, n=64, **kw):
    kw = {"obs": "neighbors", "reward": "geodesic", "seed": 5, "aug_obstacles": 6, "aug_obstacle_size": 2, **kw}
    env = BatchedNavEnv.from_dataset(ds, n, **kw)
    env.reset()
    return env


def _trace(env, steps=300, seed=1):
    g = torch.Generator().manual_seed(seed)
    cells, rewards = [env.cell.clone()], []
    for _ in range(steps):
        _, r, te, tr, _ = env.step(torch.randint(4, (env.num_envs,), generator=g))
        env.reset_where(te | tr)
        cells += [env.cell.clone(), env.target.clone()]
        rewards.append(r)
    return torch.stack(cells).numpy().astype(np.int64), torch.stack(rewards).numpy()


def test_without_augmentation_the_env_is_bit_identical_to_before(synth):
    # Golden numbers recorded with the batched env as it was before augmentation existed (same torch RNG streams).
    plain = BatchedNavEnv.from_dataset(synth, 64, obs="neighbors", reward="geodesic", seed=7)
    off = BatchedNavEnv.from_dataset(
        synth,
        64,
        obs="neighbors",
        reward="geodesic",
        seed=7,
        aug_obstacles=0,
        aug_obstacle_size=3,
        aug_potential="blueprint",
    )
    assert not hasattr(off, "extra") and off.state_keys == ("cell", "target", "tpool", "steps")
    plain.reset(), off.reset()
    a, b = _trace(plain), _trace(off)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert a[0][:3, :8].tolist() == [
        [259, 395, 174, 224, 510, 610, 386, 243],
        [260, 437, 173, 223, 552, 611, 428, 244],
        [559, 367, 315, 393, 187, 236, 238, 41],
    ]
    assert int(a[0].sum()) == 14893568 and float(a[1].sum()) == -1951.0


def test_extra_obstacles_never_sit_on_the_start_or_target_and_leave_them_connected(synth):
    env = aug_env(synth, n=256)
    rows = torch.arange(env.num_envs)
    for _ in range(3):
        assert env.extra.sum(1).float().mean() > 6  # up to 2x2 cells per obstacle
        assert not env.extra[rows, env.cell].any() and not env.extra[rows, env.target].any()
        assert (env.adist[rows, env.cell] > 0).all() and (env.adist[rows, env.target] == 0).all()
        assert not (env.extra & ~env.free_mask).any()  # only on free cells of the table
        for i in range(0, env.num_envs, 97):  # connected on the augmented grid
            b = np.asarray(synth.blocked, bool).ravel() | env.extra[i].numpy()
            mdp = GridMDP.from_blocked(b.reshape(synth.blocked.shape))
            assert mdp.connected(int(env.cell[i]), int(env.target[i]))
            assert np.array_equal(mdp.bfs_distances(int(env.target[i])), env.adist[i].numpy())
        env.reset_where(torch.ones(env.num_envs, dtype=torch.bool))


def test_moving_into_an_extra_obstacle_is_a_collision_and_the_robot_stays(synth):
    env = aug_env(synth, n=256)
    into = env.extra.gather(1, env.next_cell[env.cell])  # [N, 4]: move leads into an obstacle
    robots, actions = torch.nonzero(into, as_tuple=True)
    assert robots.numel() > 0
    i, a = int(robots[0]), int(actions[0])
    before = env.cell.clone()
    act = torch.zeros(env.num_envs, dtype=torch.long)
    act[i] = a
    _, reward, terminated, _, info = env.step(act)
    assert bool(info["collision"][i]) and int(env.cell[i]) == int(before[i]) and not bool(terminated[i])
    assert float(reward[i]) == -1.0  # collision penalty, no shaping change


def test_an_extra_obstacle_reads_like_a_blocked_neighbour_in_the_table(synth):
    env = aug_env(synth, n=32)
    norm = Normalizer.fit(synth)
    obs = env.observe().numpy()
    flags = [k for k, nm in enumerate(env.obs_table.names) if nm.endswith(":has_radio")]
    for i in range(env.num_envs):
        table = DtradarNavEnv(twin_with(env.extra[i].numpy()), obs="neighbors", normalizer=norm).table
        np.testing.assert_array_equal(obs[i], table.observe(int(env.cell[i]), int(env.target[i])))
        hidden = env.extra[i, env.next_cell[env.cell[i]]].numpy()
        assert (obs[i, flags][hidden] == 0).all()
    # and in general: over many robots some neighbours are extra obstacles, with flag and features all 0
    env = aug_env(synth, n=512)
    obs = env.observe()
    hidden = env.extra.gather(1, env.next_cell[env.cell])
    cols = env._nbr_cols  # [4, 9]: 8 radio features + flag
    assert hidden.any() and (obs[:, cols][hidden] == 0).all()


def test_augmented_env_equals_the_single_env_on_a_twin_with_those_cells_blocked(synth):
    norm = Normalizer.fit(synth)
    env = aug_env(synth, n=8, max_steps=40)
    singles = []
    for i in range(env.num_envs):
        e = DtradarNavEnv(
            twin_with(env.extra[i].numpy()), obs="neighbors", reward="geodesic", normalizer=norm, max_steps=40
        )
        e.reset(options={"start": env.mdp.xy(int(env.cell[i])), "target": env.mdp.xy(int(env.target[i]))})
        singles.append(e)
    rng = np.random.default_rng(0)
    done = np.zeros(env.num_envs, bool)
    for _ in range(40):
        actions = rng.integers(0, 4, env.num_envs)
        obs_b, rew_b, term_b, trunc_b, info_b = env.step(torch.as_tensor(actions))
        for i, e in enumerate(singles):
            if done[i]:
                continue
            o, r, te, tr, info = e.step(actions[i])
            np.testing.assert_array_equal(obs_b[i].numpy(), o)
            assert rew_b[i].item() == pytest.approx(r, abs=1e-6)  # replanned geodesic potential
            assert (bool(term_b[i]), bool(trunc_b[i]), bool(info_b["collision"][i])) == (te, tr, info["collision"])
            done[i] = te or tr
    assert done.all()


def test_blueprint_potential_shapes_with_the_tables_distances(synth):
    env = aug_env(synth, n=256, aug_potential="blueprint")
    mdp = env.mdp
    g = torch.Generator().manual_seed(0)
    for _ in range(5):
        before = env.cell.clone()
        a = torch.randint(4, (env.num_envs,), generator=g)
        _, reward, terminated, _, info = env.step(a)
        for i in range(0, env.num_envs, 17):
            d = mdp.bfs_distances(int(env.target[i]))
            expected = d[int(before[i])] - d[int(env.cell[i])] + float(terminated[i]) - float(info["collision"][i])
            assert float(reward[i]) == expected
        env.reset_where(terminated)


def test_explicit_pairs_keep_their_cells_free(synth):
    env = aug_env(synth, n=128)
    pairs = env.mdp.sample_pairs(128, np.random.default_rng(3))
    env.reset_where(torch.ones(128, dtype=torch.bool), starts=pairs[:, 0], targets=pairs[:, 1])
    rows = torch.arange(128)
    assert env.cell.tolist() == pairs[:, 0].tolist() and env.target.tolist() == pairs[:, 1].tolist()
    assert not env.extra[rows, env.cell].any() and (env.adist[rows, env.cell] > 0).all()


def test_bad_augmentation_settings_raise_typed_errors(synth):
    with pytest.raises(InvalidCoordinatesError):
        BatchedNavEnv.from_dataset(synth, 4, aug_obstacles=-1)
    with pytest.raises(UnknownNameError, match="replan"):
        BatchedNavEnv.from_dataset(synth, 4, aug_obstacles=1, aug_potential="replann")
    with pytest.raises(ConfigError):
        config_for("tuned", aug_obstacle_size=0)
    with pytest.raises(UnknownNameError):
        config_for("tuned", aug_potential="map")


def test_the_robust_preset_validates_and_only_adds_augmentation_to_tuned():
    cfg = config_for("robust", scene="synthetic")
    tuned = config_for("tuned", scene="synthetic")
    assert cfg.preset == "robust" and cfg.aug_obstacles > 0
    assert tuned.aug_obstacles == 0
    changed = {k for k, v in cfg.to_dict().items() if v != tuned.to_dict()[k]}
    assert changed <= {"preset"} | set(PRESETS["robust"])
    assert {k for k in changed if not k.startswith("aug_")} <= {"preset", "total_env_steps"}


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_resumed_augmented_training_equals_an_uninterrupted_run(tmp_path):
    cfg = {
        "scene": "synthetic-12x8",
        "num_envs": 32,
        "hidden": (32,),
        "batch_size": 64,
        "learning_starts": 500,
        "env_steps_per_update": 8,
        "target_update_every": 50,
        "buffer_size": 1_000,
        "eps_start": 0.3,
        "eps_end": 0.3,
        "lr_end": -1.0,
        "threads": 1,
        "verbose": False,
        "checkpoint_every": 0,
        "aug_obstacles": 2,
        "aug_obstacle_size": 2,
    }
    full = train(config_for("tuned", out=str(tmp_path / "full"), total_env_steps=3_200, **cfg))
    train(config_for("tuned", out=str(tmp_path / "res"), total_env_steps=1_600, **cfg))
    resumed = train(config_for("tuned", out=str(tmp_path / "res"), resume=True, total_env_steps=3_200, **cfg))
    assert resumed.env_steps == full.env_steps and resumed.episodes == full.episodes
    qa, qb = load_policy(full.checkpoint).q.state_dict(), load_policy(resumed.checkpoint).q.state_dict()
    assert all(torch.equal(qa[k], qb[k]) for k in qa)
