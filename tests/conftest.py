"""Shared fixtures."""

import pytest
import torch


@pytest.fixture
def one_thread():
    """Small tensors: one thread avoids OpenMP spin-waiting on a busy machine."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
