"""The web viewer in a real browser: a small .rrd to show, and headless Debian Chromium to look.

Chromium is the system's (`/usr/bin/chromium`, installed by scripts/sysdeps.sh), driven by
Selenium through the system's chromedriver: nothing is downloaded at test time. WebGL runs on
SwiftShader (software), so the first frame takes tens of seconds on a small machine.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Final

import numpy as np

from benchmarks import viewer_screenshot
from capture.recording import Intrinsics, RgbdFrame
from viz import layout
from viz.rerun_log import RerunLogger

CHROMIUM: Final = viewer_screenshot.CHROMIUM
CHROMEDRIVER: Final = viewer_screenshot.CHROMEDRIVER
WINDOW: Final = (1280, 800)
CHROMIUM_FLAGS: Final = (*viewer_screenshot.FLAGS, f"--window-size={WINDOW[0]},{WINDOW[1]}")
# The colour image of the small recording: four flat quadrants, easy to find in a screenshot.
QUADRANTS: Final = ((230, 30, 30), (30, 200, 40), (40, 60, 230), (240, 220, 30))


def quadrant_image(height: int = 120, width: int = 160) -> np.ndarray[Any, np.dtype[np.uint8]]:
    """Return an RGB image of the four QUADRANTS colours (top-left, top-right, ...)."""
    image = np.zeros((height, width, 3), np.uint8)
    h, w = height // 2, width // 2
    for i, colour in enumerate(QUADRANTS):
        image[(i // 2) * h : (i // 2 + 1) * h, (i % 2) * w : (i % 2 + 1) * w] = colour
    return image


def write_small_rrd(path: Path, *, frames: int = 10) -> Path:
    """Write a small .rrd of every kind of view: images, depth, labels, map, trajectory, plots."""
    k = Intrinsics(160, 120, 150.0, 150.0, 80.0, 60.0)
    colour = quadrant_image()
    depth = np.tile(np.linspace(1.0, 3.0, 160, dtype=np.float32), (120, 1))
    labels = np.zeros((120, 160), np.uint8)
    labels[60:, :] = 2  # floor
    labels[20:60, 50:110] = 5  # chair
    rng = np.random.default_rng(0)
    floor = np.c_[rng.uniform(-1, 1, (2000, 2)), np.zeros(2000)][:, [0, 2, 1]] + [0, 1, 2]
    chair = rng.normal([0.0, 0.6, 2.0], 0.1, (500, 3))
    with RerunLogger(path, recording_name="browser") as log:
        for i in range(frames):
            log.set_frame(i, stamp_ns=1_000_000_000 + i * 33_333_333)
            frame = RgbdFrame(i, 1_000_000_000 + i * 33_333_333, colour, depth, k, k, aligned=True)
            log.log_frame(frame, keyframe=i % 3 == 0)
            pose = np.eye(4)
            pose[0, 3] = 0.05 * i
            log.log_pose(pose, keyframe=i % 3 == 0)
            xy = rng.uniform(0, 160, (20, 2))
            log.log_keypoints(xy * [1, 0.75], inliers=np.arange(20) < 15)
            log.log_tracking(100 + 10 * i, status="ok")
            if i % 3 == 0:
                log.log_segmentation(labels, confidence=np.full((120, 160), 0.8))
            log.log_timing("odometry", 0.01 * (1 + i % 4))
        log.set_stage(layout.STAGE_FUSED)
        points = np.concatenate([floor, chair])
        ids = np.r_[np.full(len(floor), 2), np.full(len(chair), 5)].astype(np.uint8)
        log.log_map("fused", points, labels=ids)
        log.log_text("small recording for the browser test")
    return path


def have_chromium() -> str | None:
    """Return why the browser test cannot run here, or None when it can."""
    for binary in (CHROMIUM, CHROMEDRIVER):
        if not binary.is_file():
            return (
                f"{binary} not found; install Debian's chromium and chromium-driver (make sysdeps)"
            )
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is not installed; pip install -e '.[dev]'"
    return None


@contextmanager
def headless_chromium(user_data_dir: Path) -> Iterator[Any]:
    """Yield a Selenium driver of headless system Chromium with a fresh profile."""
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    options = Options()
    options.binary_location = str(CHROMIUM)
    for flag in (*CHROMIUM_FLAGS, f"--user-data-dir={user_data_dir}"):
        options.add_argument(flag)
    driver = webdriver.Chrome(options=options, service=Service(str(CHROMEDRIVER)))
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(user_data_dir, ignore_errors=True)


def wait_for(predicate: Any, *, timeout_s: float, every_s: float = 2.0) -> bool:
    """Call predicate until it is true or timeout_s passed; return its last answer."""
    deadline = time.monotonic() + timeout_s
    while True:
        if predicate():
            return True
        if time.monotonic() > deadline:
            return False
        time.sleep(every_s)


@contextmanager
def served(rrd: Path, *, port: int, grpc_port: int) -> Iterator[str]:
    """Run `semreplay-view rrd --web` and yield the address it prints; stop it afterwards."""
    import subprocess
    import sys

    command = [sys.executable, "-m", "viz", str(rrd), "--web"]
    command += ["--port", str(port), "--grpc-port", str(grpc_port)]
    view = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
    try:
        assert view.stdout is not None
        line = view.stdout.readline()  # "Serving FILE at ADDRESS (Ctrl-C stops)"
        assert " at http://" in line, f"semreplay-view printed {line!r}"
        yield line.split(" at ", 1)[1].split()[0]
    finally:
        view.terminate()
        view.wait(timeout=30)


def screenshot(driver: Any) -> np.ndarray[Any, np.dtype[np.uint8]]:
    """Return the browser's viewport as an RGB array."""
    import cv2

    bgr = cv2.imdecode(np.frombuffer(driver.get_screenshot_as_png(), np.uint8), cv2.IMREAD_COLOR)
    assert bgr is not None, "the browser's screenshot is not a PNG"
    rgb: np.ndarray[Any, np.dtype[np.uint8]] = np.ascontiguousarray(bgr[..., ::-1], np.uint8)
    return rgb


def near(
    image: np.ndarray[Any, np.dtype[np.uint8]], colour: tuple[int, int, int], *, tol: int = 30
) -> np.ndarray[Any, np.dtype[np.bool_]]:
    """Return where an RGB image is within tol of colour in every channel."""
    diff = np.abs(image.astype(np.int16) - np.array(colour, np.int16))
    mask: np.ndarray[Any, np.dtype[np.bool_]] = np.all(diff <= tol, axis=-1)
    return mask
