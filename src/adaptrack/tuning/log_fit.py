"""A recorded log (GNSS, local positions, radar plots): fit motion and noise, then filter.

Truth-free: the motion model's PSD and the measurement noise variances are the maximum of the
innovations' log-likelihood (:func:`adaptrack.tuning.fit_by_likelihood`), separately for the
horizontal axes and the vertical one. GNSS fixes are filtered in a local east-north-up frame
at the log's first fix and converted back to latitude, longitude and altitude; radar plot
lists (:mod:`adaptrack.tuning.radar_log`) with an EKF in the radar's frame, one noise
variance per measured component. Reading the logs and writing the estimates:
:mod:`adaptrack.io.position_log` and :mod:`adaptrack.io.radar_plots`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np

from .._typing import FloatArray
from ..filters.ekf import ekf_filter
from ..filters.imm import IMMResult, imm_filter
from ..filters.run import kalman_filter
from ..io.position_log import ALL_MEASUREMENTS, PositionLog
from ..io.radar_plots import RADAR_LAYOUTS, RadarLog
from ..models import (
    ConstantAcceleration,
    ConstantVelocity,
    CoordinatedTurn,
    MeasurementModel,
    NonlinearMotionModel,
    PositionMeasurement,
)
from ..models.continuous import MotionModel
from ..smoothers import imm_smooth, rts_smooth
from ..types import FilterResult, GaussianState
from .calibration import fit_clock_offset
from .causal import OnlineFit, refit_online
from .likelihood import LikelihoodFit, fit_by_likelihood
from .radar_log import TURN_PRIOR_STD, VELOCITY_PRIOR_STD_MPS, radar_inputs, radar_parameters

Model = Literal["cv", "ca", "ct", "cv+ca", "cv+ct"]
MODELS: tuple[str, ...] = ("cv", "ca", "ct", "cv+ca", "cv+ct")
IMM_MODELS: tuple[str, ...] = ("cv+ca", "cv+ct")  # CV and a manoeuvre model, switching
_AXES = ("x", "y", "z")


@dataclass(frozen=True)
class MotionFit:
    """Maximum-likelihood motion model of a position log.

    ``model`` "cv" (white acceleration, PSD [m^2/s^3]), "ca" (white jerk, [m^2/s^5]), "ct"
    (coordinated turn, turn PSD ``q_turn`` [rad^2/s^3]), or an IMM of CV and one of them
    ("cv+ca", "cv+ct": the manoeuvre model's PSDs ``q_ca_*`` or ``q_ct_*``, and the rate of
    switching between the two, ``switch_rate`` [1/s]); parameters ``q_horizontal``,
    ``r_horizontal`` [m^2] (and ``q_vertical``, ``r_vertical`` for a 3-D log) with their
    standard errors and intervals in ``fit``; ``clock``: how late the
    fixes are stamped against the log's velocity reports (``offset_s``,
    :func:`~adaptrack.tuning.calibration.fit_clock_offset`), if fitted.
    """

    model: str
    n_axes: int
    fit: LikelihoodFit
    clock: LikelihoodFit | None = None  # the fixes' clock offset against the velocity reports

    @property
    def offset_s(self) -> float:
        """How late the fixes are stamped [s] (0 without a clock fit)."""
        return self.clock.value("offset_s") if self.clock is not None else 0.0

    def filter(self, log: PositionLog, smooth: bool = False) -> tuple[FloatArray, FloatArray]:
        """Estimates at the log's times: state means (T, n) and covariances (T, n, n).

        State order ``x, y(, z), vx, vy(, vz)`` (and accelerations for "ca", the turn rate
        for "ct"; an IMM's, the states its models share), east-north-up.
        """
        est, _ = self.estimate(self.run(log), smooth)
        return est.mean, est.cov

    def estimate(
        self, run: FilterResult | IMMResult, smooth: bool = False
    ) -> tuple[GaussianState, FloatArray | None]:
        """Return a :meth:`run`'s estimates and an IMM's model probabilities (T, 2).

        Filtered, or smoothed (RTS, or the IMM smoother); no probabilities for one model.
        """
        if isinstance(run, FilterResult):
            return (rts_smooth(run) if smooth else run.filtered), None
        if not smooth:
            return run.filtered, run.mode_probabilities
        values = {name: self.fit.value(name) for name in self.fit.names}
        models = motion_models(self.model, values, self.n_axes)
        out = imm_smooth(run, models, switching_rates=_switching(values))
        return out.smoothed, out.mode_probabilities

    def filter_online(
        self, log: PositionLog | RadarLog
    ) -> tuple[FloatArray, FloatArray, OnlineFit]:
        """Return causal estimates, the parameters refitted from the log's own earlier fixes.

        :func:`~adaptrack.tuning.refit_online` starting at this fit's values (noise variances
        included): each estimate uses the fixes up to it, with the parameters of the last
        refit before it. Returns the filtered means (T, n), covariances (T, n, n), the refits.
        """
        n = self.run(_head(log, 1)).filtered.mean.shape[-1]  # checks the fit against the log

        def run(times: FloatArray, _: FloatArray, values: dict[str, float]) -> tuple[Any, Any]:
            out = _run(_head(log, times.size), self.model, values)
            est = out.filtered
            flat = np.concatenate([est.mean, est.cov.reshape(times.size, -1)], axis=1)
            return _step_log_likelihoods(out), flat

        values = {name: self.fit.value(name) for name in self.fit.names}
        online = refit_online([(log.times, _measured(log))], run, values)
        flat = online.estimates[0]
        return flat[:, :n], flat[:, n:].reshape(-1, n, n), online

    def run(self, log: PositionLog | RadarLog) -> FilterResult | IMMResult:
        """Return the filter's full result on ``log`` (an IMM's, or its innovations included)."""
        if log.n_axes != self.n_axes:
            raise ValueError(f"the fit is {self.n_axes}-D; the log has {log.n_axes} axes")
        if isinstance(log, RadarLog):
            missing = [c for c in log.components if f"r_{c}" not in self.fit.names]
            if missing:
                raise ValueError(
                    f"the fit has no noise variance for the log's {missing}: fit this layout"
                )
        return _run(log, self.model, {name: self.fit.value(name) for name in self.fit.names})


def _head(log: PositionLog | RadarLog, k: int) -> PositionLog | RadarLog:
    """Return the log's first ``k`` fixes or plots."""
    if isinstance(log, RadarLog):
        accel = None if log.range_accel is None else log.range_accel[:k]
        return replace(log, times=log.times[:k], plots=log.plots[:k], range_accel=accel)
    velocity = None if log.velocity is None else log.velocity[:k]
    return replace(log, times=log.times[:k], enu=log.enu[:k], velocity=velocity)


