"""`python -m benchmarks fuzz N`: N mutants of a small recording through `info` and `run`.

Each mutant (truncation, byte flips, zeroed range, chunk surgery, a file that is not MCAP) is
given to `semreplay-capture info` and `semreplay-process run --stages odometry --no-viz`, in
this process, and every outcome is classed: exit 0, a clean one-line error, a traceback, a
hang (over the time limit) or a partial file (a temporary left in --out). The counts by class
are printed; a traceback, a hang or a partial file is a bug.
The mutants are deterministic (seeded), so a failing one can be rebuilt from its number.
Not a `bench_*` module: `make bench` does not run it.
"""

from __future__ import annotations

import random
import signal
import struct
import sys
import tempfile
import time
import traceback
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Final

import numpy as np

OUTCOMES: Final = ("exit 0", "one-line error", "traceback", "hang", "partial file")
_HEAD: Final = struct.Struct("<BQ")
W, H = 96, 72


@dataclass(frozen=True, slots=True)
class Outcome:
    """How one command ended on one input."""

    kind: str  # one of OUTCOMES; "partial file": a temporary was left in --out
    detail: str  # the error line or the traceback's last line


def write_base_recording(path: Path, *, frames: int = 10) -> Path:
    """Write a small unaligned RGB-D recording with ground truth, in many small chunks."""
    from capture.recording import Extrinsics, Intrinsics, RecordingWriter

    rng = np.random.default_rng(7)
    texture = rng.integers(0, 255, (H + 8, W + 64, 3), dtype=np.uint8)
    k = Intrinsics(W, H, 90.0, 90.0, W / 2 - 0.5, H / 2 - 0.5)
    extr = Extrinsics.from_librealsense([1, 0, 0, 0, 1, 0, 0, 0, 1], [0.015, 0.0, 0.0])
    with RecordingWriter(path, chunk_interval_s=0.05, chunk_size_bytes=16_000) as writer:
        writer.write_metadata("device", {"name": "fuzz", "depth_scale_m": "0.001"})
        writer.write_calibration(extr, stamp_ns=1_000_000_000)
        for i in range(frames):
            stamp = 1_000_000_000 + i * 33_333_333
            color = np.ascontiguousarray(texture[4 : 4 + H, 2 * i : 2 * i + W])
            depth = np.full((H, W), 2000, np.uint16)
            depth[: H // 3] = 2500
            writer.write_color(color, stamp_ns=stamp, intrinsics=k)
            writer.write_depth(depth, stamp_ns=stamp, intrinsics=k, aligned=False)
            pose = np.eye(4)
            pose[0, 3] = 0.005 * i
            writer.write_ground_truth(stamp_ns=stamp, world_from_camera=pose)
    return path


def top_level_records(data: bytes) -> list[tuple[int, int, int]]:
    """Return (opcode, start, end) of each top-level record of an intact MCAP file."""
    out, pos = [], 8
    while pos + _HEAD.size <= len(data) - 8:
        opcode, length = _HEAD.unpack_from(data, pos)
        out.append((opcode, pos, pos + _HEAD.size + length))
        pos += _HEAD.size + length
    return out


def mutate(data: bytes, seed: int) -> tuple[str, bytes]:
    """Return (what was done, the mutant) for one seed: the same seed gives the same mutant."""
    rng = random.Random(seed)
    kinds = ("truncate", "flip", "zero", "drop", "duplicate", "swap", "head", "tail", "junk")
    weights = (3, 4, 3, 2, 2, 2, 1, 1, 1)
    kind = rng.choices(kinds, weights)[0]
    n = len(data)
    if kind == "truncate":
        cut = rng.randrange(0, n)
        return f"truncate at {cut}", data[:cut]
    if kind in ("flip", "head", "tail"):
        lo, hi = {"flip": (0, n), "head": (0, min(n, 300)), "tail": (max(0, n - 3000), n)}[kind]
        out = bytearray(data)
        spots = [rng.randrange(lo, hi) for _ in range(rng.choice((1, 1, 2, 5, 20)))]
        for at in spots:
            out[at] ^= rng.randrange(1, 256)
        return f"{kind} flips at {spots[:5]}", bytes(out)
    if kind == "zero":
        at, size = rng.randrange(0, n), rng.choice((8, 64, 512, 4096, 40_000))
        return f"zero {size} at {at}", data[:at] + bytes(min(size, n - at)) + data[at + size :]
    if kind == "junk":
        choice = rng.randrange(5)
        junk = [b"", b"\x89MCAP0\r\n", b"ply\nformat ascii 1.0\n", rng.randbytes(5000)]
        junk.append(data[:8] + rng.randbytes(3000))
        return f"not mcap #{choice}", junk[choice]
    chunks = [(s, e) for op, s, e in top_level_records(data) if op == 0x06]
    if len(chunks) < 2:
        return "unchanged (no chunks)", data
    i, j = sorted(rng.sample(range(len(chunks)), 2))
    (a, b), (c, d) = chunks[i], chunks[j]
    if kind == "drop":
        return f"drop chunk {i}", data[:a] + data[b:]
    if kind == "duplicate":
        return f"duplicate chunk {i}", data[:b] + data[a:b] + data[b:]
    return f"swap chunks {i} {j}", data[:a] + data[c:d] + data[b:c] + data[a:b] + data[d:]


class _HangError(Exception):
    pass


def _alarm(signum: int, frame: object) -> None:
    raise _HangError


def classify(call: Callable[[], tuple[int, str]], *, limit_s: float = 60.0) -> Outcome:
    """Run call() -> (exit code, stderr) under a time limit and class how it ended."""
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, limit_s)
    try:
        code, err = call()
    except _HangError:
        return Outcome("hang", f"over {limit_s:g} s")
    except BaseException as exc:
        last = traceback.format_exception_only(type(exc), exc)[-1].strip()
        return Outcome("traceback", last)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    if code == 0:
        return Outcome("exit 0", "")
    if code == 1 and len(lines) == 1 and "Traceback" not in err:
        return Outcome("one-line error", lines[0][:200])
    return Outcome("traceback", err.strip().splitlines()[-1][:200] if err.strip() else str(code))


