"""A screenshot of the Rerun web viewer showing a run's `.rrd`, for the README.

    python -m benchmarks.viewer_screenshot RUN/recording.rrd OUT.png [--wait 90]

Serves the file with `semreplay-view --web`, opens it in headless system Chromium (WebGL on
SwiftShader, as the browser test does) and saves the viewport once two screenshots taken
`--settle` seconds apart are the same (the viewer has loaded and drawn everything), or after
`--wait` seconds. Needs Debian's chromium and chromium-driver (`make sysdeps`) and selenium.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
FLAGS = (  # also the browser test's (tests/helpers_browser.py)
    "--headless",
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-dev-shm-usage",
)


def _png(driver: object) -> npt.NDArray[np.uint8]:
    data = driver.get_screenshot_as_png()  # type: ignore[attr-defined]
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    return np.asarray(image, np.uint8)


def shoot(
    rrd: Path, out: Path, *, size: tuple[int, int], wait_s: float, settle_s: float, port: int
) -> float:
    """Save the viewer's screenshot of `rrd` to `out`; return the seconds it took to settle."""
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    command = [sys.executable, "-m", "viz", str(rrd), "--web", "--port", str(port)]
    command += ["--grpc-port", str(port + 1)]
    view = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
    profile = Path(tempfile.mkdtemp(prefix="semreplay-shot-"))
    try:
        assert view.stdout is not None
        line = view.stdout.readline()  # "Serving FILE at ADDRESS (Ctrl-C stops)"
        if " at http://" not in line:
            raise RuntimeError(f"semreplay-view printed {line!r}, not an address")
        options = Options()
        options.binary_location = str(CHROMIUM)
        for flag in (*FLAGS, f"--window-size={size[0]},{size[1]}", f"--user-data-dir={profile}"):
            options.add_argument(flag)
        driver = webdriver.Chrome(options=options, service=Service(str(CHROMEDRIVER)))
        try:
            driver.get(line.split(" at ", 1)[1].split()[0])
            t0 = time.monotonic()
            last = _png(driver)
            while time.monotonic() - t0 < wait_s:
                time.sleep(settle_s)
                shot = _png(driver)
                if shot.shape == last.shape and np.mean(shot != last) < 1e-4:
                    break
                last = shot
            cv2.imwrite(str(out), last)
            return time.monotonic() - t0
        finally:
            driver.quit()
    finally:
        view.terminate()
        view.wait(timeout=30)
        shutil.rmtree(profile, ignore_errors=True)


def main(argv: list[str]) -> int:
    """Write the screenshot; print where and how long the viewer took."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rrd", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--width", type=int, default=1600)
    parser.add_argument("--height", type=int, default=860)
    parser.add_argument("--wait", type=float, default=120.0, help="seconds at most")
    parser.add_argument("--settle", type=float, default=10.0, help="seconds between checks")
    parser.add_argument("--port", type=int, default=9190)
    args = parser.parse_args(argv)
    for binary in (CHROMIUM, CHROMEDRIVER):
        if not binary.is_file():
            print(f"{binary} not found: install Debian's chromium and chromium-driver")
            return 2
    try:
        import selenium  # noqa: F401
    except ImportError:
        print("selenium is not installed: pip install -e '.[dev]'")
        return 2
    if not args.rrd.is_file():
        print(f"expected a .rrd file, found nothing at {args.rrd}")
        return 2
    try:
        took = shoot(
            args.rrd, args.out, size=(args.width, args.height), wait_s=args.wait,
            settle_s=args.settle, port=args.port,
        )  # fmt: skip
    except RuntimeError as err:  # the viewer would not serve the file
        print(f"no screenshot of {args.rrd}: {err}")
        return 2
    print(f"{args.out}: the viewer settled after {took:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
