"""Each shipped segmentation model side by side: steady ms per keyframe, agreement with the
combined teacher on held-out real frames, mIoU on unseen simulated rooms.

    python -m benchmarks.seg_models [checkpoint ...]   (`bench_segmentation` adds these as rows)

Real frames: TUM RGB-D `freiburg1_rpy` (../shared/data, or SEMREPLAY_SHARED_DATA), the frames in
HELD_OUT (the last fifth of the sequence, every 20th, never used to train anything). Agreement
is the share of pixels whose label equals the combined teacher's: agreement, not accuracy (the
teacher is not ground truth). A checkpoint whose training frames (`trained_frames` in its
info, written by `semreplay-process train`) span a held-out frame is refused. Simulated rooms:
SIM_SEEDS, never used for training, against their exact `/ground_truth/labels`, mIoU by
`process.evaluate.confusion_miou` (labels 1-10).
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from capture.recording import LABEL_NAMES, NUM_LABELS, RecordingReader
from process.errors import ReplayError
from process.evaluate import confusion_iou, confusion_matrix, confusion_miou
from process.segmentation import SegmentationConfig, Segmenter
from process.segmentation.models import SHIPPED, ModelChoice, shipped
from process.segmentation.weights import load_checkpoint

SHARED = Path(
    os.environ.get("SEMREPLAY_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)
TUM_RGB = SHARED / "tum_fr1_rpy" / "rgb"
HELD_OUT = tuple(range(580, 723, 20))  # 8 frames
SIM_SEEDS = (9001, 9002, 9003)
SIM_FRAMES = 4  # per seed, spread around the room (0.5 fps)
TEACHER = "combined"


@dataclass(frozen=True)
class ModelFigures:
    """What was measured of one model."""

    name: str
    ms: float  # median steady ms per 640x480 keyframe (load and first call excluded)
    load_s: float
    agreement: float | None  # with the teacher on held-out real frames
    miou: float | None  # on the simulated rooms
    iou: dict[int, float]
    # The model's agreement with itself when the frames are halved in size (then its labels
    # scaled back): how stable its labels are, a ceiling for a student that sees less detail.
    half_size_agreement: float | None = None


def read_rgb(path: Path) -> npt.NDArray[np.uint8]:
    """Return an image file as (H, W, 3) uint8 RGB."""
    bgr = cv2.imread(str(path))
    if bgr is None:
        raise FileNotFoundError(f"cannot read an image from {path}")
    return np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), np.uint8)


def tum_files() -> list[Path]:
    """Return the TUM fr1_rpy colour files in time order, or [] when the data is absent."""
    return sorted(TUM_RGB.glob("*.jpg")) if TUM_RGB.is_dir() else []


def real_frames() -> list[npt.NDArray[np.uint8]]:
    """Return the held-out TUM frames (RGB), or [] when the data is absent."""
    files = tum_files()
    return [read_rgb(files[i]) for i in HELD_OUT if files]


def held_out_stamps_ns() -> list[int]:
    """Return the stamps of the held-out TUM frames (their file names) in ns, [] when absent."""
    files = tum_files()
    return [stamp_ns(files[i].stem) for i in HELD_OUT if files]


def stamp_ns(text: str) -> int:
    """Return a TUM stamp ("1305031248.861712", seconds) in integer nanoseconds, as imported."""
    seconds, _, fraction = text.partition(".")
    return int(seconds) * 10**9 + int(fraction.ljust(9, "0")[:9])


def check_held_out(info: Mapping[str, Any], held_out: Sequence[int], name: str) -> None:
    """Raise ValueError if a checkpoint's training frames span one of the held-out stamps."""
    for span in info.get("trained_frames", []):
        inside = [s for s in held_out if span["first_stamp_ns"] <= s <= span["last_stamp_ns"]]
        if inside:
            raise ValueError(
                f"{name} was trained on {span['frames']} frames of {span['recording']} whose "
                f"stamps span {len(inside)} held-out frame(s) (the first at {inside[0]} ns); "
                "its agreement would not be held out: train on frames that end before them"
            )


def sim_frames(tmp: Path) -> list[tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint8]]]:
    """Return (colour, ground-truth labels) of the simulated rooms."""
    from capture.sim import simulate_recording

    out = []
    for seed in SIM_SEEDS:
        path = tmp / f"sim_{seed}.mcap"
        simulate_recording(path, seed=seed, frames=SIM_FRAMES, fps=0.5, width=640, height=480)
        with RecordingReader(path) as rec:
            for frame in rec.frames():
                gt = frame.ground_truth
                if gt is not None and gt.labels is not None:
                    out.append((frame.color, gt.labels))
    return out


