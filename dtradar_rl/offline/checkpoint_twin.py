"""The twin an ``epsilon-greedy`` behaviour's checkpoint may log on: the one it was trained on, by its record.

:func:`dtradar_rl.offline.behaviours.checkpoint_policy` also compares the checkpoint's feature normaliser with the
logged twin's, but a normaliser does not tell the twins apart where a checkpoint carries another twin's: ``make
adapt`` fine-tunes the blueprint agent on the dynamic twin with the blueprint's normaliser, so its ``model.pt``
observes the blueprint exactly as a log there does while its moves were learned on the dynamic twin's cells. The
twin every ``model.pt`` records (:func:`~dtradar_rl.train.saved_runs.trained_twin`) tells them apart.
"""

from __future__ import annotations

import shlex
from pathlib import Path

from dtradar_data.core.dataset import Dataset
from dtradar_rl.agents.checkpoints import WrongTwinError
from dtradar_rl.agents.policy import Policy
from dtradar_rl.train.saved_runs import check_same_twin, trained_twin

__all__ = ["check_logs_on_its_twin"]


def check_logs_on_its_twin(policy: Policy, ds: Dataset, path: str | Path) -> None:
    """:class:`WrongTwinError` unless the checkpoint ``policy`` (read from ``path``) was trained on ``ds`` itself
    (the same ``scene/variant``, and the same stored version where both record one); the hint says how to log with
    it, or what to log with instead."""
    try:
        check_same_twin(policy, ds, what=f"--checkpoint {path}")
    except WrongTwinError as exc:
        twin = trained_twin(policy)
        scene, variant = ds.name.split("/")
        if f"{twin['scene']}/{twin['variant']}" == ds.name:  # another stored version of this twin
            where = f"--revision {twin['version']}"
        else:
            where = f"--scene {twin['scene']} --variant {twin['variant']}"
        train = f"make train SCENE={scene} ARGS={shlex.quote(f'--preset tuned --variant {variant}')}"
        raise WrongTwinError(
            f"{exc.message}: an epsilon-greedy log acts with the checkpoint's greedy moves, learned on another "
            "twin's cells and radio features",
            hint=f"log on the twin it was trained on ({where}), or pass a memoryless checkpoint trained on "
            f"{ds.name} ({train})",
        ) from exc
