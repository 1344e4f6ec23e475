r"""Public system-identification benchmarks as data: a task is its files, its split, its
input and output signals, its initialisation window and its metric, so that one runner
scores any model on it and writes the same JSON + markdown table.

The convention is that of the nonlinear system-identification benchmark suite
(`nonlinear_benchmarks`, Schoukens & Beintema, the split behind the identibench tables):
a model receives the **whole input** of a test record and the **first `init_window`
samples of its output** (to estimate its initial state), predicts the output over the
whole record by free-run simulation, and is scored on the samples after the window only.

A task admits what the public benchmarks need:

- several training and several test records ([`Segment`][]: a file, optionally a sample
  range of it, e.g. Wiener–Hammerstein's `[5200:184000]` split at 100 000, or Silverbox's
  arrow and multisine parts);
- several inputs and outputs (the industrial robot: six torques, six joint angles);
- a per-task initialisation window (EMPS 20, cascaded tanks 5, Silverbox and
  Wiener–Hammerstein 50 samples);
- RMSE in the output's unit (optionally rescaled for display, e.g. m → mm), the RMSE
  normalised by the standard deviation of the measured output (NRMSE), and the relative
  error `100 ‖y − ŷ‖ / ‖y‖` [%] of the EMPS description (Janot, Gautier, Brunot 2019,
  eq. (11)).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ...data import Record

__all__ = [
    "BenchmarkTask",
    "ExperimentScore",
    "ModelReport",
    "PublishedResult",
    "Segment",
    "SealedTestSplit",
    "TestSplitSealedError",
    "TaskData",
    "TaskScore",
    "markdown_table",
    "nrmse",
    "relative_error",
    "rmse",
    "score_predictor",
    "write_report",
]


# ----------------------------------------------------------------------------- metrics


def _pair(y_true: Any, y_pred: Any, where: str) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(y_true, dtype=np.float64)
    b = np.asarray(y_pred, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(
            f"{where}: y_true has shape {a.shape} but y_pred has {b.shape}; give one "
            "prediction per measured sample (time first, outputs second)."
        )
    if a.ndim not in (1, 2) or a.shape[0] == 0:
        raise ValueError(
            f"{where}: expected a non-empty (time,) or (time, output) array; got {a.shape}."
        )
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise ValueError(
            f"{where}: NaN or inf in the signals (a diverged simulation?); a score needs "
            "finite values."
        )
    return a, b


def rmse(y_true: Any, y_pred: Any) -> np.ndarray:
    r"""Root-mean-square error `sqrt(mean_k (y_k − ŷ_k)²)` per output, in the output's unit.

    **Arguments:**

    - `y_true`, `y_pred`: `(time,)` or `(time, output)` arrays of the same shape.

    **Returns:**

    A scalar for 1-D input, else one value per output.
    """
    a, b = _pair(y_true, y_pred, "rmse")
    return np.sqrt(np.mean((a - b) ** 2, axis=0))


def nrmse(y_true: Any, y_pred: Any) -> np.ndarray:
    r"""RMSE divided by the (population) standard deviation of the measured output, per
    output (dimensionless; 1 is the error of predicting the mean).

    **Arguments:**

    - `y_true`, `y_pred`: `(time,)` or `(time, output)` arrays of the same shape.

    **Returns:**

    A scalar for 1-D input, else one value per output.

    **Raises:**

    `ValueError` when a measured output is constant (its NRMSE is undefined).
    """
    a, b = _pair(y_true, y_pred, "nrmse")
    sd = np.std(a, axis=0)
    if np.any(sd == 0):
        raise ValueError("nrmse: a measured output is constant; its NRMSE is undefined.")
    return np.sqrt(np.mean((a - b) ** 2, axis=0)) / sd


def relative_error(y_true: Any, y_pred: Any) -> np.ndarray:
    r"""Relative error `100 ‖y − ŷ‖₂ / ‖y‖₂` [%] per output (Janot, Gautier, Brunot 2019,
    *Data set and reference models of EMPS*, eq. (11)).

    **Arguments:**

    - `y_true`, `y_pred`: `(time,)` or `(time, output)` arrays of the same shape.

    **Returns:**

    A scalar for 1-D input, else one value per output [%].

    **Raises:**

    `ValueError` when a measured output is identically zero.
    """
    a, b = _pair(y_true, y_pred, "relative_error")
    norm = np.linalg.norm(a, axis=0)
    if np.any(norm == 0):
        raise ValueError("relative_error: a measured output is zero; ‖y‖ = 0.")
    return 100 * np.linalg.norm(a - b, axis=0) / norm


# ----------------------------------------------------------------------------- task


@dataclasses.dataclass(frozen=True)
class Segment:
    """One record of a benchmark split: a file, or the sample range `[start, stop)` of it.

    **Arguments:**

    - `file`: file name inside the benchmark's data folder.
    - `name`: label in tables (default: the file name, with the range when one is given).
    - `start`, `stop`: sample range (Python slice semantics; `stop=None` = to the end).
    - `samples`: expected number of samples of the segment (checked on load; `None` = no
      check). Catches a truncated download or a different version of the file.
    - `sha256`: SHA-256 of the published file (checked on load; `None` = no check).
      Catches an edited file and two files of a task swapped under each other's names.
    """

    file: str
    name: str | None = None
    start: int = 0
    stop: int | None = None
    samples: int | None = None
    sha256: str | None = None

    def __post_init__(self):
        if not isinstance(self.file, str) or not self.file:
            raise TypeError(f"Segment: file must be a non-empty file name; got {self.file!r}.")
        if not isinstance(self.start, int) or self.start < 0:
            raise ValueError(f"Segment: start must be an int >= 0; got {self.start!r}.")
        if self.stop is not None and (not isinstance(self.stop, int) or self.stop <= self.start):
            raise ValueError(
                f"Segment: stop must be None or an int > start ({self.start}); got {self.stop!r}."
            )
        if self.samples is not None and (not isinstance(self.samples, int) or self.samples < 1):
            raise ValueError(f"Segment: samples must be None or an int >= 1; got {self.samples!r}.")

    @property
    def label(self) -> str:
        if self.name is not None:
            return self.name
        if self.start == 0 and self.stop is None:
            return self.file
        return f"{self.file}[{self.start}:{'' if self.stop is None else self.stop}]"


@dataclasses.dataclass(frozen=True)
class TaskData:
    """The records of a task, loaded: `train` and `test` are tuples of `Record`s in the
    order of the task's segments; `labels_*` name them."""

    train: tuple[Record, ...]
    test: tuple[Record, ...]
    labels_train: tuple[str, ...]
    labels_test: tuple[str, ...]


