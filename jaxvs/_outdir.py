"""Report folders of the `jaxvs` command (`--out`), checked first and written atomically.

`--out DIR` is checked before any work: it must not be a file, nor lie under a file, nor
hold input files, nor be the current folder, one of its parents or the home folder, nor be
a symbolic link, and its nearest existing parent folder must be writable.

**Only what jaxvs wrote is ever replaced.** Every report folder holds a marker file
`.jaxvs-report` (JSON: the writer, its version and the list of files it wrote). An
existing `DIR` is accepted when it is empty or holds that marker and no file besides the
ones it lists; a folder without the marker (even one holding a `report.json`) or with
files the user added is refused, naming them.

**One run per folder.** A run holds a lock on `DIR` (`.DIR.lock` beside it, an advisory
`flock`) from its checks to its end; a second run on the same `DIR` is refused at once.

The report is written into a hidden staging folder beside `DIR` (`.DIR.partial-<pid>`)
and renamed into place once complete; an earlier report in `DIR` is replaced only then.
So after any run, interrupted or not, `DIR` holds a complete report or none. Staging
folders left by a run that was killed (its process no longer exists) are removed by the
next run on the same `DIR`.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import re
import shutil
import tempfile
from collections.abc import Iterable
from pathlib import Path

from . import _interrupt
from ._version import __version__

__all__ = ["MARKER", "ReportFolder", "UsageError", "release_all"]

MARKER = ".jaxvs-report"
_HELD: list[ReportFolder] = []


class UsageError(ValueError):
    """A user error of the command (exit code 2): the message names the problem and the fix."""


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: alive
        return True
    return True


def _files_in(folder: Path) -> set[str]:
    return {
        p.relative_to(folder).as_posix()
        for p in folder.rglob("*")
        if not p.is_dir() or p.is_symlink()
    }


def written_by_jaxvs(folder: Path) -> tuple[bool, list[str]]:
    """Whether `folder` holds the marker of a jaxvs report, and the files in it that the
    marker does not list (added by someone else)."""
    try:
        marker = json.loads((folder / MARKER).read_text(encoding="utf-8"))
        listed = set(marker["files"]) if marker.get("written_by") == "jaxvs" else None
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        listed = None
    if listed is None:
        return False, []
    return True, sorted(_files_in(folder) - listed - {MARKER})


def held() -> int:
    """How many report folders this process holds (for `release_all`)."""
    return len(_HELD)


def release_all(since: int = 0) -> None:
    """Release the locks of the report folders taken after the first `since` (the end of
    one command run)."""
    for folder in list(_HELD[since:]):
        folder.release()


def _nearest_existing(path: Path) -> Path:
    for parent in [path, *path.parents]:
        if parent.exists() or parent.is_symlink():
            return parent
    return Path(".")  # pragma: no cover - "/" always exists


class ReportFolder:
    """The folder `--out` of one command run (see the module docstring).

    **Arguments:**

    - `out`: the folder the user named.
    - `inputs`: the input files of the run (refused when they lie inside `out`).
    - `option`: the option's name, for messages (`--out`).
    """

    def __init__(
        self,
        out: str | os.PathLike,
        inputs: Iterable[str | os.PathLike] = (),
        *,
        option: str = "--out",
    ):
        text = os.fspath(out)
        if not text.strip():
            raise UsageError(
                f"{option} is empty; give the name of a folder to write, e.g. {option} report."
            )
        self.out = Path(text)
        self.existed = self.out.exists()
        fix = f"give {option} the name of a new folder (it is created)"
        if self.out.is_symlink():
            raise UsageError(
                f"{option} {text} is a symbolic link (to {os.readlink(self.out)}); jaxvs "
                f"replaces the whole folder and would replace the link, so {fix} or name "
                "the folder the link points to."
            )
        resolved = self.out.resolve()
        cwd = Path.cwd().resolve()
        if (
            self.out.name in ("", ".", "..")
            or resolved == cwd
            or resolved in cwd.parents
            or resolved == Path.home().resolve()
        ):
            raise UsageError(
                f"{option} {text} is the current folder, one of its parents or your home "
                f"folder; jaxvs replaces the whole --out folder, so {fix}, e.g. {option} report."
            )
        if self.out.exists() and not self.out.is_dir():
            raise UsageError(f"{option} {text} is a file, not a folder; {fix}.")
        base = _nearest_existing(self.out.parent if not self.existed else self.out)
        if not base.is_dir():
            raise UsageError(
                f"{option} {text}: {base} is a file, so no folder can be made under it; {fix}."
            )
        # The staging folder is made beside DIR: try it (os.access says yes to root).
        probe_in = self.out.parent if self.existed else base
        try:
            tempfile.TemporaryDirectory(prefix=".jaxvs-probe-", dir=probe_in).cleanup()
        except OSError as err:
            raise UsageError(
                f"{option} {text}: cannot write in {probe_in} ({err.strerror or err}); {fix} "
                "in a folder you can write to."
            ) from None
        for item in inputs:
            p = Path(item).resolve()
            if p == resolved or resolved in p.parents:
                raise UsageError(
                    f"{option} {text} holds the input file {item}; the report replaces the "
                    f"whole folder, so {fix} outside the data's folder."
                )
        self.staging = self.out.parent / f".{self.out.name}.partial-{os.getpid()}"
        self.committed = False
        self._lock_path = self.out.parent / f".{self.out.name}.lock"
        self._lock: int | None = None
        if self.out.parent.is_dir():  # else nothing of DIR exists: no other run on it
            self._acquire(option, text)
        try:
            self._clean_stale()
            if self.existed:
                self._check_replaceable(option, text, fix)
        except BaseException:
            self.release()
            raise
        _interrupt.report_folder(self.out, self.existed, self.staging, self._lock_path)

    def _acquire(self, option: str, text: str) -> None:
        """Hold the lock of DIR for this run (refused at once when another run holds it)."""
        for _ in range(5):
            fd = os.open(self._lock_path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                try:
                    pid = os.read(fd, 32).decode(errors="replace").strip() or "?"
                finally:
                    os.close(fd)
                raise UsageError(
                    f"{option} {text} is being written by another jaxvs run (process {pid}); "
                    f"wait for it to finish or give {option} another folder."
                ) from None
            try:  # the file may have been removed by the run that held it: lock again
                same = os.fstat(fd).st_ino == os.stat(self._lock_path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                os.ftruncate(fd, 0)
                os.write(fd, str(os.getpid()).encode())
                self._lock = fd
                _HELD.append(self)
                return
            os.close(fd)
        raise UsageError(  # pragma: no cover - five races in a row
            f"{option} {text}: could not lock the folder; try again."
        )

    def release(self) -> None:
        """Give the lock of DIR back (and remove its file)."""
        if self._lock is None:
            return
        _interrupt.lock_released(self._lock_path)
        with contextlib.suppress(OSError):
            os.unlink(self._lock_path)
        with contextlib.suppress(OSError):
            os.close(self._lock)
        self._lock = None
        with contextlib.suppress(ValueError):
            _HELD.remove(self)

    def _clean_stale(self) -> None:
        """Remove staging folders of earlier runs on DIR whose process no longer exists."""
        if not self.out.parent.is_dir():
            return
        pattern = re.compile(re.escape(f".{self.out.name}.") + r"(partial|old)-(\d+)$")
        for entry in self.out.parent.iterdir():
            match = pattern.fullmatch(entry.name)
            if not match or entry.is_symlink() or not entry.is_dir():
                continue
            if int(match.group(2)) == os.getpid() or _pid_alive(int(match.group(2))):
                continue
            if match.group(1) == "old" and not self.out.exists():
                os.rename(entry, self.out)  # a replaced report whose successor never came
                self.existed = True
                continue
            shutil.rmtree(entry, ignore_errors=True)
            for leftover in self.out.parent.glob(f".{entry.name}.*"):
                shutil.rmtree(leftover, ignore_errors=True)

    def _check_replaceable(self, option: str, text: str, fix: str) -> None:
        entries = sorted(p.name for p in self.out.iterdir())
        if not entries:
            return
        ours, extra = written_by_jaxvs(self.out)
        if not ours:
            shown = ", ".join(entries[:3]) + (", ..." if len(entries) > 3 else "")
            raise UsageError(
                f"{option} {text} is a folder with files ({shown}) that jaxvs did not write "
                f"(no {MARKER} marker); the report replaces the whole folder, so {fix}. "
                "jaxvs never deletes files it did not write: remove the folder yourself if "
                "it is an old report."
            )
        if extra:
            shown = ", ".join(extra[:3]) + (", ..." if len(extra) > 3 else "")
            raise UsageError(
                f"{option} {text} holds an earlier jaxvs report and files added since "
                f"({shown}); the report replaces the whole folder, so move them out or {fix}."
            )

    def prepare(self) -> Path:
        """Create the parent folders and return the staging path (not created: a report's
        `save` creates it); an interrupt removes it."""
        self.out.parent.mkdir(parents=True, exist_ok=True)
        self.discard()
        return self.staging

    def commit(self) -> Path:
        """Write the marker, rename the complete staging folder into place (a first Ctrl-C
        waits for it) and release the lock."""
        files = sorted(_files_in(self.staging) - {MARKER})
        marker = {"written_by": "jaxvs", "version": __version__, "files": files}
        (self.staging / MARKER).write_text(json.dumps(marker, indent=1) + "\n", encoding="utf-8")
        with _interrupt.deferred():
            old = self.out.parent / f".{self.out.name}.old-{os.getpid()}"
            if self.out.exists():
                os.rename(self.out, old)
            os.rename(self.staging, self.out)
            self.committed = True
            _interrupt.committed()
        shutil.rmtree(old, ignore_errors=True)
        self.release()
        return self.out

    def discard(self) -> None:
        """Remove the staging folder (and a report save's own temporary folders); the lock
        is kept (the run goes on)."""
        shutil.rmtree(self.staging, ignore_errors=True)
        for leftover in self.out.parent.glob(f".{self.staging.name}.*"):
            with contextlib.suppress(OSError):
                shutil.rmtree(leftover)
