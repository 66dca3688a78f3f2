"""Where an agent's mover collisions and hits come from: ``python -m dtradar_rl.experiments.mover_events
<model.pt> <scene>/moving [--pairs 500 --seed 2024]`` prints, per episode of the evaluation's episodes, each kind
of event split by what the robot could have done and what it could have seen.

For every step with a mover collision or a mover hit, two questions of the true MDP
(:meth:`~dtradar_rl.task.grid_mdp.MovingGridMDP.step_at`) and of the observation: was there an action that met no
mover at the next snapshot (``avoidable``: among the four moves and, where the MDP has it, the wait; otherwise not
even perfect knowledge of the next snapshot helps at that step), and was a mover within the sensed diamond (Manhattan
distance <= the agent's sense radius) now or a snapshot before (``in_sight``; without it the observation carried no
trace of the mover and only a clock could have told). An agent trained with the clock observes its cell (``x, y``)
and the snapshot exactly, so for it every avoidable event is a failure to learn, not to observe.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_rl.agents.policy import Policy
from dtradar_rl.evaluation.evaluate import sample_eval_pairs
from dtradar_rl.task.grid_mdp import ACTIONS, WAIT


def mover_events(policy: Policy, ds: Dataset, pairs: int = 500, seed: int = 2024) -> dict[str, float]:
    """Events per episode on ``pairs`` evaluation episodes of ``ds`` (a moving twin; the evaluation's pairs):
    ``<kind>`` (``collision``, ``hit`` or ``collision+hit``: both in one step), ``<kind>|avoidable=<bool>``,
    ``<kind>|in_sight=<bool>``, their product, and ``action=<a>|<kind>`` (the action that met the mover)."""
    episodes = sample_eval_pairs(ds, pairs, seed)
    n = len(episodes)
    env = policy.env_for(ds, n, reward="paper")
    mdp, radius = env.mdp, policy.sense_radius
    env.reset_where(torch.ones(n, dtype=torch.bool), starts=episodes[:, 0], targets=episodes[:, 1], t0=episodes[:, 2])
    iy, ix = np.divmod(np.arange(mdp.num_cells), mdp.nx)
    near = (np.abs(ix[:, None] - ix[None]) + np.abs(iy[:, None] - iy[None])) <= radius  # [cells, cells]
    actions = range(len(ACTIONS) + int(env.wait_action))
    done = torch.zeros(n, dtype=torch.bool)
    counts: Counter[str] = Counter()
    while not bool(done.all()):
        cell, t = env.cell.numpy().copy(), env.t.numpy().copy()
        action = policy.act(env.observe())
        _, _, terminated, truncated, info = env.step(action)
        met = (~done).numpy() & (info["mover_collision"].numpy() | info["mover_hit"].numpy())
        for i in np.flatnonzero(met):
            c, s = int(cell[i]), int(t[i])
            avoidable = any(not any(mdp.step_at(c, s, a)[3:]) for a in actions)
            seen = bool((mdp.mover[s] | mdp.mover[(s - 1) % mdp.snapshots])[near[c]].any())
            collision, hit = bool(info["mover_collision"][i]), bool(info["mover_hit"][i])
            kind = "collision+hit" if collision and hit else "collision" if collision else "hit"
            a = int(action[i])
            name = "wait" if a == WAIT else ACTIONS[a]
            for key in (kind, f"{kind}|avoidable={avoidable}", f"{kind}|in_sight={seen}", f"action={name}|{kind}"):
                counts[key] += 1
            counts[f"{kind}|avoidable={avoidable}|in_sight={seen}"] += 1
        done |= terminated | truncated
    return {k: v / n for k, v in sorted(counts.items())}


def main(argv: list[str] | None = None) -> None:
    from dtradar_rl.task.twins import load_dataset
    from dtradar_rl.train.saved_runs import load_policy

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoint")
    parser.add_argument("twin", help="a moving twin, e.g. cubicle/moving")
    parser.add_argument("--pairs", type=int, default=500)
    parser.add_argument("--seed", type=int, default=2024)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    events = mover_events(load_policy(args.checkpoint), load_dataset(args.twin), args.pairs, args.seed)
    print(json.dumps({k: round(v, 4) for k, v in events.items()}, indent=1))


if __name__ == "__main__":
    main()
