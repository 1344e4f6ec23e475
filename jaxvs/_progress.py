"""Progress bars and structured logging for long runs, interruptible with a clean message.

A calibration, a diagnosis or a parameter sweep that takes more than a few seconds shows
where it is (a tqdm bar on stderr, only on a terminal) and leaves a machine-readable trail
(records on the standard `logging` logger `"jaxvs"`, each carrying a `jaxvs` dict with
the event, the task, the step and any fields the caller adds). Ctrl-C ends it with one
line saying what was done, instead of a traceback from inside JAX.
"""

from __future__ import annotations

import json
import logging
import os
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import IO, Any

__all__ = ["Interrupted", "Progress", "log_to"]

LOGGER_NAME = "jaxvs"
_ON_INTERRUPT = ("raise", "return")


class Interrupted(KeyboardInterrupt):
    """A long jaxvs run was interrupted (Ctrl-C); the message says after how many steps.

    A subclass of `KeyboardInterrupt`, so `except KeyboardInterrupt` still catches it.
    """


def _jsonable(value: Any) -> Any:
    try:
        json.dumps(value)
        return value
    except (TypeError, ValueError):
        pass
    try:
        import numpy as np

        arr = np.asarray(value)
        if arr.dtype.kind in "biuf" and arr.size <= 64:
            return arr.item() if arr.ndim == 0 else arr.tolist()
    except Exception:
        pass
    return repr(value)


class Progress:
    """A progress bar with structured logging, as a context manager.

    ```python
    with jaxvs.Progress("diagnosis", total=len(effects), unit="effect") as p:
        for effect in effects:
            result = ...                          # one long step
            p.update(1, effect=effect, gap=0.012) # bar postfix + a log record
    ```

    On Ctrl-C inside the block the bar is closed, one line
    `"jaxvs: diagnosis interrupted after 3/8 effects (12.4 s)"` is written to stderr and
    logged, and [`Interrupted`][jaxvs.Interrupted] is raised with that message (or, with
    `on_interrupt="return"`, the block is left quietly and `p.interrupted` is `True`, so
    the caller can return partial results).

    **Arguments:**

    - `description`: what runs (the task name in the bar and in the log).
    - `total`: number of steps, if known.
    - `unit`: the name of one step (`"step"`, `"start"`, `"point"`, ...).
    - `disable`: `True` hides the bar; `None` (default) shows it only when stderr is a
      terminal and the environment variable `JAXVS_PROGRESS` is not `"0"`. Logging is
      independent of the bar.
    - `logger`: a `logging.Logger` (default `logging.getLogger("jaxvs")`). Start, end and
      interruption are logged at INFO, every update at DEBUG.
    - `on_interrupt`: `"raise"` (default) or `"return"`, see above.
    - `file`: the stream of the bar (default `sys.stderr`).
    """

    def __init__(
        self,
        description: str,
        total: int | None = None,
        *,
        unit: str = "step",
        disable: bool | None = None,
        logger: logging.Logger | None = None,
        on_interrupt: str = "raise",
        file: IO[str] | None = None,
    ):
        if not isinstance(description, str) or not description:
            raise TypeError("Progress: description must be a non-empty string.")
        if total is not None and (not isinstance(total, int) or total < 0):
            raise ValueError(f"Progress: total must be a non-negative int or None; got {total!r}.")
        if on_interrupt not in _ON_INTERRUPT:
            raise ValueError(
                f"Progress: on_interrupt must be one of {_ON_INTERRUPT}; got {on_interrupt!r}."
            )
        self.description = description
        self.total = total
        self.unit = unit
        self.on_interrupt = on_interrupt
        self.logger = logger if logger is not None else logging.getLogger(LOGGER_NAME)
        self.file = file if file is not None else sys.stderr
        if disable is None:
            isatty = getattr(self.file, "isatty", lambda: False)
            disable = os.environ.get("JAXVS_PROGRESS", "1") == "0" or not isatty()
        self.disable = bool(disable)
        self.step = 0
        self.interrupted = False
        self.message: str | None = None
        self._bar: Any = None
        self._t0: float | None = None
        self._fields: dict[str, Any] = {}

    # -- structured log -----------------------------------------------------------------

    @property
    def elapsed(self) -> float:
        """Seconds since the block was entered."""
        return 0.0 if self._t0 is None else time.perf_counter() - self._t0

    def log(self, event: str, level: int = logging.INFO, **fields: Any) -> None:
        """Write one structured log record (`record.jaxvs` holds the fields) without
        advancing the bar."""
        payload = {
            "event": event,
            "task": self.description,
            "step": self.step,
            "total": self.total,
            "elapsed_s": round(self.elapsed, 6),
            **{k: _jsonable(v) for k, v in fields.items()},
        }
        extras = ", ".join(f"{k}={payload[k]}" for k in fields)
        where = f"{self.step}/{self.total}" if self.total is not None else f"{self.step}"
        msg = f"{self.description}: {event} ({where} {self.unit}s){': ' + extras if extras else ''}"
        self.logger.log(level, msg, extra={"jaxvs": payload})

    # -- progress -----------------------------------------------------------------------

    def __enter__(self) -> Progress:
        self._t0 = time.perf_counter()
        if not self.disable:
            from tqdm.auto import tqdm

            self._bar = tqdm(
                total=self.total, desc=self.description, unit=self.unit, file=self.file
            )
        self.log("start")
        return self

    def update(self, n: int = 1, **fields: Any) -> None:
        """Advance by `n` steps; `fields` (e.g. `cost=1.2e-3`) go to the bar's postfix and
        to a DEBUG log record."""
        if self._t0 is None:
            raise RuntimeError("Progress.update: use the Progress object inside `with`.")
        self.step += n
        self._fields.update(fields)
        if self._bar is not None:
            self._bar.update(n)
            if fields:
                self._bar.set_postfix({k: _short(v) for k, v in fields.items()}, refresh=False)
        self.log("update", logging.DEBUG, **fields)

    def set_total(self, total: int) -> None:
        """Set the number of steps once it is known."""
        self.total = int(total)
        if self._bar is not None:
            self._bar.total = self.total
            self._bar.refresh()

    def tick(self, x: Any, n: int = 1) -> Any:
        """Advance by `n` from inside `jax.jit` (through `jax.debug.callback`); returns `x`.

        The callback runs when the compiled computation reaches this point; under `vmap`
        it runs once per batch element.
        """
        import jax

        jax.debug.callback(lambda: self.update(n))
        return x

    def __exit__(self, exc_type, exc, tb) -> bool:
        if self._bar is not None:
            self._bar.close()
        if exc_type is not None and issubclass(exc_type, KeyboardInterrupt):
            if isinstance(exc, Interrupted):  # an inner Progress already reported it
                self.interrupted = True
                self.message = str(exc)
                return self.on_interrupt == "return"
            done = f"{self.step}/{self.total}" if self.total is not None else f"{self.step}"
            self.message = (
                f"jaxvs: {self.description} interrupted after {done} {self.unit}s "
                f"({self.elapsed:.1f} s)"
            )
            self.interrupted = True
            from . import _interrupt

            # The jaxvs command prints one line for everything (logging's last-resort
            # handler would print a WARNING as a second line).
            self.log("interrupted", logging.INFO if _interrupt.installed() else logging.WARNING)
            if _interrupt.installed():
                _interrupt.note(f"{self.description} ({done} {self.unit}s done)")
            else:
                print(self.message, file=sys.stderr)
            if self.on_interrupt == "return":
                return True
            raise Interrupted(self.message) from None
        if exc_type is None:
            self.log("end", **self._fields)
        else:
            self.log("error", logging.ERROR, error=f"{exc_type.__name__}: {exc}")
        return False


