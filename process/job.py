"""One recording through the pipeline into one folder: what `run` and each batch task call."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from process import outputs
from process.config import ReplayConfig
from process.errors import RunInterruptedError
from process.pipeline import ReplayPipeline, RunResult

if TYPE_CHECKING:
    import threading
    from collections.abc import Callable

    from viz.rerun_log import LiveViewer


def run_recording(
    recording: Path,
    out: Path,
    *,
    cfg: ReplayConfig,
    stages: tuple[str, ...],
    weights: Path | None = None,
    device: str = "auto",
    no_viz: bool = False,
    progress: bool = True,
    live: LiveViewer | None = None,
    follow_idle_s: float | None = None,
    stop: threading.Event | None = None,
    on_start: Callable[[], None] | None = None,
) -> RunResult:
    """Replay `recording` through `stages` into `out`; every output is written whole or not at all.

    `live` also streams the log to a viewer; `follow_idle_s` follows a recording still being
    written (setting `stop` ends it with the frames so far). `on_start` is called once the
    log's sinks are open (a viewer can connect), before the first frame is read.

    Raises:
        RunInterruptedError: Ctrl-C stopped the run; complete files stay, no partial one.
        ReplayError, CaptureError: the recording, config or a stage failed (one-line message).
    """
    from viz.logger import NullLogger
    from viz.rerun_log import RerunLogger

    out.mkdir(parents=True, exist_ok=True)
    rrd = out / outputs.RRD
    viz = (
        NullLogger()
        if no_viz
        else RerunLogger(outputs.temporary_path(rrd), recording_name=recording.stem, live=live)
    )
    pipeline = ReplayPipeline(
        recording,
        out_dir=out,
        cfg=cfg,
        stages=stages,
        viz=viz,
        weights=weights,
        device=device,
        progress=progress,
        follow_idle_s=follow_idle_s,
        stop=stop,
    )
    if on_start is not None:
        on_start()
    try:
        result = pipeline.run()
    except BaseException as err:
        # Every output but the .rrd is written whole or not at all; drop the .rrd's temporary.
        viz.close()
        outputs.temporary_path(rrd).unlink(missing_ok=True)
        if isinstance(err, KeyboardInterrupt):
            done = ", ".join(p.name for p in pipeline.result.written) or "nothing"
            raise RunInterruptedError(
                f"interrupted; complete files written: {done}; no partial file was left in {out}"
            ) from err
        raise
    viz.close()
    if not no_viz:
        outputs.temporary_path(rrd).replace(rrd)
        result.written.append(rrd)
    return result