def _psds(values: dict[str, float], n_axes: int, prefix: str = "q") -> list[float]:
    """Per-axis PSDs from the horizontal / vertical parameters (``<prefix>_horizontal``...)."""
    horizontal = [values[f"{prefix}_horizontal"]] * 2
    return horizontal + ([values[f"{prefix}_vertical"]] if n_axes == 3 else [])


def motion_models(
    model: str, values: dict[str, float], n_axes: int
) -> list[MotionModel | NonlinearMotionModel]:
    """Return the fit's motion models: one, or an IMM's CV and its manoeuvre model."""
    if model not in IMM_MODELS:
        return [motion_model(model, values, n_axes)]
    manoeuvre = model.split("+")[1]
    return [
        motion_model("cv", values, n_axes),
        motion_model(manoeuvre, values, n_axes, prefix=f"q_{manoeuvre}"),
    ]


def _switching(values: dict[str, float]) -> list[list[float]]:
    """Return an IMM's generator of switching between its two models [1/s]."""
    rate = values["switch_rate"]
    return [[-rate, rate], [rate, -rate]]


def motion_model(
    model: str, values: dict[str, float], n_axes: int, prefix: str = "q"
) -> MotionModel | NonlinearMotionModel:
    """Return a motion model: CV, CA or the coordinated turn (``q_turn`` [rad^2/s^3]).

    Its PSDs are the parameters ``<prefix>_horizontal`` (and ``<prefix>_vertical``).
    """
    q = _psds(values, n_axes, prefix)
    if model == "ct":
        return CoordinatedTurn(q[0], values["q_turn"], q[-1], n_axes)
    if model == "cv":
        return ConstantVelocity(accel_psd=q, n_axes=n_axes)
    return ConstantAcceleration(jerk_psd=q, n_axes=n_axes)


