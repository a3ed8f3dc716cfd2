"""Averaging on SE(3): the mean of sampled rigid transforms, with outlier rejection.

The translation is the (weighted) mean; the rotation is Markley's quaternion average, the
eigenvector of the largest eigenvalue of ``sum w q q^T``, which minimises the weighted sum of squared
chordal distances and does not care about the sign of each quaternion (``q`` and ``-q`` are the same
rotation). Outliers are rejected iteratively, starting from a robust centre (the per-axis median
translation and the medoid rotation): a sample is kept when its translation distance and its
rotation angle to the current estimate are both within ``threshold`` times the median of those
distances over all samples (and within the optional absolute limits); the estimate is the mean of
the kept samples; repeat until the kept set no longer changes.

Plain functions of arrays (no graph): the registration workflow (:mod:`.registration`) uses them,
and so can samples that come from elsewhere.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from . import se3
from ..errors import RegistrationError

log = logging.getLogger("coco.transforms")


def _as_samples(samples: Sequence[np.ndarray] | np.ndarray) -> np.ndarray:
    """Check a stack of 4x4 rigid transforms (vectorised version of :func:`se3.as_transform`)."""
    stack = np.array(samples, dtype=float)
    if stack.ndim == 2 and stack.shape == (4, 4):
        stack = stack[None]
    if stack.ndim != 3 or stack.shape[1:] != (4, 4):
        raise RegistrationError(f"expected a sequence of 4x4 homogeneous transforms, got shape {stack.shape}")
    if not np.all(np.isfinite(stack)):
        bad = np.flatnonzero(~np.isfinite(stack).all(axis=(1, 2)))
        raise RegistrationError(f"sample(s) {bad[:10].tolist()} contain NaN or infinite values")
    bottom = np.abs(stack[:, 3] - np.array([0.0, 0.0, 0.0, 1.0])).sum(axis=1)
    rotations = stack[:, :3, :3]
    orthonormality = np.abs(np.einsum("nij,nkj->nik", rotations, rotations) - np.eye(3)).max(axis=(1, 2))
    bad = np.flatnonzero((bottom > 1e-9) | (orthonormality > 1e-6))
    if bad.size:
        raise RegistrationError(f"sample(s) {bad[:10].tolist()} are not rigid transforms (the last row must be "
                                "0 0 0 1 and the rotation orthonormal)")
    return stack


def _as_weights(weights: Sequence[float] | np.ndarray | None, count: int) -> np.ndarray:
    if weights is None:
        return np.ones(count)
    array = np.asarray(weights, dtype=float).reshape(-1)
    if array.shape[0] != count:
        raise RegistrationError(f"got {array.shape[0]} weights for {count} samples")
    if not np.all(np.isfinite(array)) or np.any(array < 0.0):
        raise RegistrationError("weights must be finite and non-negative")
    return array


def _quaternions(rotations: np.ndarray) -> np.ndarray:
    return np.array([se3.matrix_to_quaternion(rotation) for rotation in rotations])


def _markley(quaternions: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Markley's average of unit quaternions (rows, ``(x, y, z, w)``); ``w >= 0``."""
    total = float(weights.sum())
    if total <= 0.0:
        raise RegistrationError("the weights of the samples sum to zero")
    matrix = np.einsum("n,ni,nj->ij", weights / total, quaternions, quaternions)
    values, vectors = np.linalg.eigh(matrix)  # ascending
    if values[-1] - values[-2] < 1e-9:
        raise RegistrationError(
            "the rotations have no unique mean: they are spread too evenly (e.g. two rotations 180 degrees "
            f"apart with equal weights; eigenvalues {values[-1]:.6g} and {values[-2]:.6g} coincide)")
    mean = vectors[:, -1]
    mean = mean / np.linalg.norm(mean)
    return -mean if mean[3] < 0.0 else mean


def average_quaternions(quaternions: Sequence[Sequence[float]] | np.ndarray,
                        weights: Sequence[float] | np.ndarray | None = None) -> np.ndarray:
    """Weighted mean rotation of quaternions ``(x, y, z, w)`` (Markley et al., 2007): the unit
    eigenvector of the largest eigenvalue of ``sum w q q^T``. The sign of each input quaternion does
    not matter; the result has ``w >= 0``. Raises :class:`RegistrationError` when the mean is not
    unique (the rotations are spread evenly, e.g. two of them 180 degrees apart)."""
    array = np.array(quaternions, dtype=float)
    if array.ndim != 2 or array.shape[1] != 4 or array.shape[0] == 0:
        raise RegistrationError(f"expected a non-empty sequence of quaternions (x, y, z, w), got shape {array.shape}")
    norms = np.linalg.norm(array, axis=1)
    if not np.all(np.isfinite(norms)) or np.any(norms < 1e-12):
        raise RegistrationError("quaternions must be finite and non-zero")
    return _markley(array / norms[:, None], _as_weights(weights, array.shape[0]))


