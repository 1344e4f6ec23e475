"""The `jaxvs` command."""

import argparse
import sys

import jaxvs


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="jaxvs",
        description="Virtual sensors of machine tools and sim-to-real gap diagnosis (JAX).",
    )
    p.add_argument("--version", action="version", version=f"jaxvs {jaxvs.__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    demo = sub.add_parser(
        "demo",
        help="end-to-end run on the embedded machine-structure twin (no download)",
        description=(
            "Identify the encoder-to-TCP transmissibility (TMF) of a position-dependent "
            "machine-structure twin at several positions of the other axis from PRBS "
            "excitation data, calibrate the whole TMF family in one vectorised call, "
            "print a summary and write it with a Bode figure to --out."
        ),
    )
    demo.add_argument("--out", default="demo-report", help="output folder (created)")
    demo.add_argument("--positions", type=int, default=8, help="number of Y positions")
    demo.add_argument("--seed", type=int, default=0, help="noise seed")

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
    diag.add_argument("data", nargs="+", help="calibration experiment file(s)")
    diag.add_argument("--family", required=True, choices=["drive", "tmf", "thermal"])
    diag.add_argument("--validate", nargs="+", default=None, help="validation experiment file(s)")
    diag.add_argument("--out", required=True, help="output folder (created)")
    diag.add_argument(
        "--holdout", type=float, default=0.3, help="share held out without --validate"
    )
    diag.add_argument("--max-effects", type=int, default=3, help="most effects added")
    diag.add_argument("--seed", type=int, default=0, help="bootstrap seed")
    diag.add_argument("--order", type=int, default=None, help="tmf: TMF order (default 4)")
    diag.add_argument("--cutoff-hz", type=float, default=None, help="drive: low-pass cut-off [Hz]")
    diag.add_argument(
        "--option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="further family option (repeatable), e.g. --option decimation=4",
    )
    diag.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    diag.add_argument("--quiet", action="store_true", help="no progress messages")

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
    chk.add_argument("data", nargs="+", help="experiment file(s)")
    chk.add_argument("--family", required=True, choices=["drive", "tmf", "thermal"])
    chk.add_argument(
        "--out", default=None, help="folder for report.json, report.md and report.html"
    )
    chk.add_argument(
        "--option", action="append", default=[], metavar="KEY=VALUE", help="family option"
    )
    des = sub.add_parser(
        "design",
        help="search inputs, delays and model structures for a virtual sensor and rank them",
        description=(
            "Search candidate inputs, their delays and model structures (static regression, "
            "first-order lag, ARX, static network, TDNN) for a virtual sensor of --target in "
            "one vectorised run, rank the designs on held-out data (whole experiments or a "
            "contiguous block), and write report.json, report.md, report.html, figures and "
            "best.eqx (jaxvs.load_model) to --out. The target may be sparse: empty/NaN cells "
            "between measurements, or --target-samples."
        ),
    )
    des.add_argument("data", nargs="+", help="calibration experiment file(s)")
    des.add_argument("--target", required=True, help="name of the signal to predict")
    des.add_argument(
        "--inputs", default=None, help="candidate inputs A,B,... (default: all other signals)"
    )
    des.add_argument("--validate", nargs="+", default=None, help="held-out experiment file(s)")
    des.add_argument("--out", required=True, help="output folder (replaced atomically)")
    des.add_argument("--budget", type=float, default=None, help="search time limit [s]")
    des.add_argument(
        "--target-samples", default=None, help="file of sparse target samples (t, target)"
    )
    des.add_argument("--max-inputs", type=int, default=4, help="size of the input pool")
    des.add_argument("--max-delay", type=int, default=2, help="largest input delay [samples]")
    des.add_argument("--hidden", default="3,6,10,15", help="network hidden sizes (comma separated)")
    des.add_argument("--inits", type=int, default=3, help="initialisations per network")
    des.add_argument("--holdout", type=float, default=0.3, help="share held out (one record)")
    des.add_argument("--seed", type=int, default=0, help="initialisation and bootstrap seed")
    des.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    des.add_argument("--quiet", action="store_true", help="no progress messages")
    return p


def _check(args) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    import pathlib

    for f in args.data:
        if not pathlib.Path(f).exists():
            print(f"jaxvs check: no such file: {f}", file=sys.stderr)
            return 2
    options = dict(_parse_option(o) for o in args.option)
    try:
        report = jaxvs.check(list(args.data), family=args.family, **options)
    except (ValueError, TypeError, KeyError) as err:
        print(f"jaxvs check: {err}", file=sys.stderr)
        return 2
    if args.out:
        report.save(args.out)
    print(report.to_markdown())
    return report.exit_code


def _parse_option(text: str) -> tuple[str, object]:
    if "=" not in text or not text.split("=", 1)[0].strip():
        raise ValueError(f"--option expects KEY=VALUE, got {text!r}")
    key, value = text.split("=", 1)
    for cast in (int, float):
        try:
            return key.strip(), cast(value)
        except ValueError:
            pass
    return key.strip(), value