def _short(v: Any) -> Any:
    if isinstance(v, float):
        return f"{v:.4g}"
    return _jsonable(v)


class JSONFormatter(logging.Formatter):
    """One JSON object per line: time, level, message and the record's `jaxvs` fields."""

    def format(self, record: logging.LogRecord) -> str:
        out: dict[str, Any] = {
            "time": self.formatTime(record, "%Y-%m-%dT%H:%M:%S"),
            "level": record.levelname,
            "logger": record.name,
            "message": record.getMessage(),
        }
        payload = getattr(record, "jaxvs", None)
        if isinstance(payload, Mapping):
            out.update(payload)
        return json.dumps(out, default=repr)


def log_to(
    target: str | os.PathLike | IO[str] = sys.stderr,
    *,
    level: int | str = "INFO",
    json: bool = True,
) -> logging.Handler:
    """Send jaxvs's log records to a stream or file.

    **Arguments:**

    - `target`: a path (appended to) or a text stream (default stderr).
    - `level`: the lowest level written (`"DEBUG"` includes every progress update).
    - `json`: one JSON object per line (time, level, message, event, task, step, total,
      elapsed_s and the caller's fields) instead of plain text.

    **Returns:**

    The handler added to the `"jaxvs"` logger; remove it with
    `logging.getLogger("jaxvs").removeHandler(handler)` (and `handler.close()`).
    """
    if isinstance(target, (str, os.PathLike)):
        handler: logging.Handler = logging.FileHandler(Path(target), mode="a", encoding="utf-8")
    else:
        handler = logging.StreamHandler(target)
    handler.setLevel(level)
    handler.setFormatter(
        JSONFormatter() if json else logging.Formatter("%(asctime)s %(levelname)s %(message)s")
    )
    logger = logging.getLogger(LOGGER_NAME)
    logger.addHandler(handler)
    if logger.level == logging.NOTSET or logger.level > handler.level:
        logger.setLevel(handler.level)
    return handler
