"""The checkpoint a behaviour acts with (an ``epsilon-greedy`` one, or the medium agent), loaded and checked to act in
a log (:func:`checkpoint_policy`), and the twin an ``epsilon-greedy`` checkpoint may log on: the one it was trained
on, by its record (:func:`check_logs_on_its_twin`).

A logged step holds the twin's observation of the four neighbours and one of the four moves, so a checkpoint with a
memory, a wider sense radius, the schedule's clock in its observation or the wait action (the settings of ``make
train VARIANT=moving``) cannot act in a log: each is refused, naming the setting.

:func:`checkpoint_policy` also compares the checkpoint's feature normaliser with the
logged twin's, but a normaliser does not tell the twins apart where a checkpoint carries another twin's: ``make
adapt`` fine-tunes the blueprint agent on the dynamic twin with the blueprint's normaliser, so its ``model.pt``
observes the blueprint exactly as a log there does while its moves were learned on the dynamic twin's cells. The
twin every ``model.pt`` records (:func:`~dtradar_rl.train.saved_runs.trained_twin`) tells them apart.
"""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import Any

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_rl.agents.checkpoints import WrongTwinError
from dtradar_rl.agents.policy import Policy
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.train.saved_runs import check_same_twin, load_policy, trained_twin

__all__ = ["check_logs_on_its_twin", "checkpoint_policy"]

#: What a checkpoint that acts in a log is trained with (a memoryless DQN of the four neighbours and four moves).
LOGGABLE_AGENT = 'make train SCENE=<scene> ARGS="--preset tuned --variant <variant> --out runs/<scene>/tuned"'


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


def checkpoint_policy(
    spec: Any, obs: str, normalizer: Normalizer, device: str = "cpu", *, ds: Dataset | None = None
) -> Policy | None:
    """The DQN of an ``epsilon-greedy`` (or ``medium``) behaviour ``spec`` (a
    :class:`~dtradar_rl.offline.behaviours.BehaviourSpec`; untyped here, as its module imports this one), checked to
    act in a log (module docstring), to observe like the log (preset and normaliser) and, given the logged twin
    ``ds``, an ``epsilon-greedy`` one to be trained on it (:func:`check_logs_on_its_twin`). A ``medium`` spec must have
    been resolved (:func:`dtradar_rl.offline.medium_agent.resolve_spec`)."""
    if "epsilon-greedy" in spec.used:
        path = spec.checkpoint
    elif "medium" in spec.used:
        path = spec.medium_checkpoint
        if not path:
            raise ConfigError(
                f"the {spec.kind} behaviour acts with the medium agent, which this spec does not name yet",
                hint="resolve it first: dtradar_rl.offline.medium_agent.resolve_spec(config, dataset) trains or reuses",
            )
    else:
        return None
    policy = load_policy(path, device)
    if ds is not None and "epsilon-greedy" in spec.used:  # the medium agent is trained on ds by resolve_spec
        check_logs_on_its_twin(policy, ds, path)
    if getattr(policy.config, "memory_radius", 0):
        raise ConfigError(
            f"the checkpoint {path} is a memory agent ({policy.config.preset} preset): a logged step holds "
            "the twin's observation only, not the agent's memory of the episode",
            hint=f"log with a memoryless agent: {LOGGABLE_AGENT}",
        )
    if policy.wait_action or policy.clock != "none":
        what = "the wait action (a fifth action)" if policy.wait_action else f"the clock ({policy.clock})"
        raise ConfigError(
            f"the checkpoint {path} was trained with {what}: a logged step holds one of the four moves and the "
            f"{obs!r} observation without the schedule's phase",
            hint=f"log with an agent trained without --wait-action and --clock ({LOGGABLE_AGENT}), or log a dataset "
            "family (expert, medium, ...), which needs no checkpoint",
        )
    if policy.sense_radius != 1:
        raise ConfigError(
            f"the checkpoint {path} senses the cells up to {policy.sense_radius} away (--sense-radius "
            f"{policy.sense_radius}): a logged step holds the {obs!r} observation of the four neighbours only",
            hint="log with an agent trained with --sense-radius 1 (the default of make train on a blueprint)",
        )
    if policy.obs_preset != obs:
        raise ConfigError(
            f"the checkpoint {path} observes {policy.obs_preset!r}, the log {obs!r}",
            hint=f"pass --obs {policy.obs_preset}",
        )
    if not np.allclose(policy.normalizer.mean, normalizer.mean, rtol=1e-5, atol=1e-6) or not np.allclose(
        policy.normalizer.std, normalizer.std, rtol=1e-5, atol=1e-6
    ):
        raise ConfigError(
            f"the checkpoint {path} was trained on another twin (its feature normaliser "
            "differs from the logged twin's)",
            hint="log on the twin the checkpoint was trained on",
        )
    return policy
