"""Off-policy evaluation beside the truth: d3rlpy's Fitted Q Evaluation of a trained agent, from the logged data
alone, next to the value the agent really gets when it is rolled out on the twin.

    from dtradar_rl.offline.ope import episode_starts, fqe_estimate, true_value
    est = fqe_estimate(policy, logged, n_steps=2000, seed=0, gamma=0.9)      # from the logged transitions only
    starts = episode_starts(logged)                                          # (start, target) of every episode
    truth = true_value(policy, twin, starts, gamma=0.9, reward="geodesic", max_steps=240)

**The value** of a policy π here is its expected discounted return from the logged dataset's episode starts,
``V = mean over episodes of Σ_t γ^t r_t`` with the logged reward (``meta.settings.reward``, e.g. geodesic), in the
return's units (no reward scaling), π acting greedily and unshielded (``algo.predict``, as the benchmark evaluates it).

- :func:`fqe_estimate` fits ``d3rlpy.ope.DiscreteFQE`` (Le et al. 2019: ``Q(s, a) ← r + γ Q'(s', π(s'))`` on the
  logged transitions, terminals not bootstrapped, time-limit cuts bootstrapped) and returns the mean of
  ``Q(s₀, π(s₀))`` over the first observation of every logged episode. Nothing but the logged data is read.
- :func:`true_value` rolls π out on the twin from the same (start, target) pairs (:func:`episode_starts`), with the
  same reward and step limit as the logging, and averages the discounted returns. The sum stops at the step limit
  (where FQE bootstraps on): with γ = 0.9 and the cubicle's limit of 240 steps that differs by γ^240 ≈ 1e-11 of the
  largest value; with γ close to 1 on a short limit it would not (see :func:`true_value`).

γ is a choice of the evaluation, the same for both sides (the benchmark's ``--fqe-gamma``, default
:data:`FQE_GAMMA`): the agents train with γ = 0.5, under which every reasonable agent's value is a few steps of
progress toward the target; at 0.9 the value reaches about ten steps ahead, where the agents differ.

The offline benchmark (``offline-bench``, ``--no-fqe`` to skip) reports both per agent, and the Spearman rank
correlation across agents: whether FQE orders the agents as the twin does, which is what model selection needs.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.store.logged import LoggedDataset
from dtradar_rl.agents.policy import Policy
from dtradar_rl.offline.formats import as_logged, import_d3rlpy
from dtradar_rl.offline.policy import d3rlpy_device
from dtradar_rl.offline.trainer import fit, mdp_dataset

#: FQE's defaults in the benchmark, validated on the cubicle twin (18 agents: 6 algorithms x random, noisy-shortest
#: and expert data, 1000 updates each): at γ = 0.9 and 2000 updates (100 target syncs, 0.9^100 ≈ 3e-5 of the initial
#: error left) FQE's ranking had a Spearman correlation of 0.63 with the true values (0.83 / 0.31 / 1.0 within each
#: dataset); at 1000 updates -0.10, with a 64 x 64 network -0.31 (it ranked the datasets, not the agents); at γ = 0.5
#: (the agents' own discount; 500 updates) the true values of 17 of the 18 lay within 1.5-1.9 (a few steps toward the
#: target) and the correlation was -0.51
FQE_GAMMA = 0.9
FQE_STEPS = 2000
FQE_TARGET_INTERVAL = 20
#: a rollout stops once γ^t is below this: later rewards cannot move the value by more than this x the largest one
DISCOUNT_FLOOR = 1e-12


def _algo(algo_or_policy: Any):
    """The d3rlpy algorithm of an :class:`~dtradar_rl.offline.policy.OfflinePolicy` (or the algorithm itself)."""
    algo = getattr(algo_or_policy, "algo", None) or algo_or_policy
    if not hasattr(algo, "predict_value") or getattr(algo, "impl", None) is None:
        raise TypeError(f"expected a trained d3rlpy algorithm or an OfflinePolicy, got {type(algo_or_policy)!r}")
    return algo


def _replay(logged: LoggedDataset | str | Any):
    """A d3rlpy dataset: ``logged`` itself when it already is one, else the logged dataset opened (or the copy the
    trainer opened in this process, :func:`dtradar_rl.offline.trainer.mdp_dataset`)."""
    if hasattr(logged, "sample_transition_batch"):
        return logged
    return mdp_dataset(as_logged(logged))


def initial_observations(data) -> np.ndarray:
    """``float32[E, D]``: the first observation of every episode of a d3rlpy dataset (its episode starts)."""
    return np.stack([ep.observations[0] for ep in data.episodes]).astype(np.float32)


def episode_starts(logged: LoggedDataset | str) -> np.ndarray:
    """``int64[E, 2]``: the (start cell, target cell) of every logged episode, in episode order (the order of
    :func:`initial_observations` of its d3rlpy dataset)."""
    a = as_logged(logged).arrays()
    first = a["step"] == 0
    return np.stack([a["cell"][first], a["target"][first]], 1).astype(np.int64)


def fqe_estimate(
    algo_or_policy: Any,
    logged_dataset: LoggedDataset | str | Any,
    *,
    n_steps: int = FQE_STEPS,
    seed: int = 0,
    gamma: float,
    batch_size: int = 256,
    learning_rate: float = 3e-4,
    hidden: tuple[int, ...] = (256, 256),
    target_update_interval: int = FQE_TARGET_INTERVAL,
    device: str = "cpu",
) -> float:
    """FQE's estimate of the greedy policy's value on ``logged_dataset``'s episode starts (see the module docs).

    ``algo_or_policy``: a trained d3rlpy algorithm or an :class:`~dtradar_rl.offline.policy.OfflinePolicy`;
    ``logged_dataset``: a stored logged dataset (or its name), or the d3rlpy dataset made from it. FQE's own
    Q-network (``hidden`` ReLU layers, Adam at ``learning_rate``, minibatches of ``batch_size``, a hard target sync
    every ``target_update_interval`` updates) is seeded with ``seed`` and trained ``n_steps`` updates with the
    trainer's settings (:func:`dtradar_rl.offline.trainer.fit`). The torch thread count is the caller's.
    """
    d3rlpy = import_d3rlpy()
    algo = _algo(algo_or_policy)
    data = _replay(logged_dataset)
    if not 0 < gamma <= 1:
        raise ValueError(f"gamma must be in (0, 1], got {gamma}")
    d3rlpy.seed(seed)
    config = d3rlpy.ope.FQEConfig(
        learning_rate=learning_rate,
        batch_size=batch_size,
        gamma=gamma,
        target_update_interval=target_update_interval,
        encoder_factory=d3rlpy.models.VectorEncoderFactory(hidden_units=list(hidden)),
    )
    fqe = d3rlpy.ope.DiscreteFQE(algo=algo, config=config, device=d3rlpy_device(device))
    fit(fqe, data, n_steps)
    s0 = initial_observations(data)
    values = fqe.predict_value(s0, algo.predict(s0))
    return float(np.mean(values))


def true_value(
    policy: Policy,
    twin: Dataset,
    starts: np.ndarray,
    *,
    gamma: float,
    reward: str = "geodesic",
    max_steps: int | None = None,
    device: str = "cpu",
) -> float:
    """The mean discounted return ``Σ_t γ^t r_t`` of ``policy`` (greedy, unshielded) rolled out on ``twin`` from every
    (start, target) pair of ``starts`` (``int[N, 2]``, e.g. :func:`episode_starts`), with ``reward`` and the episode
    step limit ``max_steps`` (default the twin's ``4·(nx + ny)``): use the logged dataset's ``settings`` so the value
    is the one FQE estimates.

    An episode ends at the target (terminal: nothing after it counts) or at the step limit (its return stops there,
    where FQE would bootstrap: the two agree up to ``γ^max_steps`` times the largest value). The sum also stops once
    ``γ^t`` is below :data:`DISCOUNT_FLOOR`.
    """
    if not 0 < gamma <= 1:
        raise ValueError(f"gamma must be in (0, 1], got {gamma}")
    pairs = np.asarray(starts, np.int64).reshape(-1, 2)
    n = len(pairs)
    if n == 0:
        raise ValueError("no (start, target) pairs to roll out from")
    # target_pool=1: the shaped reward's distance rows are computed for the rolled-out targets only (added by
    # reset_where), not for every free cell: 19 s -> 1.7 s on a Dallas quadrant, the same rewards
    env = policy.env_for(twin, n, reward=reward, max_steps=max_steps or None, device=device, target_pool=1)
    env.reset_where(torch.ones(n, dtype=torch.bool), starts=pairs[:, 0], targets=pairs[:, 1])
    done = torch.zeros(n, dtype=torch.bool, device=env.device)
    ret = torch.zeros(n, dtype=torch.float64, device=env.device)
    discount = 1.0
    while not bool(done.all()) and discount >= DISCOUNT_FLOOR:
        _, r, terminated, truncated, _ = env.step(policy.act(env.observe()))
        ret += torch.where(done, 0.0, discount * r.double())
        done |= terminated | truncated
        discount *= gamma
    return float(ret.mean())


__all__ = [
    "DISCOUNT_FLOOR",
    "FQE_GAMMA",
    "FQE_STEPS",
    "FQE_TARGET_INTERVAL",
    "episode_starts",
    "fqe_estimate",
    "initial_observations",
    "true_value",
]
