"""The scene kernels' named bundles, built for tests with only the fields a test sets."""

import numpy as np

from adaptrack.crossing.scene.bundles import RadarView
from adaptrack.crossing.scene.tracker import (
    SceneTracker,
    SceneTrackerConfig,
    _loop_settings,
    _track_rows,
    _Tracks,
)
from adaptrack.crossing.site.model import load_site
from adaptrack.tracking import LifecycleRules, TrackBook


def track_rows(n, n_radars=1, **columns):
    """Rows of ``n`` new tentative tracks, with ``columns`` (the arrays themselves) in place."""
    tracks = _Tracks.opened(
        np.zeros(n, np.int64), np.zeros((n, 4)), np.tile(np.eye(4), (n, 1, 1)), 0.0, 1.0, n_radars
    )
    book = TrackBook(LifecycleRules())
    book.add(n, 0.0)
    return _track_rows(book, tracks)._replace(**columns)


def settings(**values):
    """The default tracker's loop settings, with ``values`` in place."""
    return _loop_settings(SceneTrackerConfig())._replace(**values)


def site_tables(site="lx_default", **tables):
    """The compiled site of a built-in site's tracker, with ``tables`` in place."""
    return SceneTracker(load_site(site))._tables._replace(**tables)


def radar_view(radar, noise_tab, noise_cnt, fields=None, pd_tab=None, pd_cnt=None):
    """One radar as the kernels read it (fields of view and P_D: none given, none used)."""
    fields = np.zeros((1, 2)) if fields is None else fields
    pd_tab = np.ones((1, 2, 1)) if pd_tab is None else pd_tab
    pd_cnt = np.ones(1, np.int64) if pd_cnt is None else pd_cnt
    return RadarView(radar, noise_tab, noise_cnt, fields, pd_tab, pd_cnt)


def scan_radar_view(site, r):
    """Radar ``r`` of compiled site tables as the scan loop hands it to the stages."""
    return RadarView(
        site.radar[r], site.noise_tab[r], site.noise_cnt[r],
        site.fields[r, : site.field_count[r]], site.pd_tab[r], site.pd_cnt[r],
    )  # fmt: skip
