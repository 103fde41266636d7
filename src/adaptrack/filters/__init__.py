"""Kalman filters: pure predict/update steps, the online step, the sequence runner, EKF, UKF."""

from .dead_reckoning import DeadReckoningResult, dead_reckoning_filter
from .ekf import ekf_filter
from .kalman import CovarianceError, kalman_step, predict, update
from .online import OnlineFilter, StreamEstimates
from .run import kalman_filter
from .shared_gain import SharedGainResult, shared_gain_filter
from .ukf import SigmaPoints, ukf_filter

__all__ = [
    "CovarianceError",
    "DeadReckoningResult",
    "OnlineFilter",
    "SharedGainResult",
    "SigmaPoints",
    "StreamEstimates",
    "dead_reckoning_filter",
    "ekf_filter",
    "kalman_filter",
    "kalman_step",
    "predict",
    "shared_gain_filter",
    "ukf_filter",
    "update",
]
