"""Predict stage of a scan: every live track to the scan's time (compiled)."""

from __future__ import annotations

import numba

from ..._borrowed import on_stack
from .body import N_STATE


@numba.njit(cache=True)
def predict_tracks(tracks, frozen, time_s, cfg):  # type: ignore[no-untyped-def]
    """Predict every track to ``time_s`` in place (white-jerk CA; stopped rows held).

    A track with a known ``direction`` (+1 / -1 along ``u``) does not reverse: a predicted
    speed against it becomes a standstill (speed and acceleration 0), as a braking vehicle.
    ``frozen`` rows (learnt clutter: :func:`update_tracks`) keep their state and covariance.
    Bundles: ``tracks`` (the track rows, :class:`~.bundles.TrackRows`), ``cfg`` (the settings,
    :class:`~.bundles.Settings`); a setting named here is the field of ``cfg``.
    """
    x, p, t, stopped = tracks.x, tracks.p, tracks.time_s, tracks.stopped
    direction = tracks.direction
    accel_psd, lateral_psd, stopped_psd = cfg.accel_psd, cfg.lateral_psd, cfg.stopped_psd
    q_moving, q_stopped = on_stack((N_STATE, N_STATE)), on_stack((N_STATE, N_STATE))
    tmp = on_stack((N_STATE, N_STATE))
    moving_dt, stopped_dt = -1.0, -1.0  # the steps q_moving, q_stopped were made for
    for i in range(x.shape[0]):
        dt = max(time_s - t[i], 0.0)
        t[i] = max(t[i], time_s)
        if dt == 0.0 or frozen[i]:
            continue
        if stopped[i]:
            if dt != stopped_dt:  # tracks mostly share the step
                stopped_dt = dt
                _process_noise_into(dt, True, accel_psd, lateral_psd, stopped_psd, q_stopped)
            _predict_row(x, p, i, dt, True, q_stopped, tmp)
        else:
            if dt != moving_dt:
                moving_dt = dt
                _process_noise_into(dt, False, accel_psd, lateral_psd, stopped_psd, q_moving)
            _predict_row(x, p, i, dt, False, q_moving, tmp)
        if direction[i] != 0 and x[i, 1] * direction[i] < 0.0:
            x[i, 1] = x[i, 2] = 0.0


@numba.njit(cache=True, inline="always")
def _process_noise_into(dt, stopped, accel_psd, lateral_psd, stopped_psd, q):  # type: ignore[no-untyped-def]
    """Fill the process noise ``q`` (4, 4) of a step ``dt`` [s]: white jerk along, walk across."""
    q[:, :] = 0.0
    if stopped:
        q[0, 0] = q[3, 3] = stopped_psd * dt
    else:
        q[0, 0] = accel_psd * dt**5 / 20.0
        q[0, 1] = q[1, 0] = accel_psd * dt**4 / 8.0
        q[0, 2] = q[2, 0] = accel_psd * dt**3 / 6.0
        q[1, 1] = accel_psd * dt**3 / 3.0
        q[1, 2] = q[2, 1] = accel_psd * dt**2 / 2.0
        q[2, 2] = accel_psd * dt
        q[3, 3] = lateral_psd * dt


@numba.njit(cache=True, inline="always")
def _predict_row(x, p, i, dt, stopped, q, tmp):  # type: ignore[no-untyped-def]
    """Predict row ``i`` over ``dt`` [s] in place: ``x = Phi x``, ``P = Phi P Phi^T + q``.

    ``Phi`` is CA along (``[[1, dt, dt^2/2], [0, 1, dt], [0, 0, 1]]``) and 1 across, or the
    identity when ``stopped``. The sums of :func:`adaptrack.filters._kernels.predict_into`,
    in its order, with the terms of zero ``Phi`` entries left out: the same values to the last
    bit for finite states (a test compares the two). ``tmp`` (4, 4) scratch.
    """
    if stopped:
        for a in range(N_STATE):
            x[i, a] = (0.0 + x[i, a]) + 0.0
            for b in range(N_STATE):
                tmp[a, b] = 0.0 + p[i, a, b]
        for a in range(N_STATE):
            for b in range(N_STATE):
                p[i, a, b] = (0.0 + tmp[a, b]) + q[a, b]
    else:
        h = 0.5 * dt * dt
        x0, x1, x2, x3 = x[i, 0], x[i, 1], x[i, 2], x[i, 3]
        x[i, 0] = (((0.0 + x0) + dt * x1) + h * x2) + 0.0
        x[i, 1] = ((0.0 + x1) + dt * x2) + 0.0
        x[i, 2] = (0.0 + x2) + 0.0
        x[i, 3] = (0.0 + x3) + 0.0
        for b in range(N_STATE):
            tmp[0, b] = ((0.0 + p[i, 0, b]) + dt * p[i, 1, b]) + h * p[i, 2, b]
            tmp[1, b] = (0.0 + p[i, 1, b]) + dt * p[i, 2, b]
            tmp[2, b] = 0.0 + p[i, 2, b]
            tmp[3, b] = 0.0 + p[i, 3, b]
        for a in range(N_STATE):
            p[i, a, 0] = (((0.0 + tmp[a, 0]) + tmp[a, 1] * dt) + tmp[a, 2] * h) + q[a, 0]
            p[i, a, 1] = ((0.0 + tmp[a, 1]) + tmp[a, 2] * dt) + q[a, 1]
            p[i, a, 2] = (0.0 + tmp[a, 2]) + q[a, 2]
            p[i, a, 3] = (0.0 + tmp[a, 3]) + q[a, 3]
    for a in range(N_STATE):
        for b in range(a + 1, N_STATE):
            v = 0.5 * (p[i, a, b] + p[i, b, a])
            p[i, a, b] = v
            p[i, b, a] = v
