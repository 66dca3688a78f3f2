"""Online training: DQN read top to bottom, its config and presets beside it, the replay buffer, and loading a
trained checkpoint back as a policy."""

from dtradar_rl.train.config import PRESETS, DQNConfig, config_for
from dtradar_rl.train.dqn import TrainResult, train
from dtradar_rl.train.saved_runs import load_policy

__all__ = ["PRESETS", "DQNConfig", "TrainResult", "config_for", "load_policy", "train"]
