"""semreplay-process: replay a recording through the stages, refine a cloud, train the network."""

from __future__ import annotations

import logging
import signal
from pathlib import Path
from typing import Annotated, NoReturn

import typer

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
"""


def _fail(message: str) -> NoReturn:
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(1)


def _interrupt(signum: int, frame: object) -> NoReturn:
    """Treat SIGTERM as Ctrl-C, so that a killed run cleans up the same way."""
    raise KeyboardInterrupt


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
    verbose: Annotated[bool, typer.Option("--verbose", "-v")] = False,
) -> None:
    """Replay REC.mcap through the stages and write the outputs to --out."""
    from capture.errors import CaptureError
    from process.errors import ReplayError

    _setup_logging(verbose)
    if device not in ("auto", "cpu", "cuda"):
        raise typer.BadParameter(f"{device!r}; valid: auto, cpu, cuda", param_hint="--device")
    if not recording.is_file():
        _fail(f"expected a recording file, found none (or a folder, pipe or device): {recording}")
    try:
        _run(recording, out, config, stages, weights, device, no_viz, force)
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
    force: bool = False,
) -> None:
    from rich.console import Console

    from process import outputs
    from process.config import load_config, resolve_stages
    from process.pipeline import ReplayPipeline
    from viz.logger import NullLogger
    from viz.rerun_log import RerunLogger

    cfg = load_config(config)
    stage_list = resolve_stages(stages)
    with outputs.staged(out, force=force) as staging:
        rrd = staging / outputs.RRD
        viz = NullLogger() if no_viz else RerunLogger(rrd, recording_name=recording.stem)
        pipeline = ReplayPipeline(
            recording,
            out_dir=staging,
            cfg=cfg,
            stages=stage_list,
            viz=viz,
            weights=weights,
            device=device,
        )
        signal.signal(signal.SIGTERM, _interrupt)
        try:
            result = pipeline.run()
            outputs.close_logger(viz, quiet=False)
        except BaseException as err:
            outputs.close_logger(viz, quiet=True)  # the staging folder goes, whatever is in it
            if isinstance(err, KeyboardInterrupt):
                _fail(f"interrupted; no output was written and {out} is as it was")
            raise
        written = result.written + ([] if no_viz else [rrd])
        result.written = outputs.commit(staging, out, written)
    console = Console(stderr=False)
    console.print(outputs.summary_table(result.metrics))
    console.print(f"outputs in {out}: " + ", ".join(sorted(p.name for p in result.written)))
    if not no_viz:
        console.print(f"view: semreplay-view {out / outputs.RRD}")


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
    verbose: Annotated[bool, typer.Option("--verbose", "-v")] = False,
) -> None:
    """Fine-tune the segmentation network on recordings that carry ground-truth labels."""
    from capture.errors import CaptureError
    from process.errors import ReplayError

    _setup_logging(verbose)
    try:
        from process.segmentation.train import train as train_fn

        train_fn(recordings, out=out, val=val or None, epochs=epochs, init=weights, seed=seed)
        typer.echo(f"checkpoint written: {out} (use it with --weights {out})")
    except (ReplayError, CaptureError) as err:
        _fail(str(err))


if __name__ == "__main__":
    app()
