"""Exact and approximate discretisation of continuous linear motion models (spec 0.3).

For a step ``dt >= 0`` the exact discrete model of ``dx = F x dt + G dbeta + B u dt`` is
``Phi = expm(F dt)``, ``Qd = int_0^dt e^{Fs} G Qc G^T e^{F^T s} ds`` and the input gain
``Gamma = int_0^dt e^{Fs} [G B] ds``. Methods:

``"expm"`` (default)
    Van Loan block exponentials on a sub-step ``h = dt / 2^s`` with ``norm1(F) h <= 0.5``,
    then ``s`` doublings. Accurate for ``norm1(F) dt`` from 1e-6 to beyond 1e3 (a single
    block exponential overflows or cancels for long steps).
``"analytic"``
    Element-wise accurate closed forms (phi-functions) for the models that have them
    (constant velocity/acceleration, Singer, M1); the Taylor(30) sub-step recipe with
    doublings for the others (M2, generic SDEs).
``"taylor"``
    Truncated series of order ``order`` (no sub-stepping; for ``norm1(F) dt << 1``).
``"source"``
    Seed 000's printed Euler-type Singer transition and noise (spec A.4), for comparison only.
``"auto"``
    The closed form where a model block has one, ``"expm"`` otherwise: the fastest accurate
    choice (used by the level-crossing trackers).

Noise conventions: ``"white"`` (default, exact white noise) or ``"piecewise"`` (the noise
held constant over each step with covariance ``Qc/dt``: ``Qd = Gamma_G (Qc/dt) Gamma_G^T``).
``dt = 0`` gives ``Phi = I``, ``Qd = 0``, ``Gamma = 0`` exactly for every method.
"""

from __future__ import annotations

import math
from typing import Literal, NamedTuple

import numpy as np

from .._linalg import mT, symmetrize
from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array
from ._layout import Block, ClosedForm, assemble
from .continuous import MotionModel, as_motion_model

Method = Literal["expm", "analytic", "taylor", "source", "auto"]
Noise = Literal["white", "piecewise"]
_SUBSTEP_NORM = 0.5
_ANALYTIC_SERIES_ORDER = 30
_CHUNK = 65536  # distinct steps discretised per batch (bounds memory)
_EXPM_TAYLOR_DEGREE = 18
_VAN_LOAN_BLOCK_NORM = 0.25


class Discretization(NamedTuple):
    """Discrete transition ``Phi`` (..., n, n) and process covariance ``Qd`` (..., n, n)."""

    transition: FloatArray
    process_cov: FloatArray


def discretize(
    model: MotionModel,
    dt: ArrayLike,
    method: Method = "expm",
    *,
    noise: Noise = "white",
    order: int = 2,
) -> Discretization:
    """Discretise a continuous motion model over steps ``dt``.

    Parameters
    ----------
    model : MotionModel
        E.g. :class:`~adaptrack.models.Singer`.
    dt : float or array_like, shape (...)
        Step(s) [s], >= 0; an array gives one discretisation per entry (e.g. per track).
    method : {"expm", "analytic", "taylor", "source", "auto"}
        See the module docstring; ``"auto"``: a model block's closed form where it has one
        (CV, CA, Singer, M1: several times faster), else ``"expm"``.
    noise : {"white", "piecewise"}
        Process-noise convention (spec 0.3.4).
    order : int
        Series order ``p`` for ``method="taylor"``.

    Returns
    -------
    Discretization
        ``(transition, process_cov)``, each of shape ``dt.shape + (n, n)``.

    Examples
    --------
    >>> from adaptrack.models import ConstantVelocity
    >>> phi, q = discretize(ConstantVelocity(accel_psd=3.0), 1.0)
    >>> phi
    array([[1., 1.],
           [0., 1.]])
    >>> q
    array([[1. , 1.5],
           [1.5, 3. ]])
    """
    phi_, qd, _ = discretize_with_input(model, dt, method, noise=noise, order=order)
    return Discretization(phi_, qd)


def control_offset(
    model: MotionModel, dt: ArrayLike, method: Method = "expm", *, order: int = 2
) -> FloatArray:
    """Offset ``u_n = Gamma_B u`` added by the model's known constant input over ``dt``.

    Returns an array of shape ``dt.shape + (n,)`` (zeros for models without an input, e.g. a
    Singer model with zero mean acceleration).
    """
    _, _, offset = discretize_with_input(model, dt, method, order=order)
    return offset


