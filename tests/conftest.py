"""Shared fixtures, and the hypothesis profiles: derandomised in CI, random locally."""

import os

import pytest
import torch
from hypothesis import settings

# CI (the CI variable set, as CI services and .ci/run do) tests the same examples on every run
# and keeps no example database; a local run draws new examples each time and replays failures.
settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
settings.register_profile("local", print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "local")


@pytest.fixture
def one_thread():
    """Small tensors: one thread avoids OpenMP spin-waiting on a busy machine."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
