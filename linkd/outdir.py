"""Write an output folder all at once: build it in a temporary folder, move it into place last.

A failure or Ctrl-C part-way leaves no half-written output behind.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

from linkd.errors import InputError

MARKER = "mechanism.json"  # a folder holding this is a linkd output and may be replaced


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_replaceable(final: Path, force: bool) -> None:
    """Refuse to replace a folder that is not empty and not a linkd output, unless forced."""
    if not final.exists() or force:
        return
    if not final.is_dir():
        raise InputError(f"{final}: exists and is not a folder")
    if any(final.iterdir()) and not (final / MARKER).exists():
        raise InputError(f"{final}: folder exists and is not a linkd output (use --force)")


@contextmanager
def staged_output(final: str | Path, force: bool = False) -> Iterator[Path]:
    """Yield a temporary folder beside `final`; it replaces `final` only if the block succeeds."""
    final = Path(final)
    check_replaceable(final, force)
    final.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{final.name}.", dir=final.parent))
    os.chmod(staging, 0o777 & ~_umask())  # mkdtemp makes it private; outputs are ordinary folders
    try:
        yield staging
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    old = None
    if final.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{final.name}.old.", dir=final.parent))
        os.replace(final, old / final.name)
    os.replace(staging, final)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


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
    if path.parent and not path.parent.is_dir():
        raise InputError(f"{path}: folder {path.parent} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes it private; outputs are ordinary files
    try:
        with os.fdopen(fd, "wb" if binary else "w") as handle:
            yield handle
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
