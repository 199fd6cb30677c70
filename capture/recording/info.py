"""What `semreplay-capture info` says about a recording: topics, frames, duration, drops, device."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from capture.errors import RecordingError
from capture.recording.index import TopicInfo, damage_note
from capture.recording.reader import RecordingReader


@dataclass(frozen=True, slots=True)
class RecordingInfo:
    """A summary of one recording."""

    path: Path
    finished: bool
    topics: list[TopicInfo]
    duration_s: float
    frames: int | None  # colour frames; None when it is not an RGB-D recording
    aligned: bool | None
    not_rgbd: str = ""  # why the reader refuses it, when frames is None
    device: dict[str, str] = field(default_factory=dict)
    capture: dict[str, str] = field(default_factory=dict)
    attachments: list[str] = field(default_factory=list)
    damage: str = ""  # what was lost, one line ("" when intact)

    @property
    def drops(self) -> dict[str, int] | None:
        """Return frames dropped per stream, from the `capture` record written at the end."""
        text = self.capture.get("frames_dropped")
        if not text:
            return None
        data = json.loads(text)
        return {str(k): int(v) for k, v in data.items()} if isinstance(data, dict) else None


def describe(path: Path) -> RecordingInfo:
    """Return the summary of a recording (finished, recovered or damaged; RGB-D or not).

    The frame count: for an intact finished recording, its colour frames; for an unfinished or
    damaged one, the frames that `process run` replays (they are decoded here, so that both
    commands give the same number).
    """
    path = Path(path)
    rec = RecordingReader(path, verify=True)  # every chunk checked: exact counts
    frames: int | None = None
    aligned: bool | None = None
    reason = ""
    try:
        rec.open()
    except RecordingError as err:
        if rec.index is None:
            raise  # not a file, not MCAP, nothing readable: nothing to describe
        reason = str(err)
    else:
        with rec:
            aligned = rec.aligned
            try:
                frames = _count_frames(rec)
            except RecordingError as err:
                reason = str(err)
    index = rec.index
    if index is None:  # open() read it or raised above
        raise RecordingError(f"recording could not be read: {path}")
    return RecordingInfo(
        path=path,
        finished=index.finished,
        topics=sorted(index.topics.values(), key=lambda t: t.name),
        duration_s=(index.end_ns - index.start_ns) / 1e9,
        frames=frames,
        aligned=aligned,
        not_rgbd=reason,
        device=index.metadata.get("device", {}),
        capture=index.metadata.get("capture", {}),
        attachments=list(index.attachments),
        damage=damage_note(index, path),
    )


def _count_frames(rec: RecordingReader) -> int:
    """Return the frames a run replays (a replay when the file is damaged or unfinished)."""
    index = rec.index
    if index is not None and index.finished and not index.damage.any and not index.duplicates:
        return len(rec)
    return sum(1 for _ in rec.frames())


def format_info(info: RecordingInfo) -> str:
    """Return the lines `info` prints."""
    if info.finished:
        state = "yes"
    else:
        got = "no RGB-D frames" if info.frames is None else f"{info.frames} colour frames"
        state = f"no (writer killed?): recovered {got} from its complete chunks"
    if info.frames is None:
        frames = f"none: {info.not_rgbd}"
    else:
        depth = "aligned to colour" if info.aligned else "raw, registered with the extrinsics"
        frames = f"{info.frames} (depth {depth})"
    drops = info.drops
    dropped = (
        ", ".join(f"{k} {v}" for k, v in drops.items())
        if drops is not None
        else "unknown (no end-of-capture record)"
    )
    damage = info.damage.rsplit(": ", 1)[0].removeprefix("recording is damaged: ")
    device = " ".join(f"{k}={v}" for k, v in info.device.items() if v) or "unknown"
    lines = [
        f"recording  {info.path}",
        f"finished   {state}",
        f"frames     {frames}",
        f"duration   {info.duration_s:.3f} s",
        f"dropped    {dropped}",
        f"damage     {damage or 'none'}",
        f"device     {device}",
        f"attached   {', '.join(info.attachments) or 'nothing'}",
        "topics",
    ]
    width = max((len(t.name) for t in info.topics), default=0)
    lines += [f"  {t.name:<{width}}  {t.datatype:<40}  {t.count}" for t in info.topics]
    return "\n".join(lines)
