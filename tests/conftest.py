"""Shared fixtures, and the hypothesis profiles: derandomised in CI, random locally."""

import os
from contextlib import contextmanager

import numpy as np
import pytest
import torch
from hypothesis import settings

from linkd.export import ExportOptions, buildable, framed, strapped
from linkd.generator import GeneratorSettings, generate
from linkd.graph import from_graph

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


@contextmanager
def no_straps_nor_frames():
    """No eccentric straps (`linkd.export.strapped`) nor frames (`linkd.export.framed`) within."""

    def no_modules(*args, **kwargs):
        raise ValueError("not modules on one crank: frames are off")

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(strapped, "MAX_STRAPS", 0)
        patch.setattr(framed, "_modules", no_modules)
        yield


@pytest.fixture(scope="module")
def straps_and_frames_off():
    """No straps nor frames: the mechanisms that test the constructions tried after them are
    built with straps or frames when those are on."""
    with no_straps_nor_frames():
        yield


@pytest.fixture(scope="module")
def pool():
    """Small generated designs; the first one can be built in flat layers, straight or bent (not
    every valid mechanism can: its export is refused, uses straps or splits plates and uses
    brackets). The first generated design needs a bracket and holds a smaller linkage tracing
    its very path, which the design tests would deliver instead of the sample itself."""
    graphs = generate(12, seed=3, settings=GeneratorSettings(min_nodes=5, max_nodes=7)).graphs
    flat = ExportOptions(brackets=False)
    with no_straps_nor_frames():
        first = next((k for k, g in enumerate(graphs) if buildable(from_graph(g), flat)), None)
    assert first is not None, "no exportable design in the pool"
    return np.concatenate([graphs[first:], graphs[:first]])
