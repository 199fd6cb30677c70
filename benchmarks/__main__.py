"""`make bench`: run every benchmark module and print one table."""

from __future__ import annotations

import importlib
import pkgutil
import sys

from rich.console import Console
from rich.markup import escape
from rich.table import Table

import benchmarks
from benchmarks.common import Row


def main(selected: list[str]) -> int:
    """Run the `bench_*` modules (all, or those named) and print their rows."""
    rows: list[Row] = []
    names = sorted(
        i.name for i in pkgutil.iter_modules(benchmarks.__path__) if i.name.startswith("bench_")
    )
    unknown = [s for s in selected if not any(s in name for name in names)]
    if unknown:
        areas = ", ".join(n.removeprefix("bench_") for n in names)
        print(f"no benchmark matches {', '.join(unknown)}; expected one of: {areas}, fuzz",
              file=sys.stderr)  # fmt: skip
        return 2
    for name in names:
        if selected and not any(s in name for s in selected):
            continue
        module = importlib.import_module(f"benchmarks.{name}")
        print(f"running {name} ...", file=sys.stderr, flush=True)
        rows.extend(module.run())
    table = Table(title="semreplay benchmarks (ratio > 1: we are better)")
    for col in ("area", "metric", "ours", "reference", "ratio", "goal", "reference source"):
        table.add_column(col)
    for r in rows:
        table.add_row(
            r.area,
            escape(f"{r.metric} [{r.unit}]"),
            f"{r.ours:.4g}",
            f"{r.reference:.4g}",
            f"{r.ratio:.2f}x",
            r.goal,
            r.source,
        )
    Console(width=200).print(table)
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["fuzz"]:  # `python -m benchmarks fuzz N`: not a bench_* module
        from benchmarks.fuzz import main as fuzz_main

        sys.exit(fuzz_main(sys.argv[2:]))
    sys.exit(main(sys.argv[1:]))
