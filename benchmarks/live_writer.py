"""Write a recording again at camera speed, as a capture would: the writer side of `--follow`.

`python -m benchmarks.live_writer SRC.mcap DST.mcap [--speed 1.0]` re-records SRC's frames into
DST at their own rate (chunks closed every second), stamped with the wall clock at the moment
each frame is written, so a follower's lag is `now - stamp`. It ends with a finished file.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from capture.recording import RecordingReader, RecordingWriter


def write_live(src: Path, dst: Path, *, speed: float = 1.0) -> int:
    """Copy SRC's frames into DST at `speed` times their recorded rate; return the frame count."""
    with RecordingReader(src) as rec, RecordingWriter(dst) as writer:
        device = rec.metadata.get("device")
        if device is not None:  # a capture says which camera it is before its first frame
            writer.write_metadata("device", device)
        first_stamp: int | None = None
        t0 = time.monotonic()
        n = 0
        for frame in rec.frames():
            first_stamp = frame.stamp_ns if first_stamp is None else first_stamp
            due = t0 + (frame.stamp_ns - first_stamp) / 1e9 / speed
            time.sleep(max(0.0, due - time.monotonic()))
            stamp = time.time_ns()
            if n == 0 and frame.depth_to_color is not None:
                writer.write_calibration(frame.depth_to_color, stamp_ns=stamp)
            writer.write_color(frame.color, stamp_ns=stamp, intrinsics=frame.color_intrinsics)
            depth_mm = np.clip(frame.depth_m * 1000.0 + 0.5, 0, 65535).astype(np.uint16)
            writer.write_depth(
                depth_mm, stamp_ns=stamp, intrinsics=frame.depth_intrinsics, aligned=frame.aligned
            )
            gt = frame.ground_truth
            if gt is not None:
                writer.write_ground_truth(
                    stamp_ns=stamp, world_from_camera=gt.world_from_camera, labels=gt.labels
                )
            writer.flush_if_due()
            n += 1
    return n


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("src", type=Path)
    parser.add_argument("dst", type=Path)
    parser.add_argument("--speed", type=float, default=1.0)
    args = parser.parse_args(argv)
    print(write_live(args.src, args.dst, speed=args.speed))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
