"""What kind of road user a track is, with its probability, from its box and its speed.

Each class has a typical length and width (mean and spread over the class, DOMAIN 3 and
seed 001's table 1.1) and a top speed; a track's estimated length and width (with their
variances) give each class a Gaussian likelihood, a class slower than the fastest speed the
track has shown is ruled out, and the class priors are a level crossing's mix. The most
probable class is named when its probability reaches ``NAMED_AT``, else ``unknown``. An
object-list radar (one point per object) does not see the box: its tracks keep the prior
box's class, with the probability saying how little that is known.
"""

from __future__ import annotations

import numpy as np

from ..._typing import FloatArray

CLASSES = ("car", "truck", "bus", "motorcycle", "cyclist", "pedestrian")
# (length mean, length sd, width mean, width sd) [m], top speed [m/s], prior
CLASS_MODEL = np.array([
    [4.5, 0.6, 1.8, 0.15, 70.0, 0.62],
    [10.0, 3.0, 2.5, 0.1, 40.0, 0.08],
    [12.0, 1.5, 2.55, 0.05, 30.0, 0.04],
    [2.2, 0.3, 0.8, 0.15, 70.0, 0.06],
    [1.8, 0.2, 0.6, 0.15, 12.0, 0.1],
    [0.5, 0.2, 0.5, 0.15, 4.0, 0.1],
])  # fmt: skip
NAMED_AT = 0.5


def class_probabilities(
    length_m: FloatArray,
    length_var: FloatArray,
    width_m: FloatArray,
    width_var: FloatArray,
    top_speed_mps: FloatArray,
) -> FloatArray:
    """Probability of each of :data:`CLASSES` (N, 6) for N tracks."""
    length, width = np.asarray(length_m, float)[:, None], np.asarray(width_m, float)[:, None]
    m = CLASS_MODEL
    var_l = m[:, 1] ** 2 + np.asarray(length_var, float)[:, None]
    var_w = m[:, 3] ** 2 + np.asarray(width_var, float)[:, None]
    log_like = (-0.5 * (length - m[:, 0]) ** 2 / var_l - 0.5 * np.log(var_l)
                - 0.5 * (width - m[:, 2]) ** 2 / var_w - 0.5 * np.log(var_w))  # fmt: skip
    log_like += np.log(m[:, 5])
    log_like = np.where(np.asarray(top_speed_mps, float)[:, None] > m[:, 4], -np.inf, log_like)
    top = log_like.max(axis=1, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    weight = np.exp(log_like - top)
    total = weight.sum(axis=1, keepdims=True)
    return np.where(total > 0, weight / np.where(total > 0, total, 1.0), 0.0)


def class_names(probabilities: FloatArray) -> tuple[np.ndarray, FloatArray]:
    """Return each track's named class (``unknown`` below :data:`NAMED_AT`), its probability."""
    best = np.argmax(probabilities, axis=1) if len(probabilities) else np.zeros(0, int)
    p = probabilities[np.arange(best.size), best] if best.size else np.zeros(0)
    names = np.array(CLASSES, dtype=object)[best] if best.size else np.zeros(0, dtype=object)
    return np.where(p >= NAMED_AT, names, "unknown"), p


__all__ = ["CLASSES", "CLASS_MODEL", "class_names", "class_probabilities"]
