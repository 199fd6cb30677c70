"""The refinement's 58 test clouds: phase I and III F1 of each, against its ground truth.

The clouds of generators 1-5, TSDF maps of degraded simulated keyframes and the fused maps of
five 300-frame simulated recordings (`process run`), each with its truth and gravity-up (none for
the recordings' maps: refinement finds it). Making them took 12 minutes on 2 cores, so each is kept
in `--cache` (an .npz per cloud, 0.6 GB in all) and made once; refining all of them takes 6.

    python -m benchmarks.refine_suite [--cache DIR] [--only SUBSTRING] [--make-only] [--paper]
                                      [--set FIELD=VALUE ...] [--labels DIR] [--ceiling]
                                      [--held-out | --recordings]

`--set` changes one RefineConfig field (`--set piece_vote=false --set seam_vote_m=0.05`), to
measure a setting against ground truth on all the clouds before making it the default;
`--labels` keeps each cloud's phase-III labels, to check that a change meant to be faster
leaves them as they were. `--held-out` runs 152 other clouds of generators 2-5 and recordings
instead, of seeds that no rule was made looking at (`held_out()`, about 20 minutes the first
time): whether a rule generalises or fits the 58. `--recordings` runs the fused maps of 40 more
simulated recordings (`recordings()`, seeds 60-99, about 40 minutes the first time), which
rules for recordings' maps were made looking at: a wider look at recordings than the suite's five.

One line per cloud: name, points, object points, F1 phase I, II, III and III - I, then per
generator the mean, how many reach 0.95 and how many gain at least 0.05 over phase I. Written
for issue 12: the README's refinement figures per generator come from this list.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any, Final, NamedTuple

import numpy as np
import numpy.typing as npt

from process.cloud import LabelledCloud
from process.errors import ConfigError

CACHE: Final = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "semreplay-suite"
TESTS: Final = Path(__file__).resolve().parents[1] / "tests"
SPACINGS_G2: Final = (0.02, 0.016, 0.012, 0.008, 0.018, 0.025, 0.01)  # by seed, in turn
ROOMS: Final = ("office", "kitchen", "living", "meeting")  # generators 4 and 5, by seed


class Case(NamedTuple):
    """One labelled test cloud with its truth."""

    cloud: LabelledCloud
    truth: npt.NDArray[np.uint8]
    up: npt.NDArray[np.float64] | None  # None: refinement guesses it


def _gen1(seed: int, spacing_m: float) -> Case:
    from benchmarks.synthetic_office import indoor_scene

    s = indoor_scene(seed=seed, spacing_m=spacing_m)
    return Case(s.cloud, s.truth, np.array([0.0, 0.0, 1.0]))


def _gen2(seed: int, spacing_m: float) -> Case:
    sys.path.insert(0, str(TESTS))
    from helpers_refine_sim import sim_scene

    s = sim_scene(seed=seed, spacing_m=spacing_m)
    return Case(s.cloud, s.truth, s.up)


def _tsdf(seed: int) -> Case:
    sys.path.insert(0, str(TESTS))
    from helpers_refine_sim import sim_fused_map

    s = sim_fused_map(seed=seed, keyframes=20)
    return Case(s.cloud, s.truth, s.up)


def _gen3(seed: int, spacing_m: float, rotate: bool = False) -> Case:
    from benchmarks.generator3 import gen3_scene

    s = gen3_scene(seed=seed, spacing_m=spacing_m, rotate=rotate)
    return Case(s.cloud, s.truth, s.up)


def _gen4(seed: int, object_points: int) -> Case:
    from benchmarks.generator4 import gen4_scene

    s = gen4_scene(seed=seed, object_points=object_points)
    return Case(s.cloud, s.truth, s.up)


def _gen5(seed: int, size: str) -> Case:
    from benchmarks.generator5 import sized_scene

    s = sized_scene(seed, size)
    return Case(s.cloud, s.truth, s.up)


def _recording(seed: int, frames: int = 300) -> Case:
    """The fused map (phase I) of `process run` on a simulated recording, truth by nearest point."""
    from capture.recording import GT_CLOUD_ATTACHMENT, RecordingReader
    from process.cloud import parse_ply, read_cloud
    from process.evaluate import match_labels

    bin_dir = Path(sys.executable).parent
    with tempfile.TemporaryDirectory() as tmp:
        rec, out = Path(tmp) / "sim.mcap", Path(tmp) / "run"
        for cmd in (
            [bin_dir / "semreplay-capture", "simulate", rec, "--seed", seed, "--frames", frames],
            [bin_dir / "semreplay-process", "run", rec, "--out", out, "--no-viz"],
        ):
            subprocess.run([str(c) for c in cmd], check=True, capture_output=True)
        cloud = read_cloud(out / "map_fused.ply")
        with RecordingReader(rec) as reader:
            gt = parse_ply(reader.attachment(GT_CLOUD_ATTACHMENT) or b"", source="ground truth")
    return Case(cloud, match_labels(cloud.points, gt, max_distance_m=0.05), None)


def cases() -> dict[str, Callable[[], Case]]:
    """Return the 58 clouds by name, each made on demand."""
    made: dict[str, Callable[[], Case]] = {
        "g1 office 1.6cm": partial(_gen1, 0, 0.016),
        "g1 office 3cm": partial(_gen1, 1, 0.03),
        "tsdf room 0": partial(_tsdf, 0),
        "tsdf room 1": partial(_tsdf, 1),
    }
    for seed in range(14):
        sp = SPACINGS_G2[seed % len(SPACINGS_G2)]
        made[f"g2 room {seed} {sp * 100:g}cm"] = partial(_gen2, seed, sp)
    for seed in range(8):
        sp = {6: 0.016, 7: 0.007}.get(seed, 0.011)
        made[f"g3 room {seed} {sp * 100:g}cm"] = partial(_gen3, seed, sp)
    made["g3 room 5 0.7cm turned"] = partial(_gen3, 5, 0.007, rotate=True)
    for i, points in enumerate((60_000, 200_000, 500_000)):
        for r, room in enumerate(ROOMS):
            made[f"g4 {room} {points // 1000}k"] = partial(_gen4, 4 * i + r, points)
    for seed in range(4):
        made[f"g5 {ROOMS[seed]} 60k"] = partial(_gen5, seed, "60k")
    for seed in range(8):
        made[f"g5 seed {seed} 200k"] = partial(_gen5, seed, "200k")
    for seed in range(2):
        made[f"g5 {ROOMS[seed]} 500k"] = partial(_gen5, seed, "500k")
    for seed in (7, 8, 9, 12, 13):
        made[f"rec seed {seed} 300f"] = partial(_recording, seed)
    return made


def held_out() -> dict[str, Callable[[], Case]]:
    """Return 152 clouds of seeds no rule was looked at or measured on: measure, never tune.

    Generators 2 (seeds 28-41, its seven spacings in turn), 3 (seeds 14-19 at 1.1 cm), 4
    (seeds 200-259 at 60k object points, 200-239 at 200k, 200-203 at 500k; the room follows the
    seed: office, kitchen, living room, meeting room) and 5 (seeds 100-115 at 60k, 100-103 at
    200k, since 3 Dec: rules had been made looking at its 14 clouds in `cases()`), and the fused
    maps of eight 300-frame simulated recordings (seeds 20-27, about a minute each to make). A
    rule that helps on `cases()` but not here fits those clouds, not the errors; a rule made
    looking at these clouds makes them one more tuning set.
    """
    made: dict[str, Callable[[], Case]] = {}
    for seed in range(28, 42):
        made[f"g2 room {seed}"] = partial(_gen2, seed, SPACINGS_G2[seed % len(SPACINGS_G2)])
    for seed in range(14, 20):
        made[f"g3 room {seed}"] = partial(_gen3, seed, 0.011)
    for points, seeds in ((60_000, range(200, 260)), (200_000, range(200, 240))):
        for seed in seeds:
            made[f"g4 {points // 1000}k {ROOMS[seed % 4]} {seed}"] = partial(_gen4, seed, points)
    for seed in range(200, 204):
        made[f"g4 500k {ROOMS[seed % 4]} {seed}"] = partial(_gen4, seed, 500_000)
    for size, g5_seeds in (("60k", range(100, 116)), ("200k", range(100, 104))):
        for seed in g5_seeds:
            made[f"g5 {size} {ROOMS[seed % 4]} {seed}"] = partial(_gen5, seed, size)
    for seed in range(20, 28):
        made[f"rec seed {seed} 300f"] = partial(_recording, seed)
    return made


def recordings() -> dict[str, Callable[[], Case]]:
    """Return the fused maps of 40 simulated recordings (seeds 60-99, 300 frames each).

    Made in sessions 27-33 of issue 12 to find what the refinement misses on recordings' maps:
    rules were made looking at them (seeds 92-99 were first measured once, on finished code), so
    they are a development set, not a held-out one.
    """
    return {f"rec seed {seed} 300f": partial(_recording, seed) for seed in range(60, 100)}


def _group(name: str) -> str:
    """Return the line a cloud's figures are summed in: its generator (and size, held out)."""
    parts = name.split()
    sized = parts[0] in ("g4", "g5") and parts[1].endswith("k")
    return " ".join(parts[:2]) if sized else parts[0]


