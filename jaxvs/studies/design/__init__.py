"""The virtual-sensor design assistant: `jaxvs.design` searches inputs, delays and model
structures in one vectorised run and suggests the best designs (docs/guides/design.md)."""

from ._data import DesignDataWarning as DesignDataWarning
from ._design import design as design
from ._model import (
    AbstractDesignCore as AbstractDesignCore,
    ARXCore as ARXCore,
    DesignedSensor as DesignedSensor,
    LagCore as LagCore,
    LinearCore as LinearCore,
    NetworkCore as NetworkCore,
)
from ._report import DesignReport as DesignReport
