"""The web viewer draws our blueprint in a real browser: headless Debian Chromium, software WebGL.

`semreplay-view X.rrd --web` serves a small recording (helpers_browser.write_small_rrd); the test
waits until the screenshot shows the colour image's four quadrants in the right-hand column and
the labelled map (floor and chair colours) in the 3-D view at the top left. ~1-2 min on 2 cores.
"""

from __future__ import annotations

import socket
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from helpers_browser import (
    QUADRANTS,
    have_chromium,
    headless_chromium,
    near,
    screenshot,
    served,
    wait_for,
    write_small_rrd,
)
from helpers_viz import assert_rrd_verifies

from capture.recording import LABEL_COLORS, LABEL_NAMES

FIRST_FRAME_TIMEOUT_S = 240.0
FLOOR = LABEL_COLORS[LABEL_NAMES.index("floor")]
CHAIR = LABEL_COLORS[LABEL_NAMES.index("chair")]

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(have_chromium() is not None, reason=str(have_chromium())),
]


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def _views_drawn(image: np.ndarray[Any, np.dtype[np.uint8]]) -> dict[str, bool]:
    """Return which expected views the screenshot shows, by colour and place."""
    h, w = image.shape[:2]
    right, world = image[:, int(0.6 * w) :], image[: int(0.45 * h), : int(0.6 * w)]
    return {
        **{f"colour quadrant {c}": int(near(right, c).sum()) > 300 for c in QUADRANTS},
        "floor in the 3-D view": int(near(world, FLOOR, tol=40).sum()) > 300,
        "chair in the 3-D view": int(near(world, CHAIR, tol=40).sum()) > 30,
        "not blank": float(image.std()) > 20.0,
    }


def test_the_web_viewer_draws_the_views_in_headless_chromium(tmp_path: Path) -> None:
    rrd = write_small_rrd(tmp_path / "small.rrd")
    assert_rrd_verifies(rrd)
    t0 = time.monotonic()
    shots: list[np.ndarray[Any, np.dtype[np.uint8]]] = []

    def drawn() -> bool:
        shots.append(screenshot(driver))
        return all(_views_drawn(shots[-1]).values())

    with (
        served(rrd, port=_free_port(), grpc_port=_free_port()) as address,
        headless_chromium(tmp_path / "profile") as driver,
    ):
        driver.get(address)
        ok = wait_for(drawn, timeout_s=FIRST_FRAME_TIMEOUT_S, every_s=3.0)
        canvases = driver.execute_script("return document.querySelectorAll('canvas').length")
    seconds = time.monotonic() - t0
    cv2.imwrite(str(tmp_path / "viewer.png"), cv2.cvtColor(shots[-1], cv2.COLOR_RGB2BGR))
    missing = [name for name, seen in _views_drawn(shots[-1]).items() if not seen]
    assert ok, f"after {seconds:.0f} s the viewer shows no {missing}: {tmp_path / 'viewer.png'}"
    assert canvases == 1  # the viewer draws everything into one WebGL canvas
    print(f"web viewer drew every view after {seconds:.0f} s")
