"""Write an output folder all at once: build it in a temporary folder, move it into place last.

A failure or Ctrl-C part-way leaves no half-written output behind.
"""

from __future__ import annotations

import os
import shutil
import signal
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

from linkd.errors import InputError
from linkd.termination import check

MARKER = "mechanism.json"  # a folder holding this is a linkd output and may be replaced
OUTPUTS = frozenset({MARKER, "mechanism.xml", "scene.xml", "meshes", "animation.html",
                     "report.json", "curve.png", "alternatives", "passed_over"})  # fmt: skip


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_replaceable(final: Path, force: bool, inputs: tuple[Path, ...] = ()) -> None:
    """Refuse to replace the current folder (or one holding it), a folder holding one of the
    `inputs`, and, unless forced, a folder that is not empty and not a linkd output: one with
    files linkd does not write, which replacing it would delete."""
    above = next((p for p in final.parents if p.exists()), Path("."))
    if not above.is_dir():
        raise InputError(f"{final}: {above} is not a folder")
    if not final.exists():
        return
    where = final.resolve()
    if Path.cwd().resolve().is_relative_to(where):
        raise InputError(f"{final}: is the current folder or holds it; choose another --out")
    held = [p for p in inputs if p.resolve().is_relative_to(where)]
    if held:
        raise InputError(f"{final}: holds the input {held[0]}; choose another --out")
    if force:
        return
    if not final.is_dir():
        raise InputError(f"{final}: exists and is not a folder")
    others = sorted(p.name for p in final.iterdir() if p.name not in OUTPUTS)
    if any(final.iterdir()) and (others or not (final / MARKER).exists()):
        listed = f" ({', '.join(others[:3])}{', ...' if len(others) > 3 else ''})" if others else ""
        raise InputError(f"{final}: folder exists and is not a linkd output{listed}; "
                         "replacing it would delete what it holds (use --force)")  # fmt: skip


@contextmanager
def staged_output(
    final: str | Path, force: bool = False, inputs: tuple[Path, ...] = ()
) -> Iterator[Path]:
    """Yield a temporary folder beside `final`; it replaces `final` only if the block succeeds
    (`check_replaceable` first: `inputs` are the files the run reads)."""
    final = Path(final)
    check_replaceable(final, force, inputs)
    made = [p for p in final.parents if not p.exists()]  # the folders to make, deepest first
    _hold(signal.SIG_BLOCK)  # Ctrl-C or SIGTERM now would leave the staging folder behind
    try:
        final.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{final.name}.", dir=final.parent))
    except OSError as exc:
        _hold(signal.SIG_UNBLOCK)
        _remove(made)
        raise InputError(f"{final}: cannot make the folder ({exc.strerror})") from None
    try:
        _hold(signal.SIG_UNBLOCK)  # one that came meanwhile is raised here, and cleaned up
        os.chmod(staging, 0o777 & ~_umask())  # mkdtemp makes it private: make it ordinary
        yield staging
        check()  # a termination the run swallowed on its way: nothing is put in place
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        _remove(made)
        raise
    old = None
    if final.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{final.name}.old.", dir=final.parent))
        os.replace(final, old / final.name)
    os.replace(staging, final)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _hold(how: int) -> None:
    """Block or unblock the signals that end a run (where the platform can)."""
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(how, {signal.SIGINT, signal.SIGTERM})


def _remove(made: list[Path]) -> None:
    """Remove the folders a failed run made for its output, deepest first, where still empty."""
    for folder in made:
        try:
            folder.rmdir()
        except OSError:
            return


def fresh_name(base: Path) -> Path:
    """`base`, or `base-2`, `base-3`, ... : the first name not yet taken."""
    candidate, k = base, 1
    while candidate.exists():
        k += 1
        candidate = base.with_name(f"{base.name}-{k}")
    return candidate


def write_atomic(path: str | Path, text: str) -> None:
    """Write a text file through a temporary file in the same folder, then rename it."""
    with atomic_file(path) as handle:
        handle.write(text)


@contextmanager
def atomic_file(path: str | Path, binary: bool = False) -> Iterator[IO]:
    """A temporary file beside `path`, open for writing; it becomes `path` (with the mode of
    any new file) only when the block succeeds."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a folder")
    if not path.parent.is_dir():
        missing = "is not a folder" if path.parent.exists() else "does not exist"
        raise InputError(f"{path}: folder {path.parent} {missing}")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    except OSError as exc:
        raise InputError(f"{path}: cannot write there ({exc.strerror})") from None
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes it private; outputs are ordinary files
    try:
        with os.fdopen(fd, "wb" if binary else "w") as handle:
            yield handle
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
