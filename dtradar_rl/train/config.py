"""The online DQN's settings and its seven presets (``memory-escape-noise-margin``, the default;
``memory-escape-noise``, ``memory-escape``, ``tuned``, ``robust``, ``memory``, ``paper``).

:class:`DQNConfig` extends :class:`~dtradar_rl.task.config.TwinConfig`; its field defaults are the default preset's
settings (:data:`DEFAULT_PRESET`), so ``DQNConfig() == config_for()``, and each entry of :data:`PRESETS` lists how its
preset differs from them. :func:`config_for` gives a preset with overrides. What each preset reaches on each twin is
measured in the docs (Navigation), not here.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from dtradar_data.core.errors import unknown_name
from dtradar_rl.envs.batched import AUG_POTENTIALS
from dtradar_rl.task.clock import check_clock
from dtradar_rl.task.config import INDOOR_SCENES, ConfigError, TwinConfig, flag
from dtradar_rl.task.noise import noise_model
from dtradar_rl.task.runs import run_dir
from dtradar_rl.task.twins import is_synthetic

PAIR_MODES = ("random", "paper")


@dataclass(frozen=True)
class DQNConfig(TwinConfig):
    """Deep Q-learning on the navigation MDP of one dataset (defaults: the default preset,
    ``memory-escape-noise-margin``)."""

    preset: str = "memory-escape-noise-margin"
    """the preset these settings started from (see the command's description); recorded in config.json"""
    aug_obstacles: int = 10
    """obstacle augmentation: extra random obstacles per robot, redrawn at every episode reset, that collide and
    read as blocked neighbours (0 = off; see dtradar_rl.envs.batched)"""
    aug_obstacle_size: int = 2
    """largest side of an extra obstacle in cells (each is a 1..size x 1..size rectangle; 2 = 1 m at 0.5 m cells)"""
    aug_potential: str = "replan"
    """geodesic shaping with extra obstacles: replan (BFS per robot on its augmented grid) or blueprint"""
    memory_radius: int = 5
    """memory agent: append a (2R+1)^2 window of the cells sensed as occupied and visited so far this episode
    (0 = off; needs --obs neighbors; see dtradar_rl.envs.memory)"""
    memory_bumps: bool = False
    """memory agent: also keep a map of the cells a move into failed (a bumper's feedback), so a free street cell
    that no ray reached, which reads as "no radio" like an obstacle, can be told from a wall by trying it"""
    memory_visits: bool = True
    """memory agent: also observe how many times the robot has stood on its cell this episode (visits_here)"""
    sense_radius: int = 1
    """cells the robot senses around it: 1 = its four neighbours; R > 1 also observes whether each cell at Manhattan
    distance 2..R has radio features, now and one snapshot before, so a mover is seen coming (needs --obs neighbors;
    see dtradar_rl.task.observations)"""
    wait_action: bool = False
    """a fifth action, wait (stay on the cell: no collision, still hit by a mover walking onto the robot), besides the
    four moves; without it the robot waits only by bumping (see dtradar_rl.envs.batched_moves)"""
    mover_penalty: float = 1.0
    """the collision penalty of a step with a mover collision or a mover hit, in units of the reward's collision
    penalty (1 = as a wall bump); larger makes meeting a mover dearer than the time lost to avoid it (training only;
    see dtradar_rl.envs.batched_moves)"""
    clock: str = "none"
    """the phase of a moving twin's periodic schedule in the observation: none, or sincos (cos and sin of 2 pi t/T,
    the cell part's last two columns; constant on a static twin; see dtradar_rl.task.clock)"""
    escape_after: int = 2
    """loop escape when acting (needs --memory-visits): a robot standing on a cell for the (k+1)-th time this episode
    takes a random move, so a greedy policy cannot repeat a cycle until the step limit (0 = off)"""
    noise: str = "realistic"
    """measurement-noise augmentation: train on radio features as a receiver would measure them (none, realistic,
    2x; see dtradar_rl.task.noise), drawn anew at every step"""
    total_env_steps: int = 0
    """training budget in environment steps (all robots together); 0 = the twin's default (budget_for): the paper's
    600K, or 500 steps per free cell of the training twin where that is more (a twin of over 1 200 free cells), twice
    that on a moving twin"""
    episodes: int = 0
    """also stop after this many finished episodes (0 = no limit; the paper: 500 indoor, 80 outdoor)"""
    pair: str = "random"
    """start/target pairs: random (a new connected pair every episode: goal-conditioned agents) or paper (one fixed
    pair per run, the paper's protocol: the scene's Table VI pair on the grid, see dtradar_rl.task.pairs; episodes then
    run until the target, capped at 10x the pair's shortest path unless --max-steps is set)"""
    start: tuple[int, int] | None = None
    """fixed start cell (ix iy), with --target: one pair per run as with --pair paper, instead of Table VI's"""
    target: tuple[int, int] | None = None
    """fixed target cell (ix iy), with --start"""
    lr: float = 1e-3
    """Adam learning rate"""
    lr_end: float = 1e-4
    """learning rate at the end of the budget, reached linearly (negative = constant lr)"""
    gamma: float = 0.5
    """discount factor (the paper: 0.9; with the geodesic reward every step is informative, so a short horizon
    learns faster and keeps the shortest-path optimum)"""
    batch_size: int = 512
    """minibatch size of one gradient update"""
    buffer_size: int = 200_000
    """replay buffer capacity (transitions)"""
    learning_starts: int = 10_000
    """environment steps collected before the first update"""
    env_steps_per_update: int = 48
    """environment steps per gradient update (1 = an update every step, as in the paper)"""
    target_update_every: int = 250
    """copy the online network into the target network every this many updates"""
    double_dqn: bool = True
    """Double DQN targets (the online network picks the next action, the target network values it)"""
    eps_start: float = 1.0
    """initial exploration rate"""
    eps_end: float = 0.05
    """final exploration rate"""
    eps_decay_fraction: float = 0.4
    """fraction of the budget over which exploration decays linearly from eps_start to eps_end"""
    expert_weight: float = 1.0
    """weight of a large-margin loss towards the training twin's breadth-first shortest moves (DQfD's; 0 = off, plain
    DQN); on a moving twin the actions of a shortest path in time, which meet no mover. The twin's map is known in
    training, as the geodesic reward already uses it; the agent still acts from its observation alone. On by default
    (the margin preset); make adapt uses it to fine-tune fast"""
    expert_margin: float = 1.0
    """margin by which the expert loss wants a shortest move's value above every other move's"""
    max_grad_norm: float = 10.0
    """gradient-norm clipping (0 = off)"""
    checkpoint_every: int = 200_000
    """write last.pt every this many environment steps (0 = only at the end)"""
    save_replay: bool = True
    """include the replay buffer in last.pt, so a resumed run is exact"""
    resume: bool = False
    """continue from <out>/last.pt up to the (possibly raised) budget (exploration follows the new budget)"""

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> DQNConfig:
        """The config saved by :meth:`to_dict`. A field missing from ``d`` (a config saved before the field existed)
        takes the default it had then (:data:`SAVED_DEFAULTS`), not today's: an old checkpoint keeps its meaning."""
        return super().from_dict({**SAVED_DEFAULTS, **d})

    @property
    def out_dir(self) -> Path:
        return Path(self.out or run_dir(self.scene, "dqn"))

    @property
    def fixed_pair(self) -> bool:
        """One (start, target) pair for the whole run (the paper's protocol) rather than a new one per episode."""
        return self.pair == "paper" or self.start is not None

    def check_ranges(self) -> None:
        super().check_ranges()
        self.check_at_least(
            1,
            "sense_radius",
            "batch_size",
            "buffer_size",
            "env_steps_per_update",
            "target_update_every",
            "aug_obstacle_size",
        )
        self.check_at_least(
            0,
            "total_env_steps",
            "episodes",
            "learning_starts",
            "aug_obstacles",
            "checkpoint_every",
            "memory_radius",
            "escape_after",
        )
        for name in ("start", "target"):
            cell = getattr(self, name)
            if cell is not None and (
                len(cell) != 2 or any(isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < 0 for v in cell)
            ):
                raise ConfigError(f"{flag(name)} must be a cell: two integers ix iy >= 0, got {cell!r}")
        if not self.lr > 0:
            raise ConfigError(f"--lr must be > 0, got {self.lr}", hint="the presets use 1e-3")
        if self.lr_end == 0:
            raise ConfigError(
                "--lr-end 0 stops learning at the end of the budget",
                hint="use a positive end rate, or a negative one for a constant --lr",
            )
        if self.expert_weight < 0 or not self.expert_margin > 0:
            raise ConfigError(
                f"--expert-weight must be >= 0 and --expert-margin > 0, got {self.expert_weight} and "
                f"{self.expert_margin}"
            )
        if not self.mover_penalty >= 0:
            raise ConfigError(f"--mover-penalty must be >= 0, got {self.mover_penalty}", hint="1 = as a wall bump")
        if self.max_grad_norm < 0:
            raise ConfigError(f"--max-grad-norm must be >= 0 (0 = off), got {self.max_grad_norm}")
        self.check_within(0, 1, "gamma", open_interval=True)
        self.check_within(0, 1, "eps_start", "eps_end", "eps_decay_fraction")

    def validate(self) -> DQNConfig:
        super().validate()
        if self.preset not in PRESETS:
            raise unknown_name("training preset", self.preset, PRESETS)
        self.check_memory()
        if self.sense_radius > 1 and self.obs != "neighbors":
            raise ConfigError(
                f"--sense-radius {self.sense_radius} widens the neighbours' flags, which only --obs neighbors "
                f"observes, got --obs {self.obs}",
                hint="use --obs neighbors, or --sense-radius 1",
            )
        noise_model(self.noise)
        check_clock(self.clock)
        if self.pair not in PAIR_MODES:
            raise unknown_name("pair mode (--pair)", self.pair, PAIR_MODES)
        if (self.start is None) != (self.target is None):
            raise ConfigError("--start and --target go together", hint="give both cells (ix iy), or neither")
        if self.fixed_pair and self.aug_obstacles:
            raise ConfigError(
                "obstacle augmentation draws a new pair at every reset; it does not combine with a fixed pair",
                hint="use --pair random, or --aug-obstacles 0",
            )
        if self.aug_potential not in AUG_POTENTIALS:
            raise unknown_name("augmentation potential", self.aug_potential, AUG_POTENTIALS)
        if self.expert_weight > 0 and self.reward != "geodesic":
            raise ConfigError(
                f"--expert-weight reads the breadth-first distances of the geodesic reward, got --reward {self.reward}",
                hint="use --reward geodesic, or --expert-weight 0",
            )
        return self

    def preset_value(self, name: str) -> Any:
        """What ``--preset`` gives field ``name`` when it is not typed (the field's own default, the default
        preset's, where the preset keeps it)."""
        return PRESETS.get(self.preset, {}).get(name, DQNConfig.__dataclass_fields__[name].default)

    def _memory_off(self) -> str:
        """The flags that turn the memory agent off, from this config."""
        flags = ["--memory-radius 0"] if self.memory_radius else []
        flags += ["--no-memory-bumps"] if self.memory_bumps else []
        flags += ["--no-memory-visits"] if self.memory_visits else []
        flags += ["--escape-after 0"] if self.escape_after else []
        return " ".join(flags)

    def check_memory(self) -> None:
        """The memory agent's settings fit together (the escape reads the visit counts, the maps need the window,
        the window needs neighbour observations); a refusal names the flag the user typed, and a setting the
        preset gave as the preset's, with the flags that turn it off."""
        preset = f"the {self.preset} preset"
        typed = lambda name: getattr(self, name) != self.preset_value(name)  # noqa: E731
        maps = [flag(m) for m in ("memory_bumps", "memory_visits") if getattr(self, m)]
        if self.escape_after and not self.memory_visits:
            if typed("memory_visits") and not typed("escape_after"):
                raise ConfigError(
                    f"--no-memory-visits: {preset}'s loop escape (--escape-after {self.escape_after}, on by "
                    "default) reads the memory's visit counts",
                    hint="add --escape-after 0 too, or keep --memory-visits",
                )
            raise ConfigError("--escape-after reads the memory's visit counts", hint="set --memory-visits too")
        if maps and not self.memory_radius:
            if typed("memory_radius") and not any(typed(m) for m in ("memory_bumps", "memory_visits")):
                raise ConfigError(
                    f"--memory-radius 0 turns the memory window off, and {preset}'s {' and '.join(maps)} (on by "
                    "default) are maps of it",
                    hint=f"turn the whole memory off: {self._memory_off()}; or keep --memory-radius "
                    f"{self.preset_value('memory_radius') or 5}",
                )
            raise ConfigError(
                "--memory-bumps and --memory-visits are maps of the memory agent",
                hint="set --memory-radius too (e.g. 5)",
            )
        if self.memory_radius and self.obs != "neighbors":
            if typed("obs") and not typed("memory_radius"):
                raise ConfigError(
                    f"--obs {self.obs} does not fit {preset}'s memory, which is on by default (--memory-radius "
                    f"needs --obs neighbors, and the preset sets it to {self.memory_radius}: obstacles are sensed "
                    "through the neighbours' radio features)",
                    hint=f"keep --obs neighbors, or turn the memory off: add {self._memory_off()}, or use "
                    "--preset tuned (no memory)",
                )
            raise ConfigError(
                f"--memory-radius needs --obs neighbors (obstacles are sensed through the neighbours' "
                f"radio features), got --obs {self.obs}",
                hint=f"use --obs neighbors, or turn the memory off: {self._memory_off()}",
            )


#: What ``tuned`` turns off of the default agent: the extra obstacles, the memory and its visit counts, the loop escape,
#: the measurement noise and the margin loss. ``robust``, ``memory`` and ``paper`` start from it, as they were built on
#: ``tuned``.
_TUNED: dict[str, Any] = {
    "aug_obstacles": 0,
    "memory_radius": 0,
    "memory_visits": False,
    "escape_after": 0,
    "noise": "none",
    "expert_weight": 0.0,
    "total_env_steps": 600_000,
}

#: Each preset's settings where they differ from :class:`DQNConfig`'s defaults (the default preset's).
PRESETS: dict[str, dict[str, Any]] = {
    # Goal-conditioned over random pairs, no memory, exact features: the default before the memory agents.
    "tuned": {**_TUNED},
    # tuned + 10 random extra obstacles per robot and episode (aug_obstacle_size 2, aug_potential replan).
    "robust": {**_TUNED, "aug_obstacles": 10},
    # robust + a window of what the robot has sensed and visited (memory_radius 5), no visit count or escape.
    "memory": {**_TUNED, "aug_obstacles": 10, "memory_radius": 5},
    # The memory agent that counts its visits and leaves a cell it keeps coming back to, on exact features.
    "memory-escape": {"noise": "none", "expert_weight": 0.0, "total_env_steps": 600_000},
    # memory-escape trained on noisy measurements (dtradar_rl.task.noise), so the features it learns to rely on are
    # the ones a receiver measures well enough: the default until the margin loss (docs: Navigation).
    "memory-escape-noise": {"expert_weight": 0.0, "total_env_steps": 600_000},
    # The default (DEFAULT_PRESET): memory-escape-noise also told, in every state it visits in training, the moves of
    # the training twin's breadth-first shortest path (DQfD's large-margin loss, --expert-weight 1), so it learns
    # the shortest way in the same budget; it acts from its observation alone. Its budget grows with the twin
    # (budget_for: 600K, or 500 steps per free cell where that is more) (docs: Navigation).
    "memory-escape-noise-margin": {},
    # The paper's agent, on tuned's base. The episodes decide the paper's budget; total_env_steps is only a backstop
    # far above what they use.
    "paper": dict(
        _TUNED,
        obs="paper",
        reward="paper",
        pair="paper",
        num_envs=1,
        episodes=500,
        total_env_steps=10_000_000,
        hidden=(256,) * 5,
        lr=1e-3,
        lr_end=-1.0,
        gamma=0.9,
        batch_size=64,
        buffer_size=100_000,
        learning_starts=1_000,
        env_steps_per_update=1,
        target_update_every=500,
        double_dqn=False,
        eps_start=0.1,
        eps_end=0.1,
    ),
}

#: The defaults a config saved without a field got for it: until the field defaults became the default preset's,
#: they were the ``tuned`` preset's (every later feature off). :meth:`DQNConfig.from_dict` fills missing fields
#: from here, so a checkpoint or ``config.json`` written before a field existed keeps what it meant.
SAVED_DEFAULTS: dict[str, Any] = {**_TUNED, "preset": "tuned"}


#: The paper's training budget (Table VII) and the steps per free cell of the training twin that the default budget
#: gives a larger twin (:func:`budget_for`): 600K covers twins of up to 1 200 free cells (the cubicle has 592, the
#: meeting room 1 282, the Dallas quadrants 1 527-1 968, Munich 3 069).
PAPER_BUDGET = 600_000
STEPS_PER_FREE_CELL = 500


def budget_for(free_cells: int, moving: bool = False) -> int:
    """The default training budget (``total_env_steps=0``) of a twin with ``free_cells`` free cells: the paper's
    600K, or 500 steps per free cell where that is more; twice that on a moving twin, whose agent also learns when
    the movers come (measured: the cubicle's and the meeting room's movers needed 1.2M where their static twins
    need 600K). Measured: Munich (3 069 free cells) with the default preset reaches SPL 0.898 in 600K steps, 0.953
    in 1.2M and 0.978 in the 1.53M this gives it (docs: Navigation)."""
    return max(PAPER_BUDGET, STEPS_PER_FREE_CELL * int(free_cells)) * (2 if moving else 1)


def with_budget(cfg: DQNConfig, free_cells: int, moving: bool = False) -> DQNConfig:
    """``cfg`` with its budget resolved: ``total_env_steps=0`` becomes :func:`budget_for` of the training twin's free
    cells (of its static map on a moving twin); a budget given stays. Training saves the resolved config, so a run
    records the steps it was given."""
    if cfg.total_env_steps:
        return cfg
    return replace(cfg, total_env_steps=budget_for(free_cells, moving))


#: What ``make train`` trains without ``--preset``: the best agent measured on every twin (docs: Navigation).
DEFAULT_PRESET = "memory-escape-noise-margin"


def config_for(preset: str = DEFAULT_PRESET, **overrides) -> DQNConfig:
    """The config of a preset, with ``overrides``; the paper preset uses 80 episodes for outdoor scenes."""
    if preset not in PRESETS:
        raise unknown_name("training preset", preset, PRESETS)
    values = {**PRESETS[preset], "preset": preset}
    scene = overrides.get("scene", DQNConfig.scene)
    if preset == "paper" and scene.split("-")[0] not in INDOOR_SCENES and not is_synthetic(scene):
        values["episodes"] = 80
    return DQNConfig(**{**values, **overrides}).validate()
