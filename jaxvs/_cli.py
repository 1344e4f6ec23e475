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
    return p


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.command == "demo":
        from ._demo import run_demo

        return run_demo(out=args.out, n_positions=args.positions, seed=args.seed)
    return 2  # pragma: no cover - argparse enforces the sub-command


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
