"""Compiled (numba) extended Kalman filters of :mod:`adaptrack.crossing.estimators.road_filters`.

The NumPy loops there are the readable reference; these kernels run the same recursion run by
run (runs in parallel): predict with the transition of each step evaluated from a series table
(:mod:`adaptrack.models.series_table`), hold an approaching vehicle at standstill instead of
reversing (road model), linearise the (range, azimuth, radial speed)
measurement at the prediction, Joseph update. Tracks start at their first detection with the
initial state computed in NumPy. They agree with the reference to rounding (tests).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import prange

from ...angles import wrapped
from ...filters._kernels import predict_into, series_transition_into, update_into
from ..site.geometry import (
    RADAR_DOPPLER_GATE,
    RADAR_FOLD,
    RADAR_MIN_RANGE,
    RADAR_X,
    RADAR_Y,
    centreline,
    curve_at,
    in_view,
    lane_at,
    off_boresight,
    polar_into,
)

ROAD, FREE = 0, 1  # measurement models
GATE_MIN_COS = 0.3  # the gate informs on speed only where |d v_r / d speed| is at least this
MISS_RUN_FLOOR = 1e-4  # a run of misses has at least this probability (occlusion, interference)
UNFOLD_SIGMAS = 5.0  # a folded radial speed is used once its prediction sigma is below fold / this


@numba.njit(cache=True, inline="always")
def _noise_into(radar, noise_tab, noise_cnt, zp, jp, ux, uy, scatter_std, rm):  # type: ignore[no-untyped-def]
    """Fill the measurement noise at the predicted geometry ``zp`` (with body scatter).

    The radar's sigma curves ``noise_tab``/``noise_cnt`` (range and radial speed against
    range, azimuth against the angle off boresight ``radar[3]``) plus the rank-one
    reflection-point scatter along ``u``.
    """
    b0 = jp[0, 0] * ux + jp[0, 1] * uy
    b1 = jp[1, 0] * ux + jp[1, 1] * uy
    b2 = jp[2, 0] * ux + jp[2, 1] * uy
    s2 = scatter_std * scatter_std
    off = off_boresight(zp[1], radar)
    rm[0, 0] = curve_at(noise_tab, noise_cnt, 0, zp[0]) ** 2
    rm[1, 1] = curve_at(noise_tab, noise_cnt, 1, off) ** 2
    rm[2, 2] = curve_at(noise_tab, noise_cnt, 2, zp[0]) ** 2
    rm[0, 1] = rm[1, 0] = rm[0, 2] = rm[2, 0] = rm[1, 2] = rm[2, 1] = 0.0
    bb = (b0, b1, b2)
    for a in range(3):
        for c in range(3):
            rm[a, c] += s2 * bb[a] * bb[c]


@numba.njit(cache=True, inline="always")
def alias_known(var, radar):  # type: ignore[no-untyped-def]
    """Whether a radial-speed innovation variance ``var`` tells a folding radar's alias.

    True without folding (``radar[6]`` 0); else while the sigma is below
    ``radar[6] / UNFOLD_SIGMAS``.
    """
    fold = radar[RADAR_FOLD]
    return fold <= 0.0 or var * UNFOLD_SIGMAS * UNFOLD_SIGMAS < fold * fold


@numba.njit(cache=True, inline="always")
def doppler_usable(h, p, rm, radar):  # type: ignore[no-untyped-def]
    """Whether a detection's radial speed can be used at this prediction (else leave it out).

    A radar folding radial speeds at ``+-radar[6]`` (> 0) reports them modulo twice that; the
    prediction (Jacobian ``h`` (3, n), covariance ``p``, noise ``rm``) tells the alias while
    the radial speed's innovation sigma is below ``radar[6] / UNFOLD_SIGMAS``. Otherwise the
    radial-speed row of ``h`` and the noise's cross terms with it are zeroed: an update with a
    zero radial-speed residual then uses range and azimuth alone.
    """
    if radar[RADAR_FOLD] <= 0.0:
        return True
    n = h.shape[1]
    var = rm[2, 2]
    for a in range(n):
        for b in range(n):
            var += h[2, a] * p[a, b] * h[2, b]
    if alias_known(var, radar):
        return True
    for a in range(n):
        h[2, a] = 0.0
    rm[0, 2] = rm[2, 0] = rm[1, 2] = rm[2, 1] = 0.0
    return False


@numba.njit(cache=True, inline="always")
def innovation_into(z, zp, radar, doppler, nu):  # type: ignore[no-untyped-def]
    """Innovation ``nu`` (3,) of detection ``z`` at the prediction ``zp``.

    Azimuth wrapped to ``[-pi, pi)``; the radial speed unfolded to the alias nearest the
    prediction where the radar folds (``radar[6] > 0``), or 0 where it is left out
    (``doppler`` false: :func:`doppler_usable`).
    """
    fold = radar[RADAR_FOLD]
    nu[0] = z[0] - zp[0]
    nu[1] = wrapped(z[1] - zp[1], math.pi)
    if not doppler:
        nu[2] = 0.0
    elif fold > 0.0:
        nu[2] = wrapped(z[2] - zp[2], fold)
    else:
        nu[2] = z[2] - zp[2]


@numba.njit(cache=True, inline="always")
def folded_log_likelihood_gap(rm, radar):  # type: ignore[no-untyped-def]
    """Return the log-likelihood correction of a left-out folded radial speed.

    The update counted ``N(0; 0, rm[2, 2])`` for it; a folded radial speed the prediction
    cannot place is uniform over the folding interval ``2 radar[6]``.
    """
    return 0.5 * math.log(2.0 * math.pi * rm[2, 2]) - math.log(2.0 * radar[RADAR_FOLD])


@numba.njit(cache=True)
def measure(  # type: ignore[no-untyped-def]
    kind, x, k, radar, noise_tab, noise_cnt, road, half_width, scatter_std, zp, h, rm, jp, jv
):
    """Fill predicted detection ``zp``, Jacobian ``h`` (3, n) and noise ``rm`` at state ``x``.

    ``radar``: x, y, height, boresight; ``noise_tab``/``noise_cnt`` its sigma curves;
    ``road`` (5, S): sampled centreline ``s``, ``x``, ``y``, heading and curvature rows.
    """
    measure_span(
        kind, x, k, radar, noise_tab, noise_cnt, road, 0, road.shape[1], half_width,
        scatter_std, zp, h, rm, jp, jv,
    )  # fmt: skip


@numba.njit(cache=True)
def measure_span(  # type: ignore[no-untyped-def]
    kind, x, k, radar, noise_tab, noise_cnt, roads, lo, hi, half_width, scatter_std, zp, h, rm,
    jp, jv,
):  # fmt: skip
    """:func:`measure` of the road in columns ``lo:hi`` of ``roads`` (:func:`centreline_span`).

    Returns the centreline point and unit tangent ``(cx, cy, tx, ty)`` at the state's ``u``
    (ROAD; zeros for FREE), for a caller that needs the lane frame there too.
    """
    if kind == ROAD:
        lane = lane_at(roads, lo, hi, x[0])
        return road_measure(
            x, k, radar, noise_tab, noise_cnt, lane, half_width, scatter_std, zp, h, rm, jp, jv
        )
    h[:, :] = 0.0
    if kind == FREE:
        vx, vy = x[2], x[3]
        polar_into(x[0], x[1], vx, vy, radar, zp, jp, jv)
        for a in range(3):
            h[a, 0], h[a, 1], h[a, 2], h[a, 3] = jp[a, 0], jp[a, 1], jv[a, 0], jv[a, 1]
        speed = math.sqrt(vx * vx + vy * vy)
        if speed > 0.5:
            ux, uy = vx / max(speed, 1e-9), vy / max(speed, 1e-9)
        else:
            ex, ey = x[0] - radar[RADAR_X], x[1] - radar[RADAR_Y]
            dist = math.sqrt(ex * ex + ey * ey)
            ux, uy = -ex / dist, -ey / dist
        _noise_into(radar, noise_tab, noise_cnt, zp, jp, ux, uy, scatter_std, rm)
    return 0.0, 0.0, 0.0, 0.0


@numba.njit(cache=True)
def road_measure(  # type: ignore[no-untyped-def]
    x, k, radar, noise_tab, noise_cnt, lane, half_width, scatter_std, zp, h, rm, jp, jv
):
    """:func:`measure_span` of a ROAD state ``x`` given its lane frame (:func:`lane_at`)."""
    h[:, :] = 0.0
    vs, d = x[1], x[k]
    cx, cy, kappa, tx, ty = lane
    rx, ry = -ty, tx
    off = half_width + d
    lever = 1.0 + kappa * off  # the lane point moves at lever * ds/dt
    dpx, dpy = lever * tx, lever * ty
    polar_into(cx + off * rx, cy + off * ry, vs * dpx, vs * dpy, radar, zp, jp, jv)
    dvx, dvy = -(vs * lever * kappa) * rx, -(vs * lever * kappa) * ry
    ex, ey = vs * kappa * tx, vs * kappa * ty  # d velocity / d d
    for a in range(3):
        h[a, 0] = jp[a, 0] * dpx + jp[a, 1] * dpy + jv[a, 0] * dvx + jv[a, 1] * dvy
        h[a, 1] = jv[a, 0] * dpx + jv[a, 1] * dpy
        h[a, k] = jp[a, 0] * rx + jp[a, 1] * ry + jv[a, 0] * ex + jv[a, 1] * ey
    _noise_into(radar, noise_tab, noise_cnt, zp, jp, -tx, -ty, scatter_std, rm)
    return cx, cy, tx, ty


@numba.njit(cache=True)
def _planar_into(kind, x, p, k, road, half_width, pos, vel, pcov):  # type: ignore[no-untyped-def]
    """Planar position, velocity and position covariance (2, 2) of state ``x``, ``p``.

    ROAD: ``p = c(s) + (w/2 + d) right(s)``, ``v = (1 + kappa (w/2 + d)) ds/dt t(s)``,
    covariance through
    ``dp/ds = (1 + kappa (w/2 + d)) t``, ``dp/dd = right``. Returns the speed.
    """
    if kind == FREE:
        pos[0], pos[1], vel[0], vel[1] = x[0], x[1], x[2], x[3]
        pcov[0, 0], pcov[0, 1], pcov[1, 0], pcov[1, 1] = p[0, 0], p[0, 1], p[1, 0], p[1, 1]
        return math.sqrt(x[2] * x[2] + x[3] * x[3])
    s, vs, d = x[0], x[1], x[k]
    cx, cy, th, kappa = centreline(road, s)
    tx, ty = math.sin(th), math.cos(th)
    rx, ry = -ty, tx
    off = half_width + d
    pos[0], pos[1] = cx + off * rx, cy + off * ry
    ax, ay = (1.0 + kappa * off) * tx, (1.0 + kappa * off) * ty
    vel[0], vel[1] = vs * ax, vs * ay
    pss, psd, pdd = p[0, 0], p[0, k], p[k, k]
    pcov[0, 0] = pss * ax * ax + 2.0 * psd * ax * rx + pdd * rx * rx
    pcov[1, 1] = pss * ay * ay + 2.0 * psd * ay * ry + pdd * ry * ry
    pcov[0, 1] = pcov[1, 0] = pss * ax * ay + psd * (ax * ry + rx * ay) + pdd * rx * ry
    return abs(vs) * (1.0 + kappa * off)


@numba.njit(cache=True, inline="always")
def _normal_cdf(x):  # type: ignore[no-untyped-def]
    return 0.5 * math.erfc(-x / math.sqrt(2.0))


@numba.njit(cache=True)
def gate_update_into(  # type: ignore[no-untyped-def]
    kind, xp, pp, k, radar, noise_tab, noise_cnt, fields, pd_tab, pd_cnt, road, half_width,
    scatter_std, miss_run, x, p, zp, h, rm, jp, jv, hp, s, lo, kt, w, ikh, tmp, nu1, r1,
):  # fmt: skip
    """Posterior ``x``, ``p`` of the prior ``xp``, ``pp`` after a scan without a detection.

    Inside the field of view, where the radial speed measures the speed
    (``|d v_r / d speed| >= GATE_MIN_COS``; with a folding radar, once the prediction tells
    the alias: :func:`doppler_usable`) and the Doppler gate ``g = radar[5]`` explains the
    run of misses better than ``1 - P_D`` (``miss_run``: its probability for a moving target
    so far; :mod:`adaptrack.crossing.estimators.road_filters`), the pseudo-measurement
    ``v_r = 0`` with variance ``g^2 / 3`` is applied. Returns ``log P(no detection)`` (0
    outside the view) and the updated ``miss_run``. ``hp``/``kt`` (1, n), ``s``/``lo``/``r1``
    (1, 1), ``w``/``nu1`` (1,) are scratch.
    """
    measure(
        kind, xp, k, radar, noise_tab, noise_cnt, road, half_width, scatter_std, zp, h, rm, jp, jv
    )
    n = xp.shape[0]
    for a in range(n):
        x[a] = xp[a]
        for b in range(n):
            p[a, b] = pp[a, b]
    off = off_boresight(zp[1], radar)
    if not in_view(zp[0], off, fields, radar[RADAR_MIN_RANGE]):
        return 0.0, miss_run
    if kind == ROAD:
        along = abs(h[2, 1])
    else:  # the radial speed's sensitivity to the speed along the predicted velocity
        sp = math.sqrt(xp[2] * xp[2] + xp[3] * xp[3])
        along = abs(h[2, 2] * xp[2] + h[2, 3] * xp[3]) / sp if sp > 0.5 else 1.0
    var = 0.0
    for a in range(n):
        for b in range(n):
            var += h[2, a] * pp[a, b] * h[2, b]
    sd = math.sqrt(max(var, 1e-24))
    gate, mu = radar[RADAR_DOPPLER_GATE], zp[2]
    p_gate = _normal_cdf((gate - mu) / sd) - _normal_cdf((-gate - mu) / sd)
    p_det = curve_at(pd_tab, pd_cnt, 0, zp[0])
    p_miss = p_gate + (1.0 - p_det) * (1.0 - p_gate)
    if along < GATE_MIN_COS or not alias_known(var + rm[2, 2], radar):  # says little on speed
        return math.log(p_miss) if p_miss > 0.0 else -math.inf, miss_run
    miss_run = max(miss_run * (1.0 - p_det), MISS_RUN_FLOOR)
    if gate > 0.0 and p_gate > miss_run * (1.0 - p_gate):
        nu1[0] = -mu
        r1[0, 0] = gate * gate / 3.0
        update_into(xp, pp, nu1, h[2:3], r1, True, x, p, hp, s, lo, kt, w, ikh, tmp)
    return (math.log(p_miss) if p_miss > 0.0 else -math.inf), miss_run


@numba.njit(cache=True, parallel=True)
def ekf_kernel(  # type: ignore[no-untyped-def]
    kind,
    times,
    phi_coef,
    qd_coef,
    off_coef,
    h_max,
    z,
    detected,
    first,
    m0,
    p0,
    k,
    radar,
    noise_tab,
    noise_cnt,
    fields,
    pd_tab,
    pd_cnt,
    road,
    half_width,
    scatter_std,
    pos,
    vel,
    speed,
    pcov,
    status,
):
    """Run the EKF of ``kind`` (ROAD or FREE) over every run from its first detection.

    ``times`` (N, T) [s]; the transitions come from the series table ``phi_coef``,
    ``qd_coef``, ``off_coef``, ``h_max`` (:mod:`adaptrack.models.series_table`); ``z``
    (N, T, 3); ``first`` (N,) first detection (-1: none); ``m0``/``p0`` the initial state
    there; ``k`` the along-road model size (ROAD). ``radar``: x, y, height, boresight, min
    range, Doppler gate; ``noise_tab``/``noise_cnt``: its sigma curves; ``fields`` its fields of
    view and ``pd_tab``/``pd_cnt`` the class's P_D (the meaning of a missed detection).
    ``pos``/``vel`` (N, T, 2), ``speed`` (N, T), ``pcov`` (N, T, 2, 2) (pre-filled with
    NaN) receive the planar estimates; ``status[i] = t + 1`` if run ``i`` stops at step ``t``
    (S not positive definite). Generic loops:
    :mod:`.codegen` generates the same recursion in straight-line code per state size.
    """
    n_runs, n_steps = detected.shape
    n = m0.shape[1]
    for i in prange(n_runs):
        f = first[i]
        if f < 0:
            continue
        x = m0[i].copy()
        p = p0[i].copy()
        xp, u, w = np.empty(n), np.zeros(n), np.empty(3)
        phi, qd = np.empty((n, n)), np.empty((n, n))
        pp, tmp, ikh = np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
        zp, resid, rm = np.empty(3), np.empty(3), np.empty((3, 3))
        h, hp, kt = np.zeros((3, n)), np.empty((3, n)), np.empty((3, n))
        jp, jv = np.empty((3, 2)), np.empty((3, 2))
        s, lo = np.empty((3, 3)), np.empty((3, 3))
        nu1, r1 = np.empty(1), np.empty((1, 1))
        miss_run = 1.0
        speed[i, f] = _planar_into(
            kind, x, p, k, road, half_width, pos[i, f], vel[i, f], pcov[i, f]
        )
        for t in range(f + 1, n_steps):
            series_transition_into(
                times[i, t] - times[i, t - 1], phi_coef, qd_coef, off_coef, h_max, phi, qd, u, tmp
            )
            predict_into(x, p, phi, qd, u, xp, pp, tmp)
            if kind == ROAD and xp[1] > 0:  # an approaching vehicle does not reverse
                for a in range(1, k):
                    xp[a] = 0.0
            if detected[i, t]:
                measure(
                    kind, xp, k, radar, noise_tab, noise_cnt, road, half_width, scatter_std,
                    zp, h, rm, jp, jv,
                )  # fmt: skip
                doppler = doppler_usable(h, pp, rm, radar)
                innovation_into(z[i, t], zp, radar, doppler, resid)
                ok, _, _ = update_into(xp, pp, resid, h, rm, True, x, p, hp, s, lo, kt, w, ikh, tmp)
                if not ok:
                    status[i] = t + 1
                    break
                miss_run = 1.0
            else:
                _, miss_run = gate_update_into(
                    kind, xp, pp, k, radar, noise_tab, noise_cnt, fields, pd_tab, pd_cnt, road,
                    half_width, scatter_std, miss_run, x, p, zp, h, rm, jp, jv, hp[:1],
                    s[:1, :1], lo[:1, :1], kt[:1], w[:1], ikh, tmp, nu1, r1,
                )  # fmt: skip
            speed[i, t] = _planar_into(
                kind, x, p, k, road, half_width, pos[i, t], vel[i, t], pcov[i, t]
            )


@numba.njit(cache=True, parallel=True)
def pcrlb_kernel(  # type: ignore[no-untyped-def]
    times,
    phi_coef,
    qd_coef,
    off_coef,
    h_max,
    truth,
    detected,
    p0,
    k,
    radar,
    noise_tab,
    noise_cnt,
    fields,
    road,
    half_width,
    scatter_std,
    pos_var,
    spd_var,
):
    """Bound covariance recursion of the road model along the true states ``truth`` (N, T, n).

    Transitions as in :func:`ekf_kernel`. The covariance stays at ``p0`` until the first
    detection; a scan without a detection, in view, with the true radial speed below the
    Doppler gate ``radar[5]`` and a line of sight along the road (``GATE_MIN_COS``), adds the
    gate's information (``v_r`` with variance ``g^2 / 3``), as the filters do.
    ``pos_var``/``spd_var`` (N, T), pre-filled with NaN, receive ``P[0, 0] + P[k, k]`` and
    ``P[1, 1]`` from then on.
    """
    n_runs, n_steps = detected.shape
    n = p0.shape[0]
    for i in prange(n_runs):
        p = p0.copy()
        x, xp, u, w = np.zeros(n), np.empty(n), np.zeros(n), np.empty(3)
        phi, qd = np.empty((n, n)), np.empty((n, n))
        pp, tmp, ikh = np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
        zp, resid, rm = np.empty(3), np.zeros(3), np.empty((3, 3))
        h, hp, kt = np.zeros((3, n)), np.empty((3, n)), np.empty((3, n))
        jp, jv = np.empty((3, 2)), np.empty((3, 2))
        s, lo = np.empty((3, 3)), np.empty((3, 3))
        r1 = np.full((1, 1), radar[RADAR_DOPPLER_GATE] * radar[RADAR_DOPPLER_GATE] / 3.0)
        started = False
        for t in range(n_steps):
            if started:
                series_transition_into(
                    times[i, t] - times[i, t - 1],
                    phi_coef,
                    qd_coef,
                    off_coef,
                    h_max,
                    phi,
                    qd,
                    u,
                    tmp,
                )
                predict_into(x, p, phi, qd, u, xp, pp, tmp)  # (means unused)
            else:
                pp[:, :] = p0
            if detected[i, t]:
                xp[:] = truth[i, t]
                measure(
                    ROAD, xp, k, radar, noise_tab, noise_cnt, road, half_width, scatter_std,
                    zp, h, rm, jp, jv,
                )  # fmt: skip
                ok, _, _ = update_into(xp, pp, resid, h, rm, True, x, p, hp, s, lo, kt, w, ikh, tmp)
                if not ok:
                    break
                started = True
            else:
                p[:, :] = pp
                if started and radar[RADAR_DOPPLER_GATE] > 0.0:
                    xp[:] = truth[i, t]
                    measure(
                        ROAD, xp, k, radar, noise_tab, noise_cnt, road, half_width, scatter_std,
                        zp, h, rm, jp, jv,
                    )  # fmt: skip
                    off = off_boresight(zp[1], radar)
                    informs = abs(h[2, 1]) >= GATE_MIN_COS
                    if (
                        in_view(zp[0], off, fields, radar[RADAR_MIN_RANGE])
                        and abs(zp[2]) < radar[RADAR_DOPPLER_GATE]
                        and informs
                    ):
                        update_into(
                            xp, pp, resid[:1], h[2:3], r1, True, x, p, hp[:1], s[:1, :1],
                            lo[:1, :1], kt[:1], w[:1], ikh, tmp,
                        )  # fmt: skip
            if started:
                pos_var[i, t] = p[0, 0] + p[k, k]
                spd_var[i, t] = p[1, 1]
