"""The default agent: a localisation filter over the blueprint's radio fingerprints, acting on exact distances (QMDP).

The robot is switched on somewhere and is never told where it is (:mod:`dtradar_rl.task.sensing`). It carries the
blueprint twin as its map: every cell's radio fingerprint (what each transmitter's strongest path looks like there),
which cells are blocked, and where each cell lies. At every step it

1. **predicts** where its last move took it: the belief (a histogram over the map's cells) shifts one cell the way
   it moved; after a bump it stays, and cells where the map has that move free lose weight (a new obstacle may stand
   there, so not all of it: :data:`MAP_ERROR`); a move the map forbids keeps a little weight too (a dynamic twin may
   have moved an object out of the way);
2. **weighs** each cell by how well it explains what the robot senses now: the measured radio of every transmitter
   against the cell's fingerprint, each quantity a Gaussian error with the receiver's noise (:attr:`FilterConfig.noise`)
   plus a floor for what a twin's change does to it (:data:`FLOOR`), circular for azimuths and phase (as a cosine
   and a sine, so the distances to every fingerprint are one matrix product), and robust (a transmitter's mismatch
   counts at most :data:`TX_CLIP` squared standard deviations per quantity: a changed twin's radio differs in places);
   whether each transmitter is heard against whether the map hears it there (a mismatch weighs as the worst match);
   and the proximity sensor's four readings against the map's obstacles around the cell;
3. **acts** by QMDP (Littman et al. 1995): the move whose expected distance to the target, over the belief, is
   smallest, with breadth-first distances on the map plus the obstacles it has sensed this episode (through the map's
   obstacles where no free path exists); a move the proximity sensor reports blocked is never taken. When the belief
   is sure of a cell (:data:`SURE`), a neighbour the sensor reports blocked where the map has it free, or a move that
   bumped, is a new obstacle: it goes into the robot's own map and the distances are replanned. A robot whose
   odometry shows it going back and forth, or bumping, :data:`ESCAPE_AFTER` times in a row takes a seeded random
   move. On a moving twin it keeps no sensed obstacle and waits for a mover by walking into it (:meth:`env_for`).

Nothing is learnt: the filter's model is the blueprint (its fingerprints and obstacles) and the receiver's noise model.
A decision is one Bayes update and one expectation over the map's cells, batched over robots in torch.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import InvalidSettingError
from dtradar_data.core.files import write_atomic
from dtradar_rl.agents.grid_search import GridSearch
from dtradar_rl.envs.honest import HonestNavEnv
from dtradar_rl.task.config import Config
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.moving_masks import background
from dtradar_rl.task.noise import noise_model
from dtradar_rl.task.runs import agent_path
from dtradar_rl.task.sensing import CIRCULAR, PER_TX, Readings, neighbours, sensing_for

#: How far (in squared standard deviations per measured quantity) one transmitter's mismatch counts at most: a
#: changed twin's radio differs in places.
TX_CLIP = 4.0
#: Each quantity's error floor on top of the receiver's noise, in SI units (angles 3°, delay 3 ns, gain 3 dB, phase
#: 30°): what a twin's change does to the radio, and a flatter belief while the robot is still unsure, which QMDP acts
#: on better. Chosen by measurement (realistic noise, 300 pairs; the cubicle, meeting room and office dynamic twins,
#: Dallas Q2's blueprint and Q3's dynamic twin): 2° / 2 ns / 2 dB / 20° gave 0.967 / 0.975 / 0.987 / 0.995 / 0.973
#: SPL, these 0.972 / 0.972 / 0.983 / 0.995 / 0.974, 4° / 4 ns / 4 dB / 40° 0.969 / 0.968 / 0.974 / 0.995 / 0.972.
FLOOR = np.array([math.radians(3)] * 4 + [3e-9, 3.0, math.radians(30)])
#: The weight of a reading the map cannot explain: a proximity reading or a heard flag against the map, a move the map
#: forbids, a bump where the map has the move free (a twin's change; a wrong map costs a few steps, never the robot).
MAP_ERROR = 0.05
LOG_MAP_ERROR = math.log(MAP_ERROR)
#: Elements of one chunk of robots' distances to every fingerprint (robots x cells x transmitters).
CHUNK = 1 << 21
#: Log-weight floor below the best cell: no cell is ever ruled out for good, so a wrong belief recovers.
FLOOR_LOG = 30.0
#: Belief in one cell above which what the robot senses around it is taken as a fact about that cell.
SURE = 0.9
#: Moves back and forth in a row after which the robot takes a random move (:meth:`RadioFilterAgent._escape`), and
#: the seed of those moves (restarted with every batch of episodes: evaluations repeat).
ESCAPE_AFTER = 3
ESCAPE_SEED = 0
#: The opposite of each move (X- <-> X+, Y- <-> Y+).
OPPOSITE = torch.tensor([1, 0, 3, 2])
#: The format of a saved agent.
FORMAT = "dtradar-radio-filter/1"


@dataclass(frozen=True)
class FilterConfig(Config):
    """Build the default agent of a scene: a localisation filter over its blueprint's radio fingerprints, acting on
    exact distances (nothing to learn: its model is the map and the receiver's noise model)."""

    scene: str = "cubicle"
    """scene whose blueprint is the agent's map"""
    sensing: str = "radio"
    """what the robot observes (dtradar_rl.task.sensing): radio, radio-no-proximity, no-angles, no-delay, no-gain,
    no-phase, rssi or no-radio"""
    noise: str = "realistic"
    """the receiver noise the filter's likelihood assumes: none, realistic or 2x"""
    out: str = ""
    """where the agent is saved (default runs/<scene>/agent/agent.json)"""

    def validate(self) -> FilterConfig:
        super().validate()
        s = sensing_for(self.sensing)
        if s.privileged:
            raise InvalidSettingError(
                "the radio-filter agent acts from honest sensing; 'privileged' is the learnt agents' observation",
                hint="pick an honest sensing (e.g. radio), or train a DQN for the privileged upper bound",
            )
        noise_model(self.noise)
        return self

    @property
    def path(self) -> Path:
        return Path(self.out) if self.out else agent_path(self.scene)


class RadioFilterAgent:
    """Histogram localisation over the blueprint's fingerprints + QMDP on breadth-first distances (module docstring).

    It has the part of :class:`~dtradar_rl.agents.policy.Policy` the evaluation loop uses (``env_for``, ``act``,
    ``obs_preset``, ``meta``) and keeps one belief per robot, started afresh whenever a robot is switched on."""

    obs_preset = "honest"

    def __init__(self, blueprint: Dataset, config: FilterConfig | None = None, device: str = "cpu"):
        self.config = (config or FilterConfig()).validate()
        self.sensing = sensing_for(self.config.sensing)
        self.device = dev = torch.device(device)
        self.blueprint = blueprint
        blueprint = background(blueprint)  # a moving twin's static map
        self.mdp = GridMDP.from_dataset(blueprint)
        readings = Readings.from_dataset(blueprint)
        t = lambda a, dt=torch.float32: torch.as_tensor(np.ascontiguousarray(a), dtype=dt, device=dev)
        n = self.mdp.num_cells
        free = self.mdp.free
        self.k = readings.transmitters
        self.heard = heard = t(readings.heard, torch.bool)
        self.known = t(free, torch.bool)  # cells whose fingerprint the map has (a blocked cell's is unknown)
        self.around = t(readings.blocked_around, torch.bool)  # [cells, 4] the map's obstacles around each cell
        self._heard_t, self._around_t = self.heard.float().T.contiguous(), self.around.float().T.contiguous()
        self._heard_count, self._around_count = self._heard_t.sum(0), self._around_t.sum(0)
        self._known_f = self.known.float()
        # the quantities measured, each in units of its standard deviation (the receiver's noise and the floor)
        used = np.flatnonzero(self.sensing.measured)
        inv_sigma = 1.0 / np.sqrt(noise_model(self.config.noise).sigmas() ** 2 + FLOOR**2)[used]
        self.used = t(used, torch.long)
        circ = CIRCULAR[used]
        self._lin, self._circ = t(np.flatnonzero(~circ), torch.long), t(np.flatnonzero(circ), torch.long)
        self._lin_scale = t(inv_sigma[~circ], torch.float64)
        self._circ_scale = t(np.tile(inv_sigma[circ], 2), torch.float64)
        fp = self._embed(t(readings.radio))  # [cells, K, e]
        self.center = (fp * heard[..., None]).sum(0) / heard.sum(0).clamp(min=1)[:, None]  # [K, e]
        fp = (fp - self.center) * heard[..., None]
        self.fp = fp.permute(1, 2, 0).float().contiguous()  # [K, e, cells]
        self.fp2 = fp.square().sum(2).T[:, None, :].float().contiguous()  # [K, 1, cells]
        self._heard_f = heard.T[:, None, :].float().contiguous()
        self._heard_penalty = -0.5 * TX_CLIP * len(used) + LOG_MAP_ERROR if len(used) else LOG_MAP_ERROR
        #: the radio term of a cell without a fingerprint (blocked on the map): the worst match
        self._unknown = t(np.where(free, 0.0, -0.5 * TX_CLIP * len(used) * readings.transmitters))
        self.positions = t(readings.target_xy)
        nbr = neighbours(blueprint.shape)
        # prediction: the cell each move came from (-1: none), and the weight of that move on the map
        prev = np.full((4, n), -1, np.int64)
        weight = np.zeros((4, n), np.float32)
        for a in range(4):
            src = np.flatnonzero(nbr[:, a] >= 0)
            prev[a, nbr[src, a]] = src
            weight[a, nbr[src, a]] = np.where(free[nbr[src, a]], 1.0, MAP_ERROR)
        self.prev, self.log_move = t(prev.clip(min=0), torch.long), t(np.log(np.maximum(weight, 1e-30)))
        self.next_cell = t(self.mdp.next_cell, torch.long)
        self._next_flat = self.next_cell.reshape(-1)
        self._bump_cost = t(self.mdp.collides, torch.float32)  # [cells, 4]
        self.neighbour = t(nbr.clip(min=0), torch.long)
        self.log_bump = t(np.where(self.mdp.collides, 0.0, math.log(MAP_ERROR)))  # [cells, 4]
        self.log_prior = t(np.where(free, 0.0, math.log(MAP_ERROR)))
        self.search = GridSearch(self.mdp, dev)
        # a step through a cell the map blocks costs more than any free path, so the robot plans through the map's
        # obstacles only where no free path exists (a changed twin may have freed the cell it needs)
        self._through = float(n)
        self._far = float(n) * float(n)
        self.meta: dict[str, Any] = {
            "dataset": {"name": blueprint.name, "version": blueprint.version},
            "path": "radio-filter",
            "sensing": self.sensing.name,
            "stats": {},
        }
        self._n = -1
        #: a moving twin (set by :meth:`env_for`): no sensed obstacles, and a move into a mover waits by the bump
        self.forget = False
        self._opposite = OPPOSITE.to(dev)

    @classmethod
    def from_agent(cls, agent: RadioFilterAgent, sensing: str) -> RadioFilterAgent:
        """The same agent (map, noise model) observing with another honest ``sensing``."""
        return cls(agent.blueprint, replace(agent.config, sensing=sensing), str(agent.device))

    # -- the Policy interface used by dtradar_rl.evaluation.evaluate -----------------------------------------------
    def env_for(self, ds: Dataset, num_envs: int, *, noise="none", seed: int = 0, **kwargs) -> HonestNavEnv:
        """The honest env of ``ds`` for ``num_envs`` robots (each switched on afresh). On a moving twin the robot
        knows that things move around it (people, vehicles): what it senses blocked where its map is free is a mover
        that walks on, so it keeps no sensed obstacle and plans on the map; a move into a mover is not refused, the
        bump waits for it to go (a four-move robot's only way to wait). Walking round it instead was measured worse:
        on the dense 12 x 8 synthetic moving twin 0.76 success, against 0.97 waiting."""
        self._start(num_envs)
        self.forget = ds.is_moving
        if ds.transmitters != self.k:
            raise InvalidSettingError(
                f"the agent's map ({self.meta['dataset']['name']}) has {self.k} transmitter(s), {ds.name} has "
                f"{ds.transmitters}",
                hint="build the agent on a blueprint of the same deployment",
            )
        return HonestNavEnv.from_dataset(ds, num_envs, sensing=self.sensing, noise=noise, seed=seed, **kwargs)

    def act(self, obs: torch.Tensor, shield: bool = False) -> torch.Tensor:
        """One move per robot from its honest observation; ``shield`` is accepted and ignored (the proximity sensor
        already keeps the robot out of what it senses)."""
        obs = obs.to(self.device)
        if obs.shape[0] != self._n:
            self._start(obs.shape[0])
        blocked_now, moved, last, fresh = self.readings(obs)
        self._new_episodes(fresh, obs[:, -2:])
        self.log_belief, belief = self.belief_step(self.log_belief, obs)
        self._sense_obstacles(belief, blocked_now, moved, last, fresh)
        action = self._qmdp(belief, blocked_now)
        return self._escape(action, last, moved, fresh, blocked_now)

    def _escape(self, action, last, moved, fresh, blocked_now) -> torch.Tensor:
        """A robot whose moves have gone back and forth :data:`ESCAPE_AFTER` times in a row (its odometry says so)
        takes a seeded random move the proximity sensor allows: a belief that two places explain equally well, or a
        changed twin that fools it, can hold a greedy robot between two cells for good; a move elsewhere reads
        something new. One that has bumped :data:`ESCAPE_AFTER` times in a row takes a random move of all four: on a
        moving twin a mover walking back and forth beside it can refuse its planned move every time, in step with
        it."""
        a = last.argmax(1)
        reversed_ = (
            last.any(1) & moved & ~fresh & (self._prev_move >= 0) & (a == self._opposite[self._prev_move.clamp(min=0)])
        )
        self._reversals = torch.where(reversed_, self._reversals + 1, torch.zeros_like(self._reversals))
        self._prev_move = torch.where(last.any(1) & moved & ~fresh, a, torch.full_like(a, -1))
        bumped = last.any(1) & ~moved & ~fresh
        self._bumps = torch.where(bumped, self._bumps + 1, torch.zeros_like(self._bumps))
        stuck, pinned = self._reversals >= ESCAPE_AFTER, self._bumps >= ESCAPE_AFTER
        if bool((stuck | pinned).any()):
            score = torch.rand(blocked_now.shape, generator=self._gen, device=self.device)
            allowed = ~blocked_now if self.sensing.proximity else torch.ones_like(blocked_now)
            allowed = (allowed | ~allowed.any(1, keepdim=True)) | pinned[:, None]
            action = torch.where(stuck | pinned, torch.where(allowed, score, -1.0).argmax(1), action)
            self._reversals = torch.where(stuck, torch.zeros_like(self._reversals), self._reversals)
            self._bumps = torch.where(pinned, torch.zeros_like(self._bumps), self._bumps)
        return action

    # -- the filter ------------------------------------------------------------------------------------------------
    def readings(self, obs: torch.Tensor):
        """``(blocked_now, moved, last, fresh)`` of honest observations: the proximity sensor's four flags, whether
        the last move moved the robot, the last move one-hot, and whether the robot was just switched on."""
        k4 = self.k * PER_TX
        return obs[:, k4 : k4 + 4] > 0.5, obs[:, k4 + 4] > 0.5, obs[:, k4 + 5 : k4 + 9], obs[:, k4 + 9] > 0.5

    def belief_step(self, log_belief: torch.Tensor, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(log_belief, belief)`` after one honest observation per robot (``float32[n, cells]`` each): the
        prediction along the odometry and the weighing by what the robot senses (module docstring, steps 1 and 2). A
        switched-on robot starts from the map's prior. Depends on nothing but ``log_belief`` and ``obs``: the offline
        learners replay logged episodes through it (:mod:`dtradar_rl.offline.filter_senses`)."""
        blocked_now, moved, last, fresh = self.readings(obs)
        log_belief = torch.where(fresh[:, None], self.log_prior.expand_as(log_belief), log_belief)
        a = last.argmax(1)
        went = last.any(1) & ~fresh
        shift = went & moved
        if bool(shift.any()):
            idx = torch.nonzero(shift, as_tuple=True)[0]
            src = self.prev[a[idx]]  # [k, cells]
            log_belief[idx] = log_belief[idx].gather(1, src) + self.log_move[a[idx]]
        bump = went & ~moved
        if bool(bump.any()):
            idx = torch.nonzero(bump, as_tuple=True)[0]
            log_belief[idx] += self.log_bump[:, a[idx]].T
        radio = obs[:, : self.k * PER_TX].reshape(-1, self.k, PER_TX)
        log_belief = log_belief + self._log_likelihood(radio[..., :-1], radio[..., -1] > 0.5, blocked_now)
        top = log_belief.max(1, keepdim=True).values
        log_belief = torch.maximum(log_belief - top, torch.full_like(top, -FLOOR_LOG))
        belief = log_belief.exp()
        return log_belief, belief / belief.sum(1, keepdim=True)

    def _new_episodes(self, fresh, target_xy) -> None:
        """A switched-on robot's target cell on the map, and no obstacles sensed or plans made yet."""
        if bool(fresh.any()):
            idx = torch.nonzero(fresh, as_tuple=True)[0]
            self.target[idx] = torch.cdist(target_xy[idx], self.positions).argmin(1)
            self.sensed[idx] = False
            self._plan_target[idx] = -1

    def _log_likelihood(self, measured, heard, blocked_now) -> torch.Tensor:
        """``float32[n, cells]``: log p(reading | cell), up to a constant per robot; robots in chunks, so that the
        distances to every fingerprint (``[robots, cells, K]``) stay small enough for the caches."""
        n = measured.shape[0]
        step = max(1, CHUNK // (self.mdp.num_cells * self.k))
        if n <= step:
            return self._likelihood_chunk(measured, heard, blocked_now)
        out = torch.empty((n, self.mdp.num_cells), device=self.device)
        for i in range(0, n, step):
            j = slice(i, i + step)
            out[j] = self._likelihood_chunk(measured[j], heard[j], blocked_now[j])
        return out

    def _likelihood_chunk(self, measured, heard, blocked_now) -> torch.Tensor:
        # readings that disagree with the map, counted by products of 0/1 flags: sum(a) + sum(b) - 2 a.b; heard or
        # not means nothing on a cell without a fingerprint (blocked on the map: its flags are all 0)
        h = heard.float()
        out = torch.zeros((h.shape[0], self.mdp.num_cells), device=self.device)
        if self.sensing.groups:  # with no radio at all the receiver is off: nothing is heard or not
            # a transmitter heard where the map has no path (or not heard where it has one) counts as the worst
            # match of its quantities: weighed any lighter, the cells no ray reaches draw a noisy robot's belief
            # (Dallas Q2 under 2x noise: 0.18 success with the weight of a proximity mismatch)
            heard_miss = h.sum(1, keepdim=True) * self._known_f + self._heard_count - 2 * h @ self._heard_t
            out += heard_miss * self._heard_penalty
        if self.sensing.proximity:
            p = blocked_now.float()
            out += (p.sum(1, keepdim=True) + self._around_count - 2 * p @ self._around_t) * LOG_MAP_ERROR
        if self.used.numel():
            # transmitter-major ([K, n, cells]): one batched product over the transmitters, no copy of the map
            m = (self._embed(measured) - self.center).float().transpose(0, 1)  # [K, n, e]
            d2 = torch.bmm(m, self.fp).mul_(-2).add_(self.fp2).add_(m.square().sum(2, keepdim=True))
            d2 = d2.clamp_(0, TX_CLIP * len(self.used)).mul_(self._heard_f)  # a transmitter the map hears there
            d2 = d2.mul_(h.T[:, :, None]).sum(0) if self.k > 1 else d2[0].mul_(h)  # ... and the robot hears
            out += d2.mul_(-0.5).add_(self._unknown)
        return out

    def _embed(self, raw: torch.Tensor) -> torch.Tensor:
        """``float64[..., K, e]``: measured quantities (``[..., K, 7]``, SI units) in units of their standard
        deviation, a circular one as its cosine and sine (their distance is the chord, the angle's error while small:
        no wrap-around), so a squared distance to every fingerprint is one matrix product."""
        x = raw[..., self.used].double()
        lin = x[..., self._lin] * self._lin_scale
        ang = x[..., self._circ]
        return torch.cat([lin, torch.cat([ang.cos(), ang.sin()], -1) * self._circ_scale], -1)

    # -- acting ----------------------------------------------------------------------------------------------------
    def _sense_obstacles(self, belief, blocked_now, moved, last, fresh) -> None:
        """Obstacles the map lacks, where the belief is sure of the robot's cell: a neighbour sensed blocked, or the
        cell a move just bumped into."""
        if self.forget:  # a moving twin: what is sensed is mostly movers, gone by the next step or two
            return
        p, cell = belief.max(1)
        sure = p > SURE
        new = torch.zeros_like(blocked_now)
        if self.sensing.proximity:
            new |= blocked_now & ~self.around[cell]
        bumped = last.any(1) & ~moved & ~fresh
        if bool(bumped.any()):  # the move bumped from where the robot is now (it did not move)
            new |= (last > 0.5) & bumped[:, None] & ~self.around[cell]
        new &= sure[:, None]
        if bool(new.any()):
            rows = torch.arange(len(cell), device=self.device)[:, None].expand(-1, 4)
            self.sensed[rows[new], self.neighbour[cell][new]] = True
            self.sensed[torch.arange(len(cell), device=self.device), self.target] = False

    def _qmdp(self, belief, blocked_now) -> torch.Tensor:
        stale = (self._plan_target != self.target) | (self.sensed != self._plan_sensed).any(1)
        if bool(stale.any()):
            d = self.search.through_obstacles(self.target[stale], self.sensed[stale], cost=self._through)
            self._dist[stale] = d.clamp(max=self._far)  # one of its sensed obstacles: as far as anything
            self._plan_target, self._plan_sensed = self.target.clone(), self.sensed.clone()
        # the expected distance after each move; a bump leaves the robot where it is, a step spent
        n, cells = belief.shape
        after = self._dist.index_select(1, self._next_flat).view(n, cells, 4)
        score = torch.bmm(belief[:, None, :], after)[:, 0] + belief @ self._bump_cost
        if self.sensing.proximity:
            refused = blocked_now
            if self.forget:  # a mover (blocked now, free on the map) is walked into: the bump waits for it to go
                refused = blocked_now & self.around[belief.argmax(1)]
            score = torch.where(refused & ~refused.all(1, keepdim=True), torch.inf, score)
        return score.argmin(1)

    def _start(self, n: int) -> None:
        self._n, dev, cells = n, self.device, self.mdp.num_cells
        self.log_belief = self.log_prior.expand(n, cells).clone()
        self.target = torch.zeros(n, dtype=torch.long, device=dev)
        self.sensed = torch.zeros((n, cells), dtype=torch.bool, device=dev)
        self._plan_target = torch.full((n,), -1, dtype=torch.long, device=dev)
        self._plan_sensed = self.sensed.clone()
        self._dist = torch.zeros((n, cells), device=dev)
        self._prev_move = torch.full((n,), -1, dtype=torch.long, device=dev)
        self._reversals = torch.zeros(n, dtype=torch.long, device=dev)
        self._bumps = torch.zeros(n, dtype=torch.long, device=dev)
        self._gen = torch.Generator(device=dev)
        self._gen.manual_seed(ESCAPE_SEED)

    # -- saving ----------------------------------------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """``agent.json``: the format, the settings and the map (blueprint name and version) it was built on."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        config = {k: v for k, v in asdict(self.config).items() if k != "out"}
        record = {"format": FORMAT, "config": config, "map": self.meta["dataset"]}
        record["observes"] = self.sensing.describe()
        write_atomic(path, json.dumps(record, indent=2) + "\n")
        return path


def load_agent(path: str | Path, device: str = "cpu") -> RadioFilterAgent:
    """The agent saved at ``path`` (``agent.json``), on the exact blueprint version it was built on."""
    from dtradar_data.core.errors import CorruptDatasetError
    from dtradar_rl.task.twins import load_dataset

    try:
        record = json.loads(Path(path).read_text())
        if record.get("format") != FORMAT:
            raise ValueError(f"format {record.get('format')!r}")
        cfg = FilterConfig(**record["config"])
        name, version = record["map"]["name"], record["map"]["version"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise CorruptDatasetError(
            f"{path} is not a radio-filter agent ({e})", hint="build it again: make train SCENE=<scene>"
        ) from e
    return RadioFilterAgent(load_dataset(f"{name}@{version}"), cfg, device)


def build_agent(cfg: FilterConfig, device: str = "cpu") -> RadioFilterAgent:
    """``make train``: the agent of ``cfg`` on its scene's blueprint, saved to ``cfg.path``; says what it built."""
    import time

    from dtradar_rl.task.twins import load_dataset

    t0 = time.perf_counter()
    agent = RadioFilterAgent(load_dataset(f"{cfg.scene}/blueprint"), cfg, device)
    path = agent.save(cfg.path)
    m = agent.meta["dataset"]
    print(
        f"agent: {path}\nmap: {m['name']} version {m['version']} ({int(agent.mdp.free.sum())} free cells, "
        f"{agent.k} transmitter(s)); sensing {agent.sensing.name}: {agent.sensing.describe()}\n"
        f"filter noise model: {cfg.noise}; nothing to learn (its model is the map and the receiver's noise), "
        f"built in {time.perf_counter() - t0:.1f} s\nnext: make eval SCENE={cfg.scene}"
    )
    return agent
