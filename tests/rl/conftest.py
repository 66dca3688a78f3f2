"""Fixtures shared by the agent tests."""

import numpy as np
import pytest

from dtradar_data.pipeline.synthetic import synthetic_multi_tx_dataset
from dtradar_rl.task.twins import synthetic_blocked


def two_transmitter_twin(nx: int = 12, ny: int = 8, variant: str = "blueprint", silent: bool = True, k: int = 2):
    """A ``nx`` x ``ny`` synthetic twin with two transmitters, in opposite corners: transmitter 0 does not reach the
    right third, transmitter 1 not the left third, and (``silent``) two cells of the top row hear neither (a silent
    street, which must still read as no radio). ``k=1``: transmitter 0 alone, the right third silent."""
    blocked = synthetic_blocked(nx, ny, variant)
    heard = np.ones((2, ny, nx), bool)
    heard[0, :, 2 * nx // 3 :] = False
    heard[1, :, : nx // 3] = False
    if silent:
        heard[:, ny - 1, nx // 2 : nx // 2 + 2] = False
    txs = ((0.3, 0.2, 3.0), (0.5 * nx - 0.3, 0.5 * ny - 0.2, 3.0))[:k]
    name = f"synthetic-tx{k}-{nx}x{ny}/{variant}"
    return synthetic_multi_tx_dataset(nx, ny, blocked, txs=txs, heard=heard[:k], name=name)


@pytest.fixture(scope="session")
def two_tx():
    """The 12 x 8 two-transmitter blueprint (:func:`two_transmitter_twin`)."""
    return two_transmitter_twin()


@pytest.fixture(scope="session")
def tx_twin():
    """:func:`two_transmitter_twin` itself, for tests that need another variant of it (test files import no
    modules of their own)."""
    return two_transmitter_twin
