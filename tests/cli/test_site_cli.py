"""``adaptrack site list / new / check`` and ``--version``, run in-process."""

import sys
from importlib.metadata import version
from pathlib import Path

import pytest
from pydantic import BaseModel

from adaptrack.crossing.site.authoring import site_template
from adaptrack.crossing.site.model import builtin_sites, load_site
from adaptrack.crossing.site.schema import SiteFile


def _field_names(model: type[BaseModel]) -> set[str]:
    """Every key of a schema model and of the models nested in it."""
    names = set()
    for name, info in model.model_fields.items():
        names.add(name)
        for arg in _types(info.annotation):
            if isinstance(arg, type) and issubclass(arg, BaseModel):
                names |= _field_names(arg)
    return names


def _types(annotation):
    yield annotation
    for arg in getattr(annotation, "__args__", ()) or ():
        yield from _types(arg)
    for arg in getattr(annotation, "__metadata__", ()) or ():
        yield from _types(arg)
    origin = getattr(annotation, "__origin__", None)
    if origin is not None:
        yield from _types(origin)


def test_version_is_the_installed_one(cli):
    code, out, _ = cli("--version")
    assert code == 0 and out.strip() == f"adaptrack {version('adaptrack')}"


def test_site_list_names_every_builtin_site(cli):
    code, out, _ = cli("site", "list")
    assert code == 0
    for name in builtin_sites():
        assert name in out


def test_template_shows_every_key_of_the_site_format():
    text = site_template()
    keys = _field_names(SiteFile)
    assert len(keys) > 60  # the walk reached the nested tables
    missing = sorted(k for k in keys if f"{k} =" not in text and f"[{k}" not in text)
    assert not missing, f"keys of the site format absent from the template: {missing}"


def test_site_new_then_check_writes_map_and_coverage(cli, tmp_path):
    path = tmp_path / "mine.toml"
    code, out, err = cli("site", "new", str(path))
    assert code == 0, err
    site = load_site(path)
    assert site.name == "my_crossing" and "scene" in site.source
    code, out, err = cli("site", "check", str(path), "--out", str(tmp_path / "chk"))
    assert code == 0, err
    assert "my_crossing: valid (2 roads, 2 radars, 4 cases, a scene)" in out
    assert "north" in out and "100 %" in out
    svg = (tmp_path / "chk" / "site_map.svg").read_text()
    assert svg.startswith("<svg") and "stop line" in svg and "pole_n" in svg
    assert "road south" in svg and "static clutter" in svg
    cover = (tmp_path / "chk" / "coverage.svg").read_text()
    assert cover.startswith("<svg") and "road north" in cover
    code, _, err = cli("site", "new", str(path))
    assert code == 1 and "exists; pass --force" in err
    assert cli("site", "new", str(path), "--force")[0] == 0


def test_site_check_names_a_misspelt_key(cli, tmp_path):
    path = tmp_path / "typo.toml"
    path.write_text(site_template().replace("\nstop_line_m = ", "\nstop_lin_m = "))
    code, _, err = cli("site", "check", str(path), "--out", str(tmp_path / "chk"))
    assert code == 1
    assert err.strip() == (
        f"error: {path}: the site: unknown key 'stop_lin_m' (did you mean 'stop_line_m'?)"
    )
    assert not (tmp_path / "chk").exists()  # nothing written for an invalid site


def test_site_check_reports_a_blind_zone(cli, tmp_path):
    path = tmp_path / "narrow.toml"  # the north radar's field narrowed to +-5 deg: near part unseen
    text = site_template().replace("fov_half_deg = 60.0          ", "fov_half_deg = 5.0 ", 1)
    path.write_text(text)
    code, out, err = cli("site", "check", str(path), "--out", str(tmp_path / "chk"))
    assert code == 0, err
    assert "blind zone on road north: 0.0-" in out
    svg = (tmp_path / "chk" / "site_map.svg").read_text()
    assert "blind zone (its radar does not see it)" in svg


def test_site_check_refuses_a_file_as_its_output_folder(cli, tmp_path):
    (tmp_path / "f").write_text("")
    code, _, err = cli("site", "check", "lx_default", "--out", str(tmp_path / "f"))
    assert code == 1 and "is a file; give a folder" in err


def _tuned(path, site: str, fingerprint: str = ""):
    """A tuned.toml of one CV candidate, recording ``site`` (and its fingerprint)."""
    from adaptrack.crossing.studies.selection import Candidate, SiteTuning

    cv = Candidate("cv", "road EKF (CV)", {"accel_psd": 0.5}, 0.4, 10, 0.42, 0.5, "car / x")
    tuning = SiteTuning(site, "tail", 0, 1, 2, (cv,), "cv", "test", site_fingerprint=fingerprint)
    path.write_text(tuning.to_toml())
    return path


