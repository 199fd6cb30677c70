"""ReplayConfig: one frozen dataclass per stage, loaded from TOML, written next to every output."""

from __future__ import annotations

import dataclasses
import stat
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, Final

from process.depth import DepthConfig
from process.errors import ConfigError
from process.fusion.votes import FusionConfig
from process.odometry.config import OdometryConfig
from process.refine import RefineConfig
from process.segmentation.config import SegmentationConfig

STAGES: Final = ("odometry", "segmentation", "fusion", "refinement")
MAX_CONFIG_BYTES: Final = 1 << 20


@dataclasses.dataclass(frozen=True, slots=True)
class VizConfig:
    """What goes into recording.rrd: compact by default; full fidelity with compress = false.

    By default (measured on TUM fr1_rpy, 640x480): colour of every frame as JPEG (~30 KB), depth
    as lossless PNG (~95 KB) on keyframes and every depth_every_n-th frame (once a second at
    30 fps), segmentation on keyframes, poses and tracking every frame. Full fidelity
    (`compress = false`, `depth_every_n = 1`): raw colour and depth of every frame, ~1 MB a frame.
    """

    # Colour and keypoints of every n-th frame (keyframes always); poses and tracking: every frame.
    images_every_n: int = 1
    # Depth (raw and registered) of every n-th frame; keyframes' depth always.
    depth_every_n: int = 30
    # Colour and confidence as JPEG, depth as lossless PNG; false: raw images.
    compress: bool = True
    jpeg_quality: int = 70

    def __post_init__(self) -> None:
        for name in ("images_every_n", "depth_every_n"):
            if getattr(self, name) < 1:
                raise ConfigError(f"viz.{name} must be >= 1, got {getattr(self, name)}")
        if not 1 <= self.jpeg_quality <= 100:
            raise ConfigError(f"viz.jpeg_quality must be in 1..100, got {self.jpeg_quality}")

    def logger_options(self) -> dict[str, Any]:
        """Return the keyword arguments of viz.rerun_log.RerunLogger for these settings."""
        return {
            "compress": self.compress,
            "jpeg_quality": self.jpeg_quality,
            "depth_every_n": self.depth_every_n,
        }


@dataclasses.dataclass(frozen=True, slots=True)
class BatchConfig:
    """What each task of `semreplay-process batch` asks of a Ray cluster (one recording a task)."""

    cpus_per_task: float = 1.0
    # > 0 puts tasks on GPU nodes only; segmentation then runs there (--device auto).
    gpus_per_task: float = 0.0
    # Ray schedules no more tasks on a node than its memory holds; the local default of --jobs
    # divides this machine's available memory by it too (10 simulated minutes peaked at 1.47 GB).
    memory_gb_per_task: float = 1.5
    # Times Ray runs a task again after its worker process or node was lost.
    max_retries: int = 2

    def __post_init__(self) -> None:
        if self.cpus_per_task <= 0 or self.gpus_per_task < 0 or self.memory_gb_per_task <= 0:
            raise ConfigError(
                "batch.cpus_per_task and batch.memory_gb_per_task must be > 0 and"
                f" batch.gpus_per_task >= 0, got {self.cpus_per_task}, {self.memory_gb_per_task},"
                f" {self.gpus_per_task}"
            )
        if self.max_retries < 0:
            raise ConfigError(f"batch.max_retries must be >= 0, got {self.max_retries}")


@dataclasses.dataclass(frozen=True, slots=True)
class FollowConfig:
    """`process run --follow`: keeping up with a capture that is still being written."""

    # A frame whose turn comes more than this many seconds after the camera took it is dropped
    # (not tracked), so that a job slower than the camera stays close behind it instead of
    # falling further behind each second; 0 tracks every frame. Offline runs track every frame.
    max_lag_s: float = 1.2
    # ... but the frames tracked stay at most 1 / min_tracked_hz seconds apart in camera time
    # (100 ms: a hand-held camera moves a few centimetres and degrees), so that tracking holds.
    min_tracked_hz: float = 10.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.max_lag_s <= 3600.0:
            raise ConfigError(f"follow.max_lag_s must be in 0..3600 s, got {self.max_lag_s}")
        if not 0.1 <= self.min_tracked_hz <= 1000.0:
            raise ConfigError(
                f"follow.min_tracked_hz must be in 0.1..1000 Hz, got {self.min_tracked_hz}"
            )


@dataclasses.dataclass(frozen=True, slots=True)
class ReplayConfig:
    """Every setting of `semreplay-process`, one section per stage."""

    depth: DepthConfig = dataclasses.field(default_factory=DepthConfig)
    odometry: OdometryConfig = dataclasses.field(default_factory=OdometryConfig)
    segmentation: SegmentationConfig = dataclasses.field(default_factory=SegmentationConfig)
    fusion: FusionConfig = dataclasses.field(default_factory=FusionConfig)
    refine: RefineConfig = dataclasses.field(default_factory=RefineConfig)
    viz: VizConfig = dataclasses.field(default_factory=VizConfig)
    follow: FollowConfig = dataclasses.field(default_factory=FollowConfig)
    batch: BatchConfig = dataclasses.field(default_factory=BatchConfig)