def load(name: str, make: Callable[[], Case], cache: Path) -> Case:
    """Return the case from `cache`, making and storing it first if it is not there."""
    path = cache / (name.replace(" ", "_") + ".npz")
    if not path.exists():
        case = make()
        cache.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(
            tmp,
            points=case.cloud.points,
            colors=case.cloud.colors,
            labels=case.cloud.labels,
            truth=case.truth,
            up=np.full(3, np.nan) if case.up is None else case.up,
        )
        tmp.replace(path)
    with np.load(path) as z:
        up = None if np.isnan(z["up"]).any() else z["up"].astype(np.float64)
        cloud = LabelledCloud(z["points"], z["colors"], z["labels"])
        return Case(cloud, z["truth"], up)


_BOOLS: Final = {"true": True, "1": True, "yes": True, "on": True, "false": False, "0": False}


def _field(cfg: object, text: str) -> tuple[str, Any]:
    """Return (name, value) of a FIELD=VALUE, the value of the field's type."""
    name, _, value = text.partition("=")
    if not hasattr(cfg, name):
        raise SystemExit(f"--set: RefineConfig has no field {name!r}; see process/refine/config.py")
    current = getattr(cfg, name)
    try:
        if isinstance(current, bool):
            return name, _BOOLS[value.lower()]
        if isinstance(current, tuple):
            return name, tuple(float(v) for v in value.split(","))
        return name, type(current)(value)
    except (KeyError, ValueError):
        kind = "true or false" if isinstance(current, bool) else type(current).__name__
        raise SystemExit(f"--set: {name} expects {kind} (now {current!r}); got {value!r}") from None


