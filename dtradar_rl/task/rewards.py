"""The rewards of the navigation MDP, chosen by name (:data:`REWARDS`): one step's reward from the distances before and
after the move, whether it collided and whether it reached the target.

Plain numpy-or-torch arithmetic (:func:`reward_fn` works elementwise on either, or on Python scalars), so the
gymnasium env, the batched torch env and the tabular solvers share one definition. Distances are in **cell units**
(``dx = ix_target - ix``, ``dy = iy_target - iy``).

``paper``      exactly the paper's reward: ``-(dx² + dy²)`` after the move, ``+5000`` on reaching the target,
               ``-5000`` on a collision (the terms add).
``scaled``     the paper's three terms rescaled to order one: ``-(dx² + dy²) / (nx² + ny²)``, ``+1`` on reaching the
               target, ``-1`` on a collision. Same optimum as ``paper``, better conditioned for a neural network.
``euclidean``  potential-based shaping (Ng et al. 1999) with the straight-line distance ``d``: ``d(s) - d(s')``
               (cell units), ``+1`` on reaching the target, ``-1`` on a collision. Uses no map knowledge.
``geodesic``   potential-based shaping with the breadth-first (obstacle-aware) distance ``g`` on the training twin:
               ``g(s) - g(s')`` (+1 for a step along a shortest path, -1 for a step away), ``+1`` on reaching the
               target, ``-1`` on a collision. The twin is known while training, so this is a legitimate training
               signal; the policy itself still sees only its observation. Being potential-based it leaves the
               shortest-path objective unchanged, and it makes every step informative, so it trains fastest;
               it is the tuned default.

The wait action (an option of the environments: the robot stays on its cell) is rewarded by the same function as
any step, with the cell after the step the one before and no collision: it keeps the distance, so under ``paper`` and
``scaled`` it pays the distance term like a bump does, and under the shaped rewards it earns 0 (the potential does
not change), i.e. a step that costs time (the target's bonus comes one step later) like a bump, without the
collision penalty. A mover walking onto the waiting robot is still a mover hit, charged the collision penalty.
"""

from __future__ import annotations

from dtradar_data.core.errors import unknown_name

REWARDS: tuple[str, ...] = ("paper", "scaled", "euclidean", "geodesic")
PAPER_GOAL_BONUS = 5000.0
PAPER_COLLISION_PENALTY = 5000.0


def check_reward(name: str) -> str:
    """Return ``name`` if it is a known reward, else raise :class:`UnknownNameError` with a suggestion."""
    if name not in REWARDS:
        raise unknown_name("reward", name, REWARDS)
    return name


def reward_fn(name: str, *, d2_after, pot_before, pot_after, collision, reached, diag2: float):
    """The reward of one step, elementwise, for numpy arrays, torch tensors or Python scalars.

    ``d2_after``: squared straight-line distance to the target after the move (cell units²), used by
    ``paper``/``scaled``; ``pot_before``/``pot_after``: the shaping distance before/after the move (straight-line
    for ``euclidean``, breadth-first for ``geodesic``, see :func:`potential_kind`); ``collision``/``reached``:
    booleans (bools or 0/1 numbers); ``diag2 = nx² + ny²``.
    """
    collision = collision * 1.0
    reached = reached * 1.0
    if name == "paper":
        return -d2_after + PAPER_GOAL_BONUS * reached - PAPER_COLLISION_PENALTY * collision
    if name == "scaled":
        return -d2_after / diag2 + reached - collision
    if name in ("euclidean", "geodesic"):
        return (pot_before - pot_after) + reached - collision
    raise unknown_name("reward", name, REWARDS)


def potential_kind(name: str) -> str | None:
    """Which distance a reward shapes with: ``"euclidean"``, ``"geodesic"`` or ``None``."""
    return name if check_reward(name) in ("euclidean", "geodesic") else None


__all__ = ["PAPER_COLLISION_PENALTY", "PAPER_GOAL_BONUS", "REWARDS", "check_reward", "potential_kind", "reward_fn"]
