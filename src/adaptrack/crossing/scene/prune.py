"""Prune stage of a scan: expired, departed and duplicate tracks, and the confirmed rows."""

from __future__ import annotations

import math

import numba
import numpy as np

from ...tracking.lifecycle import expired_rows
from .body import bodies_overlap
from .rows import rows_where


@numba.njit(cache=True)
def confirmed_rows(  # type: ignore[no-untyped-def]
    confirmed, time_s, last_hit_s, stopped, moved, x, spread, corridor, lateral_m, coasting_s,
    codes,
):  # fmt: skip
    """Rows of the confirmed tracks and their status codes.

    ``codes``: the codes of confirmed, coasting (no detection for more than ``coasting_s``
    [s]), stopped, static (stopped, never moved) and tentative. A confirmed track that has not
    moved yet and lies on the body of an established track (one that has moved or stopped) of
    its corridor (within ``lateral_m`` across, ``BODY_HALF_SPREADS`` spreads either side
    along) is reported tentative: most such tracks are a body's far reflections or a ghost,
    which :func:`merged_rows` drops once they have moved; one that outlives that test is
    another road user.
    """
    rows = rows_where(confirmed, True)
    status = np.empty(rows.size, np.int64)
    for k in range(rows.size):
        i = rows[k]
        if stopped[i]:
            status[k] = codes[2] if moved[i] else codes[3]
            continue
        status[k] = codes[1] if time_s[i] - last_hit_s[i] > coasting_s else codes[0]
        if moved[i]:
            continue
        for j in rows:
            if (
                j != i and (moved[j] or stopped[j]) and corridor[j] == corridor[i]
                and abs(x[i, 3] - x[j, 3]) < lateral_m
                and bodies_overlap(x, spread, i, j)
            ):  # fmt: skip
                status[k] = codes[4]
                break
    return rows, status


@numba.njit(cache=True)
def merged_rows(  # type: ignore[no-untyped-def]
    rows, corridor, x, p, spread, static, stopped, moved, ids, confirmed, lateral_m, speed_mps,
    parts_speed, young, settled, settled_lateral_m, born,
):  # fmt: skip
    """Of the tracks ``rows``, those to drop (bool per entry of ``rows``).

    The younger of two tracks on one body (see ``SceneTracker._retire``); the other arrays are
    per track.

    Pairs in row order; a confirmed track outlives an unconfirmed one whatever their ages; a track
    already dropped removes no other. Besides tracks within their spreads of each other, two
    road users that have moved, faster than ``parts_speed``, whose bodies (``BODY_HALF_SPREADS``
    spreads either side) overlap are one long body tracked in two parts (no one drives into
    another): the younger goes, and the body's other reflections, on no body now, teach the
    survivor its length. A ``young`` static object (not yet learnt clutter), ``born`` after the
    road user, whose body overlaps a stopped road user's (``BODY_HALF_SPREADS`` spreads either
    side along, within ``lateral_m`` across) is that road user's reflection: it goes (one that
    stood there before the road user came is clutter under it, e.g. a rail; a bus stopped with
    an under-learnt body would otherwise see its far end taken for a post, which then holds part
    of its reflections, learns their spread and leaves the bus track a shorter body further off;
    a point of clutter learns a small spread and stays off a body beside it). A ``settled``
    track (one followed for a while) is not dropped for a track more than ``settled_lateral_m``
    beside it: two road users side by side (a motorcycle filtering past a queue) stay apart,
    while a duplicate of one body sits in its lane.
    """
    m = rows.size
    drop = np.zeros(m, dtype=np.bool_)  # per entry of rows
    for ka in range(m):
        a = rows[ka]
        for kb in range(ka + 1, m):
            b = rows[kb]
            if corridor[a] != corridor[b]:
                continue
            if static[a] != static[b]:
                s, r = (a, b) if static[a] else (b, a)  # the static one, the road user
                ks, kr = (ka, kb) if static[a] else (kb, ka)
                if (
                    young[s] and born[s] > born[r] and stopped[r] and moved[r] and not drop[kr]
                    and bodies_overlap(x, spread, s, r)
                    and abs(x[s, 3] - x[r, 3]) < lateral_m
                ):  # fmt: skip
                    drop[ks] = True
                continue
            sv = math.sqrt(p[a, 1, 1] + p[b, 1, 1])
            du = abs(x[a, 0] - x[b, 0])
            parts = (
                moved[a] and moved[b] and not (stopped[a] or stopped[b])
                and min(abs(x[a, 1]), abs(x[b, 1])) > parts_speed
                and bodies_overlap(x, spread, a, b)
            )  # fmt: skip
            if not (
                (du < spread[a] + spread[b] + 0.5 or parts)
                and abs(x[a, 3] - x[b, 3]) < lateral_m
                and abs(x[a, 1] - x[b, 1]) < speed_mps + 3.0 * sv
            ):
                continue
            older, younger = (ka, kb) if ids[a] < ids[b] else (kb, ka)
            if confirmed[rows[younger]] and not confirmed[rows[older]]:
                older, younger = younger, older
            if settled[rows[younger]] and abs(x[a, 3] - x[b, 3]) > settled_lateral_m:
                continue
            if not drop[older]:
                drop[younger] = True
    return drop


