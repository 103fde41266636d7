"""Quick start: filter and smooth irregularly sampled positions of a Singer target.

Run: python examples/quickstart.py
"""

import numpy as np

import adaptrack as at

rng = np.random.default_rng(7)
model = at.models.Singer(time_constant_s=5.0, accel_std_mps2=2.0)
times = np.cumsum(rng.uniform(0.02, 0.1, 500))  # irregular sampling [s]
truth = at.simulation.simulate_linear_trajectory(
    model, times, initial_mean=[0.0, 15.0, 0.0], initial_cov=np.diag([1.0, 1.0, 4.0]), rng=rng
)
z = at.simulation.simulate_linear_measurements(truth, [[1.0, 0.0, 0.0]], [[0.25]], rng=rng)
prior = at.GaussianState(mean=[z[0, 0], 0.0, 0.0], cov=np.diag([0.25, 400.0, 16.0]), time=times[0])
result = at.kalman_filter(times, z, model, [[1.0, 0.0, 0.0]], [[0.25]], prior)
smoothed = at.rts_smooth(result)

for name, est in (("filter", result.filtered), ("RTS smoother", smoothed)):
    err = est.mean[50:] - truth[50:]
    print(
        f"{name:>12}: position RMSE {np.sqrt(np.mean(err[:, 0] ** 2)):.3f} m, "
        f"speed RMSE {np.sqrt(np.mean(err[:, 1] ** 2)):.3f} m/s"
    )

phi, _ = at.discretize(model, 0.05)
print("observable from position:", at.is_observable(phi, [[1.0, 0.0, 0.0]]))
print("observable from speed only:", at.is_observable(phi, [[0.0, 1.0, 0.0]]))
