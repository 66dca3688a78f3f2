"""How the OGBench-style dataset families walk: ``navigate``, ``stitch`` and ``explore``.

OGBench (Park et al. 2024, arXiv 2410.20092) names its goal-conditioned datasets by how they were collected, beside
D4RL's levels of skill (:data:`~dtradar_rl.offline.behaviours.FAMILIES`). Here, on a twin's grid:

- ``navigate``: a noisy expert (the breadth-first shortest-path move with probability
  :data:`NAVIGATE_SHORTEST_PROB`, else a uniformly random move) walking to random goals one after another. When it
  reaches a goal the MDP's episode ends there (a terminal step, as every logged episode) and the next one starts on
  that very cell with a new goal drawn uniformly from its component, so each robot's log is one unbroken walk through
  many goals: the trajectories do not stop at a goal, OGBench's ``navigate``.
- ``stitch``: the same noisy expert on short hops: every episode starts on a random cell and its goal is a cell within
  :data:`STITCH_HOP` moves (Manhattan distance, the same component) of it, so no logged episode joins the far pairs
  an evaluation draws: an agent must stitch hops together (OGBench's ``stitch``).
- ``explore``: near-random coverage: a random walk that keeps its last move with probability :data:`EXPLORE_KEEP`
  (after a bump it always draws a new one), which travels further than uniformly random moves; the logged goals are
  the env's random ones, for relabelling to replace (OGBench's ``explore``).

The walk's parameters enter the dataset's version (:meth:`~dtradar_rl.offline.behaviours.BehaviourSpec.to_dict`).
"""

from __future__ import annotations

import torch

#: The OGBench-style families, in the order ``--behaviour all`` logs them (after D4RL's).
KINDS: tuple[str, ...] = ("navigate", "stitch", "explore")
#: ``navigate`` and ``stitch``: probability of the shortest-path move (the ``expert`` family's is 0.95; not tuned).
NAVIGATE_SHORTEST_PROB = 0.9
#: ``stitch``: the farthest a hop's goal lies from its start, in moves (Manhattan; not tuned).
STITCH_HOP = 8
#: ``explore``: probability of keeping the last move (not tuned).
EXPLORE_KEEP = 0.8
#: ``stitch``: rounds of drawing a near goal before a robot keeps the env's own random one.
STITCH_ROUNDS = 16

DESCRIPTIONS = {
    "navigate": f"the OGBench navigate level: a noisy expert (with probability {NAVIGATE_SHORTEST_PROB} a "
    "breadth-first shortest-path move towards the goal, otherwise a uniformly random move) walking to random goals "
    "one after another: each episode ends on its goal and the next starts there, towards a new goal drawn uniformly "
    "from the component",
    "stitch": f"the OGBench stitch level: the same noisy expert (shortest-path move with probability "
    f"{NAVIGATE_SHORTEST_PROB}) on short hops: each episode starts on a random cell and its goal lies within "
    f"{STITCH_HOP} moves (Manhattan) of it",
    "explore": f"the OGBench explore level: a random walk that keeps its last move with probability {EXPLORE_KEEP} "
    "(a new uniformly random move otherwise, and always after a bump); the goals are the env's random ones",
}


def parameters(kind: str) -> dict[str, float | int]:
    """What a walk of ``kind`` is made of (part of the logged dataset's version)."""
    if kind == "explore":
        return {"explore_keep": EXPLORE_KEEP}
    out: dict[str, float | int] = {"shortest_prob": NAVIGATE_SHORTEST_PROB}
    if kind == "stitch":
        out["hop"] = STITCH_HOP
    return out


class Walk:
    """The per-robot state of a walk and the episodes it starts (one per logging env)."""

    def __init__(self, kind: str, env, gen: torch.Generator):
        self.kind, self.env, self.gen = kind, env, gen
        self.last = torch.randint(4, (env.num_envs,), generator=gen, device=env.device)
        self.cell = env.cell.clone()

    def explore(self, random_actions: torch.Tensor, coin: torch.Tensor) -> torch.Tensor:
        """``explore``'s moves: the last one kept with probability :data:`EXPLORE_KEEP` unless it bumped."""
        moved = self.env.cell != self.cell
        keep = (coin < EXPLORE_KEEP) & moved
        self.last = torch.where(keep, self.last, random_actions)
        self.cell = self.env.cell.clone()
        return self.last

    def next_episodes(self, terminated: torch.Tensor, truncated: torch.Tensor) -> None:
        """Start the episodes that ended, as the walk's kind does (module docstring)."""
        env = self.env
        ended = terminated | truncated
        if self.kind == "navigate":
            go_on = terminated
            env.reset_where(ended & ~go_on)
            if bool(go_on.any()):
                st = env.cell[go_on]
                env.reset_where(go_on, starts=st, targets=self._elsewhere_in_component(st))
        elif self.kind == "stitch":
            env.reset_where(ended)
            if bool(ended.any()):
                idx = torch.nonzero(ended, as_tuple=True)[0]
                st = env.cell[idx]
                near, ok = self._near(st)
                if bool(ok.any()):
                    mask = torch.zeros_like(ended)
                    mask[idx[ok]] = True
                    env.reset_where(mask, starts=st[ok], targets=near[ok])
        else:
            env.reset_where(ended)

    def _elsewhere_in_component(self, cells: torch.Tensor) -> torch.Tensor:
        """A cell drawn uniformly from each cell's component, the cell itself excepted (as the env draws starts)."""
        env = self.env
        c = env.component[cells]
        j = (torch.rand(cells.numel(), generator=self.gen, device=env.device) * (env.comp_size[c] - 1)).long()
        j = j + (j >= env.rank[cells]).long()
        return env.members[env.comp_first[c] + j]

    def _near(self, cells: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """A goal within :data:`STITCH_HOP` moves of each cell in its component (``ok`` where one was drawn)."""
        env = self.env
        nx, ny = env.mdp.nx, env.mdp.ny
        free = torch.as_tensor(env.mdp.free, device=env.device)
        x, y = cells % nx, cells // nx
        out, ok = cells.clone(), torch.zeros_like(cells, dtype=torch.bool)
        for _ in range(STITCH_ROUNDS):
            todo = ~ok
            if not bool(todo.any()):
                break
            dx = torch.randint(-STITCH_HOP, STITCH_HOP + 1, cells.shape, generator=self.gen, device=env.device)
            left = STITCH_HOP - dx.abs()
            dy = (torch.rand(cells.shape, generator=self.gen, device=env.device) * (2 * left + 1)).long() - left
            cx, cy = x + dx, y + dy
            inside = (cx >= 0) & (cx < nx) & (cy >= 0) & (cy < ny)
            cand = torch.where(inside, cy * nx + cx, cells)
            good = todo & inside & (cand != cells) & free[cand] & (env.component[cand] == env.component[cells])
            out = torch.where(good, cand, out)
            ok |= good
        return out, ok


__all__ = ["DESCRIPTIONS", "EXPLORE_KEEP", "KINDS", "NAVIGATE_SHORTEST_PROB", "STITCH_HOP", "Walk", "parameters"]
