"""Every command the how-to guides show runs as written.

Slow (in `make test-all`): one test per page of ``docs/how-to/``. Its shell commands (through this checkout's Makefile,
as the tutorials' test in ``test_docs_commands.py`` runs them) and its Python blocks run in the page's order, in a
temporary folder of the page's own with a data root of its own (``DTRADAR_DATA_ROOT``, ``MINARI_DATASETS_PATH``), so
runs/ and results/ land there and the default data root (``~/.cache/dtradar``) is never touched. What a page takes as
already there from the tutorials is put in place first (``ASSUMES``): the cubicle twin, built once per session and
copied into the page's data root, and the default agent. A command that is not run is in ``NOT_RUN`` with why; the
training and offline-learning commands among them run with a smaller budget instead (``SMALLER``), so that their
options are exercised and what a later command of the page reads (a checkpoint, a policy) is there. A Python block
holding a line of ``NOT_RUN`` is not run. Each page prints its steps' times (``pytest -s``).

Fast (in `make test`): ``NOT_RUN`` and the other lists name only commands and pages the how-to guides still have."""

from __future__ import annotations

import contextlib
import importlib.util
import os
import re
import shlex
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HOWTO = ROOT / "docs" / "how-to"
PAGES = sorted(p.stem for p in HOWTO.glob("*.md"))
#: A fenced bash or python block, also indented (a block inside a list item).
BLOCK = re.compile(r"^( *)```(bash|sh|shell|python)\n(.*?)^\1```", re.M | re.S)
COMMENT = re.compile(r"(^|\s)#.*$")

