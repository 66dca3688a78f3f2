"""Online training: DQN read top to bottom, its config and presets beside it, the replay buffer, and loading a
trained checkpoint back as a policy."""

from dtradar_rl.train.checkpoints import load_policy
from dtradar_rl.train.config import PRESETS, DQNConfig, config_for
from dtradar_rl.train.dqn import TrainResult, train

__all__ = ["PRESETS", "DQNConfig", "TrainResult", "config_for", "load_policy", "train"]
