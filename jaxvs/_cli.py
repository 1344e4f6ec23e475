"""The `jaxvs` command.

Exit codes (docs/guides/contracts.md): 0 done; 2 user error (one line `jaxvs: error: ...` on stderr
naming the problem and the fix; `--debug` adds the traceback); 3 the data cannot identify
the family's nominal model (`diagnose`, `check`; a report is still written); 130
interrupted (Ctrl-C: one line saying what was and was not written); 1 an internal error
(a bug: one line, `--debug` for the traceback).

Every path is checked before any work; report folders (`--out`) are written atomically
(`jaxvs._outdir`), and Ctrl-C is handled from the first instant (`jaxvs._interrupt`).
"""

from __future__ import annotations

import argparse
import os
import sys
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

from . import _interrupt, _memory
from ._files import regular_file
from ._outdir import ReportFolder, UsageError, held, release_all
from ._version import __version__

EXIT_OK, EXIT_INTERNAL, EXIT_USAGE, EXIT_NOT_IDENTIFIABLE = 0, 1, 2, 3
EXIT_INTERRUPTED = _interrupt.EXIT_INTERRUPTED

# --- option types: refused by argparse before any work, in one line -------------------------


def _int_at_least(lo: int) -> Callable[[str], int]:
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expects an integer >= {lo}, got {text!r}") from None
        if value < lo:
            raise argparse.ArgumentTypeError(f"expects an integer >= {lo}, got {value}")
        return value

    parse.__name__ = f"integer >= {lo}"
    return parse


def _float_in(lo: float, hi: float, what: str) -> Callable[[str], float]:
    """An argparse type: a float in the open interval (lo, hi)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = float("nan")
        if not lo < value < hi:  # also refuses nan
            raise argparse.ArgumentTypeError(f"expects {what}, got {text!r}")
        return value

    parse.__name__ = what
    return parse


_positive_float = _float_in(0.0, float("inf"), "a positive finite number")
_fraction = _float_in(0.0, 1.0, "a number in (0, 1) such as 0.3")


def _size(text: str) -> float:
    try:
        return _memory.parse_size(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expects a memory size such as 8G, 512M or 2.5GB, got {text!r}"
        ) from None


def _character(text: str) -> str:
    text = {"\\t": "\t", "tab": "\t"}.get(text, text)
    if len(text) != 1:
        raise argparse.ArgumentTypeError(f"expects one character such as ';' or ',', got {text!r}")
    return text


# --- shared options, declared once ------------------------------------------------------------

# name -> (flags, argparse keyword arguments); a sub-command lists the names it takes.
_OPTIONS: dict[str, tuple[tuple[str, ...], dict[str, Any]]] = {
    "data": (("data",), dict(nargs="+", help="calibration experiment file(s)")),
    "family": (("--family",), dict(required=True, choices=["drive", "tmf", "thermal"])),
    "validate": (
        ("--validate",),
        dict(nargs="+", default=None, help="validation (held-out) experiment file(s)"),
    ),
    "out": (("--out",), dict(required=True, help="report folder (replaced atomically)")),
    "holdout": (
        ("--holdout",),
        dict(type=_fraction, default=0.3, help="share held out without --validate"),
    ),
    "seed": (("--seed",), dict(type=_int_at_least(0), default=0, help="random seed")),
    "option": (
        ("--option",),
        dict(
            action="append",
            default=[],
            metavar="KEY=VALUE",
            help="family option (repeatable), e.g. --option decimation=4",
        ),
    ),
    "no_figures": (("--no-figures",), dict(action="store_true", help="skip the PNG figures")),
    "quiet": (("--quiet",), dict(action="store_true", help="no progress messages")),
    "delimiter": (
        ("--delimiter",),
        dict(type=_character, default=",", help="CSV column separator (default ','; ';' or tab)"),
    ),
    "decimal": (
        ("--decimal",),
        dict(type=_character, default=".", help="CSV decimal mark (default '.'; ',' for 0,5)"),
    ),
    "encoding": (
        ("--encoding",),
        dict(default="utf-8", help="CSV text encoding (default utf-8; e.g. latin-1)"),
    ),
    "signal": (
        ("--signal",),
        dict(
            action="append",
            default=[],
            metavar="NAME=COLUMN",
            help="read the file's column COLUMN as the signal NAME (repeatable), e.g. "
            "--signal q=Position --signal u=Torque; units come from the header",
        ),
    ),
    "time": (
        ("--time",),
        dict(default=None, metavar="COLUMN", help="the time column [s] when it is not named t"),
    ),
    "debug": (("--debug",), dict(action="store_true", help="show tracebacks of errors")),
    "max_memory": (
        ("--max-memory",),
        dict(
            type=_size,
            default=None,
            metavar="SIZE",
            help="refuse a run estimated to need more memory (e.g. 8G; default: 80%% of "
            "the memory available)",
        ),
    ),
}
_READS_DATA = ("signal", "time", "delimiter", "decimal", "encoding", "max_memory", "debug")


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (`jaxvs: error: ...; see 'jaxvs X --help'`)."""

    def error(self, message: str):  # type: ignore[override]
        where = self.prog.removeprefix("jaxvs").strip()
        raise UsageError(f"{where + ': ' if where else ''}{message}; see '{self.prog} --help'.")


