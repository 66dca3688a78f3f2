"""Observations of a twin with several transmitters: every transmitter's features of the robot's cell after the
preset's columns, has-radio flags that mean "a path from any transmitter", a normaliser that names the transmitters,
and a model refused on a twin with another count of them; one transmitter changes nothing."""

import numpy as np
import pytest

from dtradar_data.core.errors import InvalidSettingError
from dtradar_data.pipeline.synthetic import synthetic_dataset, synthetic_multi_tx_dataset
from dtradar_rl.envs.memory import flag_columns
from dtradar_rl.task.observations import (
    OBS_DIMS,
    PAPER_COLUMNS,
    RADIO_FEATURES,
    Normalizer,
    build_observations,
    obs_dim,
    observation_columns,
    own_radio_columns,
    radio_columns,
    tx_names,
)

NX, NY = 8, 6


def heard_mask() -> np.ndarray:
    """Transmitter 0 reaches x < 5, transmitter 1 x >= 2; the top row's last two cells hear neither."""
    heard = np.ones((2, NY, NX), bool)
    heard[0, :, 5:] = False
    heard[1, :, :2] = False
    heard[:, 5, 6:] = False
    return heard


def blocked_mask() -> np.ndarray:
    blocked = np.zeros((NY, NX), bool)
    blocked[2, 3] = True
    return blocked


@pytest.fixture(scope="module")
def twin():
    return synthetic_multi_tx_dataset(NX, NY, blocked_mask(), heard=heard_mask())


def cell(x, y):
    return y * NX + x


def test_a_street_heard_only_from_the_second_transmitter_reads_as_free(twin):
    table = build_observations(twin, "neighbors", Normalizer.fit(twin))
    names = table.names
    only_tx1 = cell(6, 1)
    assert table.has_radio[only_tx1]
    # its left neighbour sees it as free, and the robot standing on it hears transmitter 1 only
    left = table.cell_part[cell(5, 1)]
    assert left[names.index("X+:has_radio")] == 1.0
    here = table.cell_part[only_tx1]
    assert here[names.index("tx1_has_path")] == 1.0
    assert np.all(here[[names.index(c) for c in RADIO_FEATURES]] == 0)  # transmitter 0: missing, 0
    assert np.any(here[[names.index(c) for c in radio_columns(1)]] != 0)
    # the neighbour's copy of transmitter 0's features is missing too, its flag is what says "free"
    assert np.all(left[[names.index(f"X+:{c}") for c in RADIO_FEATURES]] == 0)


def test_a_free_cell_no_transmitter_hears_and_a_blocked_cell_read_as_no_radio(twin):
    table = build_observations(twin, "neighbors", Normalizer.fit(twin))
    names = table.names
    assert not table.has_radio[cell(6, 5)] and not table.has_radio[cell(3, 2)]
    assert table.cell_part[cell(5, 5)][names.index("X+:has_radio")] == 0.0
    assert table.cell_part[cell(3, 1)][names.index("Y+:has_radio")] == 0.0  # the blocked cell above it
    for c in (cell(6, 5), cell(3, 2)):
        assert np.all(table.cell_part[c][[names.index(n) for n in tx_names(1)]] == 0)
    np.testing.assert_array_equal(table.heard_by.reshape(NY, NX, 2).transpose(2, 0, 1), heard_mask() & ~blocked_mask())


