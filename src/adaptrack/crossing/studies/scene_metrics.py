"""Scoring a scene's tracks against its truth.

GOSPA over time, identities, per-vehicle accuracy through association, false tracks, time to
confirm, hazard-event timing.

At every scoring epoch (the traffic steps, every ``every_s``) the road users in the controlled
zone are compared with the moving or stopped confirmed tracks in the zone (static objects and
tentative tracks are not reported road users), each track carried from its last scan to the
epoch at its velocity. GOSPA's optimal assignment (cut-off ``c``) pairs users with tracks; a
pair's errors count towards the user's class (every epoch in the zone, stopped ones included).
A reported track in the zone that is never paired is a false track; a user's time to confirm
runs from its first scoring epoch in the zone to its first paired one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..._typing import FloatArray
from ...analysis.confidence import rms_with_bounds
from ...analysis.gospa import gospa, identity_counts
from ..simulation.scene import STEP_S, STOPPED_MPS, SceneTruth
from .compliance import CONFIDENCE, POSITION_LIMIT_M, SPEED_LIMIT_KMH, bound_level, verdict_of

TRUTH_COLUMNS = ["object_id", "vehicle_class", "time_s", "east_m", "north_m", "speed_mps",
                 "in_zone"]  # fmt: skip  # what scoring reads of the truth (`simulate --truth`)
HAZARD_COLUMNS = ["to_crossing_m"]  # and what the stopped-between-the-barriers events need
USER_COLUMNS = ["object_id", "vehicle_class", "position_rms_m", "speed_rms_kmh", "coverage",
                "epochs"]  # fmt: skip  # SceneScore.users
USER_COVERAGE = 0.9  # a road user counts as tracked when paired at this share of its epochs
UNREPORTED = ("static", "tentative")  # track statuses that are not road users
TRACK_COLUMNS = ["track_id", "time_s", "east_m", "north_m", "speed_mps", "east_speed_mps",
                 "north_speed_mps", "from_crossing_m", "status"]  # fmt: skip  # and of tracks


@dataclass(frozen=True)
class SceneScore:
    """Scores of one scene (see module docstring); per-class rows in ``classes``."""

    gospa_mean: float  # [m]
    gospa_localisation: float  # the mean parts of GOSPA^2 [m^2] (analysis.gospa)
    gospa_missed: float
    gospa_false: float
    id_switches: int
    fragmentations: int
    classes: pd.DataFrame  # class, position_rms_m, position_upper_m, speed_rms_kmh, ..., verdict
    gospa_series: pd.DataFrame  # time_s, gospa, n_truth, n_tracks
    n_epochs: int
    false_tracks: int = 0  # reported tracks in the zone never paired with a road user
    hours: float = 0.0  # the scoring epochs' span [h]
    confirm_delays_s: FloatArray = field(default_factory=lambda: np.zeros(0))  # per user
    never_confirmed: int = 0  # road users in the zone never paired with a track
    users: pd.DataFrame = field(default_factory=pd.DataFrame)  # per road user: USER_COLUMNS

    def users_meeting(self, coverage: float = USER_COVERAGE) -> int:
        """Road users within 0.7 m and 2 km/h RMS, paired at ``coverage`` of their zone epochs."""
        if not len(self.users):
            return 0
        u = self.users
        return int(((u["position_rms_m"] <= POSITION_LIMIT_M) & (u["speed_rms_kmh"]
                    <= SPEED_LIMIT_KMH) & (u["coverage"] >= coverage)).sum())  # fmt: skip


def score_scene(
    truth: SceneTruth | pd.DataFrame,
    tracks: pd.DataFrame,
    zone_m: float,
    *,
    c: float = 5.0,
    every_s: float = 0.5,
    confidence: float = CONFIDENCE,
) -> SceneScore:
    """Score ``tracks`` (rows of :func:`~adaptrack.crossing.scene.tracker.track_scene`).

    ``truth``: the scene's, or its table (:data:`TRUTH_COLUMNS`, as ``adaptrack simulate
    --truth`` writes it). Per class, the RMS bounds at ``confidence`` take the vehicle as the
    sampling unit (its epochs are one track's, correlated) and give the verdict as in
    :mod:`adaptrack.crossing.studies.compliance` (0.7 m, 2 km/h).
    """
    tab = _table_of(truth)
    k_truth = np.rint(tab["time_s"].to_numpy() / STEP_S).astype(np.int64)
    stride = max(1, round(every_s / STEP_S))
    reported = tracks[~tracks["status"].isin(UNREPORTED)] if len(tracks) else tracks
    scan_t = np.unique(reported["time_s"].to_numpy()) if len(reported) else np.zeros(0)
    by_time = {t: g for t, g in reported.groupby("time_s")} if len(reported) else {}
    truth_by_k = {
        k: g
        for k, g in tab[(k_truth % stride == 0) & tab["in_zone"].to_numpy()].groupby(
            k_truth[(k_truth % stride == 0) & tab["in_zone"].to_numpy()]
        )
    }
    series, pairs_log, assignments = [], [], []
    first_in_zone: dict[int, float] = {}  # each user's first scoring epoch in the zone [s]
    first_paired: dict[int, float] = {}  # ... and its first with a track
    reported_ids: set[int] = set()
    for k in sorted(truth_by_k):
        tau = k * STEP_S
        g = truth_by_k[k]
        j = np.searchsorted(scan_t, tau, side="right") - 1
        if j >= 0 and tau - scan_t[j] <= 0.2:
            est = by_time[scan_t[j]]
            est = est[est["from_crossing_m"] <= zone_m]
            dt = tau - scan_t[j]
            e_xy = (
                est[["east_m", "north_m"]].to_numpy()
                + dt * est[["east_speed_mps", "north_speed_mps"]].to_numpy()
            )
        else:
            est = reported.iloc[:0]
            e_xy = np.zeros((0, 2))
        t_xy = g[["east_m", "north_m"]].to_numpy()
        res = gospa(t_xy, e_xy, c)
        series.append(
            (tau, res.distance, res.localisation, res.missed, res.false, len(g), len(est))
        )
        ids = g["object_id"].to_numpy()
        tids = est["track_id"].to_numpy() if len(est) else np.zeros(0, int)
        assignments.append({int(ids[i]): int(tids[j_]) for i, j_ in res.pairs})
        reported_ids.update(int(t) for t in tids)
        for oid in ids:
            first_in_zone.setdefault(int(oid), tau)
        for i, _ in res.pairs:
            first_paired.setdefault(int(ids[i]), tau)
        for i, j_ in res.pairs:
            pairs_log.append(
                (
                    int(ids[i]), str(g["vehicle_class"].iloc[i]),
                    float(np.hypot(*(t_xy[i] - e_xy[j_]))),
                    float(est["speed_mps"].iloc[j_] - g["speed_mps"].iloc[i]),
                )
            )  # fmt: skip
    s = pd.DataFrame(
        series,
        columns=["time_s", "gospa", "localisation", "missed", "false", "n_truth", "n_tracks"],
    )
    pl = pd.DataFrame(pairs_log, columns=["object_id", "vehicle_class", "pos_err", "speed_err"])
    zone_epochs = (
        tab[(k_truth % stride == 0) & tab["in_zone"].to_numpy()].groupby("vehicle_class").size()
    )
    rows = []
    limits = np.array([POSITION_LIMIT_M, SPEED_LIMIT_KMH])
    for cls, g in pl.groupby("vehicle_class"):
        per_vehicle = (
            g.assign(p2=g["pos_err"] ** 2, s2=(3.6 * g["speed_err"]) ** 2, n=1)
            .groupby("object_id")[["p2", "s2", "n"]]
            .sum()
        )
        squares = per_vehicle[["p2", "s2"]].to_numpy()
        counts = np.repeat(per_vehicle[["n"]].to_numpy(), 2, axis=1)
        rms, lower, upper = rms_with_bounds(squares, counts, bound_level(confidence))
        rows.append(
            {
                "class": cls,
                "position_rms_m": float(rms[0]),
                "position_upper_m": float(upper[0]),
                "speed_rms_kmh": float(rms[1]),
                "speed_upper_kmh": float(upper[1]),
                "verdict": verdict_of(rms, lower, upper, limits),
                "coverage": len(g) / int(zone_epochs.get(cls, len(g))),
                "epochs": len(g),
                "vehicles": len(per_vehicle),
            }
        )
    users = _per_user(pl, tab[(k_truth % stride == 0) & tab["in_zone"].to_numpy()])
    ident = identity_counts(assignments)
    paired_ids = {t for a in assignments for t in a.values()}
    delays = np.array([first_paired[o] - first_in_zone[o] for o in first_paired])
    return SceneScore(
        float(s["gospa"].mean()) if len(s) else 0.0,
        float(s["localisation"].mean()) if len(s) else 0.0,
        float(s["missed"].mean()) if len(s) else 0.0,
        float(s["false"].mean()) if len(s) else 0.0,
        ident.switches,
        ident.fragmentations,
        pd.DataFrame(rows),
        s,
        len(s),
        len(reported_ids - paired_ids),
        float(s["time_s"].iloc[-1] - s["time_s"].iloc[0]) / 3600.0 if len(s) else 0.0,
        delays,
        len(first_in_zone) - len(first_paired),
        users,
    )


def _per_user(pairs: pd.DataFrame, zone_rows: pd.DataFrame) -> pd.DataFrame:
    """Each road user's RMS errors over its paired epochs and its share of zone epochs paired."""
    epochs = zone_rows.groupby("object_id").agg(
        vehicle_class=("vehicle_class", "first"), zone_epochs=("time_s", "size")
    )
    got = (
        pairs.assign(p2=pairs["pos_err"] ** 2, s2=(3.6 * pairs["speed_err"]) ** 2)
        .groupby("object_id")
        .agg(p2=("p2", "mean"), s2=("s2", "mean"), epochs=("p2", "size"))
    )
    table = epochs.join(got, how="left")
    return pd.DataFrame({
        "object_id": table.index.to_numpy(),
        "vehicle_class": table["vehicle_class"].to_numpy(),
        "position_rms_m": np.sqrt(table["p2"].to_numpy(float)),
        "speed_rms_kmh": np.sqrt(table["s2"].to_numpy(float)),
        "coverage": table["epochs"].fillna(0).to_numpy(float) / table["zone_epochs"].to_numpy(),
        "epochs": table["epochs"].fillna(0).to_numpy(np.int64),
    })  # fmt: skip


def _table_of(truth: SceneTruth | pd.DataFrame) -> pd.DataFrame:
    """Return the truth's table (a table is its own)."""
    return truth.table if isinstance(truth, SceneTruth) else truth


def hazard_stops(
    truth: SceneTruth | pd.DataFrame, barrier_m: float, *, confirm_s: float = 0.5
) -> pd.DataFrame:
    """Road users standing still between the barriers: the true "stopped" hazards.

    A user slower than ``STOPPED_MPS`` within ``barrier_m`` of the crossing for at least
    ``confirm_s`` (its first such standstill); ``truth`` or its table (with
    :data:`HAZARD_COLUMNS`). Returns object_id, stop_time_s (the standstill's first epoch),
    east_m, north_m.
    """
    tab = _table_of(truth)
    still = (tab["speed_mps"].to_numpy() < STOPPED_MPS) & (
        np.abs(tab["to_crossing_m"].to_numpy()) <= barrier_m
    )
    rows = []
    for oid, g in tab[still].groupby("object_id"):
        t = g["time_s"].to_numpy()
        runs = np.split(np.arange(t.size), np.flatnonzero(np.diff(t) > 1.5 * STEP_S) + 1)
        long = [r for r in runs if t[r[-1]] - t[r[0]] >= confirm_s - 1e-9]
        if long:
            first = g.iloc[long[0][0]]
            rows.append((int(oid), float(first.time_s), float(first.east_m), float(first.north_m)))
    return pd.DataFrame(rows, columns=["object_id", "stop_time_s", "east_m", "north_m"])


def _events_of(events: pd.DataFrame, kind: str) -> tuple[pd.DataFrame, FloatArray, FloatArray]:
    """Events of one kind in time order, with their times (E,) and positions (E, 2)."""
    if not len(events):
        return events, np.zeros(0), np.zeros((0, 2))
    ev = events[events["event"] == kind].sort_values("time_s")
    return ev, ev["time_s"].to_numpy(), ev[["east_m", "north_m"]].to_numpy()


def event_outcomes(
    truth: SceneTruth | pd.DataFrame,
    events: pd.DataFrame,
    barrier_m: float,
    *,
    window_s: float = 30.0,
    match_m: float = 5.0,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Match "stopped between the barriers" events with the true hazards (:func:`hazard_stops`).

    Each hazard takes the first unmatched event from 2 s before its stop to ``window_s`` after,
    within ``match_m`` of where it stopped. Returns the hazards with ``delay_s`` (NaN: missed)
    and the events that match no hazard (false events).
    """
    stops = hazard_stops(truth, barrier_m)
    ev, t, xy = _events_of(events, "stopped_between_barriers")
    used = np.zeros(t.size, dtype=bool)
    delays = []
    for st in stops.itertuples():
        near = np.hypot(xy[:, 0] - st.east_m, xy[:, 1] - st.north_m) <= match_m
        ok = ~used & near & (t >= st.stop_time_s - 2.0) & (t <= st.stop_time_s + window_s)
        k = int(np.argmax(ok)) if ok.any() else -1
        if k >= 0:
            used[k] = True
        delays.append(t[k] - st.stop_time_s if k >= 0 else np.nan)
    return stops.assign(delay_s=np.array(delays, dtype=float)), ev[~used]


def stop_line_outcomes(
    truth: SceneTruth, events: pd.DataFrame, *, horizon_s: float = 15.0, match_m: float = 5.0
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Match "will not stop before the stop line" events with the users that ran the line.

    A user that ran it (``truth.stop_line_runs``: its front crossed the stop line while the
    lights flashed or the barriers were down) takes the first unmatched event from
    ``horizon_s`` before it crossed until 0.5 s after, raised within ``match_m`` of where the
    user was at the event. Returns the runs with ``lead_s`` (crossing time less event time;
    NaN: missed) and the events that match no run (false).
    """
    runs = truth.stop_line_runs
    ev, t, xy = _events_of(events, "will_not_stop_before_stop_line")
    used = np.zeros(t.size, dtype=bool)
    tab = truth.table
    lead = []
    for run in runs.itertuples():
        path = tab[tab["object_id"] == run.object_id]
        k = -1
        for j in np.flatnonzero(
            ~used & (t >= run.cross_time_s - horizon_s) & (t <= run.cross_time_s + 0.5)
        ):
            at = path.iloc[int(np.argmin(np.abs(path["time_s"].to_numpy() - t[j])))]
            if np.hypot(at.east_m - xy[j, 0], at.north_m - xy[j, 1]) <= match_m:
                k = int(j)
                break
        if k >= 0:
            used[k] = True
        lead.append(run.cross_time_s - t[k] if k >= 0 else np.nan)
    return runs.assign(lead_s=np.array(lead, dtype=float)), ev[~used]


__all__ = [
    "HAZARD_COLUMNS",
    "TRACK_COLUMNS",
    "TRUTH_COLUMNS",
    "SceneScore",
    "event_outcomes",
    "hazard_stops",
    "score_scene",
    "stop_line_outcomes",
]
