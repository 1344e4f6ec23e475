"""Public system-identification benchmarks: task definitions (data, split, metric,
initialisation window), a runner that scores any model on them, and the simulators and
multiple-shooting calibration jaxvs enters with."""

from ._emps import (
    EMPS as EMPS,
    EMPS_PUBLISHED as EMPS_PUBLISHED,
    EMPS_PUBLISHED_IDIM as EMPS_PUBLISHED_IDIM,
    OpenLoopAxis as OpenLoopAxis,
    PositionForce as PositionForce,
)
from ._shooting import (
    AbstractSimulator as AbstractSimulator,
    ShootingOptions as ShootingOptions,
    ShootingResult as ShootingResult,
    fit_multiple_shooting as fit_multiple_shooting,
)
from ._task import (
    BenchmarkTask as BenchmarkTask,
    ExperimentScore as ExperimentScore,
    ModelReport as ModelReport,
    PublishedResult as PublishedResult,
    SealedTestSplit as SealedTestSplit,
    Segment as Segment,
    TaskData as TaskData,
    TaskScore as TaskScore,
    TestSplitSealedError as TestSplitSealedError,
    markdown_table as markdown_table,
    nrmse as nrmse,
    relative_error as relative_error,
    rmse as rmse,
    score_predictor as score_predictor,
    write_report as write_report,
)
