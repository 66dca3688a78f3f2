"""What an offline agent observes of each logged step, by ``--senses``: the log's own observation (``none``), with the
memory window rebuilt from the log (``memory``, :mod:`dtradar_rl.offline.memory_senses`), or, on an honest log, the
localisation filter's belief along each episode (``filter``, :mod:`dtradar_rl.offline.filter_senses`)."""

from __future__ import annotations

from dtradar_data.core.dataset import Dataset
from dtradar_data.store.logged import LoggedDataset
from dtradar_rl.offline.config import OfflineConfig
from dtradar_rl.offline.filter_senses import FilterSenses, filter_senses
from dtradar_rl.offline.memory_senses import MemorySenses, memory_senses
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.grid_mdp import GridMDP, MovingGridMDP


def learner_senses(cfg: OfflineConfig, logged: LoggedDataset, ds: Dataset) -> MemorySenses | FilterSenses | None:
    """The senses of ``cfg`` (resolved) built for ``logged`` on twin ``ds`` (None: the log's own observation). A moving
    twin's log is refused for ``memory``: its cells' moves depend on the snapshot, which the table does not keep."""
    senses = cfg.resolved_senses
    if senses == "filter":
        return filter_senses(logged, cfg.scene, cfg.device)
    if senses != "memory":
        return None
    mdp = GridMDP.from_dataset(ds)
    if isinstance(mdp, MovingGridMDP):
        raise ConfigError(
            f"--senses memory rebuilds the memory of each logged episode from its moves, which on the moving twin "
            f"{ds.name} depend on the snapshot the log does not keep",
            hint="train on a log of a static twin (blueprint, dynamic), or with --senses none",
        )
    return memory_senses(logged, mdp)


__all__ = ["learner_senses"]
