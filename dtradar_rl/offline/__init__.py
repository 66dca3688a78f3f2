"""Offline RL: behaviour policies and the one rollout engine that logs them into versioned datasets, their Minari
and d3rlpy formats, d3rlpy training on a named logged dataset, and the offline policy."""

from dtradar_rl.offline.config import OfflineConfig
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.policy import load_offline_policy
from dtradar_rl.offline.trainer import train_offline

__all__ = ["LogConfig", "OfflineConfig", "load_offline_policy", "log_dataset", "train_offline"]