def main(argv: list[str] | None = None) -> int:
    from process.refine import RefineConfig, refine

    parser = argparse.ArgumentParser(prog="python -m benchmarks.refine_suite")
    parser.add_argument("--cache", type=Path, default=CACHE)
    parser.add_argument("--only", default="", help="clouds whose name holds this")
    parser.add_argument("--make-only", action="store_true", help="make the clouds, refine none")
    parser.add_argument("--paper", action="store_true", help="RefineConfig.paper()")
    which = parser.add_mutually_exclusive_group()
    which.add_argument(
        "--held-out", action="store_true", help="the 152 held-out clouds instead (held_out())"
    )
    which.add_argument(
        "--recordings",
        action="store_true",
        help="the fused maps of 40 simulated recordings instead, seeds 60-99 (recordings())",
    )
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE")
    parser.add_argument(
        "--labels", type=Path, help="write each cloud's phase-III labels here (NAME.npy)"
    )
    parser.add_argument(
        "--ceiling",
        action="store_true",
        help="also each cloud's F1 with every true object at its phase-I majority (ceiling.py)",
    )
    args = parser.parse_args(argv)
    cfg = RefineConfig.paper() if args.paper else RefineConfig()
    try:
        cfg = dataclasses.replace(cfg, **dict(_field(cfg, text) for text in args.set))
    except ConfigError as err:
        raise SystemExit(f"--set: {err}") from None
    # per group: (F1 I, F1 III, the majority ceiling or None) per cloud
    gains: dict[str, list[tuple[float, float, float | None]]] = {}
    clouds = held_out() if args.held_out else recordings() if args.recordings else cases()
    for name, make in clouds.items():
        if args.only not in name:
            continue
        case = load(name, make, args.cache)
        if args.make_only:
            print(f"{name}: {len(case.cloud):,} points", flush=True)
            continue
        t0 = time.perf_counter()
        result = refine(case.cloud, cfg, up=case.up)
        seconds = time.perf_counter() - t0
        f1 = result.phase_f1(case.truth)
        objects = int((case.truth >= 4).sum())
        ceiling = _ceiling(case) if args.ceiling else None
        print(
            f"{name:24s} {len(case.cloud):>9,} {objects:>9,}  I {f1['I']:.4f}  II {f1['II']:.4f}"
            f"  III {f1['III']:.4f}  {f1['III'] - f1['I']:+.4f}  {seconds:5.1f} s"
            + ("" if ceiling is None else f"  ceiling {ceiling:.4f}"),
            flush=True,
        )
        gains.setdefault(_group(name), []).append((f1["I"], f1["III"], ceiling))
        if args.labels:
            args.labels.mkdir(parents=True, exist_ok=True)
            np.save(args.labels / (name.replace(" ", "_") + ".npy"), result.labels_iii)
    for group, pairs in gains.items():
        print(_summary(group, pairs))
    return 0


def _ceiling(case: Case) -> float:
    from benchmarks.ceiling import majority_ceiling

    return majority_ceiling(case.cloud.points, case.cloud.labels, case.truth)


def _summary(group: str, pairs: list[tuple[float, float, float | None]]) -> str:
    """Return a group's line: mean phase III, clouds >= 0.95, clouds gaining >= 0.05 on I.

    With ceilings (`--ceiling`), also how many clouds could gain 0.05 at all: a cloud whose
    phase I is within 0.05 of its majority ceiling cannot, whatever the refinement does to
    objects the network labels wrong on most of their points.
    """
    high = sum(iii >= 0.95 for _, iii, _ in pairs)
    gained = sum(iii >= i + 0.05 for i, iii, _ in pairs)
    mean = np.mean([iii for _, iii, _ in pairs])
    line = f"{group}: mean III {mean:.3f}, {high} of {len(pairs)} >= 0.95, {gained} >= I + 0.05"
    ceilings = [(i, c) for i, _, c in pairs if c is not None]
    if ceilings:
        room = sum(c >= i + 0.05 for i, c in ceilings)
        line += f" ({room} of {len(ceilings)} have a ceiling >= I + 0.05)"
    return line


if __name__ == "__main__":
    raise SystemExit(main())
