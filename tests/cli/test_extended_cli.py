"""``adaptrack track --tracker extended``: its options and its errors, run in-process."""

import pandas as pd


def test_the_command_line_refuses_options_the_extended_tracker_does_not_take(cli, tmp_path):
    det = tmp_path / "det.csv"
    table = pd.DataFrame({"radar": ["radar_A"], "time_s": [0.0], "range_m": [30.0],
                          "azimuth_rad": [0.0], "radial_speed_mps": [-3.0]})  # fmt: skip
    table.to_csv(det, index=False)
    code, _, err = cli("track", det, "--site", "lx_default", "--out", tmp_path / "t.csv",
                       "--tracker", "extended", "--warnings", det)  # fmt: skip
    assert code == 1 and "--tracker extended takes raw detections only" in err
    (tmp_path / "bg.npz").write_bytes(b"no map")
    code, _, err = cli("track", det, "--site", "lx_default", "--out", tmp_path / "t.csv",
                       "--tracker", "extended", "--background", tmp_path / "bg.npz")  # fmt: skip
    assert code == 1 and "not a background map" in err and err.count("\n") <= 2
    code, _, err = cli("track", det, "--site", "lx_default", "--out", tmp_path / "t.csv",
                       "--tracker", "fast")  # fmt: skip
    assert code == 1 and "--tracker must be 'corridor' or 'extended'" in err
    code, out, _ = cli("track", det, "--site", "lx_default", "--out", tmp_path / "t.csv",
                       "--tracker", "extended")  # fmt: skip
    assert code == 0 and "1 of 1" in out  # every detection accounted for