OFFLINE_RUN = (
    "10 000 d3rlpy updates, then 500 pairs per twin: 1.5-2.5 min on 2 cores measured beside other work, and the "
    "how-tos' seven such runs together are past this file's budget"
)
DALLAS = "reads the Dallas Q3 twin, whose build (make dataset SCENE=dallas-q3) takes about 3 min on 2 cores"
#: Commands of the how-to guides not run, each with why (the exact line as written, its comment dropped).
NOT_RUN = {
    # changed-twins.md
    'make dataset SCENE=dallas-q3 VARIANT=dynamic ARGS="--differential"': DALLAS,
    'make dataset SCENE=dallas-q3 ARGS="--variant all --differential"': "builds the Dallas Q3 blueprint in full and "
    "its dynamic twin: about 3 min on 2 cores",
    'make dataset SCENE=dallas-q3 ARGS="--tx-pose-error 0.5 5 --tx-pose-seed 1"': "builds Dallas Q3's pose twin, "
    "both variants: about 3 min on 2 cores",
    "make bench-nav SCENES=cubicle": "trains the default preset at its full budget (about 3 min on 2 cores) and SB3's "
    "DQN, then evaluates every agent on three twins at three noise levels",
    "make train SCENE=cubicle AGENT=dqn": "the full budget (600 K steps) takes about 3 min on 2 cores; the tutorials' "
    "test runs it as written (first-agent.md)",
    # city.md
    "make dataset SCENE=dallas": "four Dallas quadrants and Q3's dynamic twin: about 6 min on 2 cores",
    "make dataset SCENE=dallas-q3": "a Dallas quadrant and its dynamic twin: about 3 min on 2 cores",
    "make dataset SCENE=houston": "downloads OpenStreetMap (the Overpass endpoint: network), then builds four "
    "quadrants (minutes)",
    "make dataset SCENE=houston OSM=houston.osm": "reads the user's own OpenStreetMap export of Houston (downloaded), "
    "then builds four quadrants (minutes)",
    'make dataset SCENE=dallas ARGS="--cell-m 2"': "four Dallas quadrants at 4x the cells: over 6 min on 2 cores",
    "make dataset SCENE=sionna:munich": "over 1 min of tracing on an idle 2-core CPU (1 min 14 s measured, "
    "docs/results/ray-tracing.md), and more beside the other tests: past this file's budget",
    'make dataset SCENE=sionna:munich ARGS="--grid -200 -200 5 80 80 --tx 40 90 20"': "another Munich build "
    "(6 400 cells): over 1 min on an idle 2-core CPU",
    # moving-twins.md
    'make dataset SCENE=cubicle VARIANT=moving ARGS="--horizon-s 120"': "120 snapshots instead of 16: about 7x the "
    "default's 1.5 min on 2 cores",
    "make train SCENE=cubicle VARIANT=moving": "twice the static budget (1.2 M steps): about 6 min on 2 cores",
    'make train SCENE=cubicle VARIANT=moving MOVING_ARGS="--sense-radius 1"': "twice the static budget (1.2 M "
    "steps): about 6 min on 2 cores",
    'make offline SCENE=cubicle ARGS="--variant moving --behaviour expert"': OFFLINE_RUN,
    # offline-rl.md
    'make train SCENE=cubicle AGENT=dqn ARGS="--preset tuned --out runs/cubicle/dqn-tuned"': "the tuned preset's "
    "full budget: about 3 min on 2 cores",
    "python -m dtradar_data publish cubicle/blueprint/noisy-shortest@v0": "uploads to the Hugging Face Hub "
    "(network, an account)",
    "python -m dtradar_data pull cubicle/blueprint/noisy-shortest@v0": "downloads from the Hugging Face Hub (network)",
    "python -m dtradar_rl offline --scene dallas-q3 --behaviour expert --algorithm bcq --n-steps 12000 "
    "--transitions 1000000": DALLAS,
    "python -m dtradar_rl offline --scene dallas-q3 --behaviour expert --algorithm bcq --precision auto "
    "--batch-size 0": DALLAS,
    'make log SCENE=cubicle BEHAVIOUR=expert ARGS="--steps 1000000 --seed 1"': "logs 1 M steps (10x the default): "
    "2.5 min on 2 cores measured beside other work",
    'make offline SCENE=cubicle ARGS="--algorithm cql --logged cubicle/blueprint/noisy-shortest"': OFFLINE_RUN,
    'make offline SCENE=cubicle ARGS="--algorithm bcq --logged cubicle/blueprint/expert --n-steps 4000"': OFFLINE_RUN,
    'make offline SCENE=cubicle ARGS="--algorithm dqn --behaviour medium"': OFFLINE_RUN,
    "python -m dtradar_rl offline --scene cubicle --algorithm dqn --behaviour expert --relabel none "
    "--senses none": OFFLINE_RUN,
    "python -m dtradar_rl offline --scene cubicle --algorithm bc --behaviour expert --relabel future": OFFLINE_RUN,
    "python -m dtradar_rl offline --scene cubicle --algorithm bcq --behaviour expert --senses memory": OFFLINE_RUN,
    "export MINARI_DATASETS_PATH=~/.cache/dtradar/minari": "points Minari at the default data root, which tests "
    "never touch; the test sets MINARI_DATASETS_PATH to the page's own folder instead",
    "make offline-bench SCENE=cubicle": "90 d3rlpy runs (5 families x 6 algorithms x 3 seeds) of 10 000 updates, "
    "each 1-2 min on 2 cores, with FQE and the tabular rows: hours",
    "make offline-bench SCENE=dallas-q3": "about 29 min on 2 cores, and " + DALLAS,
    'make offline-bench SCENE=cubicle ARGS="--seeds 0 --n-steps 10000 --no-fqe"': "30 d3rlpy runs (5 families x 6 "
    "algorithms) of 10 000 updates, each 1-2 min on 2 cores",
    'make offline-bench SCENE=dallas-q3 ARGS="--no-deep"': DALLAS,
    'make offline-bench SCENE=dallas-q3 ARGS="--behaviours navigate stitch explore"': DALLAS,
    'make offline-bench SCENE=dallas-q3 ARGS="--precision auto --batch-size 0"': DALLAS,
    'make offline-bench SCENE=dallas-q3 ARGS="--relabel none --senses none"': DALLAS,
    'make offline-bench SCENE=dallas-q3 ARGS="--executor ray"': DALLAS,
    'make offline-bench SCENE=dallas-q3 ARGS="--executor ray --ray-address auto"': "needs a Ray cluster's address "
    "sharing the data root, and " + DALLAS,
    # reproduce-the-paper.md
    'make paper SCENES="cubicle meeting"': "trains the paper's agent over 5 seeds per scene and the cross matrix: "
    "hours on 2 cores",
    "make paper": "every scene's paper agent over 5 seeds: hours on 2 cores",
    'make train SCENE=dallas-q3 AGENT=dqn ARGS="--preset paper"': DALLAS,
    'make eval SCENE=dallas-q3 ARGS="--checkpoint runs/dallas-q3/dqn/model.pt"': DALLAS,
    "make train SCENE=dallas-q3": DALLAS,
    "make eval SCENE=dallas-q3": DALLAS,
    "python -m dtradar_rl cross --scenes dallas-q1 dallas-q2 dallas-q3 dallas-q4": "reads the four Dallas "
    "quadrants (about 6 min to build) and trains one agent per quadrant: tens of minutes",
    # run-benchmarks.md
    "make gpu-pack": "copies the Dallas Q3 twin, whose build takes about 3 min on 2 cores",
    "bash bench/gpu.sh": "runs on a machine with an NVIDIA GPU (and installs from PyPI: network)",
    'make bench-gpu ARGS="--device cpu --trace-cells 64 --cpu-trace-cells 64 --env-counts 256 --train-steps 20000"': (
        DALLAS
    ),
    # solve-exactly.md
    'make solve SCENE=dallas-q3 ARGS="--rewards paper --gamma 0.99"': DALLAS,
    # train-agents.md
    'make train SCENE=cubicle AGENT=dqn ARGS="--preset tuned"': "the tuned preset's full budget: about 3 min on 2 "
    "cores",
    'make train SCENE=cubicle AGENT=dqn ARGS="--seed 1 --out runs/cubicle/dqn-s1"': "the full budget: about 3 min "
    "on 2 cores",
    'make train SCENE=cubicle AGENT=dqn ARGS="--noise 2x"': "the full budget: about 3 min on 2 cores",
    'result = train(config_for(scene="cubicle"))': "the default preset's full budget: about 3 min on 2 cores",
    'make sweep SCENES="cubicle meeting" SEEDS="0 1 2"': "six trainings at the full budget (about 3 min each on 2 "
    "cores) and the meeting twin's build",
}
#: Commands of NOT_RUN run with a smaller budget instead (appended to their ARGS): as written but for their length, so
#: that what a later command of the page reads (a checkpoint, a policy) is there and their options are exercised.
TRAIN_BUDGET = "--total-env-steps 30000"  # of 600 K (1.2 M among movers): about 10 s
OFFLINE_BUDGET = "--n-steps 500 --pairs 100"  # of 10 000 updates and 500 pairs per twin: about 20 s
SMALLER = {
    "make train SCENE=cubicle AGENT=dqn": TRAIN_BUDGET,
    'make train SCENE=cubicle AGENT=dqn ARGS="--preset tuned --out runs/cubicle/dqn-tuned"': TRAIN_BUDGET,
    'make train SCENE=cubicle AGENT=dqn ARGS="--preset tuned"': TRAIN_BUDGET,
    'make train SCENE=cubicle AGENT=dqn ARGS="--seed 1 --out runs/cubicle/dqn-s1"': TRAIN_BUDGET,
    'make train SCENE=cubicle AGENT=dqn ARGS="--noise 2x"': TRAIN_BUDGET,
    "make train SCENE=cubicle VARIANT=moving": TRAIN_BUDGET,
    'make train SCENE=cubicle VARIANT=moving MOVING_ARGS="--sense-radius 1"': TRAIN_BUDGET,
    'make log SCENE=cubicle BEHAVIOUR=expert ARGS="--steps 1000000 --seed 1"': "--steps 100000",  # the default's
    **{line: OFFLINE_BUDGET for line, why in NOT_RUN.items() if why == OFFLINE_RUN},
}
#: Pages none of whose commands run, and why.
RUNS_NONE = {
    "city": "every command builds a city or a Sionna scene (minutes on 2 cores) or downloads a map",
    "reproduce-the-paper": "every command trains the paper's agents over seeds (hours) or reads the Dallas twins",
    "run-benchmarks": "its commands read the Dallas Q3 twin or need a GPU machine",
}
#: What a page takes as already there (from the tutorials), put in place before its first command: ``twin``, the
#: cubicle twin of Tutorial 2 (make dataset SCENE=cubicle); ``agent``, the default agent of Tutorial 3 (make train
#: SCENE=cubicle), which make eval reports.
TUTORIAL_AGENT = "make train SCENE=cubicle"
ASSUMES = {
    "changed-twins": ("twin",),
    "moving-twins": ("twin", "agent"),
    "offline-rl": ("twin",),
    "solve-exactly": ("twin",),
    "train-agents": ("twin", "agent"),
}

