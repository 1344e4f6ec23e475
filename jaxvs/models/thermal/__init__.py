"""Thermal virtual-sensor models: first-order exponential interpolation (study eq. 1),
bias-free linear regression (eq. 2-3), the first-order lag of a sampled signal and the
static / time-delay networks."""

from ._lag import FirstOrderLag as FirstOrderLag
from ._networks import (
    AbstractNetwork as AbstractNetwork,
    Perceptron as Perceptron,
    StaticNetwork as StaticNetwork,
    TimeDelayNetwork as TimeDelayNetwork,
)
from ._regression import BiasFreeRegression as BiasFreeRegression
from ._thermal import (
    DrivenFirstOrder as DrivenFirstOrder,
    FirstOrder as FirstOrder,
    PiecewiseFirstOrder as PiecewiseFirstOrder,
)
