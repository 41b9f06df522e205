"""Run a stage's work in two parts at once, the second in a forked process.

Sampling and batched L-BFGS over tens of small mechanisms are bound by Python's per-operation
overhead more than by arithmetic: a second thread only waits on the first, but a second process
(its own interpreter) runs its part alongside. The work is always cut the same way, whether or
not a second process is available (no fork on the platform, one CPU, or already inside a daemon
process): the parts then run one after the other, so a seed gives the same designs everywhere.

A forked child inherits the call (the loaded model too), so nothing but its result is pickled
(keep results small: about 0.2 s per 50 MB); a child that fails or dies leaves its part to be
run here.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
from collections.abc import Callable, Sequence
from typing import TypeVar

import numpy as np
import torch

PARTS = 2
T = TypeVar("T")


def split(rows: np.ndarray) -> list[np.ndarray]:
    """`rows` in PARTS interleaved parts (each gets items of every rank); empty parts are left
    out."""
    return [part for part in (rows[k::PARTS] for k in range(PARTS)) if len(part)]


def run_parts(calls: Sequence[Callable[[], T]]) -> list[T]:
    """Each call's result, in order: the first here (it may show progress), the others in
    forked processes when that is possible; their results must pickle."""
    if len(calls) <= 1 or not can_fork():
        return [call() for call in calls]
    context = multiprocessing.get_context("fork")
    sys.stdout.flush()  # a child would otherwise print what is still buffered a second time
    sys.stderr.flush()
    workers = []
    for call in calls[1:]:
        receive, send = context.Pipe(duplex=False)
        child = context.Process(target=_send_result, args=(call, send), daemon=True)
        child.start()
        send.close()
        workers.append((child, receive))
    try:
        results = [calls[0]()]
        for call, (_, receive) in zip(calls[1:], workers):
            try:
                done, value = receive.recv()
            except EOFError:  # the child died (out of memory, killed)
                done, value = False, None
            results.append(value if done else call())
    finally:  # the children are done, or not wanted any more (an error or Ctrl-C here)
        for child, receive in workers:
            receive.close()
            child.terminate()
            child.join()
    return results


def can_fork() -> bool:
    """Whether a second process can run a part: Linux (fork), more than one usable CPU, and not
    inside a daemon process (which may not have children)."""
    if sys.platform != "linux" or multiprocessing.current_process().daemon:
        return False
    return len(os.sched_getaffinity(0)) > 1


def _send_result(call: Callable[[], object], send) -> None:
    """In the child: send (True, result), or (False, None) when the call fails (the parent then
    runs it itself, raising any error there). The child runs torch on one thread: the
    parent's OpenMP workers were not forked with it, and a parallel region would wait for
    them for ever."""
    torch.set_num_threads(1)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # the parent ends it so: at once, silently
    try:
        result = (True, call())
    except BaseException:  # the parent runs the part again, and reports any error
        result = (False, None)
    try:
        send.send(result)
    finally:
        send.close()