#: A file each page's commands write (relative to its folder): they did what the page says, not only exit 0.
WRITES = {
    "changed-twins": ("data/datasets/cubicle-txpose/dynamic", "runs/cubicle/adapt/adapt.json"),
    "channels": ("ch.npz",),
    "moving-twins": ("runs/cubicle/eval-moving/paths_moving.gif", "data/logged/synthetic-moving/blueprint/expert"),
    "offline-rl": ("data/logged/cubicle/blueprint/mixture", "runs/cubicle/offline/cql"),
    "solve-exactly": ("results/solve/cubicle/solve.json",),
    "train-agents": ("runs/cubicle/dqn-s1/model.pt", "runs/cubicle/eval"),
    "your-own-room": ("plan.png", "data/datasets/my-room/dynamic"),
}


def name_it_my_room(folder: Path) -> None:
    """Step 2 of your-own-room.md: the copied room file gets a name of its own (a built-in name is refused)."""
    path = folder / "my-room.toml"
    text = path.read_text(encoding="utf-8")
    assert '\nname = "cubicle"\n' in text, "the cubicle's room file no longer names its scene as step 2 says"
    path.write_text(text.replace('\nname = "cubicle"\n', '\nname = "my-room"\n', 1), encoding="utf-8")


#: What a page's prose tells the reader to do after a command, done after it.
THEN = {"cp dtradar_data/scenes/indoor/cubicle.toml my-room.toml": name_it_my_room}