@dataclasses.dataclass(frozen=True)
class BenchmarkTask:
    r"""A benchmark task: which records train, which test, what is input and output, how
    many output samples initialise the state, and how results are shown.

    **Arguments:**

    - `name`: short name (`"EMPS"`).
    - `loader`: `loader(path) -> Record` for one file of the benchmark (e.g.
      `jaxvs.data.load_emps`); it gives the signals their jaxvs names and SI units.
    - `train`, `test`: [`Segment`][]s of the training and the test records (at least one
      each).
    - `inputs`, `outputs`: signal names in the loaded records (model input `u`, output `y`).
    - `init_window`: number of leading output samples of each record a model may use to
      initialise its state (not scored), >= 0.
    - `sample_time`: the sampling period [s] the files must have (checked on load).
    - `output_units`: the unit of each output in the records (SI, e.g. `("m",)`).
    - `display_scale`, `display_unit`: factor and unit for tables (`1e3`, `"mm"`).
    - `description`: one paragraph: what the system is and what the task asks.
    - `source`: the citation of the data set and of the split.
    """

    name: str
    loader: Callable[[Path], Record]
    train: tuple[Segment, ...]
    test: tuple[Segment, ...]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    init_window: int
    sample_time: float
    output_units: tuple[str, ...]
    display_scale: float = 1.0
    display_unit: str | None = None
    description: str = ""
    source: str = ""

    def __post_init__(self):
        where = f"BenchmarkTask({self.name!r})"
        if not callable(self.loader):
            raise TypeError(f"{where}: loader must be a function path -> Record.")
        for field in ("train", "test", "inputs", "outputs", "output_units"):
            value = getattr(self, field)
            if isinstance(value, str) or not isinstance(value, tuple) or not value:
                raise TypeError(f"{where}: {field} must be a non-empty tuple; got {value!r}.")
        for seg in self.train + self.test:
            if not isinstance(seg, Segment):
                raise TypeError(f"{where}: train and test must hold Segments; got {seg!r}.")
        if len(self.output_units) != len(self.outputs):
            raise ValueError(
                f"{where}: one unit per output: {len(self.outputs)} outputs, "
                f"{len(self.output_units)} units."
            )
        if not isinstance(self.init_window, int) or self.init_window < 0:
            raise ValueError(f"{where}: init_window must be an int >= 0; got {self.init_window!r}.")
        if not self.sample_time > 0:
            raise ValueError(f"{where}: sample_time must be > 0 s; got {self.sample_time!r}.")
        if not self.display_scale > 0:
            raise ValueError(f"{where}: display_scale must be > 0; got {self.display_scale!r}.")

    @property
    def unit(self) -> str:
        """The unit of the displayed errors."""
        return self.display_unit or self.output_units[0]

    def load(self, folder: str | Path) -> TaskData:
        """Load every training and test record from the benchmark's data folder.

        **Arguments:**

        - `folder`: the folder holding the benchmark's files.

        **Returns:**

        A [`TaskData`][].

        **Raises:**

        `FileNotFoundError` naming the missing file; `ValueError` when a record lacks a
        signal of the task, has another sampling period or another number of samples.
        """
        folder = Path(folder)
        if not folder.is_dir():
            raise FileNotFoundError(
                f"{self.name}: data folder {str(folder)!r} does not exist; point the task at "
                f"the folder holding {sorted({s.file for s in self.train + self.test})}."
            )
        cache: dict[str, Record] = {}
        digests = {s.sha256: s.file for s in self.train + self.test if s.sha256}

        def check_digest(seg: Segment, path: Path) -> None:
            if seg.sha256 is None:
                return
            digest = hashlib.sha256(path.read_bytes()).hexdigest()
            if digest == seg.sha256:
                return
            other = digests.get(digest)
            if other is not None:
                raise ValueError(
                    f"{self.name}: {str(path)!r} holds the benchmark's {other!r}, not "
                    f"{seg.file!r}: the files are swapped (or copied under the other name). "
                    "Give each file its published name; training on the test file would "
                    "report a figure the test data chose."
                )
            raise ValueError(
                f"{self.name}: {str(path)!r} is not the benchmark's published {seg.file!r} "
                "(its content differs: an edited, re-saved or other version of the file). "
                "Use the benchmark's original files."
            )

        def one(seg: Segment) -> Record:
            path = folder / seg.file
            if not path.is_file():
                raise FileNotFoundError(
                    f"{self.name}: {seg.file!r} is not in {str(folder)!r}; the task needs "
                    f"{sorted({s.file for s in self.train + self.test})}."
                )
            if seg.file not in cache:
                check_digest(seg, path)
                cache[seg.file] = self.loader(path)
            rec = cache[seg.file]
            missing = [n for n in self.inputs + self.outputs if n not in rec]
            if missing:
                raise ValueError(
                    f"{self.name}: {seg.file!r} has no signal {missing} (it has "
                    f"{list(rec.names)}); check the task's loader and signal names."
                )
            if not math.isclose(rec.dt, self.sample_time, rel_tol=1e-6):
                raise ValueError(
                    f"{self.name}: {seg.file!r} is sampled every {rec.dt:.6g} s; the task is "
                    f"defined at {self.sample_time:.6g} s. Use the benchmark's original files."
                )
            if seg.stop is not None and seg.stop > len(rec):
                raise ValueError(
                    f"{self.name}: segment {seg.label} ends at sample {seg.stop} but the "
                    f"file has {len(rec)} samples."
                )
            if seg.start != 0 or seg.stop is not None:
                rec = rec.slice(seg.start, seg.stop)
            if seg.samples is not None and len(rec) != seg.samples:
                raise ValueError(
                    f"{self.name}: {seg.label} has {len(rec)} samples; the benchmark's file "
                    f"has {seg.samples}. Use the benchmark's original, complete files."
                )
            if len(rec) <= self.init_window:
                raise ValueError(
                    f"{self.name}: {seg.label} has {len(rec)} samples, not more than the "
                    f"initialisation window ({self.init_window})."
                )
            return rec

        return TaskData(
            train=tuple(one(s) for s in self.train),
            test=tuple(one(s) for s in self.test),
            labels_train=tuple(s.label for s in self.train),
            labels_test=tuple(s.label for s in self.test),
        )

    def arrays(self, record: Record) -> tuple[np.ndarray, np.ndarray]:
        """`(u, y)` of a record as `(time, input)` and `(time, output)` float64 arrays."""
        return record.to_array(self.inputs), record.to_array(self.outputs)

    def score(self, y_true: Any, y_pred: Any) -> dict[str, list[float]]:
        """Metrics of one record's prediction on the samples after the initialisation
        window: `rmse` (in the display unit), `nrmse` [-], `relative_error` [%], one value
        per output.

        **Arguments:**

        - `y_true`, `y_pred`: `(time, output)` measured and predicted outputs of the whole
          record (the first `init_window` samples are ignored).
        """
        a = np.asarray(y_true, dtype=np.float64)
        b = np.asarray(y_pred, dtype=np.float64)
        if a.ndim == 1:
            a = a[:, None]
        if b.ndim == 1:
            b = b[:, None]
        if b.shape != a.shape:
            raise ValueError(
                f"{self.name}: the prediction has shape {b.shape}; the record's output has "
                f"{a.shape} (time, output). Predict every sample, the initialisation window "
                "included (its values are not scored)."
            )
        a, b = a[self.init_window :], b[self.init_window :]
        return {
            "rmse": [float(x) for x in self.display_scale * rmse(a, b)],
            "nrmse": [float(x) for x in nrmse(a, b)],
            "relative_error": [float(x) for x in relative_error(a, b)],
        }


