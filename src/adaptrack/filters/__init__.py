"""Kalman filters: pure predict/update steps, the online step and the sequence runner."""

from .dead_reckoning import DeadReckoningResult, dead_reckoning_filter
from .kalman import CovarianceError, kalman_step, predict, update
from .online import OnlineFilter, StreamEstimates
from .run import kalman_filter
from .shared_gain import SharedGainResult, shared_gain_filter

__all__ = [
    "CovarianceError",
    "DeadReckoningResult",
    "OnlineFilter",
    "SharedGainResult",
    "StreamEstimates",
    "dead_reckoning_filter",
    "kalman_filter",
    "kalman_step",
    "predict",
    "shared_gain_filter",
    "update",
]
