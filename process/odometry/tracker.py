"""The odometry's state machine: initialise, track, make keyframes, relocalise, close loops."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from capture.recording import RgbdFrame
from process.geometry import project, rigid_inverse
from process.odometry.covisibility import link_recent
from process.odometry.dense import DenseAligner, pose_difference
from process.odometry.features import FeatureExtractor, Keyframe, thumbnail
from process.odometry.keyframes import FeatureCheck, needs_keyframe, refine_densely
from process.odometry.locate import Located, Locator
from process.odometry.loop_closure import LoopCloser
from process.odometry.pose_graph import Edge, PoseGraph
from process.odometry.rolling_shutter import NO_MOTION, RollingShutter, twist_of
from process.odometry.state import TrackState, match_arrays

if TYPE_CHECKING:
    from process.odometry.config import OdometryConfig

__all__ = ["TrackState", "Tracker"]

_WEAK_INFORMATION = 1e-3  # ties a new segment to the old one without constraining it
_DENSE_REFUSALS = 5
_PREDICT_THROUGH_LOST = 5  # lost frames over which the last motion is still extrapolated
_DENSE_PAUSE_FRAMES = 30
_TWIST_FRAMES = 3  # frame intervals over which the rolling-shutter twist is measured


@dataclass(frozen=True, slots=True)
class _Image:
    """One frame's inputs to the tracker."""

    frame: RgbdFrame
    gray: npt.NDArray[np.uint8]
    depth: npt.NDArray[np.float32]
    xy: npt.NDArray[np.float32]  # (N, 2) ORB keypoints
    descriptors: npt.NDArray[np.uint8]  # (N, 32)