@numba.njit(cache=True)
def retired_rows(time_s, t, site, cfg):  # type: ignore[no-untyped-def]
    """Tracks to delete after a scan at ``time_s`` (bool per track).

    Those the life-cycle rules expire (:func:`adaptrack.tracking.lifecycle.expired_rows`,
    with the position sigma along and across the corridor), those that left their corridor
    (``length_m`` per corridor) and, of the rest, the younger of two on one body
    (:func:`merged_rows`; a static object younger than ``clutter_age_s`` may be absorbed if
    ``absorb_young_static``; a confirmed road user that has moved and been followed longer
    than ``settled_s`` is settled).
    Bundles: ``t`` (the track rows, :class:`~.bundles.TrackRows`), ``site`` (the site,
    :class:`~.bundles.SiteTables`), ``cfg`` (the settings, :class:`~.bundles.Settings`); a setting
    named here is the field of ``cfg``.
    """
    track_time_s, x, p, corridor, spread = t.time_s, t.x, t.p, t.corridor, t.spread
    stopped, moved, occluded, ids, confirmed = t.stopped, t.moved, t.occluded, t.ids, t.confirmed
    misses, born_s, last_hit_s = t.misses, t.born_s, t.last_hit_s
    length_m = site.length_m
    stopped_detectable, tentative_misses = cfg.stationary_detections, cfg.tentative_misses
    max_tentative_s, max_coast_s = cfg.max_tentative_s, cfg.max_coast_s
    max_coast_stopped_s, max_coast_hidden_s = cfg.max_coast_stopped_s, cfg.max_coast_hidden_s
    max_position_std_m, max_stopped_misses = cfg.max_position_std_m, cfg.max_stopped_misses
    lateral_m, speed_mps = cfg.merge_lateral_m, cfg.merge_speed_mps
    parts_speed, clutter_age_s = cfg.merge_parts_speed_mps, cfg.clutter_age_s
    absorb_young_static, settled_s = cfg.absorb_young_static, cfg.merge_settled_s
    settled_lateral_m = cfg.merge_settled_lateral_m
    n = x.shape[0]
    position_std = np.zeros(n)
    for i in range(n):
        position_std[i] = math.sqrt(p[i, 0, 0] + p[i, 3, 3])
    gone = expired_rows(
        confirmed, misses, born_s, last_hit_s, time_s, stopped, occluded, position_std, True,
        stopped_detectable, tentative_misses, max_tentative_s, max_coast_s,
        max_coast_stopped_s, max_coast_hidden_s, max_position_std_m, max_stopped_misses,
    )  # fmt: skip
    dead = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        dead[i] = x[i, 0] < 0 or x[i, 0] > length_m[corridor[i]]
    for i in gone:
        dead[i] = True
    alive = rows_where(dead, False)
    young = np.empty(n, dtype=np.bool_)
    settled = np.empty(n, dtype=np.bool_)
    static = np.empty(n, np.bool_)
    for i in range(n):
        age = track_time_s[i] - born_s[i]
        young[i] = absorb_young_static and age < clutter_age_s
        settled[i] = confirmed[i] and moved[i] and age > settled_s
        static[i] = stopped[i] and not moved[i]
    merged = merged_rows(
        alive, corridor, x, p, spread, static, stopped, moved, ids, confirmed, lateral_m,
        speed_mps, parts_speed, young, settled, settled_lateral_m, born_s,
    )  # fmt: skip
    for k in range(alive.size):
        dead[alive[k]] |= merged[k]
    return dead
