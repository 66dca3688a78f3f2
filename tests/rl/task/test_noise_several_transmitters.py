"""Measurement noise on a twin with several transmitters: each further transmitter's features of the robot's cell are
one more group of errors, perturbed as transmitter 0's are, and only where that transmitter has a path."""

import numpy as np
import torch

from dtradar_data.pipeline.synthetic import synthetic_multi_tx_dataset
from dtradar_rl.task.noise import RadioNoise, noise_model
from dtradar_rl.task.observations import RADIO_FEATURES, Normalizer, build_observations, radio_columns

NX, NY = 8, 6


def _noisy(ds, preset="neighbors", same_errors=False, seed=0):
    norm = Normalizer.fit(ds)
    table = build_observations(ds, preset, norm)
    noise = RadioNoise(noise_model("realistic"), table, norm, "cpu")
    rows = torch.arange(NX * NY)
    obs = torch.as_tensor(table.observe(rows.numpy(), rows.numpy()))
    errors = noise.draw(len(rows), torch.Generator().manual_seed(seed))
    if same_errors:  # transmitter 1's group (the last) gets transmitter 0's errors (the first group)
        errors[:, -1] = errors[:, 0]
    return table, noise, obs, noise.apply(obs, rows, errors)


def test_every_transmitter_is_perturbed_as_transmitter_zero_is():
    # two transmitters at one place: identical features, statistics and, with the same errors, identical noise
    tx = (1.1, 0.7, 3.0)
    ds = synthetic_multi_tx_dataset(NX, NY, txs=(tx, tx))
    table, noise, obs, noisy = _noisy(ds, same_errors=True)
    assert noise.groups == 6
    zero = [table.names.index(c) for c in RADIO_FEATURES]
    one = [table.names.index(c) for c in radio_columns(1)]
    assert not torch.equal(noisy[:, zero], obs[:, zero])
    torch.testing.assert_close(noisy[:, one], noisy[:, zero], rtol=0, atol=0)


def test_noise_leaves_a_transmitters_missing_features_flags_and_positions_alone():
    heard = np.ones((2, NY, NX), bool)
    heard[0, :, 5:] = False
    heard[1, :, :2] = False
    ds = synthetic_multi_tx_dataset(NX, NY, heard=heard)
    table, _, obs, noisy = _noisy(ds, preset="goal")
    names = table.names
    zero = [names.index(c) for c in RADIO_FEATURES]
    one = [names.index(c) for c in radio_columns(1)]
    for cols, k in ((zero, 0), (one, 1)):
        missing = ~table.heard_by[:, k]
        assert torch.all(noisy[missing][:, cols] == 0)
        assert torch.all((noisy[~missing][:, cols] != obs[~missing][:, cols]).any(1))
    kept = [names.index(c) for c in ("x_m", "y_m", "tx1_has_path", "target_x_m", "target_y_m")]
    assert torch.equal(noisy[:, kept], obs[:, kept])
