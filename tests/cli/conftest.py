"""In-process CLI runs: exit status, stdout and stderr of ``adaptrack.cli.main``."""

import pytest

from adaptrack.cli import main


@pytest.fixture
def cli(capsys, monkeypatch):
    """Run the CLI in-process (200 columns); return (exit status, stdout, stderr)."""
    monkeypatch.setenv("COLUMNS", "200")

    def run(*args):
        with pytest.raises(SystemExit) as info:
            main([str(a) for a in args])
        out = capsys.readouterr()
        return info.value.code, out.out, out.err

    return run