# ----------------------------------------------------------------------------- scoring


@dataclasses.dataclass(frozen=True)
class ExperimentScore:
    """Scores of one record: `metrics[name]` has one value per output (see
    [`BenchmarkTask.score`][]); `predict_s` is the wall time of the prediction [s] (for a
    jitted model the first record's includes its compilation)."""

    label: str
    metrics: Mapping[str, list[float]]
    predict_s: float


@dataclasses.dataclass(frozen=True)
class TaskScore:
    """Scores of a predictor on every training and test record of a task."""

    train: tuple[ExperimentScore, ...]
    test: tuple[ExperimentScore, ...]

    def mean(self, metric: str = "rmse", split: str = "test") -> float:
        """The metric averaged over the split's records and outputs."""
        scores = self.test if split == "test" else self.train
        return float(np.mean([v for s in scores for v in s.metrics[metric]]))

    def to_json(self) -> dict[str, Any]:
        return {
            split: [dataclasses.asdict(s) for s in getattr(self, split)]
            for split in ("train", "test")
        }


Predictor = Callable[[Any, Any], Any]


def score_predictor(task: BenchmarkTask, predictor: Predictor, data: TaskData) -> TaskScore:
    r"""Score a model on every record of a task by free-run prediction.

    For each record, `predictor(u, y_init)` receives the whole input `u`
    (`(time, input)` array) and the first `task.init_window` output samples `y_init`
    (`(init_window, output)`), and returns the predicted output of every sample
    (`(time, output)`); the samples after the window are scored. The predictor never sees
    the rest of the measured output.

    **Arguments:**

    - `task`: the [`BenchmarkTask`][].
    - `predictor`: any callable (a function, or an `eqx.Module` with `__call__`).
    - `data`: the task's records ([`BenchmarkTask.load`][]).

    **Returns:**

    A [`TaskScore`][].

    **Raises:**

    `TypeError` when `predictor` is not callable; `ValueError` when its prediction has the
    wrong shape or is not finite.
    """
    if not callable(predictor):
        raise TypeError(
            f"score_predictor: the model must be callable as model(u, y_init) -> y; got "
            f"{type(predictor).__name__}."
        )

    def one(record: Record, label: str) -> ExperimentScore:
        u, y = task.arrays(record)
        start = time.perf_counter()
        y_hat = np.asarray(predictor(u, y[: task.init_window]))
        elapsed = time.perf_counter() - start
        return ExperimentScore(label, task.score(y, y_hat), elapsed)

    return TaskScore(
        train=tuple(one(r, n) for r, n in zip(data.train, data.labels_train)),
        test=tuple(one(r, n) for r, n in zip(data.test, data.labels_test)),
    )