def measure(
    names: tuple[str, ...] = tuple(SHIPPED),
    *,
    threads: int = 2,
    checkpoints: tuple[Path, ...] = (),
) -> list[ModelFigures]:
    """Return the figures of each model (the teacher first, as the others are compared to it).

    `checkpoints`: more models (our checkpoints, e.g. a distilled student) to measure.
    """
    held_out = held_out_stamps_ns()
    for path in checkpoints:
        check_held_out(load_checkpoint(path).info, held_out, path.name)
    real = real_frames()
    with tempfile.TemporaryDirectory() as tmp:
        sim = sim_frames(Path(tmp))
    cfg = SegmentationConfig(threads=threads)
    teacher: list[npt.NDArray[np.uint8]] = []
    out = []
    choices = [shipped(n, "benchmark", cfg) for n in sorted(names, key=lambda n: n != TEACHER)]
    choices += [ModelChoice(p.name, p, "torch", "benchmark") for p in checkpoints]
    for choice in choices:
        name = choice.name
        t0 = time.perf_counter()
        seg = Segmenter(cfg, choice=choice, device="cpu")
        seg.warm_up()
        load_s = time.perf_counter() - t0
        ms, labels = _timed(seg, real or [sim[0][0]])
        if name == TEACHER:
            teacher = labels
        agreement = (
            float(np.mean([np.mean(a == b) for a, b in zip(labels, teacher, strict=True)]))
            if real
            else None
        )
        half = _half_size_agreement(seg, real, labels) if name == TEACHER and real else None
        cm = np.zeros((NUM_LABELS, NUM_LABELS), np.int64)
        for color, gt in sim:
            cm += confusion_matrix(seg.segment(color).labels, gt)
        iou = confusion_iou(cm)
        out.append(ModelFigures(name, ms, load_s, agreement, confusion_miou(cm), iou, half))
    return out


def steady_ms(name: str, *, threads: int) -> float:
    """Return a shipped model's median ms per 640x480 frame on `threads` (load excluded)."""
    cfg = SegmentationConfig(threads=threads)
    seg = Segmenter(cfg, choice=shipped(name, "benchmark", cfg), device="cpu")
    seg.warm_up()
    return _timed(seg, real_frames() or [np.full((480, 640, 3), 128, np.uint8)] * 5)[0]


def _timed(
    seg: Segmenter, images: list[npt.NDArray[np.uint8]]
) -> tuple[float, list[npt.NDArray[np.uint8]]]:
    """Return the median ms per image of `seg.segment` and the labels it gave."""
    times, labels = [], []
    for image in images:
        t0 = time.perf_counter()
        labels.append(seg.segment(image).labels)
        times.append(time.perf_counter() - t0)
    return 1000 * statistics.median(times), labels


def _half_size_agreement(
    seg: Segmenter, images: list[npt.NDArray[np.uint8]], labels: list[npt.NDArray[np.uint8]]
) -> float:
    """Return the share of pixels a model labels the same on the frames and on half-size ones."""
    same = []
    for image, full in zip(images, labels, strict=True):
        h, w = image.shape[:2]
        small = np.asarray(
            cv2.resize(image, (w // 2, h // 2), interpolation=cv2.INTER_AREA), np.uint8
        )
        back = cv2.resize(seg.segment(small).labels, (w, h), interpolation=cv2.INTER_NEAREST)
        same.append(np.mean(back == full))
    return float(np.mean(same))


def main(argv: list[str]) -> int:
    """Print each model's figures (argv: more checkpoints to measure); 2 on a bad checkpoint."""
    try:
        figures = measure(checkpoints=tuple(Path(a) for a in argv))
    except (ReplayError, ValueError) as err:
        print(f"seg_models: {err}", file=sys.stderr)
        return 2
    for f in figures:
        agree = "n/a" if f.agreement is None else f"{f.agreement:.3f}"
        per = ", ".join(f"{LABEL_NAMES[k]} {v:.2f}" for k, v in f.iou.items())
        half = (
            ""
            if f.half_size_agreement is None
            else (f", agreement with itself on half-size frames {f.half_size_agreement:.3f}")
        )
        print(
            f"{f.name}: {f.ms:.0f} ms/keyframe (load {f.load_s:.2f} s), agreement with "
            f"{TEACHER} {agree}{half}, sim mIoU {f.miou:.3f} [{per}]"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
