"""semreplay-process: replay a recording through the stages, refine a cloud, train the network."""

from __future__ import annotations

import logging
import signal
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, NoReturn

import typer

if TYPE_CHECKING:
    import threading

    from viz.rerun_log import LiveViewer

app = typer.Typer(
    help="Replay an MCAP recording offline: odometry, segmentation, fusion, refinement.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

_EXAMPLES_RUN = """
Examples:

  semreplay-process run demo_out/sim_seed7.mcap --out demo_out/run

  semreplay-process run rec.mcap --out out --stages odometry --no-viz

  semreplay-process run rec.mcap --out out --config samples/sample.toml --weights ckpt.pt

  semreplay-process run field.mcap --out live --follow --serve   # while `record` writes it
"""


def _fail(message: str) -> NoReturn:
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(1)


def _interrupt(signum: int, frame: object) -> NoReturn:
    """Treat SIGTERM as Ctrl-C, so that a killed run cleans up the same way."""
    raise KeyboardInterrupt


def _stop_following(stop: threading.Event) -> Callable[[int, object], None]:
    """Return a SIGINT handler: the first Ctrl-C ends the capture here, the second aborts."""

    def handler(signum: int, frame: object) -> None:
        if stop.is_set():
            raise KeyboardInterrupt
        stop.set()
        typer.echo("\nstopping: finishing with the frames so far (Ctrl-C again aborts)", err=True)

    return handler


def _setup_logging(verbose: bool) -> None:
    logging.basicConfig(
        level=logging.DEBUG if verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )


@app.command(epilog=_EXAMPLES_RUN)
def run(
    recording: Annotated[Path, typer.Argument(help="recording to replay (.mcap)")],
    out: Annotated[Path, typer.Option("--out", help="output folder")],
    config: Annotated[Path | None, typer.Option(help="TOML config overriding the defaults")] = None,
    stages: Annotated[
        str,
        typer.Option(
            help="last stage to run, or a comma list: odometry,segmentation,fusion,refinement"
        ),
    ] = "refinement",
    weights: Annotated[Path | None, typer.Option(help="segmentation checkpoint")] = None,
    device: Annotated[str, typer.Option(help="auto | cpu | cuda")] = "auto",
    no_viz: Annotated[bool, typer.Option("--no-viz", help="do not write recording.rrd")] = False,
    force: Annotated[
        bool, typer.Option("--force", help="replace the outputs of an earlier run in --out")
    ] = False,
    follow: Annotated[
        bool,
        typer.Option(
            "--follow",
            help="process a recording that is still being written, until the capture ends"
            " (Ctrl-C: stop and finish with the frames so far)",
        ),
    ] = False,
    follow_idle: Annotated[
        float, typer.Option(min=0.5, help="--follow: seconds without new data that end a capture")
    ] = 10.0,
    serve: Annotated[
        bool, typer.Option("--serve", help="also stream the log to viewers on 127.0.0.1:--port")
    ] = False,
    spawn: Annotated[
        bool, typer.Option("--spawn", help="also stream the log to a native viewer it starts")
    ] = False,
    port: Annotated[int, typer.Option(min=1, max=65535, help="--serve/--spawn gRPC port")] = 9876,
    verbose: Annotated[bool, typer.Option("--verbose", "-v")] = False,
) -> None:
    """Replay REC.mcap through the stages and write the outputs to --out."""
    from capture.errors import CaptureError
    from process.errors import ReplayError

    _setup_logging(verbose)
    if device not in ("auto", "cpu", "cuda"):
        raise typer.BadParameter(f"{device!r}; valid: auto, cpu, cuda", param_hint="--device")
    if not recording.is_file() and not follow:
        _fail(f"expected a recording file, found none (or a folder, pipe or device): {recording}")
    if (serve or spawn) and no_viz:
        raise typer.BadParameter(
            "--serve/--spawn stream the log: drop --no-viz", param_hint="--no-viz"
        )
    from viz.rerun_log import LiveViewer

    live = LiveViewer(spawn=spawn, port=port) if serve or spawn else None
    try:
        _run(
            recording,
            out,
            config,
            stages,
            weights,
            device,
            no_viz,
            follow_idle_s=follow_idle if follow else None,
            live=live,
            force=force,
        )
    except (ReplayError, CaptureError) as err:
        _fail(str(err))


def _run(
    recording: Path,
    out: Path,
    config: Path | None,
    stages: str,
    weights: Path | None,
    device: str,
    no_viz: bool,
    *,
    follow_idle_s: float | None = None,
    live: LiveViewer | None = None,
    force: bool = False,
) -> None:
    import threading

    from rich.console import Console

    from process import outputs
    from process.config import load_config, resolve_stages
    from process.job import run_recording

    cfg = load_config(config)
    stage_list = resolve_stages(stages)
    stop = threading.Event()

    def started() -> None:  # the log's sinks are open: say so, then take over the signals
        if live is not None:
            typer.echo(f"streaming the log to a viewer at {live.url}", err=True)
        signal.signal(signal.SIGTERM, _interrupt)
        if follow_idle_s is not None:
            signal.signal(signal.SIGINT, _stop_following(stop))
            typer.echo(f"following {recording}: frames are processed as they are written", err=True)

    result = run_recording(
        recording,
        out,
        cfg=cfg,
        stages=stage_list,
        weights=weights,
        device=device,
        no_viz=no_viz,
        live=live,
        follow_idle_s=follow_idle_s,
        stop=stop,
        force=force,
        on_start=started,
    )
    console = Console(stderr=False)
    console.print(outputs.summary_table(result.metrics))
    console.print(f"outputs in {out}: " + ", ".join(sorted(p.name for p in result.written)))
    if not no_viz:
        console.print(f"view: semreplay-view {out / outputs.RRD}")


_EXAMPLES_BATCH = """
Examples:

  semreplay-process batch recordings/ --out runs

  semreplay-process batch 'site_*/*.mcap' --out runs --jobs 2 --stages odometry

  semreplay-process batch /shared/recs --out /shared/runs --executor ray --address auto
"""


@app.command(epilog=_EXAMPLES_BATCH)
def batch(
    recordings: Annotated[
        list[str], typer.Argument(help="recordings (.mcap), folders of them, or globs")
    ],
    out: Annotated[Path, typer.Option("--out", help="output folder: OUT/<name>/ per recording")],
    config: Annotated[Path | None, typer.Option(help="TOML config overriding the defaults")] = None,
    jobs: Annotated[
        int | None,
        typer.Option(help="local tasks at once (default: one per core, as memory allows)"),
    ] = None,
    executor: Annotated[str, typer.Option(help="local | ray")] = "local",
    address: Annotated[
        str | None,
        typer.Option(
            help="Ray cluster address, e.g. auto (default: a running one, else a local one)"
        ),
    ] = None,
    stages: Annotated[str, typer.Option(help="as for run")] = "refinement",
    weights: Annotated[Path | None, typer.Option(help="segmentation checkpoint")] = None,
    device: Annotated[str, typer.Option(help="auto | cpu | cuda")] = "auto",
    no_viz: Annotated[bool, typer.Option("--no-viz", help="do not write recording.rrd")] = False,
    verbose: Annotated[bool, typer.Option("--verbose", "-v")] = False,
) -> None:
    """Process many recordings, one task each, as `run` would; summarise them in OUT/summary.*."""
    from capture.errors import CaptureError
    from process.errors import ReplayError

    _setup_logging(verbose)
    if device not in ("auto", "cpu", "cuda"):
        raise typer.BadParameter(f"{device!r}; valid: auto, cpu, cuda", param_hint="--device")
    try:
        from process.batch.runner import run_batch
        from process.config import load_config, resolve_stages

        signal.signal(signal.SIGTERM, _interrupt)
        rows = run_batch(
            recordings,
            out,
            cfg=load_config(config),
            stages=resolve_stages(stages),
            weights=weights,
            device=device,
            no_viz=no_viz,
            jobs=jobs,
            executor=executor,
            address=address,
        )
    except (ReplayError, CaptureError) as err:
        _fail(str(err))
    failed = [r["name"] for r in rows if r["status"] != "ok"]
    typer.echo(f"summary: {out / 'summary.html'} (and summary.csv, summary.parquet)")
    if failed:
        _fail(
            f"{len(failed)} of {len(rows)} recordings failed ({', '.join(failed)}): the reasons"
            f" are in {out / 'summary.csv'}; rerun the same command to retry them"
        )


@app.command(
    epilog="Examples:\n\n  semreplay-process refine cloud.ply --out out\n\n"
    "  semreplay-process refine scan.pcd --out out --config samples/sample.toml"
)
def refine(
    cloud: Annotated[Path, typer.Argument(help="labelled cloud (.ply with x y z label, or .pcd)")],
    out: Annotated[Path, typer.Option("--out", help="output folder")],
    config: Annotated[Path | None, typer.Option(help="TOML config overriding the defaults")] = None,
    ground_truth: Annotated[
        Path | None, typer.Option("--ground-truth", help="labelled ground-truth cloud for metrics")
    ] = None,
    force: Annotated[
        bool, typer.Option("--force", help="replace the outputs of an earlier run in --out")
    ] = False,
    verbose: Annotated[bool, typer.Option("--verbose", "-v")] = False,
) -> None:
    """Run the refinement alone (planes, SOR, adaptive DBSCAN, regrowth) on a labelled cloud."""
    from process.errors import ReplayError

    _setup_logging(verbose)
    try:
        from rich.console import Console

        from process import outputs
        from process.config import load_config, to_toml
        from process.refine.job import refine_file

        cfg = load_config(config)
        with outputs.staged(out, force=force) as staging:
            metrics = refine_file(cloud, out_dir=staging, cfg=cfg.refine, gt_cloud=ground_truth)
            outputs.write_text_atomic(staging / outputs.CONFIG, to_toml(cfg))
            names = (outputs.MAP_REFINED, outputs.METRICS, outputs.CONFIG)
            outputs.commit(staging, out, [staging / n for n in names])
        table = outputs.summary_table({"refinement": metrics}, title="semreplay process refine")
        Console().print(table)
        if cfg.refine.up is None and metrics.get("up") is not None:
            up = ", ".join(f"{v:.3f}" for v in metrics["up"])
            typer.echo(
                f"gravity: none given, so up [{up}] is a plane's normal ({metrics['up_source']});"
                " if that plane is not the floor (an object-heavy cloud in a SLAM frame), set"
                " [refine] up = [x, y, z] in --config",
                err=True,
            )
        typer.echo(f"outputs in {out}: {outputs.MAP_REFINED}, {outputs.METRICS}, {outputs.CONFIG}")
    except ReplayError as err:
        _fail(str(err))


@app.command(
    epilog="Examples:\n\n  semreplay-process train a.mcap b.mcap --out ckpt.pt --val c.mcap"
)
def train(
    recordings: Annotated[list[Path], typer.Argument(help="recordings with /ground_truth/labels")],
    out: Annotated[Path, typer.Option("--out", help="checkpoint to write")],
    val: Annotated[list[Path] | None, typer.Option(help="validation recording(s)")] = None,
    epochs: Annotated[int, typer.Option(min=1)] = 10,
    weights: Annotated[Path | None, typer.Option(help="checkpoint to start from")] = None,
    seed: Annotated[int, typer.Option()] = 0,
    teacher: Annotated[
        str | None,
        typer.Option(
            help="label recordings without ground truth with this network: combined, voc, ade20k"
        ),
    ] = None,
    teacher_every_nth: Annotated[int, typer.Option(min=1, help="teacher-labelled frames")] = 4,
    verbose: Annotated[bool, typer.Option("--verbose", "-v")] = False,
) -> None:
    """Fine-tune the segmentation network on recordings with ground-truth labels (or a teacher)."""
    from capture.errors import CaptureError
    from process.errors import ReplayError

    _setup_logging(verbose)
    try:
        from process.segmentation.train import train as train_fn

        train_fn(
            recordings,
            out=out,
            val=val or None,
            epochs=epochs,
            init=weights,
            seed=seed,
            teacher=teacher,
            teacher_every_nth=teacher_every_nth,
        )
        typer.echo(f"checkpoint written: {out} (use it with --weights {out})")
    except (ReplayError, CaptureError) as err:
        _fail(str(err))


if __name__ == "__main__":
    app()
