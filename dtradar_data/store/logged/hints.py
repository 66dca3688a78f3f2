"""The commands that (re)create a logged version, for the hints of its errors: ``python -m dtradar_rl log ...`` and
``make log ...``, exact when the version's ``meta.json`` says how it was logged (logging the same inputs again
gives the same version, which then replaces a damaged copy), generic otherwise. ``make dataset`` cannot make one."""

from __future__ import annotations

import shlex
from typing import Any

from dtradar_data.core.ids import HASH_RE, LoggedId

__all__ = ["BEHAVIOUR_KINDS", "log_commands", "relog_hint"]

#: The behaviour kinds of ``python -m dtradar_rl log --behaviour`` (:data:`dtradar_rl.offline.behaviours.BEHAVIOURS`,
#: which dtradar_data may not import: torch).
BEHAVIOUR_KINDS: tuple[str, ...] = (
    "random",
    "noisy-shortest",
    "epsilon-greedy",
    "mixture",
    "expert",
    "medium",
    "medium-replay",
    "mixed",
    "navigate",
    "stitch",
    "explore",
)


def _fmt(value: Any) -> str:
    return shlex.quote(str(value))


def log_commands(lid: LoggedId, meta: dict[str, Any] | None = None) -> tuple[str, str]:
    """``(python -m dtradar_rl log ..., make log ...)`` for ``lid``; with the version's ``meta`` every setting
    that enters its version hash is given, so the command logs that very version again."""
    meta = meta or {}
    inputs = meta.get("inputs") if isinstance(meta.get("inputs"), dict) else {}
    beh = inputs.get("behaviour") or meta.get("behaviour") or {}
    beh = beh if isinstance(beh, dict) else {}
    kind = beh.get("kind") or (lid.behaviour if lid.behaviour in BEHAVIOUR_KINDS else None)
    rest = ["--variant", lid.variant]
    if kind != lid.behaviour:
        rest += ["--name", lid.behaviour]
    if "shortest_prob" in beh:
        rest += ["--shortest-prob", _fmt(beh["shortest_prob"])]
    if "epsilon" in beh:
        rest += ["--epsilon", _fmt(beh["epsilon"])]
    if beh.get("checkpoint_sha256"):
        rest += ["--checkpoint", f"MODEL.PT(sha256:{str(beh['checkpoint_sha256'])[:12]}...)"]
    if kind == "mixture" and beh.get("components"):
        rest += ["--components", *(_fmt(c) for c in beh["components"])]
    medium = beh.get("medium") if isinstance(beh.get("medium"), dict) else {}
    if "target" in medium:  # the medium agent's recipe enters the version of every family that uses it
        rest += ["--medium-target", _fmt(medium["target"])]
    if "budget" in medium:
        rest += ["--medium-budget", _fmt(medium["budget"])]
    if inputs:
        settings = inputs.get("settings") or {}
        rest += ["--steps", _fmt(inputs.get("steps")), "--seed", _fmt(inputs.get("seed"))]
        for key, flag in (("num_envs", "--num-envs"), ("obs", "--obs"), ("reward", "--reward")):
            if key in settings:
                rest += [flag, _fmt(settings[key])]
        if settings.get("max_steps"):
            rest += ["--max-steps", _fmt(settings["max_steps"])]
        if settings.get("device_kind") == "cuda":
            rest += ["--device", "cuda"]
        pv = str(inputs.get("parent_version") or "")
        if HASH_RE.fullmatch(pv):  # a stored parent: pin its version (a synthetic twin's is a table digest)
            rest += ["--revision", pv]
    behaviour = kind or "KIND"
    python = f"python -m dtradar_rl log --scene {lid.scene} --behaviour {behaviour} " + " ".join(rest)
    make = f"make log SCENE={lid.scene} BEHAVIOUR={behaviour} ARGS={shlex.quote(' '.join(rest))}"
    return python, make


def relog_hint(
    lid: LoggedId, meta: dict[str, Any] | None = None, damaged: str | None = None, *, new: bool = False
) -> str:
    """How to get ``lid``: the log commands (``new``: it was never logged here), and for a ``damaged`` version
    folder that logging it again replaces it, or that it can be removed."""
    python, make = log_commands(lid, meta)
    exact = bool(meta and meta.get("inputs"))
    if new:
        text = f"log it: `{python}`, or `{make}`"
    else:
        settings = "" if exact else " with the settings it was logged with"
        text = f"log it again{settings}: `{python}`, or `{make}`"
    if damaged:
        text += f"; that replaces the damaged copy, or remove {damaged}"
    if "KIND" in python:
        text += f" (KIND: one of {', '.join(BEHAVIOUR_KINDS)})"
    return text
