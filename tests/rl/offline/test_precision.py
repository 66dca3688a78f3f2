"""--precision: bf16 updates run under autocast, learn (the weight-cast cache off), and unknown values are refused."""

import numpy as np
import pytest
import torch

from dtradar_data.core.errors import UnknownNameError
from dtradar_rl.experiments.offline_bench_config import OfflineBenchConfig
from dtradar_rl.experiments.offline_plan import bench_jobs
from dtradar_rl.offline import precision
from dtradar_rl.offline.config import BF16_ALGORITHMS, OfflineConfig
from dtradar_rl.offline.formats import import_d3rlpy, to_mdp_dataset
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.precision import update_autocast
from dtradar_rl.offline.trainer import fit, make_algorithm
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.twins import load_dataset

TINY = "synthetic-8x6"


def test_bf16_updates_compute_in_bfloat16_and_fp32_ones_in_float32():
    net, x = torch.nn.Linear(4, 3), torch.randn(2, 4)
    with update_autocast("bf16"):
        assert net(x).dtype == torch.bfloat16
    with update_autocast("fp32"):
        assert net(x).dtype == torch.float32


def test_a_bf16_update_sees_the_weights_the_previous_update_left():
    # with autocast's weight-cast cache on, every forward inside one context reuses the first bf16 copy of the weights
    net, x = torch.nn.Linear(4, 3), torch.randn(2, 4)
    with update_autocast("bf16"):
        before = net(x)
        with torch.no_grad():
            net.weight.add_(1.0)
        after = net(x)
    assert not torch.equal(before, after)


def test_bf16_training_learns_on_a_logged_dataset(root):
    d3rlpy = import_d3rlpy()
    torch.set_num_threads(1)
    log = LogConfig(scene=TINY, behaviour="random", steps=800, num_envs=16, max_steps=20, minari=False, verbose=False)
    data = to_mdp_dataset(log_dataset(log, load_dataset(f"{TINY}/blueprint")))
    d3rlpy.seed(3)
    np.random.seed(3)
    algo = make_algorithm(OfflineConfig(algorithm="dqn", batch_size=64, hidden=(16,)))
    losses = fit(algo, data, 200, epochs=10, precision="bf16")
    assert losses[-1]["loss"] < 0.9 * losses[0]["loss"]


def test_an_unknown_precision_is_refused_with_a_suggestion_by_offline_and_offline_bench():
    with pytest.raises(UnknownNameError, match="bf16"):
        OfflineConfig(precision="bf61").validate()
    with pytest.raises(UnknownNameError, match="fp32"):
        OfflineBenchConfig(precision="fp23").validate()


def test_bf16_is_refused_for_bc_and_cql_and_the_benchmark_trains_them_in_fp32():
    for algo in ("bc", "cql"):
        with pytest.raises(ConfigError, match="bf16"):
            OfflineConfig(algorithm=algo, precision="bf16").validate()
    cfg = OfflineBenchConfig(scene=TINY, precision="bf16", batch_size=512).validate()
    jobs = bench_jobs(cfg, {beh: f"{TINY}/blueprint/{beh}@v0" for beh in cfg.behaviours})
    got = {(j.config.algorithm, j.config.precision, j.config.batch_size) for j in jobs}
    assert got == {(a, "bf16" if a in BF16_ALGORITHMS else "fp32", 512) for a in cfg.algorithms}


@pytest.mark.parametrize("units", [True, False])
def test_auto_trains_the_q_learners_in_bf16_at_batch_512_only_on_a_cpu_with_bf16_matrix_units(monkeypatch, units):
    monkeypatch.setattr(precision, "bf16_matrix_units", lambda: units)
    for algo in ("bcq", "dqn", "ddqn", "nfq", "bc", "cql"):
        cfg = OfflineConfig(algorithm=algo, precision="auto", batch_size=0).validate()
        bf16 = units and algo in BF16_ALGORITHMS
        assert (cfg.update_precision, cfg.update_batch_size) == (("bf16", 512) if bf16 else ("fp32", 256)), algo
    assert OfflineConfig(algorithm="dqn", precision="auto", device="cuda").update_precision == "fp32"
    assert OfflineConfig(algorithm="dqn", precision="fp32", batch_size=0).update_batch_size == 256


def test_a_config_saved_before_precision_existed_reads_as_fp32():
    saved = OfflineConfig(algorithm="dqn").to_dict()
    del saved["precision"]
    assert OfflineConfig.from_dict(saved).precision == "fp32"