def _inputs(
    log: PositionLog | RadarLog, model: str, values: dict[str, float]
) -> tuple[list[MotionModel | NonlinearMotionModel], MeasurementModel, list[GaussianState]]:
    """Return the filter's motion models, measurement model and priors (one a model)."""
    k = log.n_axes
    models = motion_models(model, values, k)
    if isinstance(log, RadarLog):
        pairs = [radar_inputs(log, motion, values) for motion in models]
        return models, pairs[0][0], [prior for _, prior in pairs]
    r = [values["r_horizontal"]] * 2 + ([values["r_vertical"]] if k == 3 else [])
    priors = []
    for motion in models:
        n = motion.state_dim
        mean = np.zeros(n)
        mean[:k] = log.enu[0]
        prior_var = np.full(n, VELOCITY_PRIOR_STD_MPS**2)  # velocity (acceleration): unknown
        prior_var[:k] = r
        if isinstance(motion, NonlinearMotionModel):
            prior_var[-1] = TURN_PRIOR_STD**2
        priors.append(GaussianState(mean, np.diag(prior_var), np.asarray(log.times[0])))
    return models, PositionMeasurement(np.array(r), _AXES[:k]), priors


def _measured(log: PositionLog | RadarLog) -> FloatArray:
    """Return the log's measurements: radar plots, or fixes in the local frame."""
    return log.plots if isinstance(log, RadarLog) else log.enu


def _imm(
    log: PositionLog | RadarLog,
    models: list[MotionModel | NonlinearMotionModel],
    sensor: MeasurementModel,
    priors: list[GaussianState],
    values: dict[str, float],
) -> IMMResult:
    """Run the compiled IMM kernel of the two models."""
    return imm_filter(log.times, _measured(log), models, sensor, None, priors,
                      initial_probs=[0.5, 0.5], switching_rates=_switching(values),
                      backend="numba")  # fmt: skip


def compiled_kernel(log: PositionLog | RadarLog, model: str) -> str | None:
    """Name (``module.function`` in :mod:`adaptrack.filters`) of the kernel :func:`_run` uses.

    None for the linear Kalman filter (its kernels compile in seconds).
    """
    if model in IMM_MODELS:
        return "_imm_kernel.imm_kernel"
    if isinstance(log, RadarLog) or model not in ("cv", "ca"):
        return "_ekf_kernel.ekf_kernel"
    return None


def _run(
    log: PositionLog | RadarLog, model: str, values: dict[str, float]
) -> FilterResult | IMMResult:
    """Filter ``log`` with these parameters (priors from the first fix or plot), compiled.

    A fit evaluates it hundreds of times.
    """
    models, sensor, priors = _inputs(log, model, values)
    if model in IMM_MODELS:
        return _imm(log, models, sensor, priors, values)
    (motion,), (prior,) = models, priors
    if isinstance(log, RadarLog) or isinstance(motion, NonlinearMotionModel):
        return ekf_filter(log.times, _measured(log), motion, sensor, prior, backend="numba")
    k = log.n_axes
    return kalman_filter(
        log.times, log.enu, motion, list(_AXES[:k]), sensor.noise_cov, prior, backend="numba"
    )


def _log_likelihood(log: PositionLog | RadarLog, model: str, values: dict[str, float]) -> float:
    """Log-likelihood of the log's measurements under the filter of :func:`_run`."""
    return float(_step_log_likelihoods(_run(log, model, values)).sum())


