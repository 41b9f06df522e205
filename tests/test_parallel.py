"""Stages run in two parts at once: same results as one after the other, a failed child's part
done here, and a design run that does not depend on whether a second process was there."""

import multiprocessing
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from linkd.design import parallel
from linkd.design.parallel import run_parts, split
from linkd.design.propose import propose, random_proposer

needs_fork = pytest.mark.skipif(not parallel.can_fork(), reason="no second process to fork")


def test_split_interleaves_every_row_once_and_leaves_out_empty_parts():
    parts = split(np.arange(7))
    assert [p.tolist() for p in parts] == [[0, 2, 4, 6], [1, 3, 5]]
    assert [p.tolist() for p in split(np.arange(1))] == [[0]]
    assert split(np.arange(0)) == []


@needs_fork
def test_the_second_part_runs_in_another_process_and_results_keep_their_order():
    results = run_parts([os.getpid, os.getpid])
    assert results[0] == os.getpid() and results[1] != os.getpid()
    assert run_parts([lambda: "a", lambda: np.arange(3)])[1].tolist() == [0, 1, 2]


@needs_fork
def test_a_child_dies_silently_when_the_parent_ends_it():
    """The command line turns SIGTERM into a clean-up in the parent (`linkd.termination`);
    the child, which the parent ends with SIGTERM once its result is in, must not inherit
    that."""
    import signal

    from linkd.termination import sigterm_raises

    with sigterm_raises():
        handler = run_parts([os.getpid, lambda: signal.getsignal(signal.SIGTERM)])[1]
    assert handler == signal.SIG_DFL


@needs_fork
def test_a_part_that_fails_or_dies_in_the_child_is_run_here():
    here = os.getpid()

    def fails_elsewhere():
        if os.getpid() != here:
            raise RuntimeError("only here")
        return "done here"

    def dies_elsewhere():
        if os.getpid() != here:
            os._exit(3)
        return "done here too"

    assert run_parts([lambda: 1, fails_elsewhere]) == [1, "done here"]
    assert run_parts([lambda: 1, dies_elsewhere]) == [1, "done here too"]


def test_an_error_of_the_work_itself_is_raised_here():
    def broken():
        raise ValueError("bad part")

    with pytest.raises(ValueError, match="bad part"):
        run_parts([lambda: 1, broken])


def test_proposals_do_not_depend_on_a_second_process(monkeypatch):
    angle = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    target = np.stack([np.cos(angle), 0.5 * np.sin(angle)], 1)
    both = propose(random_proposer(), target, 32, 4, seed=3)
    monkeypatch.setattr(parallel, "can_fork", lambda: False)
    alone = propose(random_proposer(), target, 32, 4, seed=3)
    assert both.shape == (32, 20, 24) and np.array_equal(both, alone)
    assert not np.array_equal(both, propose(random_proposer(), target, 32, 4, seed=4))


@needs_fork
def test_a_child_computes_after_the_parent_ran_torch_on_several_threads():
    """OpenMP's workers are not forked: a child that opened a parallel region would wait for
    them for ever. Run in a fresh interpreter, so a hang fails the test instead of blocking."""
    script = (
        "import torch\n"
        "torch.set_num_threads(2)\n"
        "torch.randn(10**7).sin().sum()\n"  # the parent's OpenMP pool starts
        "from linkd.design.parallel import run_parts\n"
        "work = lambda: int(torch.randn(10**7).sin().abs().sum() > 0)\n"
        "print(run_parts([work, work]))\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[1, 1]"


@needs_fork
def test_an_error_here_stops_the_other_parts():
    def slow():
        time.sleep(60)
        return "late"

    def broken():
        raise KeyboardInterrupt

    start = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        run_parts([broken, slow])
    assert time.perf_counter() - start < 10
    assert multiprocessing.active_children() == []