def _user_error(message: str) -> int:
    """A user error: one line on stderr, exit code 2 (DESIGN.md §3.2)."""
    print(f"jaxvs: error: {' '.join(str(message).split())}", file=sys.stderr)
    return 2


def _diagnose(args) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)  # calibration in float64 (a program may)
    import pathlib

    try:
        options = dict(_parse_option(o) for o in args.option)
    except ValueError as err:
        return _user_error(str(err))
    if args.order is not None:
        options["order"] = args.order
    if args.cutoff_hz is not None:
        options["cutoff_hz"] = args.cutoff_hz
    for f in list(args.data) + list(args.validate or []):
        if not pathlib.Path(f).exists():
            return _user_error(f"no such file: {f}")
    try:
        report = jaxvs.diagnose(
            list(args.data),
            list(args.validate) if args.validate else None,
            family=args.family,
            holdout=args.holdout,
            max_effects=args.max_effects,
            seed=args.seed,
            progress=not args.quiet,
            **options,
        )
    except (ValueError, TypeError) as err:
        return _user_error(str(err))
    out = pathlib.Path(args.out)
    if report.content.get("not_identifiable"):
        report.save(out)
        print(f"jaxvs: not identifiable: {report.content['not_identifiable']}", file=sys.stderr)
        print(f"written: {out / 'report.json'}, {out / 'report.md'}, {out / 'report.html'}")
        return 3
    if not args.no_figures:
        from .plotting import plot_diagnosis

        report.content["figures"] = plot_diagnosis(report, out)
    report.save(out)
    print(report.to_markdown())
    print(f"written: {out / 'report.json'}, {out / 'report.md'}, {out / 'report.html'}")
    return 0


def _design(args) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)  # a program may; the library never does
    import pathlib

    for f in list(args.data) + list(args.validate or []) + [args.target_samples or ""]:
        if f and not pathlib.Path(f).exists():
            print(f"jaxvs: error: no such file: {f}", file=sys.stderr)
            return 2
    try:
        hidden = tuple(int(h) for h in args.hidden.split(",") if h.strip())
    except ValueError:
        print(
            f"jaxvs: error: --hidden expects integers like 3,6,10; got {args.hidden!r}",
            file=sys.stderr,
        )
        return 2
    inputs = [s.strip() for s in args.inputs.split(",") if s.strip()] if args.inputs else None
    try:
        report = jaxvs.design(
            list(args.data),
            target=args.target,
            inputs=inputs,
            validation=list(args.validate) if args.validate else None,
            budget=args.budget,
            target_samples=args.target_samples,
            max_inputs=args.max_inputs,
            max_delay=args.max_delay,
            hidden=hidden,
            inits=args.inits,
            holdout=args.holdout,
            seed=args.seed,
            progress=False if args.quiet else None,
        )
    except (ValueError, TypeError) as err:
        print(f"jaxvs: error: {err}", file=sys.stderr)
        return 2
    out = report.save(args.out, figures=not args.no_figures)
    if not args.quiet:
        print(report.to_markdown())
    print(
        f"written: {out / 'report.json'}, {out / 'report.md'}, {out / 'report.html'}"
        + (f", {out / 'best.eqx'}" if report.best_model is not None else "")
    )
    if report["interrupted"]:
        print("jaxvs design: interrupted; the designs ranked so far were written.", file=sys.stderr)
        return 130
    return 3 if report.content.get("not_identifiable") else 0


def _compilation_cache() -> None:
    """Keep XLA's compiled code between runs of the command (a program may configure JAX;
    the library never does): a second `jaxvs diagnose` on data of the same size skips the
    compilation. `JAXVS_NO_CACHE=1` switches it off, `JAX_COMPILATION_CACHE_DIR` moves it."""
    import os

    if os.environ.get("JAXVS_NO_CACHE"):
        return
    import jax

    path = os.environ.get("JAX_COMPILATION_CACHE_DIR") or os.path.join(
        os.path.expanduser("~"), ".cache", "jaxvs", "xla"
    )
    try:
        os.makedirs(path, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", path)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    except (OSError, AttributeError):  # read-only home or an older jax: run without cache
        pass


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.command in ("demo", "diagnose", "design"):
        _compilation_cache()
    if args.command == "demo":
        from ._demo import run_demo

        return run_demo(out=args.out, n_positions=args.positions, seed=args.seed)
    if args.command == "check":
        try:
            return _check(args)
        except KeyboardInterrupt:
            print("jaxvs check: interrupted; nothing was written.", file=sys.stderr)
            return 130
    if args.command == "diagnose":
        try:
            return _diagnose(args)
        except KeyboardInterrupt:
            print("jaxvs diagnose: interrupted; nothing was written.", file=sys.stderr)
            return 130
    if args.command == "design":
        try:
            return _design(args)
        except KeyboardInterrupt:
            print("jaxvs design: interrupted; nothing was written.", file=sys.stderr)
            return 130
    return 2  # pragma: no cover - argparse enforces the sub-command


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
