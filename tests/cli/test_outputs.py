"""Outputs are checked before any work: a folder given as a file (and the reverse) is refused."""

import pytest

from adaptrack._files import check_writable


@pytest.mark.parametrize(
    "args",
    [
        ("simulate", "lx_default", "--out", "{dir}"),
        ("simulate", "--scene", "--duration", "5", "--out", "x.csv", "--truth", "{dir}"),
        ("simulate", "--scene", "--duration", "5", "--out", "x.csv", "--warnings", "{dir}"),
        ("tune", "lx_default", "--out", "{dir}"),
        ("track", "{det}", "--site", "lx_default", "--out", "{dir}"),
        ("track", "{det}", "--site", "lx_default", "--out", "t.csv", "--events", "{dir}"),
        ("report", "summary.json", "--out", "{dir}"),
        ("smooth", "{det}", "--site", "50,30,0", "--out", "{dir}"),
        ("evaluate", "zimchuk_table1", "--json", "{dir}"),
        ("serve", "--site", "lx_default", "--listen", "stdin", "--out", "{dir}"),
    ],
)
def test_a_folder_as_an_output_file_is_refused_before_any_work(cli, tmp_path, args):
    folder = tmp_path / "a_folder"
    folder.mkdir()
    det = tmp_path / "det.csv"
    det.write_text("radar,time_s,range_m,azimuth_rad,radial_speed_mps\nradar_A,0,50,0.1,-5\n")
    argv = [a.format(dir=folder, det=det) for a in args]
    code, _, err = cli(*argv)
    assert code == 1 and err == f"error: {folder} is a folder; give a file name\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_folder", "det.csv"]  # nothing new


def test_a_file_as_the_demo_folder_is_refused(cli, tmp_path):
    (tmp_path / "out").write_text("")
    code, _, err = cli("demo", "--out", tmp_path / "out")
    said = f"error: {tmp_path / 'out'} is a file; give a folder for the outputs\n"
    assert code == 1 and err == said


def test_a_missing_parent_is_fine_and_a_file_parent_is_not(tmp_path):
    check_writable(tmp_path / "new" / "deeper" / "x.csv")  # created when written
    assert not (tmp_path / "new").exists()
    (tmp_path / "f").write_text("")
    with pytest.raises(ValueError, match=r"is a file, not a folder"):
        check_writable(tmp_path / "f" / "x.csv")
