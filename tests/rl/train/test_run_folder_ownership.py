"""A run folder belongs to one scene and one config family, and a checkpoint knows its twin: training into another
scene's run or resuming a run of another family is refused with nothing changed, make adapt refuses another scene's
agent, and a run's training state (last.pt) is evaluated as what it is."""

import hashlib
import shutil

import pytest
import torch

from dtradar_rl.agents.checkpoints import TRAINING_STATE, WrongTwinError
from dtradar_rl.cli import main
from dtradar_rl.experiments.adapt import AdaptConfig, adapt
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.train.saved_runs import RunFolderError, check_same_twin, load_policy, trained_twin

SCENE, OTHER = "synthetic-4x3", "synthetic-5x3"
TINY = dict(
    preset="tuned",
    obs="goal",
    num_envs=8,
    total_env_steps=200,
    hidden=(16,),
    batch_size=32,
    learning_starts=50,
    env_steps_per_update=4,
    threads=1,
    verbose=False,
    checkpoint_every=0,
)
ARGS = ["--preset", "tuned", "--obs", "goal", "--num-envs", "8", "--hidden", "16", "--batch-size", "32"]
ARGS += ["--learning-starts", "50", "--threads", "1", "--no-verbose", "--checkpoint-every", "0"]


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A finished tiny run of SCENE (model.pt, last.pt, config.json, ...)."""
    out = tmp_path_factory.mktemp("runs") / "finished"
    cfg = dict(TINY)
    train(config_for(cfg.pop("preset"), scene=SCENE, out=str(out), **cfg))
    return out


@pytest.fixture()
def run(finished, tmp_path):
    """A copy of the finished run, to refuse things against."""
    return shutil.copytree(finished, tmp_path / "run")


def snapshot(folder):
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


@pytest.mark.parametrize("resume", [True, False])
def test_training_another_scene_into_a_run_folder_is_refused_naming_both_scenes(run, capsys, resume):
    before = snapshot(run)
    argv = ["train", "--scene", OTHER, "--out", str(run), "--total-env-steps", "400", *ARGS]
    assert main(argv + (["--resume"] if resume else [])) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "Traceback" not in err
    assert f"{SCENE}/blueprint" in err and f"{OTHER}/blueprint" in err and "--out" in err
    assert "how to fix: pick another --out" in err
    assert snapshot(run) == before  # not a byte changed, config.json included


def test_resuming_a_run_of_another_config_family_is_refused_with_the_runs_own_settings(run):
    before = snapshot(run)
    cfg = dict(TINY, hidden=(32,), num_envs=4)
    with pytest.raises(RunFolderError, match="another config family") as err:
        train(config_for(cfg.pop("preset"), scene=SCENE, out=str(run), resume=True, **dict(cfg, total_env_steps=400)))
    message = str(err.value)
    assert "--hidden 16 (now 32)" in message and "--num-envs 8 (now 4)" in message
    assert "--hidden 16 --num-envs 8" in message  # the fix: resume with the run's settings
    assert snapshot(run) == before


def test_resuming_the_same_run_with_a_raised_budget_still_continues_it(run):
    cfg = dict(TINY)
    resumed = train(
        config_for(cfg.pop("preset"), scene=SCENE, out=str(run), resume=True, **dict(cfg, total_env_steps=400))
    )
    assert resumed.env_steps == 400


def test_a_checkpoint_records_its_twin_and_one_without_the_record_still_loads(finished, tmp_path):
    policy = load_policy(finished / "model.pt")
    assert policy.meta["dataset"]["name"] == f"{SCENE}/blueprint" and policy.meta["kind"] == "model"
    assert trained_twin(policy) == {"scene": SCENE, "variant": "blueprint", "version": None}
    state = torch.load(finished / "last.pt", weights_only=False)
    assert state["kind"] == TRAINING_STATE and state["dataset"]["name"] == f"{SCENE}/blueprint"
    old = torch.load(finished / "model.pt", weights_only=False)  # as checkpoints were before the record
    del old["dataset"], old["kind"]
    torch.save(old, tmp_path / "old.pt")
    assert trained_twin(load_policy(tmp_path / "old.pt"))["scene"] == SCENE  # from its config


def test_adapt_refuses_an_agent_trained_on_another_scene_before_writing(finished, tmp_path):
    cfg = AdaptConfig(
        scene=OTHER, checkpoint=str(finished / "model.pt"), seconds=0.2, pairs=2, out=str(tmp_path / "adapt")
    )
    with pytest.raises(WrongTwinError, match=f"trained on {SCENE}/blueprint, not on a twin of {OTHER}"):
        adapt(cfg)
    assert not (tmp_path / "adapt").exists()


@pytest.mark.parametrize("legacy", [False, True])
def test_eval_of_a_runs_training_state_evaluates_its_weights_and_says_so(run, tmp_path, capsys, legacy):
    if legacy:  # a last.pt written before checkpoints said what they are
        state = torch.load(run / "last.pt", weights_only=False)
        del state["kind"], state["dataset"], state["stats"]
        torch.save(state, run / "last.pt")
    argv = ["eval", "--scene", SCENE, "--checkpoint", str(run / "last.pt"), "--pairs", "3", "--no-planner"]
    assert main([*argv, "--plot-paths", "0", "--variants", "blueprint", "--out", str(tmp_path / "eval")]) == 0
    out = capsys.readouterr()
    assert "edited by hand" not in out.err
    assert "training state (last.pt, 200 env steps)" in out.out and "model.pt" in out.out
    assert torch.equal(load_policy(run / "last.pt").q.net[0].weight, load_policy(run / "model.pt").q.net[0].weight)


def test_a_damaged_training_state_points_to_the_model_beside_it(run, capsys):
    state = torch.load(run / "last.pt", weights_only=False)
    del state["normalizer"]
    torch.save(state, run / "last.pt")
    assert main(["eval", "--scene", SCENE, "--checkpoint", str(run / "last.pt"), "--pairs", "3"]) == 2
    err = capsys.readouterr().err
    assert "training-state checkpoint (last.pt)" in err and str(run / "model.pt") in err
    assert "edited by hand" not in err


def test_a_policy_is_checked_against_the_exact_twin_it_is_used_on(finished):
    policy = load_policy(finished / "model.pt")
    check_same_twin(policy, load_dataset(f"{SCENE}/blueprint"))
    with pytest.raises(WrongTwinError, match=f"trained on {SCENE}/blueprint, not on {SCENE}/dynamic"):
        check_same_twin(policy, load_dataset(f"{SCENE}/dynamic"))
    with pytest.raises(WrongTwinError, match=f"not on {OTHER}/blueprint"):
        check_same_twin(policy, load_dataset(f"{OTHER}/blueprint"))