def page_steps(page: str) -> list[tuple[str, str, object]]:
    """``page``'s steps in its order: ``("bash", line, words)`` per command (a line as written, continued lines joined,
    its comment dropped; ``a && b`` gives two) and ``("python", lines, code)`` per Python block (its lines, comments
    dropped, as NOT_RUN names them)."""
    text = (HOWTO / f"{page}.md").read_text(encoding="utf-8")
    steps: list[tuple[str, str, object]] = []
    for m in BLOCK.finditer(text):
        body = textwrap.dedent(m.group(3))
        if m.group(2) == "python":
            lines = [COMMENT.sub("", line).strip() for line in body.splitlines()]
            steps.append(("python", "\n".join(line for line in lines if line), body))
            continue
        for line in body.replace("\\\n", " ").splitlines():
            for part in COMMENT.sub("", line).split("&&"):
                if part.strip():
                    steps.append(("bash", " ".join(part.split()), shlex.split(part)))
    return steps


def page_commands(page: str) -> set[str]:
    """Every command line of ``page`` and every line of its Python blocks (the keys NOT_RUN may name)."""
    return {line for kind, text, _ in page_steps(page) for line in (text.splitlines() if kind == "python" else [text])}


def block_name(lines: str) -> str:
    """A Python block's first line that is not an import."""
    return next((ln for ln in lines.splitlines() if not ln.startswith(("import ", "from "))), lines.splitlines()[0])


def runs(line: str) -> bool:
    return line not in NOT_RUN or line in SMALLER


def smaller(words: list[str], budget: str) -> list[str]:
    """``words`` with ``budget`` appended to its options (a make command's ARGS)."""
    if words[0] != "make":
        return [*words, *budget.split()]
    rest = [w for w in words if not w.startswith("ARGS=")]
    args = " ".join([*(w[len("ARGS=") :] for w in words if w.startswith("ARGS=")), budget])
    return [*rest, f"ARGS={args}"]


def command(words: list[str]) -> list[str]:
    """The argv that runs ``words`` in the page's folder with this checkout's code and interpreter."""
    if words[0] == "make":
        return ["make", "-s", "-f", str(ROOT / "Makefile"), f"PY={sys.executable}", *words[1:]]
    if words[0] in ("python", ".venv/bin/python"):
        return [sys.executable, *words[1:]]
    if words[0] == "cp":  # copies a file of the repository, whose root the page's paths are relative to
        return ["cp", *(str(ROOT / w) for w in words[1:-1]), words[-1]]
    raise AssertionError(f"{shlex.join(words)}: not a command this test can run (add it or list it in NOT_RUN)")


def test_every_not_run_command_is_still_on_a_how_to_page():
    commands = set().union(*(page_commands(p) for p in PAGES))
    assert set(NOT_RUN) <= commands, f"not on any how-to page any more: {sorted(set(NOT_RUN) - commands)}"
    assert set(SMALLER) <= set(NOT_RUN), sorted(set(SMALLER) - set(NOT_RUN))
    assert set(RUNS_NONE) | set(ASSUMES) <= set(PAGES)