class TestSplitSealedError(RuntimeError):
    """Raised when a test record is scored (or read) before the model is selected."""


class SealedTestSplit:
    r"""A task's records with the test split sealed until one model is selected.

    The guard of an honest benchmark: everything that chooses (structure, options,
    hyper-parameters, when to stop) sees only `.train`; `.select(name, evidence)` records
    the choice and the training-data evidence it rests on, once; only then does
    `.score(model)` run a model on the test records. Scoring, or reading, the test split
    earlier raises [`TestSplitSealedError`][], and a second selection is refused, so the
    reported test figure is the first and only one of the model chosen without it.

    **Arguments:**

    - `task`: the [`BenchmarkTask`][].
    - `data`: its loaded records ([`BenchmarkTask.load`][]).
    """

    def __init__(self, task: BenchmarkTask, data: TaskData):
        if not isinstance(task, BenchmarkTask) or not isinstance(data, TaskData):
            raise TypeError(
                "SealedTestSplit(task, data): give a BenchmarkTask and the TaskData that "
                "task.load(folder) returned."
            )
        self.task = task
        self._data = data
        self._selected: str | None = None
        self._evidence: dict[str, Any] = {}

    @classmethod
    def load(cls, task: BenchmarkTask, folder: str | Path) -> SealedTestSplit:
        """Load a task's records ([`BenchmarkTask.load`][]) and seal their test split."""
        return cls(task, task.load(folder))

    @property
    def train(self) -> TaskData:
        """The training records only (the test split is empty): all that selection sees."""
        d = self._data
        return TaskData(d.train, (), d.labels_train, ())

    @property
    def selected(self) -> str | None:
        """The name of the selected model (`None` while the split is sealed)."""
        return self._selected

    @property
    def evidence(self) -> dict[str, Any]:
        """The training-data evidence recorded with the selection."""
        return dict(self._evidence)

    def select(self, name: str, evidence: Mapping[str, Any] | None = None) -> None:
        """Record the selected model (once) and unseal the test split.

        **Arguments:**

        - `name`: the selected model, as reported.
        - `evidence`: the training-data figures the choice rests on (e.g. held-out errors
          of every candidate), kept for the report.

        **Raises:**

        [`TestSplitSealedError`][] when a model was already selected (a selection is final).
        """
        if self._selected is not None:
            raise TestSplitSealedError(
                f"{self.task.name}: {self._selected!r} is already selected; a selection is "
                "final (choosing again after seeing test scores would use the test split)."
            )
        if not isinstance(name, str) or not name:
            raise TypeError("SealedTestSplit.select: name must be a non-empty string.")
        self._selected = name
        self._evidence = dict(evidence or {})

    def _check(self, what: str) -> None:
        if self._selected is None:
            raise TestSplitSealedError(
                f"{self.task.name}: {what} before a model is selected; choose on the "
                "training records (.train) and call .select(name, evidence) first."
            )

    @property
    def test(self) -> tuple[Record, ...]:
        """The test records (only after `.select`)."""
        self._check("the test records were read")
        return self._data.test

    def score(self, predictor: Predictor) -> TaskScore:
        """Score a model on the training and the test records ([`score_predictor`][]);
        only after a selection. Ablations (the other candidates) are scored the same way
        once the choice is final."""
        self._check("a model was scored on the test split")
        return score_predictor(self.task, predictor, self._data)


