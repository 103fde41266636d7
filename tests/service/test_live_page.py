"""The live page in headless Chromium (Playwright): the map, a track that appears and moves."""

import threading

from playwright.sync_api import sync_playwright

from tests.browser import chromium_executable

from .live_process import replay


def test_a_track_appears_on_the_live_page_and_moves(serve, scene_files, tmp_path):
    browser_path = chromium_executable()
    svc = serve("--site", "lx_default", "--listen", "udp://127.0.0.1:0", "--http", "127.0.0.1:0",
                      "--out", str(tmp_path / "live.jsonl"))  # fmt: skip
    host, port = svc.wait_for("listening udp")
    page_host, page_port = svc.wait_for("serving http")
    sender = threading.Thread(
        target=replay, args=(scene_files.detections, f"udp://{host}:{port}", "2"), daemon=True
    )
    sender.start()  # 40 s of traffic in 20 s
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=browser_path, args=["--no-sandbox"])
            page = browser.new_page()
            errors = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(f"http://{page_host}:{page_port}/")
            page.wait_for_function(
                "document.getElementById('site').textContent.includes('lx_default')"
            )
            page.wait_for_selector("#tracks tbody tr", timeout=60_000)
            moving = (
                "[...document.querySelectorAll('#tracks tbody tr')].filter("
                "r => parseFloat(r.cells[3].textContent) > 15).map(r => [r.dataset.trackId,"
                " r.cells[1].textContent, r.cells[2].textContent])"
            )
            page.wait_for_function(f"{moving}.length > 0", timeout=60_000)
            track_id, east, north = page.evaluate(moving)[0]
            page.wait_for_function(
                "(() => { const r = document.querySelector("
                f"'#tracks tr[data-track-id=\"{track_id}\"]');"
                f" return r && (r.cells[1].textContent != '{east}' ||"
                f" r.cells[2].textContent != '{north}'); }})()",
                timeout=30_000,
            )
            counters = page.inner_text("#counters")
            assert "received" in counters and "rejected" in counters
            received = page.evaluate(
                "parseInt([...document.querySelectorAll('#counters tr')].find("
                "r => r.cells[0].textContent == 'received').cells[1].textContent)"
            )
            assert received > 0
            drawn = page.evaluate(
                "(() => { const c = document.getElementById('map');"
                " const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;"
                " let n = 0; for (let i = 0; i < d.length; i += 4) if (d[i + 3]) n++;"
                " return n; })()"
            )
            assert drawn > 1000  # roads, radars and tracks on the map
            assert errors == []
            browser.close()
    finally:
        sender.join(60)
        assert svc.terminate() == 0
