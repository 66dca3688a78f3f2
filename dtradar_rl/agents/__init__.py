"""Agents that act on a twin: the Q-network and the greedy :class:`Policy`, checkpoint files, and the classical
planner (fingerprint localisation + breadth-first replanning)."""

from dtradar_rl.agents.checkpoints import CheckpointError
from dtradar_rl.agents.planner import FingerprintPlanner
from dtradar_rl.agents.policy import Policy, QNetwork

__all__ = ["CheckpointError", "FingerprintPlanner", "Policy", "QNetwork"]