# ----------------------------------------------------------------------------- reports


@dataclasses.dataclass(frozen=True)
class ModelReport:
    """One row of a benchmark table: a model run in this benchmark.

    **Arguments:**

    - `name`: the model, as shown.
    - `score`: its [`TaskScore`][].
    - `parameters`: number of calibrated parameters (`None`: not applicable).
    - `train_s`, `compile_s`: training run time and compile time [s] (`None`: not
      trained here, e.g. published parameters).
    - `details`: anything else for the JSON (parameter values, solver statistics,
      validation scores).
    - `chosen`: how the row was chosen (e.g. "selected on training data", "ablation",
      "reference"); shown as a column when any row has it.
    - `selected`: whether this row is the benchmark's result (the model selected without
      the test data).
    """

    name: str
    score: TaskScore
    parameters: int | None = None
    train_s: float | None = None
    compile_s: float | None = None
    details: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    chosen: str | None = None
    selected: bool = False


@dataclasses.dataclass(frozen=True)
class PublishedResult:
    """A result published elsewhere on the same task (not run here).

    **Arguments:**

    - `name`: the model.
    - `test_rmse`: `(low, high)` test RMSE in the task's display unit (equal for one value).
    - `train_s`: `(low, high)` training time [s], or `None` when not published.
    - `source`: where it was published.
    """

    name: str
    test_rmse: tuple[float, float]
    train_s: tuple[float, float] | None
    source: str


