"""Ctrl-C for the `jaxvs` command: exit code 130, one line, no traceback, no crash.

The library itself never touches signals; only the command does, from its first instant
(`jaxvs/__init__.py` calls `install_for_command`, which does nothing unless the process is
the `jaxvs` command), so an interrupt while JAX is still being imported is handled too.

How an interrupt ends the command:

1. The first SIGINT raises `KeyboardInterrupt` in the main thread as usual (deferred while
   a report folder is being renamed into place, so `--out` never holds half a report).
   The command's entry point catches it, removes its staging folder, prints one line that
   says what was and was not written, flushes and leaves with `os._exit(130)`: XLA's
   worker threads are not torn down by the interpreter (that teardown is what crashed
   with a segmentation fault after the "interrupted" line).
2. The main thread only sees the interrupt between Python bytecodes; inside a long XLA
   compilation, or when a callback swallows the `KeyboardInterrupt`, it may not. A
   watcher thread is woken by the signal itself (`signal.set_wakeup_fd`) and, when the
   main thread has not finished within a grace period (a few seconds), does step 1 itself.
3. A second Ctrl-C ends the command at once, the same way.
4. SIGTERM (`kill`, a job scheduler, a container stopping) ends the command at once the
   same way with exit code 143 and a line saying "terminated": the staging folder is
   removed, a report being renamed into place is finished first (so `--out` holds the
   complete report or the earlier one), and the watcher ends it when the main thread is
   inside XLA.

Only the standard library is imported here: this runs before JAX is loaded.
"""

from __future__ import annotations

import _thread
import contextlib
import os
import shutil
import signal
import socket
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

__all__ = ["install", "install_for_command"]

EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143  # 128 + SIGTERM
TERM_GRACE_S = 1.0  # heuristic: the main thread's own handler usually acts within this
GRACE_S = 4.0  # heuristic: long enough to clean up and print, short enough to feel instant


class _State:
    def __init__(self):
        self.reset("jaxvs")
        self.installed = False
        self.running = False  # False until main() takes over (during `import jaxvs`)
        self.signals = 0
        self.deferring = 0
        self.pending = False
        self.finished = False
        self.terminated = False
        self.lock = threading.RLock()
        self.echo_lock = threading.Lock()
        self.echo_handler = 0  # re-delivered interrupts (see _unraisable), not new Ctrl-Cs
        self.echo_watcher = 0
        self.redeliver = False

    def reset(self, command: str) -> None:
        self.command = command
        self.stage = "starting"
        self.out: Path | None = None  # the report folder, once validated
        self.out_existed = False
        self.committed = False
        self.staging: list[Path] = []  # removed on interrupt
        self.locks: list[Path] = []  # lock files of report folders, removed at the end
        self.grace = GRACE_S


_state = _State()


def installed() -> bool:
    """Whether the command's interrupt handling is active (never in library use)."""
    return _state.installed


def _is_command() -> bool:
    argv0 = os.path.basename(sys.argv[0]) if sys.argv else ""
    if argv0 in ("jaxvs", "jaxvs.exe", "jaxvs-script.py"):
        return True
    orig = list(getattr(sys, "orig_argv", []))
    return any(a == "-m" and b in ("jaxvs._cli", "jaxvs") for a, b in zip(orig, orig[1:]))


def install_for_command() -> None:
    """Install the handling when this process is the `jaxvs` command (console script or
    `python -m jaxvs._cli`); a no-op when jaxvs is imported as a library."""
    if _is_command():
        install()


def install() -> None:
    """Install the SIGINT handler and its watcher thread (once; main thread only)."""
    state = _state
    if state.installed or threading.current_thread() is not threading.main_thread():
        return
    reader, writer = socket.socketpair()
    writer.setblocking(False)
    try:
        signal.set_wakeup_fd(writer.fileno(), warn_on_full_buffer=False)
    except (ValueError, OSError):  # pragma: no cover - not the main thread / no support
        reader.close()
        writer.close()
        return
    state.installed = True
    state._sockets = (reader, writer)  # type: ignore[attr-defined] # keep them open
    signal.signal(signal.SIGINT, _on_sigint)
    signal.signal(signal.SIGTERM, _on_sigterm)
    state._unraisable = sys.unraisablehook  # type: ignore[attr-defined]
    sys.unraisablehook = _unraisable
    threading.Thread(target=_watch, args=(state, reader), name="jaxvs-sigint", daemon=True).start()