def discretize_with_input(
    model: MotionModel,
    dt: ArrayLike,
    method: Method = "expm",
    *,
    noise: Noise = "white",
    order: int = 2,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return ``(Phi, Qd, control offset)``; see :func:`discretize` and :func:`control_offset`."""
    model = as_motion_model(model)
    dt_arr = as_float_array(dt, "dt")
    if np.any(dt_arr < 0):
        idx = tuple(int(i) for i in np.argwhere(dt_arr < 0)[0])
        raise ValueError(f"dt must be >= 0; got {dt_arr[idx]} at index {idx}")
    if method not in ("expm", "analytic", "taylor", "source", "auto"):
        raise ValueError(
            f"method must be 'expm', 'analytic', 'taylor', 'source' or 'auto'; got {method!r}"
        )
    if noise not in ("white", "piecewise"):
        raise ValueError(f"noise must be 'white' or 'piecewise'; got {noise!r}")
    if method == "taylor" and (isinstance(order, bool) or not isinstance(order, int) or order < 0):
        raise ValueError(f"order must be an int >= 0 for method='taylor'; got {order!r}")
    blocks, _ = model.blocks()
    if method in ("analytic", "auto") and all(b.closed_form is not None for b in blocks):
        # element-wise closed forms: cheaper than sorting out the distinct steps
        steps, inv = dt_arr.reshape(-1), None
    else:
        steps, inv = np.unique(dt_arr, return_inverse=True)
    parts = [
        _discretize_model(model, steps[i : i + _CHUNK], method, noise, order)
        for i in range(0, max(steps.size, 1), _CHUNK)
    ]  # an empty dt still gives one (empty) part: arrays of shape dt.shape + (n, n)

    def per_step(j: int) -> FloatArray:
        """Gather the table of distinct steps (contiguous: layout decides BLAS rounding)."""
        table = np.ascontiguousarray(np.concatenate([p[j] for p in parts]))
        if inv is not None:
            table = np.take(table, inv.reshape(-1), axis=0)
        return table.reshape(dt_arr.shape + table.shape[1:])

    return per_step(0), per_step(1), per_step(2)


def _discretize_model(
    model: MotionModel, dt: FloatArray, method: str, noise: str, order: int
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Discretise every block for the 1-D array of distinct steps ``dt`` and assemble."""
    blocks, perm = model.blocks()
    phis, qds, offsets = [], [], []
    for b in blocks:
        phi_b, qd_b, gam_b = _discretize_block(b, dt, method, noise, order)
        phis.append(phi_b)
        qds.append(qd_b)
        c = b.control.shape[0]
        w = b.noise_input.shape[1]
        offsets.append(np.einsum("...ij,j->...i", gam_b[..., w : w + c], b.control)[..., None])
    return (
        assemble(phis, perm, square=True),
        assemble(qds, perm, square=True),
        assemble(offsets, perm, square=False)[..., 0],
    )


def _discretize_block(
    b: Block, dt: FloatArray, method: str, noise: str, order: int
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Phi, Qd (noise convention applied) and Gamma of [G B] for one block."""
    d = b.dim
    if method == "source":
        if b.source_form is None:
            raise ValueError(
                "method='source' exists only for the Singer model (seed 000's "
                "printed form, spec A.4)"
            )
        if np.any(b.control):
            raise ValueError(
                "method='source' assumes zero mean acceleration (spec A.3); "
                "got a non-zero mean_accel_mps2"
            )
        if noise != "white":
            raise ValueError(
                "method='source' defines its own process noise (spec A.4); leave noise='white'"
            )
        return b.source_form(dt)
    if method in ("analytic", "auto") and b.closed_form is not None:
        phi_, qd, gam = b.closed_form(dt)
    elif method == "analytic":
        phi_, qd, gam = _doubling_recipe(b, dt, _taylor_substep(b, _ANALYTIC_SERIES_ORDER))
    elif method == "taylor":
        phi_, qd, gam = _taylor_substep(b, order)(dt)
    else:
        phi_, qd, gam = _doubling_recipe(b, dt, _expm_substep(b))
    if noise == "piecewise":
        w = b.noise_input.shape[1]
        g = gam[..., :w]
        safe = np.where(dt > 0, dt, 1.0)[..., None, None]
        qd = np.where(dt[..., None, None] > 0, g @ (b.noise_psd / safe) @ mT(g), 0.0)
    zero = dt[..., None, None] == 0
    phi_ = np.where(zero, np.eye(d), phi_)
    return phi_, np.where(zero, 0.0, symmetrize(qd)), np.where(zero, 0.0, gam)


def _gq(b: Block) -> FloatArray:
    return b.noise_input @ b.noise_psd @ b.noise_input.T


def _inputs(b: Block) -> FloatArray:
    return np.concatenate([b.noise_input, b.control_input], axis=1)


def _expm_batched(m: FloatArray) -> FloatArray:
    """Matrix exponential of a batch (..., k, k): scaling and squaring with Taylor(18).

    Each matrix is scaled by ``2^-s`` to 1-norm <= 0.5 (truncation error below 2e-23 of the
    norm), then squared ``s`` times (per matrix). Vectorised over the batch, unlike
    :func:`scipy.linalg.expm`, which loops over it in Python; tests check the two agree.
    """
    norm = np.abs(m).sum(axis=-2).max(axis=-1)
    with np.errstate(divide="ignore"):
        s = np.where(norm <= 0.5, 0, np.ceil(np.log2(np.where(norm > 0, norm, 1.0) / 0.5))).astype(
            int
        )
    a = m / (2.0**s)[..., None, None]
    eye = np.eye(m.shape[-1])
    e = eye + a / _EXPM_TAYLOR_DEGREE
    for i in range(_EXPM_TAYLOR_DEGREE - 1, 0, -1):
        e = eye + (a @ e) / i
    for i in range(int(s.max(initial=0))):
        e = np.where((i < s)[..., None, None], e @ e, e)
    return e


def _expm_substep(b: Block) -> ClosedForm:
    """Van Loan block exponentials for one (short) step h.

    The Van Loan exponential is linear in its noise block ``G Qc G^T h``; where that block is
    large it is scaled down to 1-norm 0.25 (and the result scaled back), so that the number of
    squarings depends on ``F`` only.
    """
    d = b.dim
    gq = _gq(b)
    gq_norm = float(np.abs(gq).sum(axis=0).max()) or 1.0
    inp = _inputs(b)
    k = inp.shape[1]
    inp_norm = float(np.abs(inp).sum(axis=0).max()) if k else 1.0
    inp_norm = inp_norm or 1.0

    def step(h: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        hh = h[..., None, None]
        m = np.zeros(h.shape + (2 * d, 2 * d))
        m[..., :d, :d] = -b.drift * hh
        qscale = np.where(hh > 0, np.minimum(hh, _VAN_LOAN_BLOCK_NORM / gq_norm), 1.0)
        m[..., :d, d:] = gq * qscale
        m[..., d:, d:] = b.drift.T * hh
        e = _expm_batched(m)
        phi_ = mT(e[..., d:, d:])
        qd = symmetrize(phi_ @ e[..., :d, d:]) * (hh / qscale)
        if not k:
            return phi_, qd, np.zeros(h.shape + (d, 0))
        a = np.zeros(h.shape + (d + k, d + k))
        a[..., :d, :d] = b.drift * hh
        iscale = np.where(hh > 0, np.minimum(hh, _VAN_LOAN_BLOCK_NORM / inp_norm), 1.0)
        a[..., :d, d:] = inp * iscale
        gam = _expm_batched(a)[..., :d, d:] * (hh / iscale)
        return phi_, qd, gam

    return step


def _taylor_substep(b: Block, p: int) -> ClosedForm:
    """Spec 0.3.3: truncated series of order p for Phi, Gamma and the white-noise Qd."""
    f = b.drift
    gq = _gq(b)
    inp = _inputs(b)
    fp = [np.linalg.matrix_power(f, i) for i in range(p + 3)]
    terms = [
        [
            fp[i] @ gq @ fp[j].T / (math.factorial(i) * math.factorial(j) * (i + j + 1))
            for j in range(p + 3 - i)
        ]
        for i in range(p + 3)
    ]
    gam_terms = [fp[i] @ inp / math.factorial(i + 1) for i in range(p + 1)]

    def step(h: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        hh = h[..., None, None]
        phi_ = sum(fp[i] * hh**i / math.factorial(i) for i in range(p + 1))
        gam = sum(gam_terms[i] * hh ** (i + 1) for i in range(p + 1))
        qd = sum(terms[i][j] * hh ** (i + j + 1) for i in range(p + 3) for j in range(p + 3 - i))
        return (
            np.broadcast_to(phi_, h.shape + f.shape).copy(),
            np.broadcast_to(qd, h.shape + f.shape).copy(),
            np.broadcast_to(gam, h.shape + inp.shape).copy(),
        )

    return step


def _doubling_recipe(
    b: Block, dt: FloatArray, substep: ClosedForm
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Spec 0.3.1: sub-step ``h = dt / 2^s`` (per entry of dt), then ``s`` doublings."""
    norm1 = float(np.abs(b.drift).sum(axis=0).max())
    x = norm1 * dt
    with np.errstate(divide="ignore"):
        s = np.where(
            x <= _SUBSTEP_NORM, 0, np.ceil(np.log2(np.where(x > 0, x, 1.0) / _SUBSTEP_NORM))
        ).astype(int)
    phi_, qd, gam = substep(dt / 2.0**s)
    for i in range(int(s.max(initial=0))):
        todo = (i < s)[..., None, None]
        qd = np.where(todo, symmetrize(phi_ @ qd @ mT(phi_) + qd), qd)
        gam = np.where(todo, gam + phi_ @ gam, gam)
        phi_ = np.where(todo, phi_ @ phi_, phi_)
    return phi_, qd, gam


__all__ = ["Discretization", "control_offset", "discretize", "discretize_with_input"]
