"""Poses from 3-D/2-D matches: PnP RANSAC with a motion-prior hypothesis, refined by LM."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from process.geometry import rigid_inverse

_PRIOR_GATE = 4.0  # matches within this many RANSAC thresholds of the prior seed its hypothesis
_PRIOR_SHARE = 0.8  # the prior's hypothesis wins with at least this share of RANSAC's inliers
_PRIOR_ENOUGH = 0.5  # ... and RANSAC is not even tried when it explains this share of the matches


@dataclass(frozen=True, slots=True)
class PnpResult:
    """A pose from 3-D/2-D matches: the reference's points seen by the current camera."""

    camera_from_reference: npt.NDArray[np.float64]  # (4, 4)
    inliers: npt.NDArray[np.int64]  # indices into the matches given
    rms_px: float
    # (6, 6) of reference_from_camera as a pose-graph edge (process.odometry.pose_refine), or
    # None until the pose is refined with depth
    information: npt.NDArray[np.float64] | None = None

    @property
    def reference_from_camera(self) -> npt.NDArray[np.float64]:
        """Return the inverse pose: the current camera in the reference frame."""
        return rigid_inverse(self.camera_from_reference)


@dataclass(frozen=True, slots=True)
class PnpSolver:
    """PnP RANSAC on 3-D/2-D matches, then Levenberg-Marquardt on the inliers."""

    camera_matrix: npt.NDArray[np.float64]
    dist: npt.NDArray[np.float64] | None
    reprojection_px: float
    iterations: int
    confidence: float

    def solve(
        self,
        points: npt.NDArray[np.float32],
        xy: npt.NDArray[np.float32],
        *,
        min_inliers: int,
        prior: npt.NDArray[np.float64] | None = None,
        prior_enough: int | None = None,
    ) -> PnpResult | None:
        """Return the pose mapping reference points onto pixels, or None with < min_inliers.

        With a prior (the pose predicted by the camera's last motion) a second hypothesis is
        grown from the matches that the prior already explains. On repetitive texture (floor
        planks, book spines) RANSAC can find a consensus of matches shifted by one period, as
        large as the true one; the prior's hypothesis wins unless it has clearly fewer inliers.
        RANSAC is not tried when the prior's hypothesis explains half the matches, or at least
        prior_enough of them.
        """
        if len(points) < max(min_inliers, 6):
            return None
        obj = np.ascontiguousarray(points, np.float64)
        img = np.ascontiguousarray(xy, np.float64)
        predicted = self._from_prior(obj, img, prior, min_inliers) if prior is not None else None
        enough = min(_PRIOR_ENOUGH * len(obj), prior_enough or len(obj))
        if predicted is not None and len(predicted.inliers) >= enough:
            return predicted  # the camera moved as predicted: no need for RANSAC
        seed = self._ransac(obj, img, min_inliers)
        found = self._refine(obj, img, seed, min_inliers) if seed is not None else None
        if predicted is None:
            return found
        if found is None or len(predicted.inliers) >= _PRIOR_SHARE * len(found.inliers):
            return predicted
        return found

    def _from_prior(
        self,
        obj: npt.NDArray[np.float64],
        img: npt.NDArray[np.float64],
        prior: npt.NDArray[np.float64],
        min_inliers: int,
    ) -> PnpResult | None:
        """Return the pose grown from the matches the prior already explains, or None."""
        rvec = np.asarray(cv2.Rodrigues(prior[:3, :3])[0], np.float64)
        tvec = prior[:3, 3].reshape(3, 1).copy()
        err = _reprojection_errors(obj, img, rvec, tvec, self.camera_matrix, self.dist)
        gated = np.flatnonzero(err < _PRIOR_GATE * self.reprojection_px).astype(np.int64)
        if len(gated) < min_inliers:
            return None
        return self._refine(obj, img, (rvec, tvec, gated), min_inliers)

    def _ransac(
        self, obj: npt.NDArray[np.float64], img: npt.NDArray[np.float64], min_inliers: int
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.int64]] | None:
        ok, rvec, tvec, inliers = cv2.solvePnPRansac(
            obj,
            img,
            self.camera_matrix,
            self.dist,
            iterationsCount=self.iterations,
            reprojectionError=self.reprojection_px,
            confidence=self.confidence,
            flags=cv2.SOLVEPNP_EPNP,
        )
        if not ok or inliers is None or len(inliers) < min_inliers:
            return None
        idx = np.asarray(inliers).ravel().astype(np.int64)
        return np.asarray(rvec, np.float64), np.asarray(tvec, np.float64), idx

    def _refine(
        self,
        obj: npt.NDArray[np.float64],
        img: npt.NDArray[np.float64],
        hypothesis: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.int64]],
        min_inliers: int,
    ) -> PnpResult | None:
        """Run LM on the inliers twice, re-selecting them with the refined pose in between."""
        rvec, tvec, idx = hypothesis
        for _ in range(2):
            refined = cv2.solvePnPRefineLM(
                obj[idx], img[idx], self.camera_matrix, self.dist, rvec, tvec
            )
            rvec, tvec = np.asarray(refined[0], np.float64), np.asarray(refined[1], np.float64)
            err = _reprojection_errors(obj, img, rvec, tvec, self.camera_matrix, self.dist)
            idx = np.flatnonzero(err < self.reprojection_px).astype(np.int64)
            if len(idx) < min_inliers:
                return None
        rms = float(np.sqrt(np.mean(err[idx] ** 2)))
        return PnpResult(to_matrix(rvec, tvec), idx, rms)


def _reprojection_errors(
    obj: npt.NDArray[np.float64],
    img: npt.NDArray[np.float64],
    rvec: npt.NDArray[np.float64],
    tvec: npt.NDArray[np.float64],
    camera_matrix: npt.NDArray[np.float64],
    dist: npt.NDArray[np.float64] | None,
) -> npt.NDArray[np.float64]:
    """Return each match's reprojection error in pixels, infinite behind the camera."""
    rot = np.asarray(cv2.Rodrigues(rvec)[0], np.float64)
    cam = obj @ rot.T + tvec.reshape(1, 3)
    behind = cam[:, 2] <= 0
    if dist is None:  # pinhole (undistorted images): numpy is cheaper than projectPoints
        k = camera_matrix
        z = np.where(behind, 1.0, cam[:, 2])
        du = (k[0, 0] * cam[:, 0] + k[0, 1] * cam[:, 1]) / z + k[0, 2] - img[:, 0]
        dv = k[1, 1] * cam[:, 1] / z + k[1, 2] - img[:, 1]
        err = np.hypot(du, dv)
    else:
        proj, _ = cv2.projectPoints(obj, rvec, tvec, camera_matrix, dist)
        err = np.linalg.norm(np.asarray(proj).reshape(-1, 2) - img, axis=1)
    err = np.asarray(err, np.float64)
    err[behind] = np.inf
    return err


def to_matrix(
    rvec: npt.NDArray[np.float64], tvec: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """Return the 4x4 transform of an OpenCV (rvec, tvec) pair."""
    out = np.eye(4)
    out[:3, :3] = np.asarray(cv2.Rodrigues(np.asarray(rvec, np.float64))[0], np.float64)
    out[:3, 3] = np.asarray(tvec, np.float64).ravel()
    return out
