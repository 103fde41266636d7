"""A NumPy reference of one scene-tracker scan, for road users wholly in view of one radar.

The regime it covers: moving tracks (not stopped), each body wholly inside the field of view,
one detection per track in its gate and in no other, no occlusion, no clutter, no folding.
There a scan is: predict every track (constant acceleration along its corridor with white
jerk, a random walk across), gate (squared Mahalanobis distance of each detection), then
for each track its detection: learn the body spread from the along-lane residual, and the
EKF update (Joseph form) with the body's measurement model. Written from the model's
equations with NumPy arrays, np.interp and the site model's noise curves
(:meth:`RadarSpec.noise_std`); the compiled stages (:mod:`adaptrack.crossing.scene`) must
equal it to rounding.
"""

import numpy as np

BODY_HALF_SPREADS = 2.0  # a body reaches this many spreads either side of its centre


def lane_frame(roads, bounds, corridor, u):
    """Centreline point, curvature and unit tangent ``(cx, cy, kappa, tx, ty)`` at ``u``."""
    lo, hi = bounds[corridor]
    s = roads[0, lo:hi]
    cx, cy, heading, kappa = (np.interp(u, s, roads[k, lo:hi]) for k in (1, 2, 3, 4))
    return cx, cy, kappa, np.sin(heading), np.cos(heading)


def predict(x, p, dt, accel_psd, lateral_psd):
    """Constant acceleration along over ``dt`` [s] (white jerk), a random walk across."""
    phi = np.eye(4)
    phi[0, 1] = phi[1, 2] = dt
    phi[0, 2] = 0.5 * dt * dt
    q = np.zeros((4, 4))
    q[:3, :3] = accel_psd * np.array(
        [[dt**5 / 20, dt**4 / 8, dt**3 / 6], [dt**4 / 8, dt**3 / 3, dt**2 / 2],
         [dt**3 / 6, dt**2 / 2, dt]]
    )  # fmt: skip
    q[3, 3] = lateral_psd * dt
    pp = phi @ p @ phi.T + q
    return phi @ x, 0.5 * (pp + pp.T)


def measurement(x, lane, radar, spread, across_std):
    """Predicted (range, azimuth, radial speed), Jacobian (3, 4) and noise (3, 3) of a body.

    The body's centre is ``d`` across the lane's centreline at ``u`` (the left normal
    ``n = (-ty, tx)``) and moves along it at ``lever = 1 + kappa d`` times ``du/dt``; the
    reflection point scatters along the lane (``spread``) and across it (``across_std``).
    """
    cx, cy, kappa, tx, ty = lane
    _, speed, _, d = x
    t, n = np.array([tx, ty]), np.array([-ty, tx])
    lever = 1.0 + kappa * d
    point, vel = np.array([cx, cy]) + d * n, speed * lever * t
    rel = point - np.asarray(radar.position_m)
    h2 = rel @ rel
    r = np.sqrt(h2 + radar.height_m**2)
    rv = rel @ vel
    zp = np.array([r, np.arctan2(rel[0], rel[1]), rv / r])
    d_pos = np.array([rel / r, [rel[1] / h2, -rel[0] / h2], vel / r - rv / r**3 * rel])
    d_vel = np.array([[0.0, 0.0], [0.0, 0.0], rel / r])
    jac = np.zeros((3, 4))
    jac[:, 0] = d_pos @ (lever * t) + d_vel @ (-speed * lever * kappa * n)  # d/du
    jac[:, 1] = d_vel @ (lever * t)  # d/d(du/dt)
    jac[:, 3] = d_pos @ n + d_vel @ (speed * kappa * t)  # d/dd
    sigmas = np.array(radar.noise_std(zp[0], zp[1]), dtype=float)
    along, across = d_pos @ -t, d_pos @ n
    noise = np.diag(sigmas**2) + spread**2 * np.outer(along, along)
    return zp, jac, noise + across_std**2 * np.outer(across, across)


def innovation(z, zp):
    """Detection less prediction, the azimuth wrapped to ``[-pi, pi)``."""
    nu = z - zp
    nu[1] = (nu[1] + np.pi) % (2 * np.pi) - np.pi
    return nu


def learnt_spread(z, x, p, lane, radar, spread, rate, lo, hi):
    """The body spread after one detection: a moving average of its squared along-lane
    residual less the sensor's and the track's share, within ``[lo, hi]`` [m]."""
    cx, cy, _, tx, ty = lane
    rho = np.sqrt(max(z[0] ** 2 - radar.height_m**2, 0.01))
    ground = np.asarray(radar.position_m) + rho * np.array([np.sin(z[1]), np.cos(z[1])])
    centre = np.array([cx, cy]) + x[3] * np.array([-ty, tx])
    along = (ground - centre) @ np.array([tx, ty])
    sr, sa, _ = radar.noise_std(z[0], z[1])
    sample = max(along**2 - sr**2 - (rho * sa) ** 2 - p[0, 0], 0.0)
    var = (1.0 - rate) * spread**2 + rate * sample
    return float(np.sqrt(min(max(var, lo**2), hi**2)))


def joseph_update(x, p, nu, jac, noise):
    """EKF update in Joseph form: posterior mean and covariance."""
    s = jac @ p @ jac.T + noise
    gain = np.linalg.solve(s, jac @ p).T
    ikh = np.eye(4) - gain @ jac
    post = ikh @ p @ ikh.T + gain @ noise @ gain.T
    return x + gain @ nu, 0.5 * (post + post.T)


def scan(tracks, z, radar, roads, bounds, dt, cfg):
    """One scan of the regime above: ``tracks`` a list of dicts (corridor, x, p, spread),
    ``z`` (n, 3) with detection ``i`` the one of track ``i``, ``cfg`` a
    :class:`~adaptrack.crossing.scene.tracker.SceneTrackerConfig`. Returns the predicted
    tracks' squared distances (n, n) and the updated tracks."""
    lo, hi = cfg.spread_limits_m
    predicted, d2, out = [], np.full((len(tracks), len(z)), np.inf), []
    for i, tr in enumerate(tracks):
        x, p = predict(tr["x"], tr["p"], dt, cfg.accel_psd, cfg.lateral_psd)
        lane = lane_frame(roads, bounds, tr["corridor"], x[0])
        zp, jac, noise = measurement(x, lane, radar, tr["spread"], cfg.body_across_std_m)
        s = jac @ p @ jac.T + noise
        for j in range(len(z)):
            nu = innovation(z[j], zp)
            d2[i, j] = nu @ np.linalg.solve(s, nu)
        predicted.append((x, p, lane))
    for i, (tr, (x, p, lane)) in enumerate(zip(tracks, predicted, strict=True)):
        spread = learnt_spread(
            z[i], x, p, lane, radar, tr["spread"], cfg.spread_learning_rate, lo, hi
        )
        zp, jac, noise = measurement(x, lane, radar, spread, cfg.body_across_std_m)
        xn, pn = joseph_update(x, p, innovation(z[i], zp), jac, noise)
        out.append({"corridor": tr["corridor"], "x": xn, "p": pn, "spread": spread})
    return d2, out
