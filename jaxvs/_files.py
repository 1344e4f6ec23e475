"""Guards shared by every reader of a user's file (only the standard library: the command
uses them before JAX is imported).

A reader must never block or run without end on what the user named: a FIFO, a device
such as `/dev/zero`, a folder or a symlink loop is refused before the file is opened, with
a message naming what the path is and what to give instead.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any

__all__ = ["regular_file"]


def regular_file(path: Any, who: str) -> Path:
    """`path` as a `Path` when it names an existing regular file; every reader starts here.

    Refused before the file is opened (so nothing blocks): a path that is not a str or
    `os.PathLike` (`TypeError`), a missing file or a broken link (`FileNotFoundError`), a
    symlink loop, a folder, a FIFO, a socket or a device such as `/dev/zero`
    (`ValueError`), each naming the path and what to give instead."""
    if not isinstance(path, str | os.PathLike):
        raise TypeError(
            f"{who}: a file path must be a str or pathlib.Path, got {type(path).__name__}; "
            "pass the path of the file to read."
        )
    file = Path(path)
    try:
        mode = os.stat(file).st_mode
    except OSError as err:
        if os.path.islink(file):
            try:
                os.path.realpath(file, strict=True)
            except OSError as loop:
                if "loop" in str(loop).lower() or getattr(loop, "errno", None) == 40:
                    raise ValueError(
                        f"{who}: {str(file)!r} is a symbolic link loop (the link points back "
                        "to itself); give the path of the real file."
                    ) from None
            raise FileNotFoundError(
                f"{who}: {str(file)!r} is a broken symbolic link (it points to "
                f"{os.readlink(file)!r}, which does not exist); give the path of the real file."
            ) from None
        if isinstance(err, FileNotFoundError):
            raise FileNotFoundError(
                f"No such file: {str(file)!r}. Check the path (relative paths start in the "
                f"current directory {os.getcwd()!r})."
            ) from None
        if isinstance(err, PermissionError):
            raise PermissionError(
                f"{who}: {str(file)!r} cannot be read (permission denied); check its permissions."
            ) from None
        if getattr(err, "errno", None) == 40:
            raise ValueError(
                f"{who}: {str(file)!r} lies under a symbolic link loop; give the path of the "
                "real file."
            ) from None
        raise ValueError(f"{who}: {str(file)!r} cannot be read ({err}); check the path.") from None
    if stat.S_ISDIR(mode):
        raise ValueError(
            f"{str(file)!r} is a directory, not a file; give the path of a file inside it."
        )
    if not stat.S_ISREG(mode):
        kind = (
            "a named pipe (FIFO)"
            if stat.S_ISFIFO(mode)
            else "a device"
            if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
            else "a socket"
            if stat.S_ISSOCK(mode)
            else "not a regular file"
        )
        raise ValueError(
            f"{str(file)!r} is {kind}, not a regular file, and reading it could block or "
            "never end; save the data to a file first and give that file's path."
        )
    return file
