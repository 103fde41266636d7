"""Analysis tools: observability."""

from .observability import (
    is_observable,
    observability_matrix,
    observability_rank,
    unobservable_directions,
)

__all__ = ["is_observable", "observability_matrix", "observability_rank", "unobservable_directions"]