def _unraisable(unraisable) -> None:
    """A `KeyboardInterrupt` raised where Python cannot propagate it (a garbage-collector
    callback of XLA, a `__del__`) is delivered again by the watcher thread instead of being
    printed as "Exception ignored ... Traceback". (As little Python as possible runs here:
    an interrupt raised inside this hook would be printed.)"""
    if isinstance(unraisable.exc_value, KeyboardInterrupt) and not _state.finished:
        _state.redeliver = True
        return
    _state._unraisable(unraisable)  # type: ignore[attr-defined]


def _on_sigint(signum, frame) -> None:
    state = _state
    if state.finished:  # the command has ended (its exit code stands) or is ending
        return
    with state.echo_lock:
        echo = state.echo_handler > 0
        state.echo_handler -= echo
    state.signals += not echo
    if state.deferring:  # renaming a report into place: finish that first
        state.pending = True
        return
    if not state.running or state.signals > 1:
        # During `import jaxvs` nothing has been written; a second Ctrl-C means "now".
        abort()
    raise KeyboardInterrupt


def _on_sigterm(signum, frame) -> None:
    state = _state
    if state.finished:
        return
    state.terminated = True
    if state.deferring:  # renaming a report into place: finish that first
        state.pending = True
        return
    abort()


def _watch(state: _State, reader: socket.socket) -> None:
    deadline = None
    term_deadline = None
    while True:
        waits = [d for d in (deadline, term_deadline) if d is not None]
        reader.settimeout(None if not waits else 0.05)
        try:
            data = reader.recv(64)
        except TimeoutError:
            data = b""
        except OSError:  # pragma: no cover - socket closed at exit
            return
        if data.count(bytes([signal.SIGTERM])) and term_deadline is None:
            term_deadline = time.monotonic() + TERM_GRACE_S
        if term_deadline is not None and time.monotonic() > term_deadline:
            state.terminated = True
            abort()  # the main thread is inside XLA: end it from here
            return
        n = data.count(bytes([signal.SIGINT]))
        with state.echo_lock:
            echoes = min(n, state.echo_watcher)
            state.echo_watcher -= echoes
        n -= echoes
        if n and deadline is None and n == 1:
            deadline = time.monotonic() + state.grace
        elif n:
            abort()  # a second Ctrl-C: now
            return
        if deadline is None:
            continue
        if state.redeliver and not state.finished:  # swallowed by a callback: again
            state.redeliver = False
            with state.echo_lock:
                state.echo_handler += 1
                state.echo_watcher += 1
            _thread.interrupt_main()
        if time.monotonic() > deadline:
            abort()  # the main thread did not finish in time
            return


# --- what the command tells the handler ------------------------------------------------


def begin(command: str) -> None:
    """main() has taken over: interrupts now raise `KeyboardInterrupt` in the main thread."""
    _state.reset(command)
    _state.running = True


def stage(text: str) -> None:
    """What the command is doing now (goes into the interrupt line); also appended to the
    file named by `JAXVS_TRACE_STAGES`, which the interrupt tests use to pick a moment."""
    _state.stage = text
    if _trace(text):
        pause = os.environ.get("JAXVS_STAGE_PAUSE", "")  # "STAGE_PREFIX:SECONDS"
        prefix, _, seconds = pause.rpartition(":")
        if prefix and text.startswith(prefix):
            time.sleep(float(seconds))


def _trace(text: str) -> bool:
    """Append `text` to the file named by `JAXVS_TRACE_STAGES`; whether there is one."""
    trace = os.environ.get("JAXVS_TRACE_STAGES")
    if trace:
        with open(trace, "a", encoding="utf-8") as f:
            f.write(text + "\n")
    return bool(trace)


def set_grace(seconds: float) -> None:
    _state.grace = float(seconds)


def report_folder(out: Path, existed: bool, staging: Path, lock: Path | None = None) -> None:
    _state.out, _state.out_existed = out, existed
    _state.staging.append(staging)
    if lock is not None:
        _state.locks.append(lock)


