"""Run a module as __main__ and write its own peak RSS to a file when it exits.

`python -m benchmarks.peak_rss OUT MODULE ARGS...`. Why not wait4's ru_maxrss: Linux carries the
parent's high-water mark into a child at exec, so a child of a 1.5 GB benchmark process reports at
least 1.5 GB. VmHWM in /proc/self/status belongs to the process's own address space since exec.
"""

from __future__ import annotations

import atexit
import runpy
import sys
from pathlib import Path


def _peak_kib() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1])
    raise RuntimeError("no VmHWM in /proc/self/status (Linux only)")


def main() -> None:
    out, module, *args = sys.argv[1:]
    atexit.register(lambda: Path(out).write_text(str(_peak_kib())))
    sys.argv = [module, *args]
    runpy.run_module(module, run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    main()
