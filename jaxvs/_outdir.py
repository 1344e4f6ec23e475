"""Report folders of the `jaxvs` command (`--out`), checked first and written atomically.

`--out DIR` is checked before any work: it must not be a file, nor lie under a file, nor
hold input files, and its nearest existing parent folder must be writable. An existing
`DIR` is accepted when it is empty or holds an earlier jaxvs report (a `report.json`);
any other non-empty folder is refused, since the whole folder is replaced.

The report is written into a hidden staging folder beside `DIR` (`.DIR.partial-<pid>`)
and renamed into place once complete; an earlier report in `DIR` is replaced only then.
So after any run, interrupted or not, `DIR` holds a complete report or none.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterable
from pathlib import Path

from . import _interrupt

__all__ = ["ReportFolder", "UsageError"]


class UsageError(ValueError):
    """A user error of the command (exit code 2): the message names the problem and the fix."""


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
        if self.existed:
            entries = [p.name for p in self.out.iterdir()]
            if entries and "report.json" not in entries:
                shown = ", ".join(sorted(entries)[:3])
                raise UsageError(
                    f"{option} {text} is a folder with other files ({shown}"
                    f"{', ...' if len(entries) > 3 else ''}) and no earlier jaxvs report; the "
                    f"report replaces the whole folder, so {fix} or empty it first."
                )
        resolved = self.out.resolve()
        for item in inputs:
            p = Path(item).resolve()
            if p == resolved or resolved in p.parents:
                raise UsageError(
                    f"{option} {text} holds the input file {item}; the report replaces the "
                    f"whole folder, so {fix} outside the data's folder."
                )
        self.staging = self.out.parent / f".{self.out.name}.partial-{os.getpid()}"
        self.committed = False
        _interrupt.report_folder(self.out, self.existed, self.staging)

    def prepare(self) -> Path:
        """Create the parent folders and return the staging path (not created: a report's
        `save` creates it); an interrupt removes it."""
        self.out.parent.mkdir(parents=True, exist_ok=True)
        self.discard()
        return self.staging

    def commit(self) -> Path:
        """Rename the complete staging folder into place (a first Ctrl-C waits for it)."""
        with _interrupt.deferred():
            old = self.out.parent / f".{self.out.name}.old-{os.getpid()}"
            if self.out.exists():
                os.rename(self.out, old)
            os.rename(self.staging, self.out)
            self.committed = True
            _interrupt.committed()
        shutil.rmtree(old, ignore_errors=True)
        return self.out

    def discard(self) -> None:
        """Remove the staging folder (and a report save's own temporary folders)."""
        shutil.rmtree(self.staging, ignore_errors=True)
        for leftover in self.out.parent.glob(f".{self.staging.name}.*"):
            with contextlib.suppress(OSError):
                shutil.rmtree(leftover)
