"""Atomic output: write to a temporary file beside the target, then rename.

A crash never leaves a half-written output, and an input is never overwritten
by accident: pass ``protect=`` the input paths and a clash is refused.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

from ..errors import InputError


def _check(path: Path, protect: Iterable[str | os.PathLike] | None) -> None:
    if path.is_dir():
        raise InputError("is a folder; give the output a file name", file=str(path))
    for p in protect or ():
        p = Path(p)
        if p.exists() and path.exists() and os.path.samefile(p, path):
            raise InputError(
                "refusing to overwrite an input file; choose another output path", file=str(path)
            )


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_bytes_atomic(path, data: bytes, *, protect=None) -> Path:
    """Write ``data`` to ``path`` atomically (parents created). Returns the path."""

    def write(tmp):
        with open(tmp, "wb") as fh:
            fh.write(data)

    return write_file_atomic(path, write, protect=protect)


def write_text_atomic(path, text: str, *, protect=None, newline: str = "\n") -> Path:
    """Write ``text`` (UTF-8) atomically; ``newline`` replaces ``"\\n"``."""
    if newline != "\n":
        text = text.replace("\n", newline)
    return write_bytes_atomic(path, text.encode("utf-8"), protect=protect)


def write_file_atomic(path, writer, *, protect=None) -> Path:
    """Atomic output of a writer that wants a file name (netCDF, a library's
    `to_file`): ``writer(tmp)`` writes a temporary beside ``path``, which is then
    renamed; on any exception (Ctrl-C and SIGTERM in the CLI included) it is removed
    and ``path`` is left as it was. Returns the path."""
    path = Path(path)
    _check(path, protect)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        writer(tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path