def test_the_site_comes_from_the_option_or_the_tuned_configuration(tmp_path):
    from adaptrack.crossing.studies.selection import load_tuning, site_for

    stress = load_site("lx_stress")
    tuned = _tuned(tmp_path / "tuned.toml", "lx_stress", stress.fingerprint)
    assert load_tuning(tuned).site_fingerprint == stress.fingerprint  # written and read back
    assert site_for(None, tuned).name == "lx_stress"
    assert site_for("lx_stress", tuned).name == "lx_stress"
    assert site_for("lx_default", None).name == "lx_default"
    with pytest.raises(ValueError, match="tuned for site 'lx_stress', not 'lx_default'"):
        site_for("lx_default", tuned)
    with pytest.raises(ValueError, match="--site is required"):
        site_for(None, None)
    changed = _tuned(tmp_path / "old.toml", "lx_stress", "0123456789abcdef")
    with pytest.raises(ValueError, match="another version of site 'lx_stress'"):
        site_for("lx_stress", changed)
    own = _tuned(tmp_path / "own.toml", "my_crossing")
    with pytest.raises(ValueError, match="not built in: pass its file with --site"):
        site_for(None, own)
    path = tmp_path / "mine.toml"
    path.write_text(site_template())
    assert site_for(str(path), own).name == "my_crossing"  # no fingerprint recorded: name only


def test_track_refuses_a_configuration_tuned_for_another_site(cli, tmp_path):
    tuned = _tuned(tmp_path / "tuned.toml", "lx_stress")
    det = tmp_path / "det.csv"
    det.write_text("radar,time_s,range_m,azimuth_rad,radial_speed_mps\nradar_A,0.0,50,0.1,-5\n")
    args = ("track", str(det), "--out", str(tmp_path / "est.csv"), "--config", str(tuned))
    code, _, err = cli(*args, "--site", "lx_default")
    assert code == 1 and "tuned for site 'lx_stress', not 'lx_default'" in err
    code, _, err = cli("track", str(det), "--out", str(tmp_path / "est.csv"))
    assert code == 1 and "--site is required" in err
    assert not (tmp_path / "est.csv").exists()


MAP = Path(__file__).parents[2] / "examples" / "maps" / "t_junction.osm"
needs_lanelet2 = pytest.mark.skipif(  # on Linux the test extra installs it
    sys.platform != "linux", reason="lanelet2 publishes Linux wheels only"
)


@needs_lanelet2
def test_site_import_then_check(cli, tmp_path):
    out = tmp_path / "tj.toml"
    code, stdout, err = cli("site", "import", MAP, "--crossing", "-40,0", "--out", out)
    assert code == 0, err
    assert "--origin -40.00,0.00" in stdout
    code, stdout, err = cli("site", "check", out, "--out", tmp_path / "chk")
    assert code == 0, err
    assert "driven paths: west->east, west->north, east->north" in stdout
    assert (tmp_path / "chk" / "site_map.svg").stat().st_size > 1000
    code, _, err = cli("site", "import", MAP, "--crossing", "-40,0", "--out", out)
    assert code == 1 and "exists; pass --force" in err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((), "give the crossing point"),
        (("--crossing", "1"), "--crossing takes two numbers A,B; got '1'"),
        (("--crossing", "0,0", "--crossing-latlon", "0,0"), "give the crossing point"),
        (("--crossing", "0,60"), "no lane of the map passes within 15 m"),
    ],
)
@needs_lanelet2
def test_site_import_errors(cli, tmp_path, args, message):
    code, _, err = cli("site", "import", MAP, *args, "--out", tmp_path / "x.toml")
    assert code == 1 and message in err, err
    assert not (tmp_path / "x.toml").exists()


@needs_lanelet2
def test_site_import_of_a_file_that_is_no_map(cli, tmp_path):
    bad = tmp_path / "bad.osm"
    bad.write_text("<osm version='0.6'></osm>\n", encoding="utf-8")
    code, _, err = cli("site", "import", bad, "--crossing", "0,0", "--out", tmp_path / "o.toml")
    assert code == 1 and "holds no lanelet" in err, err
    code, _, err = cli("site", "import", tmp_path / "none.osm", "--crossing", "0,0")
    assert code == 1 and "no such map file" in err, err