def capture_info(path: Path) -> tuple[int, str]:
    """Run `semreplay-capture info PATH` in this process; return (exit code, stderr)."""
    from typer.testing import CliRunner

    from capture.cli import app

    result = CliRunner().invoke(app, ["info", str(path)], catch_exceptions=False)
    return result.exit_code, result.stderr


def process_odometry(path: Path, out: Path) -> tuple[int, str]:
    """Run `semreplay-process run PATH --stages odometry --no-viz` in this process."""
    from typer.testing import CliRunner

    from process.cli import app

    args = ["run", str(path), "--out", str(out), "--stages", "odometry", "--no-viz", "--force"]
    result = CliRunner().invoke(app, args, catch_exceptions=False)
    return result.exit_code, result.stderr


def run_mutants(
    base: bytes, seeds: range, folder: Path, *, with_run: bool = True
) -> Iterator[tuple[int, str, str, Outcome]]:
    """Yield (seed, mutation, command, outcome) for every mutant and command."""
    for seed in seeds:
        what, data = mutate(base, seed)
        path = folder / f"mutant_{seed}.mcap"
        path.write_bytes(data)
        yield seed, what, "info", classify(partial(capture_info, path))
        if with_run:
            out = folder / "out"
            outcome = classify(partial(process_odometry, path, out))
            left = (
                sorted(p.name for p in out.iterdir() if p.name.startswith("."))
                if out.is_dir()
                else []
            )
            if left:
                outcome = Outcome("partial file", ", ".join(left))
            yield seed, what, "run", outcome
        path.unlink()


def main(argv: list[str]) -> int:
    """Fuzz N mutants (argv[0], default 1000); print counts per command and outcome."""
    import logging

    logging.disable(logging.CRITICAL)  # the expected warnings of damaged files are noise here
    count = int(argv[0]) if argv else 1000
    counts: Counter[tuple[str, str]] = Counter()
    bad: list[str] = []
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="semreplay_fuzz_") as tmp:
        base = write_base_recording(Path(tmp) / "base.mcap").read_bytes()
        for seed, what, command, outcome in run_mutants(base, range(count), Path(tmp)):
            counts[(command, outcome.kind)] += 1
            if outcome.kind in ("traceback", "hang", "partial file"):
                bad.append(f"seed {seed} ({what}) {command}: {outcome.detail}")
    print(
        f"{count} mutants of a {len(base)}-byte recording in {time.perf_counter() - started:.0f} s"
    )
    for command in ("info", "run"):
        row = ", ".join(f"{k} {counts[(command, k)]}" for k in OUTCOMES)
        print(f"  {command:<5} {row}")
    for line in bad[:30]:
        print("  BUG", line)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
