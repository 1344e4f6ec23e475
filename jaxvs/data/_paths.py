"""The one check every loader starts with: the path names an existing regular file."""

import os
from pathlib import Path

PathLike = str | os.PathLike[str]


def existing_file(path: PathLike) -> Path:
    """`path` as a `Path` when it names an existing file; every loader starts here."""
    if not isinstance(path, str | os.PathLike):
        raise TypeError(
            f"A file path must be a str or pathlib.Path, got {type(path).__name__}; pass the "
            "path of the file to read."
        )
    file = Path(path)
    if not file.exists():
        raise FileNotFoundError(
            f"No such file: {str(file)!r}. Check the path (relative paths start in the "
            f"current directory {os.getcwd()!r})."
        )
    if file.is_dir():
        raise ValueError(
            f"{str(file)!r} is a directory, not a file; give the path of a file inside it."
        )
    if not file.is_file():
        raise ValueError(f"{str(file)!r} is not a regular file; give the path of a file.")
    return file
