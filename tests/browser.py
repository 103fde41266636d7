"""Headless Chromium for the tests that render a page (CI installs Debian chromium)."""

import os
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest


@dataclass(frozen=True)
class Rendered:
    """What Chromium made of a page: screenshot size [bytes], its log and the DOM it built."""

    screenshot_bytes: int
    log: str
    dom: str


def chromium_executable() -> str:
    """Path of the installed Chromium.

    Skips when Chromium is not installed, except in CI (``CI=true``), where it fails.
    """
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        if os.environ.get("CI") == "true":
            pytest.fail("chromium must be installed in CI (.ci/run installs Debian chromium)")
        pytest.skip("chromium is not installed on this machine; CI installs it")
    return chromium


def render_in_chromium(page: Path, work: Path, height_px: int = 2600) -> Rendered:
    """Screenshot ``page`` and dump its DOM in headless Chromium (profile under ``work``).

    Skips when Chromium is not installed, except in CI (``CI=true``), where it fails.
    """
    chromium = chromium_executable()
    shot = work / "shot.png"
    flags = [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={work / 'profile'}",
        "--enable-logging=stderr",
        "--v=0",
    ]
    proc = subprocess.run(
        [chromium, *flags, f"--screenshot={shot}", f"--window-size=1100,{height_px}",
         page.as_uri()],
        capture_output=True,
        text=True,
        timeout=120,
    )  # fmt: skip
    dom = subprocess.run(
        [chromium, *flags, "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=120
    ).stdout
    return Rendered(shot.stat().st_size if shot.exists() else 0, proc.stderr, dom)