def _step_log_likelihoods(out: FilterResult | IMMResult) -> FloatArray:
    """Each step's log-likelihood of a run (T,)."""
    return out.info.log_likelihood if isinstance(out, FilterResult) else out.log_likelihood


def fit_motion(
    log: PositionLog | RadarLog,
    model: Model = "cv",
    clock_offset: bool = False,
    on_evaluation: Callable[[], None] | None = None,
) -> MotionFit:
    """Fit the motion PSD and the noise variances of ``log`` by maximum likelihood.

    Horizontal and vertical parameters are separate (a GNSS receiver's vertical noise is
    larger; a vehicle's vertical motion smaller); a radar log has one noise variance per
    measured component. Standard errors come from the curvature of
    the log-likelihood (they assume independent measurement noise). ``clock_offset``: also
    fit how late the fixes are stamped against the log's velocity reports (horizontal
    components; epochs with a report), which the log must have. Every model but CV starts
    from the CV fit's values (module constants ``IMM_QUIET``, ``IMM_START_RATE``,
    ``START_TURN_PSD`` for what CV does not have). ``on_evaluation`` is called after each
    evaluation of a likelihood (progress).
    """
    clock = None
    if clock_offset:
        if isinstance(log, RadarLog) or log.velocity is None:
            raise ValueError(
                "a clock offset needs the log's velocity reports (velocity_east_mps, "
                "velocity_north_mps or groundspeed_mps, track_deg columns)"
            )
        ok = np.all(np.isfinite(log.velocity[:, :2]), axis=1)
        clock = fit_clock_offset(
            log.times, log.enu[:, :2], log.times[ok], log.velocity[ok, :2], position_var=0.01,
            velocity_var=0.1,
        )  # fmt: skip
    if model not in MODELS:
        raise ValueError(f"model must be one of {MODELS}; got {model!r}")
    if log.times.size < 10:
        raise ValueError(f"a fit needs at least 10 fixes; the log has {log.times.size}")
    vertical = log.n_axes == 3
    initial = {"q_horizontal": 1.0} | ({"q_vertical": 0.1} if vertical else {})
    if isinstance(log, RadarLog):
        initial |= radar_parameters(log)
    else:
        initial |= {"r_horizontal": 1.0} | ({"r_vertical": 1.0} if vertical else {})

    def loglik_of(kind: str) -> Callable[[dict[str, float]], float]:
        def loglik(values: dict[str, float]) -> float:
            value = _log_likelihood(log, kind, values)
            if on_evaluation is not None:
                on_evaluation()
            return value

        return loglik

    cv = fit_by_likelihood(loglik_of("cv"), initial)
    if model == "cv":
        return MotionFit(model, log.n_axes, cv, clock)
    # The others start from the CV fit: far from it (noise variances off by 100x) their
    # likelihood can be too rough for the optimiser to leave its start.
    initial = {name: cv.value(name) for name in cv.names if not name.startswith("r_")}
    noise = {name: cv.value(name) for name in cv.names if name.startswith("r_")}
    if model in IMM_MODELS:  # a quieter CV and a manoeuvre model, switching now and then
        manoeuvre = model.split("+")[1]
        for axis in ("horizontal", "vertical") if vertical else ("horizontal",):
            initial[f"q_{manoeuvre}_{axis}"] = initial[f"q_{axis}"]
            initial[f"q_{axis}"] *= IMM_QUIET
        initial["switch_rate"] = IMM_START_RATE
    if model.endswith("ct"):
        initial["q_turn"] = START_TURN_PSD
    initial |= noise
    return MotionFit(model, log.n_axes, fit_by_likelihood(loglik_of(model), initial), clock)


IMM_QUIET = 0.1  # an IMM's CV starts at this fraction of the CV fit's PSDs
IMM_START_RATE = 0.05  # an IMM's switching rate to start from [1/s]
START_TURN_PSD = 1e-3  # the turn PSD to start from [rad^2/s^3]