def load_config(path: Path | None) -> ReplayConfig:
    """Return the defaults overridden by the TOML file at `path` (None: the defaults).

    Raises:
        ConfigError: the file is missing or not TOML, a section or key is unknown, a value has
            the wrong type or is out of range.
    """
    if path is None:
        return ReplayConfig()
    text = _read_config_text(Path(path))
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"config is not valid TOML ({err}): {path}") from err
    cfg: ReplayConfig = _build(ReplayConfig, data, where="", path=Path(path))
    return cfg


def _read_config_text(path: Path) -> str:
    """Return a config file's text: a regular file, at most MAX_CONFIG_BYTES, UTF-8 (BOM or not)."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError as err:
        raise ConfigError(f"config file not found: {path}") from err
    except OSError as err:
        raise ConfigError(f"cannot read the config ({err.strerror}): {path}") from err
    if not stat.S_ISREG(mode):
        raise ConfigError(f"expected a TOML config file, found a folder, pipe or device: {path}")
    try:
        with path.open("rb") as f:
            raw = f.read(MAX_CONFIG_BYTES + 1)
    except OSError as err:
        raise ConfigError(f"cannot read the config ({err.strerror}): {path}") from err
    if len(raw) > MAX_CONFIG_BYTES:
        raise ConfigError(
            f"config is larger than {MAX_CONFIG_BYTES // 1024} KiB; expected a small TOML file: "
            f"{path}"
        )
    try:
        return raw.decode("utf-8-sig")  # a BOM (Windows editors) is accepted
    except UnicodeDecodeError as err:
        raise ConfigError(
            f"config is not UTF-8 text (byte {err.start}); save it as UTF-8 TOML: {path}"
        ) from err


def _build(cls: type[Any], data: dict[str, Any], *, where: str, path: Path) -> Any:
    fields = {f.name: f for f in dataclasses.fields(cls)}
    hints = typing.get_type_hints(cls)
    unknown = sorted(set(data) - set(fields))
    if unknown:
        section = f"[{where}]" if where else "top level"
        raise ConfigError(
            f"unknown key(s) {unknown} in {section}; valid keys: {sorted(fields)}: {path}"
        )
    values: dict[str, Any] = {}
    for name, value in data.items():
        key = f"{where}.{name}" if where else name
        hint = hints[name]
        if dataclasses.is_dataclass(hint):
            if not isinstance(value, dict):
                raise ConfigError(f"'{key}' must be a table [{key}], found {value!r}: {path}")
            values[name] = _build(typing.cast(type[Any], hint), value, where=key, path=path)
        else:
            values[name] = _coerce(value, hint, key=key, path=path)
    try:
        return cls(**values)
    except ConfigError as err:
        raise ConfigError(f"{err}: {path}") from err
    except (TypeError, ValueError) as err:
        raise ConfigError(f"invalid [{where}] section ({err}): {path}") from err


def _coerce(value: Any, hint: Any, *, key: str, path: Path) -> Any:
    """Check a TOML value against a field's type; ints are accepted where floats are."""
    origin = typing.get_origin(hint)
    options = typing.get_args(hint) if origin in (typing.Union, types.UnionType) else (hint,)
    for option in options:
        base = typing.get_origin(option) or option
        if base is float and isinstance(value, int | float) and not isinstance(value, bool):
            return float(value)
        if base is tuple and isinstance(value, list):
            return tuple(value)
        if base is bool and isinstance(value, bool):
            return value
        if base in (int, str) and isinstance(value, base) and not isinstance(value, bool):
            return value
        if option is type(None) and value is None:
            return value
    expected = " or ".join(getattr(o, "__name__", str(o)) for o in options)
    raise ConfigError(f"'{key}' must be {expected}, found {value!r}: {path}")


def to_toml(cfg: ReplayConfig) -> str:
    """Return the effective config as TOML text (the `config.toml` of every output folder)."""
    lines = ["# Effective configuration of this run (defaults plus --config overrides)."]
    for section in dataclasses.fields(cfg):
        lines.append(f"\n[{section.name}]")
        for f in dataclasses.fields(getattr(cfg, section.name)):
            value = getattr(getattr(cfg, section.name), f.name)
            if value is None:
                continue  # TOML has no null: an absent key means "the default (none)"
            lines.append(f"{f.name} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {value!r} to TOML")


def resolve_stages(spec: str) -> tuple[str, ...]:
    """Return the stages for `--stages`: a name or a comma list; later ones imply earlier ones."""
    names = [s.strip() for s in spec.split(",") if s.strip()]
    bad = [n for n in names if n not in STAGES]
    if bad or not names:
        raise ConfigError(
            f"unknown stage(s) {bad or [spec]}; valid stages, in order: {', '.join(STAGES)}"
        )
    last = max(STAGES.index(n) for n in names)
    return STAGES[: last + 1]
