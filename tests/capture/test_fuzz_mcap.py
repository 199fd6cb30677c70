"""Fuzz: deterministic mutants of a recording, a cloud and a config; none may end in a traceback.

`python -m benchmarks fuzz N` runs the same MCAP mutants by the thousand.
"""

from __future__ import annotations

import logging
import random
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from benchmarks.fuzz import classify, run_mutants, write_base_recording
from process.cli import app
from process.cloud import LabelledCloud, ply_bytes, read_cloud
from process.config import load_config
from process.errors import ReplayError

MCAP_MUTANTS = 200
ROOT = Path(__file__).resolve().parents[2]


def _mutants(data: bytes, seed: int) -> bytes:
    rng = random.Random(seed)
    out = bytearray(data)
    kind = seed % 4
    if kind == 0:
        return bytes(out[: rng.randrange(len(out))])
    if kind == 1:
        for _ in range(rng.choice((1, 3, 10))):
            out[rng.randrange(len(out))] ^= rng.randrange(1, 256)
        return bytes(out)
    if kind == 2:  # damage the header only
        end = out.find(b"end_header")
        at = rng.randrange(max(end, 1))
        return bytes(out[:at] + bytes([rng.randrange(256)]) + out[at + 1 :])
    lines = bytes(out).split(b"\n")
    i = rng.randrange(min(len(lines), 12))
    return b"\n".join([*lines[:i], lines[i], *lines[i:]])  # a line twice


def test_mcap_mutants_through_info_and_run_never_end_in_a_traceback(tmp_path: Path) -> None:
    logging.disable(logging.CRITICAL)
    try:
        base = write_base_recording(tmp_path / "base.mcap").read_bytes()
        counts: Counter[tuple[str, str]] = Counter()
        bad = []
        for seed, what, command, outcome in run_mutants(base, range(MCAP_MUTANTS), tmp_path):
            counts[(command, outcome.kind)] += 1
            if outcome.kind in ("traceback", "hang", "partial file"):
                bad.append(f"seed {seed} {what} {command}: {outcome.detail}")
    finally:
        logging.disable(logging.NOTSET)
    assert bad == []
    for command in ("info", "run"):  # most mutants keep something to replay
        assert counts[(command, "exit 0")] > MCAP_MUTANTS // 2, counts
        assert counts[(command, "one-line error")] > 0, counts


@pytest.mark.parametrize("fmt", ["binary", "ascii"])
def test_ply_mutants_read_or_fail_in_one_line(tmp_path: Path, fmt: str) -> None:
    rng = np.random.default_rng(3)
    n = 200
    cloud = LabelledCloud(
        rng.normal(size=(n, 3)).astype(np.float32),
        rng.integers(0, 256, (n, 3), dtype=np.uint8),
        rng.integers(0, 11, n, dtype=np.uint8),
    )
    data = ply_bytes(cloud)
    if fmt == "ascii":
        triples = zip(cloud.points, cloud.colors, cloud.labels, strict=True)
        rows = "\n".join(" ".join(f"{v:g}" for v in (*p, *c, lab)) for p, c, lab in triples)
        head = data[: data.find(b"end_header")].replace(b"binary_little_endian", b"ascii")
        data = head + b"end_header\n" + rows.encode() + b"\n"
    path = tmp_path / "m.ply"
    outcomes: Counter[str] = Counter()
    for seed in range(150):
        path.write_bytes(_mutants(data, seed))
        try:
            read_cloud(path)
            outcomes["read"] += 1
        except ReplayError as err:
            assert "\n" not in str(err)
            outcomes["one-line error"] += 1
    assert outcomes["read"] > 0 and outcomes["one-line error"] > 0, outcomes


def test_bad_ply_through_refine_is_one_line_or_a_result(tmp_path: Path) -> None:
    rng = np.random.default_rng(4)
    n = 300
    cloud = LabelledCloud(
        rng.normal(size=(n, 3)).astype(np.float32),
        rng.integers(0, 256, (n, 3), dtype=np.uint8),
        np.full(n, 5, np.uint8),
    )
    data = ply_bytes(cloud)
    runner = CliRunner()
    kinds: Counter[str] = Counter()
    for seed in range(12):
        path = tmp_path / f"m{seed}.ply"
        path.write_bytes(_mutants(data, seed))
        out = tmp_path / f"out{seed}"

        def call(p: Path = path, o: Path = out) -> tuple[int, str]:
            result = runner.invoke(app, ["refine", str(p), "--out", str(o)], catch_exceptions=False)
            return result.exit_code, result.stderr

        outcome = classify(call, limit_s=120)
        kinds[outcome.kind] += 1
        assert outcome.kind in ("exit 0", "one-line error"), (seed, outcome)
    assert kinds["one-line error"] > 0


def test_config_mutants_load_or_fail_in_one_line(tmp_path: Path) -> None:
    sample = (ROOT / "samples" / "sample.toml").read_bytes()
    path = tmp_path / "c.toml"
    outcomes: Counter[str] = Counter()
    for seed in range(300):
        path.write_bytes(_mutants(sample, seed))
        try:
            load_config(path)
            outcomes["loaded"] += 1
        except ReplayError as err:
            assert "\n" not in str(err).strip(), str(err)
            outcomes["one-line error"] += 1
    assert outcomes["loaded"] > 0 and outcomes["one-line error"] > 0, outcomes
