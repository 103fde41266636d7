"""adaptrack: adaptive motion estimation for radar and tracking engineers.

Continuous-time motion models with exact discretisation, batched Kalman filtering and RTS
smoothing over irregular time steps, observability analysis, and the adaptive models of
the seed documents. SI units and radians throughout; time is float seconds.
"""

from . import _kernel_cache  # noqa: F401, I001  (first: kernels defined after it are stamped)
from . import models, simulation
from .analysis.observability import (
    is_observable,
    observability_matrix,
    observability_rank,
    unobservable_directions,
)
from .filters.dead_reckoning import DeadReckoningResult, dead_reckoning_filter
from .filters.ekf import ekf_filter
from .filters.kalman import CovarianceError, kalman_step, predict, update
from .filters.online import OnlineFilter, StreamEstimates
from .filters.run import kalman_filter
from .filters.shared_gain import SharedGainResult, shared_gain_filter
from .filters.ukf import SigmaPoints, ukf_filter
from .models.discretize import Discretization, control_offset, discretize
from .smoothers.rts import rts_smooth
from .types import FilterResult, GaussianState, StepInfo

__version__ = "0.1.0"

__all__ = [
    "CovarianceError",
    "DeadReckoningResult",
    "Discretization",
    "FilterResult",
    "GaussianState",
    "OnlineFilter",
    "SharedGainResult",
    "SigmaPoints",
    "StepInfo",
    "StreamEstimates",
    "__version__",
    "control_offset",
    "dead_reckoning_filter",
    "discretize",
    "ekf_filter",
    "is_observable",
    "kalman_filter",
    "kalman_step",
    "models",
    "observability_matrix",
    "observability_rank",
    "predict",
    "rts_smooth",
    "shared_gain_filter",
    "simulation",
    "ukf_filter",
    "unobservable_directions",
    "update",
]
