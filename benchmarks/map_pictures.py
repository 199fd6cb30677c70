"""The phase-I (fused) and phase-III (refined) maps of a `process run` folder, side by side.

`python -m benchmarks.map_pictures RUN_DIR OUT.png` writes the two top views (process.preview)
next to each other, both seen along the same up vector, for the README.
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

from process import outputs
from process.cloud import read_cloud
from process.errors import ReplayError
from process.preview import render_top_view, up_vector

TITLE_PX = 34  # height of the title band above each view


def main(argv: list[str]) -> int:
    """Write the run folder's fused and refined maps side by side; 2 on bad arguments."""
    if len(argv) != 2:
        print("usage: python -m benchmarks.map_pictures RUN_DIR OUT.png", file=sys.stderr)
        return 2
    run, out = Path(argv[0]), Path(argv[1])
    try:
        fused = read_cloud(run / outputs.MAP_FUSED)
        refined = read_cloud(run / outputs.MAP_REFINED)
    except ReplayError as err:
        print(f"map_pictures: {err} (expected a `process run` output folder)", file=sys.stderr)
        return 2
    up = up_vector(refined.points, refined.labels, None)
    views = []
    for title, cloud in (("phase I: fused", fused), ("phase III: refined", refined)):
        view = render_top_view(cloud.points, cloud.labels, up=up)
        white = (255, 255, 255)  # the title in a band of its own, not over the map
        image = cv2.copyMakeBorder(view, TITLE_PX, 0, 0, 0, cv2.BORDER_CONSTANT, value=white)
        cv2.putText(image, title, (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (0, 0, 0), 2)
        views.append(image)
    cv2.imwrite(str(out), np.hstack(views)[..., ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
