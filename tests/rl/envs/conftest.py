import pytest
import torch


@pytest.fixture(scope="module")
def one_torch_thread():
    """Small tensors: one torch thread (two collapse when another process keeps a core busy)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
