"""Render the three `report.html` files in a real headless browser and save screenshots
into the docs (`docs/img/report_{diagnose,design,check}.png`).

Run with `make screenshots` (it installs Chromium from the system packages when it is
missing) or directly:

    python docs/screenshot_reports.py [--keep DIR [--reuse]]

It writes the three reports with the `jaxvs` command on small twin records (a thermal
diagnosis with a hidden heat capacity, a thermal virtual-sensor design, a check of a
drive record with a clipped force), loads each `report.html` from disk in headless
Chromium with the network switched off (so a page that needed anything from elsewhere
would show it), and saves a screenshot of the top of each page. It fails when no
Chromium is found, when a report is missing, or when a screenshot is not written.
"""

from __future__ import annotations

import argparse
import pathlib
import shutil
import subprocess
import sys
import tempfile

HERE = pathlib.Path(__file__).resolve().parent
IMG = HERE / "img"
# window heights [px]: the diagnosis down to its collapsed search rounds and first figure
HEIGHTS = {"diagnose": 2900, "design": 1500, "check": 650}
BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome")


def find_browser() -> str:
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    sys.exit(
        "screenshot_reports: no Chromium found (looked for "
        + ", ".join(BROWSERS)
        + "). Install it from the system packages, e.g. `apt-get install chromium`, or run "
        "`make screenshots`, which tries that for you."
    )


def write_reports(root: pathlib.Path) -> dict[str, pathlib.Path]:
    """The three report folders, written by the `jaxvs` command."""
    import jax
    import jax.random as jr
    import numpy as np

    from jaxvs._cli import main
    from jaxvs.data import Record, save_csv
    from jaxvs.twins import SpindleThermalTwin

    jax.config.update("jax_enable_x64", True)
    thermal = SpindleThermalTwin(effects={"dynamics": 600.0}).experiment(
        jr.key(11), duration=4 * 3600.0
    )
    save_csv(thermal, root / "spindle.csv")
    fs, n = 1000.0, 3000
    t = np.arange(n) / fs
    q = 0.01 * np.sin(2 * np.pi * 0.7 * t) + 0.004 * np.sin(2 * np.pi * 3.1 * t + 1.0)
    v = np.gradient(q, 1 / fs)
    u = 95.0 * np.gradient(v, 1 / fs) + 200.0 * v - 3.0
    u = np.clip(u + 0.5 * np.random.default_rng(0).standard_normal(n), -20.0, 20.0)
    save_csv(Record({"q": q, "u": u}, dt=1 / fs, units={"q": "m", "u": "N"}), root / "axis.csv")
    runs = {
        "diagnose": (
            ["diagnose", str(root / "spindle.csv"), "--family", "thermal", "--max-effects", "1"],
            (0,),
        ),
        "design": (
            ["design", str(root / "spindle.csv"), "--target", "T_bearing"]
            + ["--hidden", "3", "--inits", "1"],
            (0,),
        ),
        "check": (["check", str(root / "axis.csv"), "--family", "drive"], (0,)),
    }
    out = {}
    for name, (argv, ok) in runs.items():
        folder = root / name
        print(f"screenshot_reports: jaxvs {' '.join(argv[:1])} ...", flush=True)
        code = main([*argv, "--out", str(folder)] + (["--quiet"] if name != "check" else []))
        if code not in ok or not (folder / "report.html").is_file():
            sys.exit(f"screenshot_reports: jaxvs {name} exited with {code} / no report.html")
        out[name] = folder / "report.html"
    return out


def screenshot(browser: str, page: pathlib.Path, png: pathlib.Path, height: int) -> None:
    png.unlink(missing_ok=True)
    cmd = [
        browser,
        "--headless",
        "--no-sandbox",  # root in a container: Chromium's sandbox needs user namespaces
        "--disable-gpu",
        "--hide-scrollbars",
        "--no-first-run",
        # offline: a page that fetched anything would render with holes
        "--proxy-server=127.0.0.1:9",
        "--proxy-bypass-list=<-loopback>",
        f"--window-size=1200,{height}",
        f"--screenshot={png}",
        page.as_uri(),
    ]
    subprocess.run(cmd, check=True, capture_output=True, timeout=120)
    if not png.is_file() or png.stat().st_size < 10_000:
        sys.exit(f"screenshot_reports: {browser} wrote no screenshot of {page}")
    print(f"screenshot_reports: wrote {png} ({png.stat().st_size // 1024} KiB)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", default=None, help="keep the report folders here")
    parser.add_argument(
        "--reuse", action="store_true", help="screenshot the reports already in --keep"
    )
    args = parser.parse_args()
    if args.reuse and not args.keep:
        parser.error("--reuse needs --keep DIR (where the reports are)")
    browser = find_browser()
    version = subprocess.run([browser, "--version"], capture_output=True, text=True).stdout
    print(f"screenshot_reports: {version.strip() or browser}")
    root = pathlib.Path(args.keep or tempfile.mkdtemp(prefix="jaxvs-reports-"))
    root.mkdir(parents=True, exist_ok=True)
    if args.reuse:
        pages = {n: root / n / "report.html" for n in HEIGHTS}
        missing = [str(p) for p in pages.values() if not p.is_file()]
        if missing:
            sys.exit(f"screenshot_reports: --reuse: no {', '.join(missing)}")
    else:
        pages = write_reports(root)
    IMG.mkdir(exist_ok=True)
    for name, page in pages.items():
        screenshot(browser, page, IMG / f"report_{name}.png", HEIGHTS[name])
    if args.keep is None:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
