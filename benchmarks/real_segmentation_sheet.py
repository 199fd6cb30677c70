"""Contact sheet of real keyframes: image | VOC | ADE20K | combined | simulator checkpoint.

    python -m benchmarks.real_segmentation_sheet [--out docs/real_segmentation.png]

Six frames of TUM RGB-D `freiburg1_rpy` (../shared/data/tum_fr1_rpy, a real office desk seen by a
Kinect), then rooms no rule was tuned on: two real frames of slambook2_rgbd (a dining room) and one
of ICL-NUIM (a rendered living room), each segmented by the four shipped models, coloured with the
RECORDING.md label colours (`capture.recording.LABEL_COLORS`), with a legend. It also prints, per
model, the share of pixels of each label over the TUM frames.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from benchmarks.seg_models import SHARED, TUM_RGB, read_rgb, tum_files
from capture.recording import LABEL_COLORS, LABEL_NAMES
from process.segmentation import SegmentationConfig, Segmenter
from process.segmentation.models import shipped

FRAMES = (60, 180, 240, 420, 540, 660)  # indices into the sorted rgb/ listing
OTHERS = (  # (file under ../shared/data, caption)
    ("slambook2_rgbd/color/1.png", "slambook2 1"),
    ("slambook2_rgbd/color/4.png", "slambook2 4"),
    ("icl_nuim/color/00000.jpg", "ICL-NUIM 0"),
)
MODELS = ("voc", "ade20k", "combined", "simulator")
TITLES = ("image", "PASCAL VOC (int8)", "ADE20K (float)", "combined", "simulator checkpoint")
TILE = (320, 240)


def colourise(labels: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    """Return the labels in their RECORDING.md colours (RGB; unlabelled is black)."""
    return np.asarray(np.array(LABEL_COLORS, np.uint8)[labels], np.uint8)


def _text(img: npt.NDArray[np.uint8], text: str, xy: tuple[int, int], scale: float = 0.55) -> None:
    cv2.putText(img, text, xy, cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(img, text, xy, cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1, cv2.LINE_AA)


def _legend(width: int) -> npt.NDArray[np.uint8]:
    bar = np.full((40, width, 3), 40, np.uint8)
    x = 10
    for name, colour in zip(LABEL_NAMES, LABEL_COLORS, strict=True):
        cv2.rectangle(bar, (x, 10), (x + 20, 30), colour, -1)
        cv2.rectangle(bar, (x, 10), (x + 20, 30), (255, 255, 255), 1)
        _text(bar, name, (x + 26, 26), 0.5)
        x += 30 + 10 * len(name) + 14
    return bar


def frames() -> list[tuple[str, npt.NDArray[np.uint8]]]:
    """Return (caption, RGB image) of the sheet's frames: TUM's, then the other rooms' found."""
    files = tum_files()
    out = [(f"TUM fr1_rpy {files[i].name[:-4]}", read_rgb(files[i])) for i in FRAMES]
    return out + [
        (caption, read_rgb(SHARED / f)) for f, caption in OTHERS if (SHARED / f).is_file()
    ]


def sheet(threads: int = 1) -> tuple[npt.NDArray[np.uint8], dict[str, npt.NDArray[np.int64]]]:
    """Return the contact sheet (RGB) and each model's label pixel counts over the frames."""
    images = frames()
    cfg = SegmentationConfig(threads=threads)
    rows = [
        [np.asarray(cv2.resize(im, TILE, interpolation=cv2.INTER_AREA), np.uint8)]
        for _, im in images
    ]
    counts: dict[str, npt.NDArray[np.int64]] = {}
    for name in MODELS:
        seg = Segmenter(cfg, choice=shipped(name, "contact sheet", cfg), device="cpu")
        counts[name] = np.zeros(len(LABEL_NAMES), np.int64)
        for row, (caption, image) in zip(rows, images, strict=True):
            labels = seg.segment(image).labels
            if caption.startswith("TUM"):
                counts[name] += np.bincount(labels.ravel(), minlength=len(LABEL_NAMES))
            tile = cv2.resize(colourise(labels), TILE, interpolation=cv2.INTER_NEAREST)
            row.append(np.asarray(tile, np.uint8))
    header = np.full((30, TILE[0] * len(TITLES), 3), 40, np.uint8)
    for i, title in enumerate(TITLES):
        _text(header, title, (i * TILE[0] + 8, 21))
    body = [np.hstack(r) for r in rows]
    for (name, _), tile_row in zip(images, body, strict=True):
        _text(tile_row, name, (8, TILE[1] - 10), 0.45)
    return np.vstack([header, *body, _legend(header.shape[1])]), counts


def main(argv: list[str]) -> int:
    """Write the sheet and print each model's label shares."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/real_segmentation.png"))
    args = parser.parse_args(argv)
    if not TUM_RGB.is_dir():
        print(f"TUM fr1_rpy frames not found; expected them in {TUM_RGB}", file=sys.stderr)
        return 1
    image, counts = sheet()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(
        str(args.out), cv2.cvtColor(image, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 9]
    )
    print(f"{args.out}: {image.shape[1]}x{image.shape[0]}, {args.out.stat().st_size / 1e6:.2f} MB")
    for name, c in counts.items():
        shares = ", ".join(
            f"{LABEL_NAMES[i]} {100 * v / c.sum():.1f}%" for i, v in enumerate(c) if v
        )
        print(f"{name}: {shares}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