def test_a_page_runs_a_command_unless_it_says_why_not():
    for page in PAGES:
        ran = [(kind, text, step) for kind, text, step in page_steps(page) if all(map(runs, text.splitlines()))]
        assert bool(ran) != (page in RUNS_NONE), f"{page}: runs {ran}; RUNS_NONE: {RUNS_NONE.get(page)}"
        for kind, _, words in ran:
            if kind == "bash":
                command(words)  # one this test knows how to run


def test_the_steps_are_read_as_written():
    steps = page_steps("train-agents")
    assert (
        "bash",
        'make eval SCENE=cubicle ARGS="--noise none"',
        ["make", "eval", "SCENE=cubicle", "ARGS=--noise none"],
    ) in steps
    assert smaller(["make", "train", "ARGS=--noise 2x"], "--a 1") == ["make", "train", "ARGS=--noise 2x --a 1"]
    assert smaller(["make", "train"], "--a 1") == ["make", "train", "ARGS=--a 1"]
    own_room = page_steps("your-own-room")  # its blocks are indented in a list
    assert [s[1] for s in own_room if s[0] == "bash"] == [
        "cp dtradar_data/scenes/indoor/cubicle.toml my-room.toml",
        "make dataset SCENE=my-room.toml",
    ]


@pytest.fixture(scope="session")
def cubicle_twin(tmp_path_factory) -> Path:
    """The cubicle twin (both variants), built once: a data root holding ``datasets/cubicle``."""
    data = tmp_path_factory.mktemp("cubicle-twin") / "data"
    env = {**os.environ, "DTRADAR_DATA_ROOT": str(data), "MINARI_DATASETS_PATH": str(data / "minari")}
    cmd = command(["make", "dataset", "SCENE=cubicle"])
    done = subprocess.run(cmd, cwd=data.parent, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"make dataset SCENE=cubicle failed:\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"
    return data


@pytest.mark.slow
@pytest.mark.sionna
@pytest.mark.skipif(shutil.which("make") is None, reason="needs make")
@pytest.mark.skipif(importlib.util.find_spec("sionna") is None, reason="its twins are built with Sionna RT")
@pytest.mark.parametrize("page", [p for p in PAGES if p not in RUNS_NONE])
def test_the_how_to_runs_as_written(page, tmp_path, request):
    data, minari = tmp_path / "data", tmp_path / "minari"
    env = {**os.environ, "DTRADAR_DATA_ROOT": str(data), "MINARI_DATASETS_PATH": str(minari)}
    assumed = ASSUMES.get(page, ())
    if "twin" in assumed:
        shutil.copytree(request.getfixturevalue("cubicle_twin") / "datasets" / "cubicle", data / "datasets" / "cubicle")
    steps = page_steps(page)
    if "agent" in assumed:
        steps.insert(0, ("assumed", TUTORIAL_AGENT, shlex.split(TUTORIAL_AGENT)))
    namespace: dict = {}
    timings: list[tuple[float, str]] = []
    start = time.monotonic()
    for kind, text, step in steps:
        t0 = time.monotonic()
        if kind == "python":
            if not all(runs(line) for line in text.splitlines()):
                continue
            with contextlib.chdir(tmp_path), pytest.MonkeyPatch.context() as mp:
                mp.setenv("DTRADAR_DATA_ROOT", str(data))
                mp.setenv("MINARI_DATASETS_PATH", str(minari))
                exec(compile(step, f"docs/how-to/{page}.md", "exec"), namespace)
            timings.append((time.monotonic() - t0, "python block: " + block_name(text)))
            continue
        if not runs(text):
            continue
        words = smaller(step, SMALLER[text]) if text in SMALLER else step
        done = subprocess.run(command(words), cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
        assert done.returncode == 0, f"{page}: {text} failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
        if text in THEN:
            THEN[text](tmp_path)
        note = f"  [{SMALLER[text]}]" if text in SMALLER else "  [assumed: Tutorial 3]" if kind == "assumed" else ""
        timings.append((time.monotonic() - t0, text + note))
    report = "\n".join(f"  {s:6.1f} s  {t}" for s, t in timings)
    print(f"\n{page}: {len(timings)} steps in {time.monotonic() - start:.0f} s\n{report}")
    assert timings, f"{page} ran nothing (list it in RUNS_NONE with why)"
    missing = [f for f in WRITES.get(page, ()) if not (tmp_path / f).exists()]
    assert not missing, f"{page}: its commands ran but did not write {missing}"