def _fmt(x: float | None, digits: int = 2) -> str:
    return "—" if x is None else f"{x:.{digits}f}"


def _range(r: tuple[float, float] | None, digits: int) -> str:
    if r is None:
        return "—"
    lo, hi = r
    return f"{lo:.{digits}f}" if lo == hi else f"{lo:.{digits}f}–{hi:.{digits}f}"


def markdown_table(
    task: BenchmarkTask,
    rows: Sequence[ModelReport],
    published: Sequence[PublishedResult] = (),
) -> str:
    """The benchmark table in markdown: one row per model run here, then the published
    results (their columns that were not published are `—`)."""
    u = task.unit
    how = any(r.chosen for r in rows)
    lines = [
        f"| model |{' how chosen |' if how else ''} parameters | train time [s] | compile [s] | "
        f"train RMSE [{u}] | test RMSE [{u}] | test NRMSE | test rel. error [%] |",
        f"|---|{'---|' if how else ''}---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        name = f"**{r.name}**" if r.selected else r.name
        lines.append(
            f"| {name} |{f' {r.chosen or chr(8212)} |' if how else ''} "
            f"{'—' if r.parameters is None else r.parameters} | "
            f"{_fmt(r.train_s, 1)} | {_fmt(r.compile_s, 1)} | "
            f"{_fmt(r.score.mean('rmse', 'train'))} | **{_fmt(r.score.mean('rmse'))}** | "
            f"{_fmt(r.score.mean('nrmse'), 4)} | {_fmt(r.score.mean('relative_error'), 2)} |"
        )
    for p in published:
        lines.append(
            f"| {p.name} (published) |{' published |' if how else ''} — | "
            f"{_range(p.train_s, 0)} | — | — | "
            f"{_range(p.test_rmse, 1)} | — | — |"
        )
    return "\n".join(lines)


def write_report(
    task: BenchmarkTask,
    rows: Sequence[ModelReport],
    path: str | Path,
    *,
    published: Sequence[PublishedResult] = (),
    preamble: str = "",
    epilogue: str = "",
    extra: Mapping[str, Any] | None = None,
) -> str:
    """Write `path.json` and `path.md` (the benchmark's table) and return the markdown.

    **Arguments:**

    - `task`: the task.
    - `rows`: the models run here ([`ModelReport`][]).
    - `path`: output path without suffix (e.g. `benchmarks/results/emps_official`).
    - `published`: published results on the same task ([`PublishedResult`][]).
    - `preamble`, `epilogue`: markdown before and after the table.
    - `extra`: more JSON fields (machine load, settings).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    md = "\n\n".join(
        part
        for part in (
            f"# {task.name}: official benchmark task",
            preamble.strip(),
            markdown_table(task, rows, published),
            epilogue.strip(),
        )
        if part
    )
    md += "\n"
    payload = {
        "task": {
            "name": task.name,
            "train": [dataclasses.asdict(s) for s in task.train],
            "test": [dataclasses.asdict(s) for s in task.test],
            "inputs": list(task.inputs),
            "outputs": list(task.outputs),
            "init_window": task.init_window,
            "sample_time": task.sample_time,
            "display_unit": task.unit,
            "display_scale": task.display_scale,
            "source": task.source,
        },
        "models": [
            {
                "name": r.name,
                "parameters": r.parameters,
                "train_s": r.train_s,
                "compile_s": r.compile_s,
                "selected": r.selected,
                "chosen": r.chosen,
                "test_rmse": r.score.mean("rmse"),
                "train_rmse": r.score.mean("rmse", "train"),
                "test_nrmse": r.score.mean("nrmse"),
                "scores": r.score.to_json(),
                "details": dict(r.details),
            }
            for r in rows
        ],
        "published": [dataclasses.asdict(p) for p in published],
        **dict(extra or {}),
    }
    path.with_suffix(".json").write_text(json.dumps(payload, indent=2, default=float) + "\n")
    path.with_suffix(".md").write_text(md)
    return md
