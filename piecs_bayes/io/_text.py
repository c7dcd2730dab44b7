"""Reading the user's text files: encodings, a byte-order mark, unreadable files.

UTF-8 is the default everywhere; a UTF-8 byte-order mark (Excel's "CSV UTF-8")
is accepted. A byte that is not valid in the expected encoding is an
`InputError` naming the file, the line, the column and the byte, and saying how
to read a Windows export (`[study] encoding = "cp1252"`). A file that cannot be
read (missing, a folder, no permission) is an `InputError` with the reason.
"""

from __future__ import annotations

import codecs
from pathlib import Path

from ..errors import InputError

#: encodings a study may name; anything Python knows is accepted, these are the usual
ENCODINGS = ("utf-8", "cp1252", "latin-1")


def check_encoding(name, *, file: str | None = None, key: str = "study.encoding") -> str:
    """The canonical name of a text encoding, or an `InputError` naming `key`."""
    if not isinstance(name, str):
        raise InputError(f"{key}: expected an encoding name such as 'cp1252', got {name!r}",
                         file=file, value=name)  # fmt: skip
    try:
        return codecs.lookup(name).name
    except LookupError:
        raise InputError(
            f"{key}: unknown encoding {name!r}; expected e.g. {', '.join(ENCODINGS)}",
            file=file, value=name,
        ) from None  # fmt: skip


def read_bytes(path, *, what: str = "file") -> bytes:
    path = Path(path)
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{what} not found", file=str(path)) from None
    except IsADirectoryError:
        raise InputError(f"{what} is a folder, not a file", file=str(path)) from None
    except PermissionError:
        raise InputError(f"{what} cannot be read: permission denied", file=str(path)) from None
    except OSError as exc:
        raise InputError(f"{what} cannot be read: {exc.strerror or exc}", file=str(path)) from None


def decode(data: bytes, *, file: str, encoding: str = "utf-8") -> str:
    """`data` as text; a UTF-8 BOM is dropped; an invalid byte is an `InputError`."""
    enc = codecs.lookup(encoding).name
    if enc == "utf-8" and data.startswith(codecs.BOM_UTF8):
        data = data[len(codecs.BOM_UTF8) :]
    try:
        return data.decode(enc)
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        col = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        byte = data[exc.start]
        hint = (
            "; save the file as UTF-8, or name its encoding with [study] encoding = "
            '"cp1252" (Windows/Excel) or "latin-1"'
            if enc == "utf-8"
            else ""
        )
        raise InputError(
            f"not valid {enc} text: byte 0x{byte:02x} at line {line}, column {col}{hint}",
            file=file, line=line, value=f"0x{byte:02x}",
        ) from None  # fmt: skip


def read_text(path, *, encoding: str = "utf-8", what: str = "file") -> str:
    """Read a text file (see the module doc)."""
    return decode(read_bytes(path, what=what), file=str(path), encoding=encoding)
