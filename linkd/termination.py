"""SIGTERM (a CI job's timeout, `kill`) ends a run as Ctrl-C does.

The handler raises `Terminated` wherever the program is, so that it cleans up on its way out:
no half-written output folder, no playback server left running. Where it lands in code that
swallows exceptions (a finaliser run by the garbage collector, a library's callback), the
request stays noted: `check` raises it again at the next stage and before an output folder
is put in place, so a terminated run never completes.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

_requested = False


class Terminated(KeyboardInterrupt):
    """The run was asked to end (SIGTERM)."""


def check() -> None:
    """Raise `Terminated` if a SIGTERM came, whether or not its first raising got through."""
    if _requested:
        raise Terminated


@contextmanager
def sigterm_raises() -> Iterator[None]:
    """SIGTERM raises `Terminated` in the block (in the main thread, where Python runs signal
    handlers); a swallowed one is not reported as an ignored exception, `check` raises it."""
    global _requested
    _requested = False
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before_signal = signal.signal(signal.SIGTERM, on_sigterm)
    before_hook = sys.unraisablehook

    def quiet(unraisable) -> None:
        if not issubclass(unraisable.exc_type, Terminated):
            before_hook(unraisable)

    sys.unraisablehook = quiet
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, before_signal)
        sys.unraisablehook = before_hook


def on_sigterm(signum: int, frame: object) -> None:
    """The SIGTERM handler: note the request, and raise it here."""
    global _requested
    _requested = True
    raise Terminated
