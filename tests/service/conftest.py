"""A short simulated scene written as the files a user would replay."""

from dataclasses import dataclass
from pathlib import Path

import pandas as pd
import pytest

from adaptrack.crossing.measurements_io import WARNING_COLUMNS
from adaptrack.crossing.simulation.scene import scene_spec, simulate_scene
from adaptrack.crossing.site.model import Site, load_site
from adaptrack.io.tables import write_table_atomic


@dataclass(frozen=True)
class SceneFiles:
    """Detections (CSV as ``adaptrack simulate --scene`` writes it), warnings, the site."""

    site: Site
    detections: Path
    warnings: Path

    @property
    def lines(self) -> list[str]:
        """The detection lines (no header)."""
        return self.detections.read_text().splitlines()[1:]


@pytest.fixture(scope="session")
def scene_files(tmp_path_factory) -> SceneFiles:
    """40 s of mixed traffic on lx_default (seed 7), with a warning interval."""
    site = load_site("lx_default")
    spec = scene_spec(site, duration_s=40.0, first_closure_s=15.0, closure_s=20.0, stalls=())
    rec = simulate_scene(site, spec, seed=7)
    folder = tmp_path_factory.mktemp("scene")
    det, warn = folder / "det.csv", folder / "warn.csv"
    write_table_atomic(rec.detections, det)
    write_table_atomic(pd.DataFrame(spec.warnings(), columns=WARNING_COLUMNS), warn)
    return SceneFiles(site, det, warn)


@pytest.fixture
def serve():
    """Start ``adaptrack serve ARGS`` processes; any still running at teardown is killed."""
    from .live_process import LiveProcess

    started: list[LiveProcess] = []

    def start(*args: str) -> LiveProcess:
        started.append(LiveProcess(*args))
        return started[-1]

    yield start
    for proc in started:
        if proc.proc.poll() is None:
            proc.kill()
