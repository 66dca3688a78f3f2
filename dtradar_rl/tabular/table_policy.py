"""A policy that is a table over blueprint cells: each robot localises, then looks up its move.

A tabular agent (:mod:`dtradar_rl.tabular.qlearning`, :mod:`dtradar_rl.tabular.dyna`, a batch-RL table) holds one
move, or one distribution over the four moves, per ``(cell, target)`` of the blueprint. A robot does not sense its
cell, so :class:`TablePolicy` acts in two lookups from the observation alone:

1. **where am I**: the believed cell, by the nearest blueprint fingerprint (:class:`Localiser`): the 8 z-scored radio
   features of the observation's own cell (of every transmitter, on a twin with several) against those of the
   blueprint's free cells with radio features, the same k-d tree query as
   :func:`~dtradar_rl.tabular.fingerprints.localisation`, so on a twin without measurement noise
   the believed cell of a robot on cell ``c`` is exactly ``localisation(blueprint, twin)[c]`` (tested), and under
   measurement noise it is the nearest fingerprint of what the receiver measured. ``localise="oracle"`` reads the
   robot's own ``x, y`` instead (the true cell): what a table would reach if localisation never failed;
2. **where is the target**: the cell whose ``x, y`` are the observation's target columns (exact).

It has the part of :class:`~dtradar_rl.agents.policy.Policy` that the evaluation loop uses (``env_for``, ``act``,
``obs_preset``, ``meta``, ``config``), like :class:`~dtradar_rl.agents.planner.FingerprintPlanner`, so
:func:`~dtradar_rl.evaluation.evaluate.evaluate_twins` and ``make eval``-style metrics run it unchanged on the
blueprint and on any twin of the same grid. It observes the ``goal`` preset (position, radio features, target), so
the evaluation reports no shielded row for it.

A table of moves acts deterministically; a table of probabilities draws each robot's move from its row with a seeded
generator that :meth:`TablePolicy.env_for` restarts, so an evaluation repeats.

    policy = TablePolicy(blueprint, actions)          # actions: int64[cells, cells], cells = H * W of the blueprint
    metrics, _ = evaluate(policy, load_dataset("cubicle/dynamic"))
    metrics, _ = evaluate(policy.oracle(), load_dataset("cubicle/dynamic"))   # with the true cell
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy.spatial import cKDTree

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import DtradarError, InvalidSettingError, unknown_name
from dtradar_data.core.files import open_atomic, write_atomic
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.tabular.fingerprints import fingerprints
from dtradar_rl.tabular.solver import TooLargeError
from dtradar_rl.task.moving_masks import background
from dtradar_rl.task.observations import PAPER_COLUMNS, Normalizer, build_observations, own_radio_columns
from dtradar_rl.task.twins import load_dataset

#: The observation preset of a table policy: the robot's position and radio features, and its target's position.
OBS_PRESET = "goal"
#: The observation columns of the robot's own radio features (``goal`` and ``neighbors`` presets; one transmitter:
#: with several, :func:`~dtradar_rl.task.observations.own_radio_columns`) and of its position.
RADIO_COLUMNS = slice(2, len(PAPER_COLUMNS))
POSITION_COLUMNS = slice(0, 2)
#: How a table policy finds the robot's cell: by fingerprint (what it senses) or the true cell (an oracle).
LOCALISATIONS: tuple[str, ...] = ("fingerprint", "oracle")
#: The default cap on a learner's table (``float32[cells, targets, 4]``), bytes.
TABLE_BYTES_CAP = 2 << 30
#: Seed of a probability table's draws (restarted by ``env_for``).
DRAW_SEED = 0
#: ``table.json``'s format tag (:meth:`TablePolicy.save`).
TABLE_FORMAT = "dtradar-table-policy/1"


class UncoveredTargetError(DtradarError, ValueError):
    """A target cell the table has no column for."""


def table_bytes(cells: int, targets: int, itemsize: int = 4) -> int:
    """Bytes of a ``[cells, targets, 4]`` table of ``itemsize``-byte values."""
    return int(cells) * int(targets) * 4 * int(itemsize)


def check_table_size(cells: int, targets: int, cap_bytes: int, name: str = "the table", itemsize: int = 4) -> int:
    """The bytes of a ``[cells, targets, 4]`` table, or :class:`TooLargeError` naming its size and the cap."""
    size = table_bytes(cells, targets, itemsize)
    if size > cap_bytes:
        raise TooLargeError(
            f"{name} would hold {cells:,} cells x {targets:,} targets x 4 actions = {size / 2**30:.2f} GiB, over the "
            f"cap of {cap_bytes / 2**30:.2f} GiB",
            hint="raise --max-table-gib if the machine has the memory, or learn on a smaller twin",
        )
    return size


class Localiser:
    """Cells from observations: the believed cell of each robot and its target's cell (module docstring)."""

    def __init__(self, blueprint: Dataset, normalizer: Normalizer | None = None, localise: str = "fingerprint"):
        if localise not in LOCALISATIONS:
            raise unknown_name("localisation", localise, LOCALISATIONS)
        blueprint = background(blueprint)
        self.normalizer = normalizer or Normalizer.fit(blueprint)
        self.localise = localise
        self.num_cells = int(np.prod(blueprint.shape))
        ref, radio = fingerprints(blueprint, self.normalizer)
        k = self.normalizer.transmitters  # the fingerprint's observation columns: every transmitter's features
        self._radio = RADIO_COLUMNS if k == 1 else own_radio_columns(OBS_PRESET, k)
        #: the blueprint cells a fingerprint can name (free, with radio features), in cell order
        self.cells = np.flatnonzero(radio)
        if self.cells.size == 0:
            raise InvalidSettingError(
                f"{blueprint.name} has no free cell with radio features: no fingerprint to localise by",
                hint="check the twin's radio columns",
            )
        self._fingerprints = cKDTree(ref[self.cells].astype(np.float64))  # as tabular.fingerprints.localisation
        # every cell's (x, y) as an observation shows it (the observation tables blank a blocked cell's own part,
        # and a dynamic twin's target may sit where the blueprint has an object)
        raw = blueprint.grid(list(self.normalizer.columns)).reshape(self.num_cells, -1).astype(np.float64)
        xy = [self.normalizer.columns.index(c) for c in PAPER_COLUMNS[POSITION_COLUMNS]]
        self._positions = cKDTree(self.normalizer.apply(raw)[:, xy].astype(np.float64))

    def believed(self, obs: torch.Tensor | np.ndarray) -> np.ndarray:
        """``int64[n]``: the cell each robot believes it is on (by fingerprint, or the oracle's true cell)."""
        o = _numpy(obs)
        if self.localise == "oracle":
            return self._positions.query(o[:, POSITION_COLUMNS].astype(np.float64))[1].astype(np.int64)
        return self.cells[self._fingerprints.query(o[:, self._radio].astype(np.float64))[1]]

    def hears(self, obs: torch.Tensor | np.ndarray) -> np.ndarray:
        """``bool[n]``: the robot senses radio features on its cell (a free cell no path reaches reads all 0, the
        normalised value of a missing feature; its nearest fingerprint says nothing about where it is)."""
        return (_numpy(obs)[:, self._radio] != 0).any(1)

    def targets(self, obs: torch.Tensor | np.ndarray) -> np.ndarray:
        """``int64[n]``: the target cell of each robot (its ``x, y`` are the observation's last two columns)."""
        return self._positions.query(_numpy(obs)[:, -2:].astype(np.float64))[1].astype(np.int64)

    def __call__(self, obs: torch.Tensor | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.believed(obs), self.targets(obs)


def _numpy(obs: torch.Tensor | np.ndarray) -> np.ndarray:
    if isinstance(obs, torch.Tensor):
        obs = obs.detach().cpu().numpy()
    return np.asarray(obs).reshape(-1, np.asarray(obs).shape[-1])


class TablePolicy:
    """A table of moves ``int64[cells, targets]`` or of move probabilities ``float[cells, targets, 4]`` over the
    blueprint's cells (row ``iy * nx + ix``), acting by localisation and lookup (module docstring).

    ``targets``: the target cells of the table's columns, in order (default every cell, column = cell); a robot
    whose target has no column raises :class:`UncoveredTargetError`. ``normalizer``: the one the table was learned
    with (default the blueprint's own, what the learners use). ``localise``: ``"fingerprint"`` (what the robot
    senses) or ``"oracle"`` (the true cell, from the observation's own position). ``name`` labels it in reports."""

    obs_preset = OBS_PRESET

    def __init__(
        self,
        blueprint: Dataset,
        actions: np.ndarray,
        normalizer: Normalizer | None = None,
        targets: np.ndarray | None = None,
        name: str = "table",
        *,
        localise: str = "fingerprint",
    ):
        self.blueprint = background(blueprint)
        self.localiser = Localiser(self.blueprint, normalizer, localise)
        self.normalizer = self.localiser.normalizer
        cells = self.localiser.num_cells
        table = np.asarray(actions)
        self.targets = np.arange(cells, dtype=np.int64) if targets is None else np.asarray(targets, np.int64).ravel()
        if self.targets.size and (self.targets.min() < 0 or self.targets.max() >= cells):
            raise InvalidSettingError(
                f"table targets must be cell indices in 0..{cells - 1}", hint="pass iy * nx + ix of each column"
            )
        if np.unique(self.targets).size != self.targets.size:
            raise InvalidSettingError("table targets repeat a cell", hint="one column per target cell")
        if (
            table.ndim not in (2, 3)
            or table.shape[:2] != (cells, self.targets.size)
            or table.shape[2:] not in ((), (4,))
        ):
            raise InvalidSettingError(
                f"a table over {self.blueprint.name} is int64[{cells}, {self.targets.size}] (moves) or "
                f"float[{cells}, {self.targets.size}, 4] (probabilities), got shape {table.shape}",
                hint="one row per blueprint cell (iy * nx + ix), one column per target",
            )
        self.stochastic = table.ndim == 3
        if self.stochastic:
            probs = table.astype(np.float64)
            if not np.isfinite(probs).all() or (probs < 0).any() or not np.allclose(probs.sum(-1), 1.0, atol=1e-4):
                raise InvalidSettingError(
                    "a probability table needs 4 non-negative probabilities summing to 1 in every row",
                    hint="normalise each [cell, target] row (uniform where nothing is known)",
                )
            self.table = torch.as_tensor(probs / probs.sum(-1, keepdims=True), dtype=torch.float32)
        else:
            if not np.issubdtype(table.dtype, np.integer) or table.size and (table.min() < 0 or table.max() > 3):
                raise InvalidSettingError(
                    f"a table of moves holds integers 0..3 (X-, X+, Y-, Y+), got {table.dtype}"
                    + (
                        f" in {table.min()}..{table.max()}"
                        if table.size and np.issubdtype(table.dtype, np.number)
                        else ""
                    ),
                    hint="pass q.argmax(-1) of a [cells, targets, 4] value table",
                )
            self.table = torch.as_tensor(table.astype(np.int64, copy=False))  # shared, not copied
        self._column = np.full(cells, -1, np.int64)
        self._column[self.targets] = np.arange(self.targets.size)
        self.name = name
        self.meta: dict[str, Any] = {
            "dataset": {"name": self.blueprint.name, "version": self.blueprint.version},
            "stats": {},
            "path": name,
            "localise": localise,
        }
        self.config = None
        self._gen: torch.Generator | None = None

    @property
    def localise(self) -> str:
        return self.localiser.localise

    def oracle(self) -> TablePolicy:
        """The same table acting on the robot's true cell (its position in the observation), not its belief."""
        return self.with_localisation("oracle")

    def with_localisation(self, localise: str) -> TablePolicy:
        """This table with another :data:`LOCALISATIONS` mode (the table itself is shared, not copied)."""
        other = object.__new__(TablePolicy)
        other.__dict__.update(self.__dict__)
        other.localiser = Localiser(self.blueprint, self.normalizer, localise)
        other.meta = {**self.meta, "localise": localise}
        other.name = self.name if localise == "fingerprint" else f"{self.name} ({localise})"
        other._gen = None
        return other

    # -- files ------------------------------------------------------------------------------------------------------
    def save(self, folder: str | Path) -> Path:
        """``actions.npy`` (moves as int8, or probabilities as float32), ``targets.npy`` (the columns' cells, when not
        every cell) and ``table.json`` (the twin, the normaliser, the name) in ``folder``; returns ``table.json``."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        table = self.table.numpy().astype(np.float32 if self.stochastic else np.int8)
        with open_atomic(folder / "actions.npy", "wb") as f:
            np.save(f, table)
        every = self.targets.size == self.localiser.num_cells and (self.targets == np.arange(self.targets.size)).all()
        if not every:
            with open_atomic(folder / "targets.npy", "wb") as f:
                np.save(f, self.targets)
        record = {
            "format": TABLE_FORMAT,
            "name": self.name,
            "dataset": self.meta["dataset"],
            "normalizer": self.normalizer.to_dict(),
            "stochastic": self.stochastic,
            "every_target": bool(every),
        }
        write_atomic(folder / "table.json", json.dumps(record, indent=2) + "\n")
        return folder / "table.json"

    @classmethod
    def load(cls, folder: str | Path, blueprint: Dataset | None = None) -> TablePolicy:
        """The table :meth:`save` wrote in ``folder``, over ``blueprint`` (default: the twin it records, loaded)."""
        folder = Path(folder)
        try:
            record = json.loads((folder / "table.json").read_text())
            if record.get("format") != TABLE_FORMAT:
                raise ValueError(f"format {record.get('format')!r}")
            table = np.load(folder / "actions.npy")
            targets = None if record["every_target"] else np.load(folder / "targets.npy")
        except (OSError, ValueError, KeyError) as e:
            raise InvalidSettingError(
                f"{folder} holds no table policy ({type(e).__name__}: {e})",
                hint="pass the folder a tabular learner wrote (table.json, actions.npy)",
            ) from e
        ds = record["dataset"]
        if blueprint is None:
            blueprint = load_dataset(ds["name"] + (f"@{ds['version']}" if ds.get("version") else ""))
        table = table.astype(np.float64) if record["stochastic"] else table.astype(np.int64)
        return cls(blueprint, table, Normalizer.from_dict(record["normalizer"]), targets, record["name"])

    # -- the Policy interface used by dtradar_rl.evaluation.evaluate ----------------------------------------------
    def env_for(self, ds: Dataset, num_envs: int, **kwargs) -> BatchedNavEnv:
        """A batched env over ``ds`` observed with the ``goal`` preset and the table's normaliser (and the draws of a
        probability table restarted, so an evaluation repeats)."""
        self._gen = None
        return BatchedNavEnv.from_dataset(ds, num_envs, obs=OBS_PRESET, normalizer=self.normalizer, **kwargs)

    def observations(self, ds: Dataset):
        return build_observations(ds, OBS_PRESET, self.normalizer)

    def cells(self, obs: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
        """``(believed cell, table column)`` of every robot; :class:`UncoveredTargetError` for a target without one."""
        believed, target = self.localiser(obs)
        column = self._column[target]
        if (column < 0).any():
            c = int(target[column < 0][0])
            raise UncoveredTargetError(
                f"{self.name}: target cell {tuple(int(v) for v in divmod(c, self.blueprint.shape[1])[::-1])} has no "
                f"column in the table ({self.targets.size} targets)",
                hint="evaluate on pairs whose targets the table covers, or learn a table over every cell",
            )
        return believed, column

    def act(self, obs: torch.Tensor, shield: bool = False) -> torch.Tensor:
        """One move per robot from its row of the table; ``shield`` is accepted and ignored (nothing is sensed)."""
        believed, column = self.cells(obs)
        b, c = torch.from_numpy(believed), torch.from_numpy(column)
        if not self.stochastic:
            action = self.table[b, c]
        else:
            if self._gen is None:
                self._gen = torch.Generator()
                self._gen.manual_seed(DRAW_SEED)
            action = torch.multinomial(self.table[b, c], 1, generator=self._gen).squeeze(1)
        return action.to(obs.device if isinstance(obs, torch.Tensor) else "cpu")


def greedy_actions(q: torch.Tensor | np.ndarray) -> np.ndarray:
    """``int64[cells, targets]``: the greedy move of a ``[cells, targets, 4]`` value table (first of equals)."""
    q = q.detach().cpu() if isinstance(q, torch.Tensor) else torch.as_tensor(q)
    return q.argmax(-1).numpy().astype(np.int64, copy=False)  # argmax is int64 already: no second table


__all__ = [
    "LOCALISATIONS",
    "OBS_PRESET",
    "TABLE_BYTES_CAP",
    "Localiser",
    "TablePolicy",
    "TooLargeError",
    "UncoveredTargetError",
    "check_table_size",
    "greedy_actions",
    "table_bytes",
]