def _add(parser: argparse.ArgumentParser, names: tuple[str, ...], **overrides: Any) -> None:
    for name in names:
        flags, kwargs = _OPTIONS[name]
        parser.add_argument(*flags, **{**kwargs, **overrides.get(name, {})})


def _parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="jaxvs",
        description="Virtual sensors of machine tools and sim-to-real gap diagnosis (JAX).",
        epilog="Exit codes: 0 done, 2 user error, 3 not identifiable, 130 interrupted.",
    )
    p.add_argument("--version", action="version", version=f"jaxvs {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="{demo,diagnose,check,design}")
    demo = sub.add_parser(
        "demo",
        help="end-to-end run on the embedded machine-structure twin (no download)",
        description=(
            "Identify the encoder-to-TCP transmissibility (TMF) of a position-dependent "
            "machine-structure twin at several positions of the other axis from PRBS "
            "excitation data, calibrate the whole TMF family in one vectorised call, "
            "diagnose a drive twin with a hidden effect, print a summary and write it with "
            "figures to --out (replaced atomically)."
        ),
    )
    _add(demo, ("out", "seed", "debug"), out=dict(required=False, default="demo-report"))
    demo.add_argument("--positions", type=_int_at_least(2), default=8, help="number of Y positions")

    diag = sub.add_parser(
        "diagnose",
        help="diagnose the sim-to-real gap of a model family on measured experiments",
        description=(
            "Recalibrate the family's nominal model on the DATA experiments, map where it "
            "still disagrees with the measurements, name the unmodelled effect(s) that close "
            "the gap on held-out data, and write report.json, report.md, report.html and figures "
            "to --out. "
            "DATA: CSV (header row, time column t [s]), NPZ, MAT or HDF5 files with the "
            "canonical signal names of the family, or the EMPS .mat files as they are."
        ),
    )
    _add(diag, ("data", "family", "validate", "out", "holdout"))
    diag.add_argument("--max-effects", type=_int_at_least(1), default=3, help="most effects added")
    _add(diag, ("seed",))
    diag.add_argument("--order", type=_int_at_least(1), default=None, help="tmf: TMF order")
    diag.add_argument(
        "--cutoff-hz", type=_positive_float, default=None, help="drive: low-pass cut-off [Hz]"
    )
    diag.add_argument(
        "--discover",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="after the named search, when the remainder stays above the null, look for an "
        "effect outside the library: a flexible term, then its formula (default: on)",
    )
    _add(diag, ("option", "no_figures", "quiet", *_READS_DATA))

    chk = sub.add_parser(
        "check",
        help="data quality and identifiability of records for a family's nominal model",
        description=(
            "Before any calibration: sample rate and time base, clipping and quantisation, "
            "excitation band, coherence, motion in both directions (drives), and the "
            "singular values of the nominal model's Jacobian with the parameter combinations "
            "the records cannot identify. Exit code 0 when the data can support the family's "
            "nominal model, 3 when not, 2 on user error. DATA: any format jaxvs.data.load "
            "reads."
        ),
    )
    _add(chk, ("data", "family", "out", "option", *_READS_DATA), out=dict(required=False))

    des = sub.add_parser(
        "design",
        help="search inputs, delays and model structures for a virtual sensor and rank them",
        description=(
            "Search candidate inputs, their delays and model structures (static regression, "
            "first-order lag, ARX, static network, TDNN) for a virtual sensor of --target in "
            "one vectorised run, rank the designs on held-out data (whole experiments or a "
            "contiguous block), and write report.json, report.md, report.html, figures and "
            "best.eqx (jaxvs.load_model) to --out. The target may be sparse: empty/NaN cells "
            "between measurements, or --target-samples. Ctrl-C writes the designs ranked so "
            "far (exit code 130)."
        ),
    )
    _add(des, ("data",))
    des.add_argument("--target", required=True, help="name of the signal to predict")
    des.add_argument(
        "--inputs", default=None, help="candidate inputs A,B,... (default: all other signals)"
    )
    _add(des, ("validate", "out"))
    des.add_argument("--budget", type=_positive_float, default=None, help="search time limit [s]")
    des.add_argument(
        "--target-samples", default=None, help="file of sparse target samples (t, target)"
    )
    des.add_argument("--max-inputs", type=_int_at_least(1), default=4, help="input pool size")
    des.add_argument(
        "--max-delay", type=_int_at_least(0), default=2, help="largest input delay [samples]"
    )
    des.add_argument("--hidden", default="3,6,10,15", help="network hidden sizes (comma separated)")
    des.add_argument("--inits", type=_int_at_least(1), default=3, help="initialisations per net")
    _add(des, ("holdout", "seed", "no_figures", "quiet", *_READS_DATA))
    return p


# --- checks before any work -------------------------------------------------------------------


def _input_files(paths: list[str], option: str) -> list[str]:
    """Every input path exists, is a file and can be read; else a one-line user error."""
    for text in paths:
        path = Path(text)
        if not path.exists() and not path.is_symlink():
            near = (
                sorted(p.name for p in path.parent.glob(f"*{path.suffix}"))[:3]
                if (path.parent.is_dir())
                else []
            )
            hint = f" (files there: {', '.join(near)})" if near else ""
            raise UsageError(f"{option} {text}: no such file{hint}; check the path.")
        if path.is_dir():
            raise UsageError(
                f"{option} {text} is a folder; give the data file(s) in it, e.g. {text}/*.csv."
            )
        try:  # a FIFO or a device would block the read below; a link loop is named
            regular_file(path, option)
        except (ValueError, OSError) as err:
            said = _one_line(err).removeprefix(f"{option}: ")
            raise UsageError(f"{option} {text}: {said}") from None
        try:
            with open(path, "rb") as handle:
                head = handle.read(1)
        except OSError as err:
            raise UsageError(
                f"{option} {text} cannot be read ({err.strerror or err}); check its permissions."
            ) from None
        if not head:
            raise UsageError(f"{option} {text} is empty (0 bytes); give the complete file.")
    return paths


def _parse_option(text: str) -> tuple[str, object]:
    key, sep, value = text.partition("=")
    if not sep or not key.strip() or not value.strip():
        raise UsageError(f"--option expects KEY=VALUE such as decimation=4, got {text!r}.")
    for cast in (int, float):
        try:
            return key.strip(), cast(value)
        except ValueError:
            pass
    return key.strip(), value.strip()


def _options(args) -> dict[str, object]:
    options: dict[str, object] = {}
    for text in args.option:
        key, value = _parse_option(text)
        if key in options:
            raise UsageError(f"--option {key} is given twice; keep one.")
        options[key] = value
    return options


def _signals(args) -> dict[str, str]:
    """`--signal NAME=COLUMN ...` and `--time COLUMN` as one mapping `{NAME: COLUMN}`."""
    mapping: dict[str, str] = {}
    for text in args.signal:
        name, sep, column = text.partition("=")
        if not sep or not name.strip() or not column.strip():
            raise UsageError(
                f"--signal expects NAME=COLUMN such as q=Position (the column's name in the "
                f"file), got {text!r}."
            )
        if name.strip() in mapping:
            raise UsageError(f"--signal {name.strip()} is given twice; keep one.")
        mapping[name.strip()] = column.strip()
    if args.time is not None:
        if not args.time.strip() or "t" in mapping:
            raise UsageError(
                "--time names the time column once, e.g. --time Zeit (not with --signal t=...)."
            )
        mapping["t"] = args.time.strip()
    return mapping


def _load(paths: list[str], args) -> list[Any]:
    """Read the files with the CSV dialect options and the column mapping (`--signal`,
    `--time`); records are named after their files."""
    from .data import Record, load_renamed

    signals = _signals(args)
    out = []
    for text in paths:
        _interrupt.stage(f"loading {text}")
        try:
            loaded = load_renamed(
                text,
                signals,
                delimiter=args.delimiter,
                decimal=args.decimal,
                encoding=args.encoding,
            )
        except (ValueError, KeyError) as err:
            message = _one_line(err)
            if Path(text).name not in message:  # e.g. a Record's own check: say which file
                raise UsageError(f"{text}: {message}") from err
            raise
        recs = loaded if isinstance(loaded, list) else [loaded]
        base = Path(text).name
        for k, rec in enumerate(recs):
            name = base if len(recs) == 1 else f"{base}[{k}]"
            out.append(
                Record(
                    {n: rec[n] for n in rec.names},
                    t=rec.t,
                    units=rec.units,
                    metadata={**rec.metadata, "name": name},
                )
            )
    return out


def _x64() -> None:
    import jax

    jax.config.update("jax_enable_x64", True)  # calibration in float64 (a program may)


# --- the sub-commands ---------------------------------------------------------------------------


def _check(args) -> int:
    _input_files(args.data, "DATA")
    options = _options(args)
    folder = ReportFolder(args.out, args.data) if args.out is not None else None
    _x64()
    import jaxvs

    records = _load(args.data, args)
    _interrupt.stage("checking the data")
    report = jaxvs.check(records, family=args.family, **options)
    if folder is not None:
        _interrupt.stage("writing the report")
        report.save(folder.prepare())
        folder.commit()
    print(report.to_markdown())
    if folder is not None:
        names = ("report.json", "report.md", "report.html")
        print("written: " + ", ".join(str(folder.out / n) for n in names))
    return report.exit_code


def _diagnose(args) -> int:
    _input_files(args.data, "DATA")
    _input_files(args.validate or [], "--validate")
    options = _options(args)
    if args.order is not None:
        options["order"] = args.order
    if args.cutoff_hz is not None:
        options["cutoff_hz"] = args.cutoff_hz
    folder = ReportFolder(args.out, [*args.data, *(args.validate or [])])
    _x64()
    import jaxvs

    cal = _load(args.data, args)
    val = _load(args.validate, args) if args.validate else None
    _interrupt.stage("diagnosing")
    report = jaxvs.diagnose(
        cal,
        val,
        family=args.family,
        holdout=args.holdout,
        max_effects=args.max_effects,
        seed=args.seed,
        progress=not args.quiet,
        discover=args.discover,
        **options,
    )
    staging = folder.prepare()
    out = folder.out
    if report.content.get("not_identifiable"):
        _interrupt.stage("writing the report")
        report.save(staging)
        folder.commit()
        print(f"jaxvs: not identifiable: {report.content['not_identifiable']}", file=sys.stderr)
        print(f"written: {out / 'report.json'}, {out / 'report.md'}, {out / 'report.html'}")
        return EXIT_NOT_IDENTIFIABLE
    if not args.no_figures:
        from .plotting import plot_diagnosis

        _interrupt.stage("drawing the figures")
        report.content["figures"] = plot_diagnosis(report, staging)
    _interrupt.stage("writing the report")
    report.save(staging)
    folder.commit()
    print(report.to_markdown())
    print(f"written: {out / 'report.json'}, {out / 'report.md'}, {out / 'report.html'}")
    print(report.status_line)
    return EXIT_OK


def _design(args) -> int:
    samples = [args.target_samples] if args.target_samples else []
    _input_files(args.data, "DATA")
    _input_files(args.validate or [], "--validate")
    _input_files(samples, "--target-samples")
    try:
        hidden = tuple(int(h) for h in args.hidden.split(",") if h.strip())
    except ValueError:
        hidden = ()
    if not hidden or min(hidden) < 1:
        raise UsageError(f"--hidden expects positive integers like 3,6,10; got {args.hidden!r}.")
    inputs = [s.strip() for s in args.inputs.split(",") if s.strip()] if args.inputs else None
    if args.inputs is not None and not inputs:
        raise UsageError("--inputs is empty; give signal names like T_chassis,v_m or leave it out.")
    signals = _signals(args)
    folder = ReportFolder(args.out, [*args.data, *(args.validate or []), *samples])
    _x64()
    import jaxvs

    raw = args.delimiter == "," and args.decimal == "." and args.encoding == "utf-8"

    def records(paths):
        if raw:
            return list(paths)  # design reads sparse (NaN) targets from the files itself
        return _load(paths, args)  # renamed by --signal / --time here

    _interrupt.stage("loading the data")
    cal = records(args.data)
    val = records(args.validate) if args.validate else None
    _interrupt.stage("searching designs")
    _interrupt.set_grace(15.0)  # an interrupted search still writes its ranked designs
    same = ("budget", "target_samples", "max_inputs", "max_delay", "inits", "holdout", "seed")
    report = jaxvs.design(
        cal,
        target=args.target,
        inputs=inputs,
        validation=val,
        hidden=hidden,
        progress=False if args.quiet else None,
        signals=(signals or None) if raw else None,
        **{name: getattr(args, name) for name in same},
    )
    interrupted = bool(report["interrupted"])
    _interrupt.stage("writing the partial report" if interrupted else "writing the report")
    from .plotting import plot_design

    report.save(folder.prepare(), figures=None if args.no_figures else plot_design)
    out = folder.commit()
    if not args.quiet and not interrupted:
        print(report.to_markdown())
    written = f"{out / 'report.json'}, {out / 'report.md'}, {out / 'report.html'}" + (
        f", {out / 'best.eqx'}" if report.best_model is not None else ""
    )
    if interrupted:
        n = len(report.designs)
        return _interrupt.finish(
            EXIT_INTERRUPTED,
            f"jaxvs design: interrupted; the {n} design(s) ranked so far were written: {written}.",
        )
    print(f"written: {written}")
    return EXIT_NOT_IDENTIFIABLE if report.content.get("not_identifiable") else EXIT_OK


def _demo(args) -> int:
    folder = ReportFolder(args.out)
    _x64()
    from ._demo import run_demo

    staging = folder.prepare()
    code, written, seconds = run_demo(staging, n_positions=args.positions, seed=args.seed)
    folder.commit()
    print(f"wrote {', '.join(str(folder.out / w) for w in written)} ({seconds:.1f} s)")
    return code


_COMMANDS = {"demo": _demo, "diagnose": _diagnose, "check": _check, "design": _design}


def _compilation_cache() -> None:
    """Keep XLA's compiled code between runs of the command (a program may configure JAX;
    the library never does): a second `jaxvs diagnose` on data of the same size skips the
    compilation. `JAXVS_NO_CACHE=1` switches it off, `JAX_COMPILATION_CACHE_DIR` moves it."""
    if os.environ.get("JAXVS_NO_CACHE"):
        return
    from ._cache import enable_compilation_cache

    enable_compilation_cache()


def _one_line(err: BaseException) -> str:
    if isinstance(err, KeyError) and err.args and isinstance(err.args[0], str):
        text = err.args[0]  # str(KeyError) would quote the message
    elif isinstance(err, OSError) and err.strerror:
        where = f" {err.filename}" if err.filename else ""
        text = f"{err.strerror}:{where}; check the path and its permissions"
    else:
        text = str(err) or type(err).__name__
    return " ".join(text.split())


# User errors: bad options, paths, files and data (exit code 2, one line).
_USER_ERRORS = (UsageError, ValueError, TypeError, KeyError, OSError, UnicodeError)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    try:
        args = _parser().parse_args(argv)
    except UsageError as err:
        message = _one_line(err)
        command = next((a for a in argv if a in _COMMANDS), None)
        if command:  # argparse reports unknown options at the top level
            message = message.replace("'jaxvs --help'", f"'jaxvs {command} --help'")
        print(f"jaxvs: error: {message}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        return _interrupt.finish(EXIT_INTERRUPTED, "jaxvs: interrupted; nothing was written.")
    _interrupt.begin(args.command)
    holding = held()
    try:
        _interrupt.stage("checking the options and files")
        if args.command != "check":
            _compilation_cache()
        with _memory.limit(getattr(args, "max_memory", None)):
            code = _COMMANDS[args.command](args)
        _interrupt.done()
        return code
    except KeyboardInterrupt:
        return _interrupt.finish(EXIT_INTERRUPTED, _interrupt.line())
    except Exception:
        if _interrupt.was_interrupted():  # the interrupt, wrapped by XLA on its way out
            return _interrupt.finish(EXIT_INTERRUPTED, _interrupt.line())
        code = _error(debug)
        _interrupt.done()
        return code
    finally:
        release_all(since=holding)


def _error(debug: bool) -> int:
    """One line for the exception being handled: a user error (2) or a bug (1)."""
    err = sys.exc_info()[1]
    _interrupt.discard_staging()
    if debug:
        traceback.print_exc()
    if isinstance(err, _USER_ERRORS):
        print(f"jaxvs: error: {_one_line(err)}", file=sys.stderr)
        return EXIT_USAGE
    print(  # a bug: one line, the traceback with --debug
        f"jaxvs: internal error: {type(err).__name__}: {_one_line(err)} (run again with "
        "--debug for the traceback, and please report it)",
        file=sys.stderr,
    )
    return EXIT_INTERNAL


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
