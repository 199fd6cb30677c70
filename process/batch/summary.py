"""The batch's table: one row per recording, written as CSV, Parquet and (via report) HTML."""

from __future__ import annotations

import csv
import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final

from process import outputs

CSV: Final = "summary.csv"
PARQUET: Final = "summary.parquet"
PREVIEW: Final = outputs.PREVIEW  # a top view of the map, where `process run` made one
MARKER: Final = "batch.json"  # a folder's row, written last: the folder is complete
STAGES: Final = (
    "read",
    "depth",
    "odometry",
    "segmentation",
    "fusion",
    "refusion",
    "refinement",
    "logging",
)
PHASES: Final = ("I", "II", "III")

# Column name -> type; the order is the order of the CSV and Parquet columns.
COLUMNS: Final[dict[str, type]] = {
    "name": str,
    "status": str,  # ok | failed
    "reason": str,  # the one-line error of a failed recording, else ""
    "frames": int,
    "duration_s": float,  # of the recording
    "keyframes": int,
    "ate_rmse_m": float,
    "rpe_trans_m": float,
    "rpe_rot_deg": float,
    "miou_2d": float,
    **{f"map_f1_{phase}": float for phase in PHASES},
    **{f"seconds_{stage}": float for stage in STAGES},  # wall time of each stage
    "fps": float,  # frames/s of the whole job
    "wall_s": float,  # the whole task, from start to the folder in place
    "peak_rss_gb": float,  # the task's own high-water mark
    "reused": bool,  # true: the folder was complete from an earlier run and kept
    "host": str,
    "recording": str,
    "out_dir": str,
    "outputs": str,  # the file names in out_dir, ';'-separated
    "preview": str,  # out_dir/preview.png where it exists
}


def empty_row(name: str, recording: Path) -> dict[str, Any]:
    """Return a row with every column present and only the name and recording set."""
    row: dict[str, Any] = dict.fromkeys(COLUMNS)
    row.update(name=name, recording=str(recording), reason="", reused=False)
    return row


def failed_row(name: str, recording: Path, reason: str, **extra: Any) -> dict[str, Any]:
    """Return the row of a recording that failed, with its reason cut to one line."""
    lines = reason.strip().splitlines() or ["unknown error"]
    row = empty_row(name, recording)
    row.update(status="failed", reason=lines[0][:500], **extra)
    return row


def ok_row(
    name: str, recording: Path, metrics: Mapping[str, Any], out_dir: Path, **extra: Any
) -> dict[str, Any]:
    """Return the row of a recording processed into out_dir, from its metrics.json content."""
    row = empty_row(name, recording)
    odo = metrics.get("odometry", {})
    phases = metrics.get("refinement", {}).get("phases", {})
    seconds = metrics.get("seconds", {})
    row.update(
        status="ok",
        frames=odo.get("frames"),
        keyframes=odo.get("keyframes"),
        ate_rmse_m=odo.get("ate_rmse_m"),
        rpe_trans_m=odo.get("rpe_trans_m"),
        rpe_rot_deg=odo.get("rpe_rot_deg"),
        miou_2d=metrics.get("segmentation", {}).get("miou_2d"),
        fps=metrics.get("job", {}).get("fps"),
        out_dir=str(out_dir),
        **{f"map_f1_{p}": phases.get(p, {}).get("all", {}).get("f1") for p in PHASES},
        **{f"seconds_{s}": seconds.get(s) for s in STAGES},
    )
    row.update(extra)
    return row


def with_output_names(row: dict[str, Any], out_dir: Path) -> dict[str, Any]:
    """Fill `outputs` (the files of `process run`) and `preview` from what out_dir holds now."""
    names = sorted(p.name for p in out_dir.iterdir() if p.name != MARKER and p.name[0] != ".")
    preview = out_dir / PREVIEW
    return {**row, "outputs": ";".join(names), "preview": str(preview) if preview.is_file() else ""}


def write_tables(out: Path, rows: Sequence[Mapping[str, Any]]) -> list[Path]:
    """Write DIR/summary.csv and DIR/summary.parquet (each whole or not at all)."""
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=list(COLUMNS), lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: _csv_value(row.get(k)) for k in COLUMNS})
    outputs.write_text_atomic(out / CSV, text.getvalue())
    _write_parquet(out / PARQUET, rows)
    return [out / CSV, out / PARQUET]


def _csv_value(value: Any) -> Any:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.6g}"
    return value


def _write_parquet(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    kinds = {str: pa.string(), int: pa.int64(), float: pa.float64(), bool: pa.bool_()}
    schema = pa.schema([(name, kinds[kind]) for name, kind in COLUMNS.items()])
    table = pa.Table.from_pylist([{k: row.get(k) for k in COLUMNS} for row in rows], schema)
    with outputs.atomic_path(path) as tmp:
        pq.write_table(table, tmp)


def read_csv(path: Path) -> list[dict[str, Any]]:
    """Read summary.csv back with the column types (empty cells, text ones too, are None)."""
    with path.open(newline="", encoding="utf-8") as f:
        return [{k: _parse(v, COLUMNS[k]) for k, v in row.items()} for row in csv.DictReader(f)]


def _parse(text: str, kind: type) -> Any:
    if text == "":
        return None
    if kind is bool:
        return text == "True"
    return kind(text)
