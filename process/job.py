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
    force: bool = False,
    on_start: Callable[[], None] | None = None,
) -> RunResult:
    """Replay `recording` through `stages` into `out`; the outputs appear all together or not.

    Everything is written into a staging folder inside `out` and moved in at the end
    (process.outputs.staged/commit), so a failed or interrupted run leaves `out` as it was.
    `force` replaces the outputs of an earlier run in `out`. `live` also streams the log to a
    viewer; `follow_idle_s` follows a recording still being written (setting `stop` ends it with
    the frames so far). `on_start` is called once the log's sinks are open (a viewer can
    connect), before the first frame is read.

    Raises:
        RunInterruptedError: Ctrl-C stopped the run; nothing was written.
        ReplayError, CaptureError: the recording, config, --out or a stage failed (one line).
    """
    from viz.logger import NullLogger
    from viz.rerun_log import RerunLogger

    with outputs.staged(out, force=force) as staging:
        rrd = staging / outputs.RRD
        viz = (
            NullLogger()
            if no_viz
            else RerunLogger(
                rrd, recording_name=recording.stem, live=live, **cfg.viz.logger_options()
            )
        )
        pipeline = ReplayPipeline(
            recording,
            out_dir=staging,
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
            outputs.close_logger(viz, quiet=False)
        except BaseException as err:
            outputs.close_logger(viz, quiet=True)  # the staging folder goes, whatever is in it
            if isinstance(err, KeyboardInterrupt):
                raise RunInterruptedError(
                    f"interrupted; no output was written and {out} is as it was"
                ) from err
            raise
        written = result.written + ([] if no_viz else [rrd])
        result.written = outputs.commit(staging, out, written)
    return result
