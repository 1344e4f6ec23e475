"""Figures: the only part of jaxvs that imports matplotlib."""

from ._bode import bode_plot as bode_plot
from ._design import plot_design as plot_design
from ._diagnosis import (
    plot_bla as plot_bla,
    plot_diagnosis as plot_diagnosis,
    plot_verdict as plot_verdict,
)
from ._discover import plot_discovered as plot_discovered
from ._drive import (
    ballbar_plot as ballbar_plot,
    loop_bode_plot as loop_bode_plot,
    scalogram_plot as scalogram_plot,
)
from ._machine import (
    machine_errors_plot as machine_errors_plot,
    volumetric_error_plot as volumetric_error_plot,
)
from ._thermal import (
    correlation_plot as correlation_plot,
    prediction_plot as prediction_plot,
    residual_plot as residual_plot,
)