def _average(stack: np.ndarray, quaternions: np.ndarray, weights: np.ndarray) -> np.ndarray:
    total = float(weights.sum())
    if total <= 0.0:
        raise RegistrationError("the weights of the samples sum to zero")
    translation = weights @ stack[:, :3, 3] / total
    return se3.make(se3.quaternion_to_matrix(_markley(quaternions, weights)), translation)


def average_transforms(samples: Sequence[np.ndarray] | np.ndarray,
                       weights: Sequence[float] | np.ndarray | None = None) -> np.ndarray:
    """Weighted mean on SE(3) of 4x4 rigid transforms, with no outlier rejection: mean translation,
    Markley mean rotation. See :func:`robust_average` for noisy data with outliers."""
    stack = _as_samples(samples)
    if stack.shape[0] == 0:
        raise RegistrationError("cannot average zero samples")
    return _average(stack, _quaternions(stack[:, :3, :3]), _as_weights(weights, stack.shape[0]))


def transform_residuals(reference: np.ndarray, samples: Sequence[np.ndarray] | np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Per sample: the distance of its translation to ``reference``'s (same unit as the input, e.g. m)
    and the angle of the rotation between them (rad, in [0, pi]; atan2 form, exact for small angles)."""
    stack = _as_samples(samples)
    reference = se3.as_transform(reference)
    translation = np.linalg.norm(stack[:, :3, 3] - reference[:3, 3], axis=1)
    relative = np.einsum("ji,njk->nik", reference[:3, :3], stack[:, :3, :3])  # R_ref^T R_i
    sine = 0.5 * np.linalg.norm(np.stack([relative[:, 2, 1] - relative[:, 1, 2], relative[:, 0, 2] - relative[:, 2, 0],
                                          relative[:, 1, 0] - relative[:, 0, 1]], axis=1), axis=1)
    cosine = 0.5 * (np.trace(relative, axis1=1, axis2=2) - 1.0)
    return translation, np.arctan2(sine, cosine)


@dataclass(frozen=True, eq=False)
class AverageResult:
    """A robust mean on SE(3) and how well the samples agree with it.

    Residuals are per sample, against the final ``transform``: translation distance (the input's
    length unit, m in the graph) and rotation angle (rad). The RMS and max statistics cover the samples
    kept (``inliers``); ``*_uncertainty`` is the RMS divided by the square root of the number kept,
    a rough standard error of the mean when the noise is independent from sample to sample.
    """

    transform: np.ndarray
    inliers: np.ndarray
    translation_residuals: np.ndarray
    rotation_residuals: np.ndarray
    translation_threshold: float
    rotation_threshold: float
    iterations: int

    @property
    def total(self) -> int:
        return int(self.inliers.size)

    @property
    def used(self) -> int:
        return int(np.count_nonzero(self.inliers))

    @property
    def rejected(self) -> int:
        return self.total - self.used

    @property
    def rejected_indices(self) -> list[int]:
        return np.flatnonzero(~self.inliers).tolist()

    @property
    def rms_translation(self) -> float:
        return root_mean_square(self.translation_residuals[self.inliers])

    @property
    def rms_rotation(self) -> float:
        return root_mean_square(self.rotation_residuals[self.inliers])

    @property
    def max_translation(self) -> float:
        kept = self.translation_residuals[self.inliers]
        return float(kept.max()) if kept.size else 0.0

    @property
    def max_rotation(self) -> float:
        kept = self.rotation_residuals[self.inliers]
        return float(kept.max()) if kept.size else 0.0

    @property
    def translation_uncertainty(self) -> float:
        return self.rms_translation / math.sqrt(max(self.used, 1))

    @property
    def rotation_uncertainty(self) -> float:
        return self.rms_rotation / math.sqrt(max(self.used, 1))

    def summary(self) -> str:
        return (f"{self.used} of {self.total} samples used ({self.rejected} rejected); residual RMS "
                f"{self.rms_translation * 1e3:.3f} mm, {math.degrees(self.rms_rotation):.4f} deg; max "
                f"{self.max_translation * 1e3:.3f} mm, {math.degrees(self.max_rotation):.4f} deg; uncertainty "
                f"~{self.translation_uncertainty * 1e3:.3f} mm, {math.degrees(self.rotation_uncertainty):.4f} deg")

    def describe(self) -> dict[str, Any]:
        """JSON-ready: the transform, as a pose too, and the residual statistics (m, rad)."""
        translation, quaternion = se3.to_pose(self.transform)
        return {"transform": self.transform.tolist(), "translation": translation.tolist(),
                "quaternion": quaternion.tolist(), "samples": self.total, "used": self.used,
                "rejected": self.rejected, "rms_translation": self.rms_translation,
                "rms_rotation": self.rms_rotation, "max_translation": self.max_translation,
                "max_rotation": self.max_rotation, "translation_uncertainty": self.translation_uncertainty,
                "rotation_uncertainty": self.rotation_uncertainty,
                "translation_threshold": self.translation_threshold,
                "rotation_threshold": self.rotation_threshold, "iterations": self.iterations}


def root_mean_square(values: np.ndarray) -> float:
    return float(math.sqrt(np.mean(values * values))) if values.size else 0.0


def _medoid_rotation(quaternions: np.ndarray) -> int:
    """Index of the sample whose rotation has the smallest median distance to all the others (a robust
    start: unlike the mean, far-off rotations do not pull it). At most 256 candidates, spread evenly."""
    count = quaternions.shape[0]
    candidates = np.unique(np.linspace(0, count - 1, min(count, 256)).astype(int))
    distance = 1.0 - np.abs(quaternions[candidates] @ quaternions.T)  # monotonic in the angle
    return int(candidates[np.argmin(np.median(distance, axis=1))])


def robust_average(samples: Sequence[np.ndarray] | np.ndarray,
                   weights: Sequence[float] | np.ndarray | None = None, *,
                   threshold: float = 3.0,
                   max_translation: float | None = None,
                   max_rotation: float | None = None,
                   min_samples: int = 3,
                   max_iterations: int = 50,
                   translation_floor: float = 1e-6,
                   rotation_floor: float = 1e-6) -> AverageResult:
    """Mean on SE(3) of noisy 4x4 transforms with outlier rejection.

    A sample is kept when its translation distance to the estimate is at most
    ``clip(threshold * median(all translation distances), translation_floor, max_translation)`` and
    its rotation angle likewise (``rotation_floor`` and ``max_rotation`` in rad). The floors keep
    near-perfect data (e.g. simulated) from being rejected over rounding. With ``threshold`` 3, a
    sample of isotropic Gaussian noise is rejected with probability ~1e-4; noise along a single axis
    ~4e-2 (raise ``threshold`` for such data if rejecting a few good samples matters).

    Raises :class:`RegistrationError` with fewer than ``min_samples`` samples (or kept samples), and when
    the rotations have no unique mean.
    """
    if threshold <= 0.0:
        raise RegistrationError(f"threshold must be positive, got {threshold}")
    min_samples = max(int(min_samples), 1)
    max_iterations = max(int(max_iterations), 1)
    stack = _as_samples(samples) if len(samples) else np.zeros((0, 4, 4))
    count = stack.shape[0]
    if count < min_samples:
        raise RegistrationError(f"a robust average needs at least {min_samples} samples, got {count}")
    weight = _as_weights(weights, count)
    quaternions = _quaternions(stack[:, :3, :3])
    estimate = se3.make(stack[_medoid_rotation(quaternions), :3, :3], np.median(stack[:, :3, 3], axis=0))
    inliers: np.ndarray | None = None
    iterations = 0
    while True:
        translation, rotation = transform_residuals(estimate, stack)
        translation_limit = max(translation_floor, threshold * float(np.median(translation)))
        rotation_limit = max(rotation_floor, threshold * float(np.median(rotation)))
        if max_translation is not None:
            translation_limit = min(translation_limit, max_translation)
        if max_rotation is not None:
            rotation_limit = min(rotation_limit, max_rotation)
        kept = (translation <= translation_limit) & (rotation <= rotation_limit) & (weight > 0.0)
        if inliers is not None and np.array_equal(kept, inliers):
            break
        if iterations >= max_iterations:
            log.warning("robust average: the kept samples still change after %d iterations", iterations)
            break
        used = int(np.count_nonzero(kept))
        if used < min_samples:
            raise RegistrationError(
                f"only {used} of {count} samples agree within {translation_limit * 1e3:.3f} mm and "
                f"{math.degrees(rotation_limit):.4f} deg of the robust centre; at least {min_samples} are needed "
                f"(closest residuals: {np.sort(translation)[:3].round(6).tolist()} m, "
                f"{np.sort(rotation)[:3].round(6).tolist()} rad)")
        inliers = kept
        estimate = _average(stack[kept], quaternions[kept], weight[kept])
        iterations += 1
    assert inliers is not None  # the first pass always sets it (max_iterations >= 1)
    translation.flags.writeable = rotation.flags.writeable = inliers.flags.writeable = False
    return AverageResult(se3.frozen(estimate), inliers, translation, rotation, translation_limit, rotation_limit,
                         iterations)