class Tracker:
    """Track frames against keyframes and keep the pose graph; see process.odometry.odometry."""

    def __init__(
        self,
        cfg: OdometryConfig,
        *,
        extractor: FeatureExtractor,
        dense: DenseAligner,
        shutter: RollingShutter | None = None,
    ) -> None:
        self.cfg = cfg
        self.extractor = extractor
        self.dense = dense
        self.shutter = shutter  # None: a global shutter
        self.graph = PoseGraph()  # keyframe poses relative to the first camera
        self.keyframes: list[Keyframe] = []  # owned here; others read it
        self.locator = Locator(cfg, extractor=extractor, shutter=shutter)
        self._ref: Keyframe | None = None
        self._kf_from_camera = np.eye(4)
        self._last_world = np.eye(4)
        self._velocity = np.eye(4)  # the last motion, previous_from_current camera
        # The camera's motion per second over the last few tracked frames (rolling shutter),
        # and those frames' (world pose, stamp).
        self._twist = NO_MOTION
        self._recent: list[tuple[npt.NDArray[np.float64], int]] = []
        self._last_gray: npt.NDArray[np.uint8] | None = None
        self._frozen = False
        self._lost = 0
        self._failure = ""
        self._segment = 0
        self._dense_refused = 0  # dense corrections of frames refused in a row
        self._dense_pause = 0  # frames left without dense refinement
        self.loops = LoopCloser(
            cfg, pnp=self.locator.pnp, graph=self.graph, intrinsics=extractor.intrinsics
        )

    def step(
        self, gray: npt.NDArray[np.uint8], depth: npt.NDArray[np.float32], frame: RgbdFrame
    ) -> TrackState:
        """Track one frame: its grey image and its depth in the colour camera."""
        if self._last_gray is not None and np.array_equal(gray, self._last_gray):
            event = (
                None
                if self._frozen
                else f"frozen frame {frame.index}: identical to the previous one"
            )
            self._frozen = True
            return self._hold("frozen", event, np.zeros((0, 2), np.float32))
        self._frozen = False
        self._last_gray = gray
        image = _Image(frame, gray, depth, *self.extractor.detect(gray))
        if self._ref is None:
            return self._initialise(image)
        found = self._track(self._ref, image) or self._relocalise(image)
        if found is None:
            return self._on_lost(image)
        return self._on_found(found, image)

    # -- tracking ------------------------------------------------------------------------------
    def _track(self, kf: Keyframe, image: _Image) -> Located | None:
        """Return the pose of the image against a keyframe, or None (reason in self._failure)."""
        found = self.locator.locate(
            kf, image.xy, image.descriptors, image.depth, prior=self._predict(kf), twist=self._twist
        )
        if isinstance(found, str):
            self._failure = found
            return None
        if not self._lost:
            world = self.graph.poses[kf.id] @ found.pnp.reference_from_camera
            step_m, _ = pose_difference(self._last_world, world)
            if step_m > self.cfg.max_step_m:
                self._failure = f"a jump of {step_m:.2f} m (> max_step_m {self.cfg.max_step_m})"
                return None
        return found

    def _predict(self, kf: Keyframe) -> npt.NDArray[np.float64] | None:
        """Return camera_from_keyframe if the camera keeps its last motion, or None.

        Through a short loss (a blurred or blank frame) the last motion is carried on over the
        lost frames; after a longer one there is no prediction.
        """
        if self._lost > _PREDICT_THROUGH_LOST:
            return None
        world = self._last_world @ np.linalg.matrix_power(self._velocity, self._lost + 1)
        return rigid_inverse(world) @ self.graph.poses[kf.id]

    def _relocalise(self, image: _Image) -> Located | None:
        """Try the recent keyframes and the two that look most alike; keep the best."""
        failure, n = self._failure, self.cfg.relocalise_keyframes
        ids = [k.id for k in self.keyframes[-n - 1 :] if k is not self._ref][-n:] if n else []
        if n and len(self.keyframes) > len(ids) + 1:
            thumb = thumbnail(image.gray)
            scores = np.array([float(k.thumbnail @ thumb) for k in self.keyframes])
            ids += [int(i) for i in np.argsort(-scores)[:2] if int(i) not in ids]
        best: Located | None = None
        for i in ids:
            found = self._track(self.keyframes[i], image)
            if found is not None and (
                best is None or len(found.pnp.inliers) > len(best.pnp.inliers)
            ):
                best = found
        self._failure = failure
        return best

    def _on_found(self, found: Located, image: _Image) -> TrackState:
        kf, n_inliers = found.keyframe, len(found.pnp.inliers)
        kf_from_camera = found.pnp.reference_from_camera
        status, events = "ok", []
        gap, previous = self._lost, self._ref
        if self._lost or kf is not self._ref:
            status = "relocalised"
            after = f" after {self._lost} lost frame(s)" if self._lost else ""
            events.append(f"relocalised frame {image.frame.index} against keyframe {kf.id}{after}")
        self._lost = 0
        is_keyframe = kf is not self._ref or needs_keyframe(
            kf, kf_from_camera, n_inliers, cfg=self.cfg, intrinsics=self.extractor.intrinsics
        )
        self._set_reference(kf)
        corrected = False
        if is_keyframe:
            made = self._make_keyframe(found, kf_from_camera, image)
            is_keyframe = made is not None
            if made is not None:
                kf_from_camera, corrected = np.eye(4), bool(made)
                events.append(made)
        elif self.cfg.dense_refine_all_frames and kf.dense is not None:
            kf_from_camera = self._refine_frame(found, kf_from_camera, image)
        ref = self._ref
        assert ref is not None  # set above
        self._kf_from_camera = kf_from_camera
        world = self.graph.poses[ref.id] @ kf_from_camera
        stamp = image.frame.stamp_ns
        if status == "ok":
            self._velocity = rigid_inverse(self._last_world) @ world
            # Over a few frames: one frame's pose error would feed back into the next frame's
            # rolling-shutter correction (measured on TUM fr1_rpy: RPE 11.5 mm with one frame,
            # 7.9-8.8 mm with two or three).
            self._recent = [*self._recent[-_TWIST_FRAMES:], (world, stamp)]
            first, first_stamp = self._recent[0]
            self._twist = twist_of(rigid_inverse(first) @ world, (stamp - first_stamp) / 1e9)
        else:
            self._recent = [(world, stamp)]
            if gap > _PREDICT_THROUGH_LOST or kf is not previous:
                self._velocity = np.eye(4)  # relocalised elsewhere: the last motion means nothing
                self._twist = NO_MOTION
        self._last_world = world
        event = "; ".join(e for e in events if e) or None
        return TrackState(
            ref.id,
            kf_from_camera,
            is_keyframe,
            status,
            n_inliers,
            *match_arrays(found, image.xy),
            event,
            corrected,
        )

    def _refine_frame(
        self, found: Located, kf_from_camera: npt.NDArray[np.float64], image: _Image
    ) -> npt.NDArray[np.float64]:
        """Return a non-keyframe's pose against kf, refined densely with the short schedule.

        After _DENSE_REFUSALS refused corrections in a row, the next _DENSE_PAUSE_FRAMES frames
        keep their feature pose without trying.
        """
        if self._dense_pause > 0:
            self._dense_pause -= 1
            return kf_from_camera
        current = self.dense.prepare(image.gray, image.depth)
        refined = refine_densely(
            self.dense,
            current,
            found.keyframe.dense,
            kf_from_camera,
            cfg=self.cfg,
            quick=True,
            check=self._check(found, image),
        )
        # Refused again and again (blur, rolling shutter): stop paying for it a while.
        self._dense_refused = self._dense_refused + 1 if refined is kf_from_camera else 0
        if self._dense_refused >= _DENSE_REFUSALS:
            self._dense_refused, self._dense_pause = 0, _DENSE_PAUSE_FRAMES
        return refined

    def _check(self, found: Located, image: _Image) -> FeatureCheck:
        """Return the PnP inliers of a located image, for checking dense corrections."""
        inliers = found.pnp.inliers
        normalised = self.extractor.normalised(found.observed[inliers])
        points = found.keyframe.points[found.train[inliers]]
        return FeatureCheck(points, normalised, self.extractor.intrinsics.fx)

    # -- keyframes -----------------------------------------------------------------------------
    def _new_keyframe(
        self, image: _Image, *, world_from_keyframe: npt.NDArray[np.float64]
    ) -> Keyframe | None:
        """Add the image as a keyframe (node of the graph) if it has enough features with depth."""
        points = self.extractor.lift(image.xy, image.depth)
        has = np.isfinite(points[:, 2])
        xy = image.xy[has]
        if self.shutter is not None and np.any(self._twist):
            # Seen row by row: move the points into the middle row's camera frame.
            points[has] = self.shutter.to_middle(points[has], xy[:, 1], self._twist)
            xy = project(points[has], self.extractor.intrinsics).astype(np.float32)
        if int(has.sum()) < 2 * self.cfg.min_inliers:
            self._failure = (
                f"{int(has.sum())} features with depth (need {2 * self.cfg.min_inliers})"
            )
            return None
        kf = Keyframe(
            id=len(self.keyframes),
            frame_index=image.frame.index,
            stamp_ns=image.frame.stamp_ns,
            segment=self._segment,
            xy=xy,
            descriptors=image.descriptors[has],
            points=points[has],
            thumbnail=thumbnail(image.gray),
        )
        self.graph.add_node(world_from_keyframe)
        self.keyframes.append(kf)
        self._set_reference(kf)
        return kf

    def _set_reference(self, kf: Keyframe) -> None:
        if self._ref is not None and self._ref is not kf:
            self._ref.dense = None  # only the reference keyframe keeps its images
        self._ref = kf

    def _make_keyframe(
        self, found: Located, kf_from_camera: npt.NDArray[np.float64], image: _Image
    ) -> str | None:
        """Make the image a keyframe; return None if it cannot be, else the loop event or ""."""
        parent, features_only = found.keyframe, kf_from_camera
        dense = self.dense.prepare(image.gray, image.depth) if self.cfg.dense_refine else None
        if dense is not None and parent.dense is not None and self._dense_pause == 0:
            kf_from_camera = refine_densely(
                self.dense,
                dense,
                parent.dense,
                kf_from_camera,
                cfg=self.cfg,
                check=self._check(found, image),
            )
        kf = self._new_keyframe(
            image, world_from_keyframe=self.graph.poses[parent.id] @ kf_from_camera
        )
        if kf is None:
            return None
        kf.dense = dense
        assert found.pnp.information is not None  # Locator gives every pose its information
        self.graph.add_edge(Edge(kf.id, parent.id, kf_from_camera, found.pnp.information, False))
        if kf_from_camera is features_only:  # a dense correction needs no more support
            link_recent(
                kf,
                parent,
                (image.xy, image.descriptors, image.depth),
                keyframes=self.keyframes,
                graph=self.graph,
                locator=self.locator,
                cfg=self.cfg,
                twist=self._twist,
            )
        return self.loops.close(kf, self.keyframes)

    def _initialise(self, image: _Image) -> TrackState:
        kf = self._new_keyframe(image, world_from_keyframe=np.eye(4))
        if kf is None:
            self._lost += 1
            note = f"cannot initialise tracking at frame {image.frame.index}: {self._failure}"
            return self._hold("lost", note if self._lost == 1 else None, image.xy)
        if self.cfg.dense_refine:
            kf.dense = self.dense.prepare(image.gray, image.depth)
        self._lost = 0
        note = (
            f"tracking initialised at frame {image.frame.index} ({len(kf.xy)} features with depth)"
        )
        return self._keyframe_state(kf, image.xy, "ok", note)

    def _on_lost(self, image: _Image) -> TrackState:
        self._lost += 1
        event = (
            f"tracking lost at frame {image.frame.index}: {self._failure}"
            if self._lost == 1
            else None
        )
        old = self._ref
        if self._lost < self.cfg.lost_frames_new_segment or old is None:
            return self._hold("lost", event, image.xy)
        self._segment += 1
        kf = self._new_keyframe(image, world_from_keyframe=self._last_world)
        if kf is None:
            self._segment -= 1
            return self._hold("lost", event, image.xy)
        if self.cfg.dense_refine:
            kf.dense = self.dense.prepare(image.gray, image.depth)
        # The new segment starts where the camera was last seen, tied by a weak edge only.
        old_from_new = rigid_inverse(self.graph.poses[old.id]) @ self._last_world
        self.graph.add_edge(Edge(kf.id, old.id, old_from_new, np.eye(6) * _WEAK_INFORMATION, False))
        note = (
            f"new segment {self._segment} at frame {image.frame.index}"
            f" after {self._lost} lost frames"
        )
        self._lost = 0
        return self._keyframe_state(kf, image.xy, "new_segment", note)

    def _keyframe_state(
        self, kf: Keyframe, xy: npt.NDArray[np.float32], status: str, event: str
    ) -> TrackState:
        self._kf_from_camera = np.eye(4)
        self._last_world = self.graph.poses[kf.id].copy()
        self._recent = [(self._last_world, kf.stamp_ns)]
        self._velocity = np.eye(4)
        self._twist = NO_MOTION
        nan = np.full((len(xy), 2), np.nan, np.float32)
        return TrackState(
            kf.id, np.eye(4), True, status, 0, xy, np.zeros(len(xy), bool), nan, event
        )

    def _hold(self, status: str, event: str | None, xy: npt.NDArray[np.float32]) -> TrackState:
        """Keep the last pose: a lost or frozen frame is assumed not to have moved."""
        ref = self._ref.id if self._ref is not None else -1
        nan = np.full((len(xy), 2), np.nan, np.float32)
        mask = np.zeros(len(xy), bool)
        return TrackState(ref, self._kf_from_camera.copy(), False, status, 0, xy, mask, nan, event)