def lock_released(lock: Path) -> None:
    """A report folder's lock was given back: its file is no longer this process's."""
    with contextlib.suppress(ValueError):
        _state.locks.remove(lock)


def committed() -> None:
    _state.committed = True


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Hold a first Ctrl-C until the block is done (renaming a report into place), then
    raise it; the watcher waits for the block too (it takes the same lock)."""
    state = _state
    with state.lock:
        state.deferring += 1
        try:
            yield
        finally:
            state.deferring -= 1
    if state.pending and not state.deferring:
        state.pending = False
        raise KeyboardInterrupt


def line(command: str | None = None, stage: str | None = None) -> str:
    """The one line printed on an interrupt: what was and was not written."""
    state = _state
    verb = "terminated (SIGTERM)" if state.terminated else "interrupted"
    cmd = command or state.command
    if (
        cmd == "jaxvs"
        and len(sys.argv) > 1
        and sys.argv[1] in ("demo", "diagnose", "check", "design")
    ):
        cmd = sys.argv[1]  # interrupted while starting, before main() parsed the command
    during = stage or state.stage
    head = f"jaxvs {cmd}: {verb} while {during}" if cmd != "jaxvs" else f"jaxvs: {verb}"
    if state.committed and state.out is not None:
        return f"{head}; the complete report was written to {state.out}."
    if state.out is None:
        return f"{head}; nothing was written."
    if state.out_existed:
        return f"{head}; nothing was written: {state.out} still holds the earlier report."
    return f"{head}; nothing was written ({state.out} was not created)."


def _discard(state: _State) -> None:
    for lock in state.locks:  # the process ends: its locks go with it
        with contextlib.suppress(OSError):
            os.unlink(lock)
    if state.committed:
        return
    for path in state.staging:
        shutil.rmtree(path, ignore_errors=True)
        for leftover in path.parent.glob(f".{path.name}.*"):  # temporary folders of a save
            shutil.rmtree(leftover, ignore_errors=True)


def done() -> None:
    """The command has ended: a Ctrl-C from now on changes nothing (the exit code stands).

    In the command, SIGINT and SIGTERM are then ignored: the interpreter's finalization
    resets Python-level handlers to the default action, so a signal arriving while JAX
    and its threads shut down would otherwise kill the finished command (exit -2) after
    its report was written. An ignored signal is not reset."""
    _state.finished = True
    _trace("ended")
    if _state.installed and _is_command() and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)


def was_interrupted() -> bool:
    """Whether Ctrl-C was pressed (an exception that followed it may be the interrupt
    wrapped by XLA, e.g. a `RuntimeError` from inside a callback)."""
    return _state.signals > 0


def discard_staging() -> None:
    """Remove the staging folders of a run that ended with an error."""
    _discard(_state)


def note(text: str) -> None:
    """A long step's own account of how far it got (a `Progress` that was interrupted)."""
    _state.stage = text


def abort(message: str | None = None) -> None:
    """End the command now: remove the staging folder, print the line, exit 130."""
    state = _state
    with state.lock:
        if state.finished:
            return
        state.finished = True
        _discard(state)
        _exit(message or line(), EXIT_INTERRUPTED)


def _exit(message: str, code: int) -> None:
    if _state.terminated:  # SIGTERM decides the code and the word, whatever came first
        code = EXIT_TERMINATED
        message = message.replace("interrupted", "terminated (SIGTERM)", 1)
    with contextlib.suppress(Exception):
        sys.stdout.flush()
    with contextlib.suppress(Exception):
        sys.stderr.write(message + "\n")
        sys.stderr.flush()
    os._exit(code)


def finish(code: int, message: str) -> int:
    """End an interrupted command from the main thread: in the command, print `message`
    and leave with `os._exit(code)` (nothing runs after); called in-process (tests),
    print it and return `code`."""
    state = _state
    if not state.installed:
        _discard(state)
        print(message, file=sys.stderr)
        return code
    with state.lock:
        if state.finished:  # pragma: no cover - the watcher got there first
            return code
        state.finished = True
        _discard(state)
        _exit(message, code)
    return code  # pragma: no cover


install_for_command()  # at import, which `jaxvs/__init__.py` does first