def fit_toml(fit: MotionFit, measurement: str, source: str) -> str:
    """Return the fit as TOML text (``adaptrack fit``'s output, ``adaptrack filter``'s input)."""
    f = fit.fit
    lines = [
        "# adaptrack fit: maximum-likelihood motion model of a position log",
        "[fit]",
        f'measurement = "{measurement}"',
        f'model = "{fit.model}"',
        f"axes = {fit.n_axes}",
        f"source = {_toml_string(source)}",
        f"log_likelihood = {f.log_likelihood!r}",
        f"converged = {str(f.converged).lower()}",
    ]
    parts = [("parameters", f)] + ([("clock", fit.clock)] if fit.clock is not None else [])
    for table, part in parts:
        for name in part.names:
            lo, hi = part.interval(name)
            lines += [
                "",
                f"[fit.{table}.{name}]",
                f"value = {float(part.value(name))!r}",
                f"std_error = {float(part.std_error(name))!r}",
                f"low_95 = {float(lo)!r}",
                f"high_95 = {float(hi)!r}",
            ]
    return "\n".join(lines) + "\n"


def _parameter_names(measurement: str, model: str, axes: int, range_rate: bool) -> set[str]:
    """Return the parameters a fit of this layout has (``range_rate``: radar range-rates)."""
    prefixes = ["q"] + ([f"q_{model.split('+')[1]}"] if model in IMM_MODELS else [])
    names = {f"{p}_horizontal" for p in prefixes}
    names |= {f"{p}_vertical" for p in prefixes} if axes == 3 else set()
    names |= {"q_turn"} if model.endswith("ct") else set()
    names |= {"switch_rate"} if model in IMM_MODELS else set()
    if measurement in RADAR_LAYOUTS:
        comps = ["range", "azimuth"] + (["elevation"] if axes == 3 else [])
        return names | {f"r_{c}" for c in comps + (["range_rate"] if range_rate else [])}
    return names | {"r_horizontal"} | ({"r_vertical"} if axes == 3 else set())


def _toml_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def fit_from_toml(data: dict[str, object], where: str) -> tuple[MotionFit, str]:
    """Return the fit and measurement kind of a parsed ``fit.toml`` (errors name ``where``)."""
    table = data.get("fit")
    if not isinstance(table, dict):
        raise ValueError(f"{where}: no [fit] table (write one with `adaptrack fit`)")
    try:
        measurement, model, axes = table["measurement"], table["model"], int(table["axes"])
        params = table["parameters"]
        names = tuple(params)
        values = np.array([float(params[n]["value"]) for n in names])
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{where}: incomplete [fit] table ({exc})") from None
    expected = _parameter_names(str(measurement), str(model), axes, "r_range_rate" in names)
    if measurement not in ALL_MEASUREMENTS or model not in MODELS or set(names) != expected:
        raise ValueError(
            f"{where}: [fit] must name a measurement in {ALL_MEASUREMENTS}, a model in {MODELS} "
            f"and parameters {sorted(expected)}; got {measurement!r}, {model!r}, {sorted(names)}"
        )
    if not np.all(np.isfinite(values) & (values > 0)):
        raise ValueError(f"{where}: fit parameters must be positive and finite; got {values}")
    fit = LikelihoodFit(names, values, np.zeros((values.size, values.size)), np.nan, True, "")
    clock = None
    if "clock" in table:
        try:
            offset = float(table["clock"]["offset_s"]["value"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{where}: [fit.clock] needs offset_s.value ({exc})") from None
        if not np.isfinite(offset):
            raise ValueError(f"{where}: the clock offset must be finite; got {offset}")
        clock = LikelihoodFit(("offset_s",), np.array([offset]), np.zeros((1, 1)), np.nan, True,
                              "", signed=("offset_s",))  # fmt: skip
    return MotionFit(str(model), axes, fit, clock), str(measurement)


__all__ = ["MODELS", "MotionFit", "fit_from_toml", "fit_motion", "fit_toml"]
