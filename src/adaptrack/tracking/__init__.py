"""Generic multi-object tracking machinery: gating, assignment, track life cycle.

Independent of any application: the level-crossing scene tracker
(:mod:`adaptrack.crossing.scene.tracker`) builds on it, as any other would.
"""

from .assignment import assignment_by_components, cluster_labels, cluster_points, gnn_assign
from .gating import gate_threshold, mahalanobis_squared
from .lifecycle import LifecycleRules, TrackBook, TrackStatus

__all__ = [
    "LifecycleRules",
    "TrackBook",
    "TrackStatus",
    "assignment_by_components",
    "cluster_labels",
    "cluster_points",
    "gate_threshold",
    "gnn_assign",
    "mahalanobis_squared",
]
