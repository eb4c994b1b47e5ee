"""Output files that appear whole or not at all.

An export or a re-decoded log is written to a hidden temporary file in the target's
folder and renamed over the target only once it is complete (a rename within one folder
is atomic).  Whatever goes wrong on the way - the input turns out to be damaged, the
disk fills, Ctrl-C - the temporary file is deleted and an earlier file of that name is
left as it was.
"""

from __future__ import annotations

import os
import secrets
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator


def create_new(path: str | Path) -> bool:
    """Create `path` as an empty file if no file has that name, atomically (O_EXCL: two
    processes racing for one name never both get it); False if the name is taken.
    Other OSErrors (no such folder, no permission, disk full) are raised.  0o666: the
    umask decides the permissions, as for any file written directly."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except FileExistsError:
        return False
    os.close(fd)
    return True


PART_SUFFIX = ".part"


def leftovers(path: str | Path) -> list[Path]:
    """The temporary files of `path` a killed writer left behind (a process that dies
    mid-way cannot delete its own)."""
    path = Path(path)
    return sorted(path.parent.glob(f".{path.name}.*{PART_SUFFIX}"))


def _describe(exc: OSError) -> str:
    return exc.strerror or str(exc)


@contextmanager
def atomic_output(path: str | Path, error_cls: type[Exception]) -> Iterator[Path]:
    """Yield a temporary path beside `path`; on success rename it to `path`, on any
    exception delete it.  An OSError creating, completing or renaming the temporary
    file raises `error_cls("cannot write PATH: reason")`; other exceptions (a read error
    of the input, for one) pass through unchanged."""
    path = Path(path)
    while True:
        tmp = path.parent / f".{path.name}.{secrets.token_hex(4)}{PART_SUFFIX}"
        try:
            if create_new(tmp):
                break
        except OSError as exc:
            raise error_cls(f"cannot write {path}: {_describe(exc)}") from None
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            tmp.unlink()
        except FileNotFoundError:
            pass
        if isinstance(exc, OSError):
            raise error_cls(f"cannot write {path}: {_describe(exc)}") from None
        raise


__all__ = ["atomic_output", "create_new", "leftovers"]
