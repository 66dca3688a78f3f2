"""``DQNConfig()`` is the default preset; every other preset lists its own differences, ``tuned`` (the defaults of
before) included; a config saved before a field existed keeps the value it had then; ``train --preset NAME`` gives
that preset's defaults to the flags around it."""

import json

import pytest
import torch

from dtradar_rl import cli
from dtradar_rl.train.config import DEFAULT_PRESET, PRESETS, SAVED_DEFAULTS, DQNConfig, config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.train.saved_runs import load_policy

SCENES = ("cubicle", "dallas-q3", "synthetic")
#: What DQNConfig() held while its defaults were the tuned preset's (the fields the default preset changes).
FORMER_DEFAULTS = {
    "preset": "tuned",
    "aug_obstacles": 0,
    "memory_radius": 0,
    "memory_visits": False,
    "escape_after": 0,
    "noise": "none",
    "expert_weight": 0.0,
    "total_env_steps": 600_000,
}
#: Fields added after the first checkpoints were written; a config.json of then has none of them.
#: (the budget is no such field: every config saved one)
LATER_FIELDS = (
    *(k for k in FORMER_DEFAULTS if k != "total_env_steps"),
    "aug_obstacle_size",
    "aug_potential",
    "memory_bumps",
    "sense_radius",
)


@pytest.mark.parametrize("scene", SCENES)
def test_the_field_defaults_are_the_default_preset(scene):
    assert DQNConfig(scene=scene) == config_for(scene=scene) == config_for(DEFAULT_PRESET, scene=scene)
    assert PRESETS[DEFAULT_PRESET] == {}


def test_the_tuned_preset_is_what_the_defaults_were():
    tuned = config_for("tuned").to_dict()
    assert {k: tuned[k] for k in FORMER_DEFAULTS} == FORMER_DEFAULTS
    assert SAVED_DEFAULTS == FORMER_DEFAULTS
    default = config_for().to_dict()
    assert {k for k in tuned if tuned[k] != default[k]} == set(FORMER_DEFAULTS)


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("scene", SCENES)
def test_every_preset_validates_and_round_trips(preset, scene):
    cfg = config_for(preset, scene=scene)
    assert cfg.preset == preset
    assert DQNConfig.from_dict(json.loads(json.dumps(cfg.to_dict()))) == cfg


def test_a_config_saved_before_a_field_existed_keeps_its_former_default():
    saved = {k: v for k, v in config_for("tuned").to_dict().items() if k not in LATER_FIELDS}
    assert DQNConfig.from_dict(saved) == config_for("tuned")
    # the keys a config does save win over the former defaults
    assert DQNConfig.from_dict({**saved, "noise": "realistic", "preset": "robust"}).noise == "realistic"


def test_an_old_checkpoint_loads_with_the_meaning_it_was_written_with(tmp_path):
    cfg = config_for(
        "tuned",
        scene="synthetic-8x6",
        num_envs=16,
        total_env_steps=400,
        hidden=(16,),
        batch_size=32,
        learning_starts=100,
        env_steps_per_update=4,
        threads=1,
        verbose=False,
        checkpoint_every=0,
        out=str(tmp_path / "run"),
    )
    model = train(cfg).checkpoint
    assert load_policy(model).config == cfg
    state = torch.load(model, weights_only=False)
    old = {k: v for k, v in json.loads(state["config"]).items() if k not in LATER_FIELDS}
    state["config"] = json.dumps(old)
    torch.save(state, tmp_path / "old.pt")
    policy = load_policy(tmp_path / "old.pt")
    assert policy.config == cfg and not policy.config.memory_radius and policy.config.noise == "none"


@pytest.fixture
def parsed(monkeypatch):
    """The config ``python -m dtradar_rl train ARGS`` would train, without training it."""
    seen = []
    monkeypatch.setattr(cli, "run_train", seen.append)

    def parse(*args: str) -> DQNConfig:
        assert cli.main(["train", *args]) == 0
        return seen.pop()

    return parse


def test_train_without_a_preset_trains_the_default(parsed):
    assert parsed("--scene", "synthetic") == DQNConfig(scene="synthetic") == config_for(scene="synthetic")


@pytest.mark.parametrize("preset", PRESETS)
def test_the_preset_option_gives_the_flags_around_it_its_defaults(parsed, preset):
    assert parsed("--scene", "synthetic", "--preset", preset, "--seed", "3") == config_for(
        preset, scene="synthetic", seed=3
    )
    assert parsed(f"--preset={preset}", "--scene=synthetic") == config_for(preset, scene="synthetic")


def test_the_paper_preset_on_a_city_quadrant_gets_its_outdoor_episodes(parsed):
    cfg = parsed("--scene", "dallas-q3", "--preset", "paper", "--gamma", "0.8")
    assert cfg == config_for("paper", scene="dallas-q3", gamma=0.8) and cfg.episodes == 80


def test_an_unknown_preset_is_the_boundarys_typed_error(capsys):
    assert cli.main(["train", "--scene", "synthetic", "--preset", "tunde"]) == 2
    assert "tuned" in capsys.readouterr().err