@pytest.mark.parametrize("preset,radius", [("paper", 1), ("goal", 1), ("neighbors", 1), ("neighbors", 3)])
def test_the_further_transmitters_columns_follow_the_presets_and_precede_the_ring(twin, preset, radius):
    one = synthetic_dataset(NX, NY, blocked_mask())
    table = build_observations(twin, preset, Normalizer.fit(twin), radius)
    single = build_observations(one, preset, Normalizer.fit(one), radius)
    assert table.dim == len(table.names) == obs_dim(preset, 2, radius) == single.dim + 9
    assert obs_dim(preset, 1, radius) == single.dim and obs_dim(preset) == OBS_DIMS[preset]
    base = 10 if preset != "neighbors" else 46
    # every column of the one-transmitter layout keeps its offset; transmitter 1's 9 sit at base..base+8
    dc = table.cell_part.shape[1]
    assert table.names[:base] == single.names[:base]
    assert table.names[base : base + 9] == tx_names(1)
    assert table.names[base + 9 :] == single.names[base:]
    assert table.names[table.ring_columns] == single.names[single.ring_columns]
    assert table.ring_columns.stop == dc
    if preset == "neighbors":
        assert [table.names[i] for i in flag_columns()] == [f"{a}:has_radio" for a in ("X-", "X+", "Y-", "Y+")]
    assert table.radio_columns == own_radio_columns(preset, 2) == list(range(2, 10)) + list(range(base, base + 8))
    assert [table.names[i] for i in table.radio_columns] == list(RADIO_FEATURES + radio_columns(1))
    assert table.transmitters == 2 and single.transmitters == 1 and single.heard_by is None


def test_the_further_transmitters_features_are_z_scored_by_the_normaliser(twin):
    norm = Normalizer.fit(twin)
    table = build_observations(twin, "goal", norm)
    raw = twin.grid(list(radio_columns(1))).reshape(NX * NY, -1).astype(np.float64)
    k = [norm.columns.index(c) for c in radio_columns(1)]
    expected = (raw - np.asarray(norm.mean)[k]) / np.asarray(norm.std)[k]
    ok = table.heard_by[:, 1]
    got = table.cell_part[:, [table.names.index(c) for c in radio_columns(1)]]
    np.testing.assert_allclose(got[ok], expected[ok], rtol=1e-5, atol=1e-6)
    assert np.all(got[~ok] == 0)
    free_heard = raw[ok]  # the statistics are those of the free cells transmitter 1 reaches
    np.testing.assert_allclose(np.asarray(norm.mean)[k], free_heard.mean(0), rtol=1e-6)


def test_the_normaliser_fits_names_and_stores_every_transmitters_columns(twin):
    norm = Normalizer.fit(twin)
    assert norm.columns == observation_columns(twin) == PAPER_COLUMNS + radio_columns(1)
    assert norm.transmitters == 2 and observation_columns(1) == PAPER_COLUMNS
    back = Normalizer.from_dict(norm.to_dict())
    assert back == norm and back.transmitters == 2


def test_a_model_of_two_transmitters_is_refused_on_a_twin_with_one_and_the_other_way_round(twin):
    one = synthetic_dataset(NX, NY, blocked_mask())
    with pytest.raises(InvalidSettingError, match=r"observes 2 transmitter\(s\), .* has 1") as err:
        build_observations(one, "neighbors", Normalizer.fit(twin))
    assert "train a model on a twin with 1" in err.value.hint
    with pytest.raises(InvalidSettingError, match=r"observes 1 transmitter\(s\), .* has 2"):
        build_observations(twin, "goal", Normalizer.fit(one))


def test_one_transmitter_built_either_way_gives_the_same_tables():
    one = synthetic_dataset(NX, NY, blocked_mask())
    multi = synthetic_multi_tx_dataset(NX, NY, blocked_mask(), txs=((0.3, 0.2, 3.0),))
    assert multi.transmitters == one.transmitters == 1
    for preset in ("paper", "goal", "neighbors"):
        a = build_observations(one, preset, Normalizer.fit(one), 2 if preset == "neighbors" else 1)
        b = build_observations(multi, preset, Normalizer.fit(multi), 2 if preset == "neighbors" else 1)
        assert a.names == b.names and a.heard_by is None and b.heard_by is None
        assert a.cell_part.tobytes() == b.cell_part.tobytes() and a.target_part.tobytes() == b.target_part.tobytes()
        np.testing.assert_array_equal(a.has_radio, b.has_radio)
