"""Read an .rrd back for the viz tests: rows per entity and timeline, static rows, components."""

from __future__ import annotations

import os
import subprocess
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from rerun.chunk import Chunk, RrdReader

from viz.cli import rerun_binary


@dataclass
class RrdContents:
    """What a recording store of an .rrd holds, counted per entity."""

    application_id: str
    blueprints: int
    rows: Counter[tuple[str, str]] = field(default_factory=Counter)  # (entity, timeline) -> rows
    static: Counter[str] = field(default_factory=Counter)  # entity -> static rows
    columns: dict[str, set[str]] = field(default_factory=dict)  # entity -> component columns
    chunks: list[Chunk] = field(default_factory=list)

    def timelines(self, entity: str) -> set[str]:
        """Return the timelines an entity has rows on."""
        return {timeline for (e, timeline) in self.rows if e == entity}

    def entities(self) -> set[str]:
        """Return every entity path with data, static or not."""
        return set(self.columns)

    def column(self, entity: str, name: str) -> list[Any]:
        """Return the values of one component column of an entity, chunk after chunk."""
        out: list[Any] = []
        for chunk in self.chunks:
            if chunk.entity_path == entity:
                batch = chunk.to_record_batch()
                if name in batch.schema.names:
                    out.extend(batch.column(name).to_pylist())
        return out

    def values(self, entity: str, name: str) -> npt.NDArray[Any]:
        """Return every value of one column of an entity flattened to one array (index or data)."""
        parts: list[npt.NDArray[Any]] = []
        for chunk in self.chunks:
            if chunk.entity_path == entity and name in chunk.to_record_batch().schema.names:
                array = chunk.to_record_batch().column(name)
                while hasattr(array, "flatten") and array.type.num_fields == 1:
                    array = array.flatten()  # peel list<...> layers down to the primitive values
                if str(array.type).startswith("timestamp"):
                    array = array.cast("int64")
                parts.append(array.to_numpy(zero_copy_only=False))
        return np.concatenate(parts) if parts else np.empty(0)


def read_rrd(path: Path, *, verify: bool = True) -> RrdContents:
    """Read the first recording store of an .rrd, after `rerun rrd verify` passed on it."""
    if verify:
        assert_rrd_verifies(path)
    reader = RrdReader(path)
    (store,) = reader.recordings()
    contents = RrdContents(application_id=store.application_id, blueprints=len(reader.blueprints()))
    for chunk in reader.stream():
        entity = chunk.entity_path
        contents.chunks.append(chunk)
        names = chunk.to_record_batch().schema.names
        contents.columns.setdefault(entity, set()).update(n for n in names if ":" in n)
        if chunk.is_static:
            contents.static[entity] += chunk.num_rows
        for timeline in chunk.timeline_names:
            contents.rows[(entity, timeline)] += chunk.num_rows
    return contents


def rerun_verify(path: Path) -> subprocess.CompletedProcess[str]:
    """Run `rerun rrd verify` (footers checked) on a file; never opens a viewer."""
    env = {**os.environ, "RERUN_APP_ONLY": "true"}  # skip the first-run analytics banner
    return subprocess.run(
        [str(rerun_binary()), "rrd", "verify", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        env=env,
    )


def assert_rrd_verifies(path: Path) -> None:
    """Fail the test unless `rerun rrd verify` passes on the file."""
    result = rerun_verify(path)
    assert result.returncode == 0, f"rerun rrd verify {path}: {result.stderr.strip()[-500:]}"
