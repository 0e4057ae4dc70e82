"""The report pages checked in a real headless Chromium (Debian's; CI installs it): the one way
the tests start it and take a screenshot, and the marker that skips without it unless
$STATION_REQUIRE_BROWSER=1 (then a missing browser fails)."""
from __future__ import annotations

import os
import shutil
import subprocess

import numpy as np
import pytest

BROWSER = shutil.which("chromium") or shutil.which("chromium-browser")

needs_browser = pytest.mark.skipif(BROWSER is None and os.environ.get("STATION_REQUIRE_BROWSER") != "1",
                                   reason="no chromium (CI installs it)")


def screenshot(page, tmp_path, height: int) -> np.ndarray:
    """The page rendered headless at 1200 x ``height`` pixels, as an RGB array of ints."""
    assert BROWSER is not None, "STATION_REQUIRE_BROWSER=1 but no chromium on PATH"
    from PIL import Image

    shot = tmp_path / "page.png"
    subprocess.run([BROWSER, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                    "--disable-background-networking", "--disable-component-update", "--disable-sync",
                    f"--user-data-dir={tmp_path / 'profile'}", "--hide-scrollbars",
                    f"--window-size=1200,{height}", f"--screenshot={shot}", page.as_uri()],
                   check=True, capture_output=True, timeout=120)
    return np.asarray(Image.open(shot).convert("RGB")).astype(int)
