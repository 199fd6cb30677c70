"""DIR/summary.html: the table, each recording's preview, and bar charts of the figures."""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final

from process import outputs
from process.batch import summary

HTML: Final = "summary.html"
# Figures plotted across recordings: column, title. Only those with a value somewhere appear.
FIGURES: Final = (
    ("ate_rmse_m", "ATE RMSE (m)"),
    ("rpe_trans_m", "RPE translation (m)"),
    ("miou_2d", "segmentation mIoU (2D)"),
    ("map_f1_III", "map F1, phase III"),
    ("keyframes", "keyframes"),
    ("wall_s", "task time (s)"),
    ("peak_rss_gb", "peak RSS (GB)"),
)
HIDDEN: Final = ("preview", "outputs", "recording")  # shown otherwise, or too long for the table
STYLE: Final = """
body { font-family: sans-serif; margin: 1.5em; }
table { border-collapse: collapse; font-size: 12px; }
td, th { border: 1px solid #ccc; padding: 2px 6px; text-align: right; white-space: nowrap; }
td.text { text-align: left; } tr.failed { background: #fde2e2; } .wide { overflow-x: auto; }
.plots, .previews { display: flex; flex-wrap: wrap; gap: 1.5em; }
figure { margin: 0; } figcaption { font-size: 12px; }
img { max-width: 320px; border: 1px solid #ccc; }
svg text { font-size: 11px; font-family: sans-serif; }
"""


def write_html(out: Path, rows: Sequence[Mapping[str, Any]]) -> Path:
    """Write DIR/summary.html for the rows (whole or not at all); return its path."""
    n_ok = sum(r["status"] == "ok" for r in rows)
    n_reused = sum(bool(r.get("reused")) for r in rows)
    body = [
        f"<h1>semreplay batch: {n_ok} of {len(rows)} recordings ok</h1>",
        f"<p>{len(rows) - n_ok} failed, {n_reused} kept from an earlier run. The same table:"
        f' <a href="{summary.CSV}">{summary.CSV}</a>, <a href="{summary.PARQUET}">'
        f"{summary.PARQUET}</a>; each recording's files are in its folder (out_dir).</p>",
        f'<div class="wide">{_table(out, rows)}</div>',
        "<h2>Figures across recordings</h2>",
        '<div class="plots">' + "".join(_plots(rows)) + "</div>",
        "<h2>Previews</h2>",
        '<div class="previews">' + "".join(_previews(out, rows)) + "</div>",
    ]
    page = (
        '<!doctype html>\n<html><head><meta charset="utf-8"><title>semreplay batch</title>'
        f"<style>{STYLE}</style></head><body>\n" + "\n".join(body) + "\n</body></html>\n"
    )
    outputs.write_text_atomic(out / HTML, page)
    return out / HTML


def _table(out: Path, rows: Sequence[Mapping[str, Any]]) -> str:
    columns = [c for c in summary.COLUMNS if c not in HIDDEN]
    head = "".join(f"<th>{html.escape(c)}</th>" for c in columns)
    lines = [f"<table><tr>{head}</tr>"]
    for row in rows:
        cells = []
        for column in columns:
            value = row.get(column)
            text = html.escape(_format(value))
            if column == "out_dir" and value:
                text = f'<a href="{html.escape(_relative(out, value))}/">{text}</a>'
            kind = "text" if summary.COLUMNS[column] is str else "num"
            cells.append(f'<td class="{kind}">{text}</td>')
        lines.append(f'<tr class="{html.escape(str(row["status"]))}">{"".join(cells)}</tr>')
    return "\n".join([*lines, "</table>"])


def _format(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _relative(out: Path, path: str) -> str:
    try:
        return Path(path).resolve().relative_to(out.resolve()).as_posix()
    except ValueError:
        return Path(path).resolve().as_uri()


def _previews(out: Path, rows: Sequence[Mapping[str, Any]]) -> list[str]:
    figures = []
    for row in rows:
        if row.get("preview"):
            src = html.escape(_relative(out, row["preview"]))
            name = html.escape(row["name"])
            figures.append(
                f'<figure><a href="{src}"><img src="{src}" alt="{name}"></a>'
                f"<figcaption>{name}</figcaption></figure>"
            )
    return figures or ["<p>No recording has a preview.png.</p>"]


def _plots(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    plots = []
    for column, title in FIGURES:
        values = [(r["name"], float(r[column])) for r in rows if r.get(column) is not None]
        if values:
            plots.append(bar_chart(title, values))
    return plots or ["<p>No recording finished yet.</p>"]


def bar_chart(title: str, values: Sequence[tuple[str, float]]) -> str:
    """Return an inline SVG of horizontal bars, one per (name, value)."""
    width, label_w, bar_h, gap, top = 380, 130, 14, 4, 24
    span = width - label_w - 60
    largest = max(abs(v) for _, v in values) or 1.0
    height = top + len(values) * (bar_h + gap)
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}"'
        f' role="img" aria-label="{html.escape(title)}">',
        f'<text x="0" y="14" font-weight="bold">{html.escape(title)}</text>',
    ]
    for i, (name, value) in enumerate(values):
        y = top + i * (bar_h + gap)
        w = span * abs(value) / largest
        label = name if len(name) <= 20 else name[:19] + "…"
        parts += [
            f'<text x="{label_w - 4}" y="{y + 11}" text-anchor="end">{html.escape(label)}</text>',
            f'<rect x="{label_w}" y="{y}" width="{w:.1f}" height="{bar_h}" fill="#4c78a8"/>',
            f'<text x="{label_w + w + 4:.1f}" y="{y + 11}">{value:.4g}</text>',
        ]
    return "".join([*parts, "</svg>"])
