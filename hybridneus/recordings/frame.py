"""The similarity that takes a recording's metric frame into the unit sphere, and back.

EventNeRF-layout scenes live in a normalised frame: cameras inside the unit sphere (NeRF++:
the farthest at radius 1/1.1), the object near the origin, world +y up (the crop cylinder's
axis). :func:`fit_frame` picks that frame from the camera track: the centre is the point
nearest to every camera's optical axis (where the cameras look) or the centre of a box the
user gives, up is the cameras' mean up direction or the one the user gives. The transform is
saved in ``scene.json`` so that meshes can be written back in the recording's frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from hybridneus.errors import RecordingError

#: Farthest camera's distance from the centre, after normalisation (NeRF++'s 1 / 1.1).
CAMERA_RADIUS = 1.0 / 1.1


@dataclass(frozen=True)
class SceneFrame:
    """``normalised = scale * rotation @ recording + translation``.

    Attributes:
        scale: metres to normalised units.
        rotation: (3, 3) rotation of the recording's axes into the normalised ones.
        translation: (3,) normalised position of the recording's origin.
        centre: (3,) the recording-frame point that becomes the origin.
        how: how the centre and up were chosen, for the user.
    """

    scale: float
    rotation: np.ndarray
    translation: np.ndarray
    centre: np.ndarray
    how: str = ""

    def matrix(self) -> np.ndarray:
        """(4, 4) the similarity from the recording frame to the normalised one."""
        m = np.eye(4)
        m[:3, :3] = self.scale * self.rotation
        m[:3, 3] = self.translation
        return m

    def to_normalised(self, points: np.ndarray) -> np.ndarray:
        """(n, 3) recording-frame points in the normalised frame."""
        return self.scale * np.asarray(points, dtype=np.float64) @ self.rotation.T \
            + self.translation

    def to_recording(self, points: np.ndarray) -> np.ndarray:
        """(n, 3) normalised points back in the recording's frame."""
        return ((np.asarray(points, dtype=np.float64) - self.translation) / self.scale) \
            @ self.rotation

    def poses_to_normalised(self, c2w: np.ndarray) -> np.ndarray:
        """(n, 4, 4) camera-to-world poses in the normalised frame (rotations stay
        orthonormal: only positions are scaled)."""
        out = np.array(c2w, dtype=np.float64, copy=True)
        out[:, :3, :3] = self.rotation @ out[:, :3, :3]
        out[:, :3, 3] = self.to_normalised(out[:, :3, 3])
        return out

    def to_json(self) -> dict:
        return {
            "normalised_from_recording": self.matrix().tolist(),
            "scale": self.scale,
            "recording_centre": self.centre.tolist(),
            "convention": "normalised = scale * R @ recording + t (the 4x4 matrix); meshes "
                          "are written back with its inverse",
            "how": self.how,
        }

    @classmethod
    def from_json(cls, doc: dict, source: str) -> SceneFrame:
        """Read :meth:`to_json`'s output back (``RecordingError`` if it is malformed)."""
        try:
            m = np.asarray(doc["normalised_from_recording"], dtype=np.float64).reshape(4, 4)
        except (KeyError, TypeError, ValueError):
            raise RecordingError(f"{source}: frame.normalised_from_recording is not a 4x4 "
                                 "matrix") from None
        sR = m[:3, :3]
        scale = float(np.cbrt(np.linalg.det(sR)))
        if not np.isfinite(m).all() or not scale > 0:
            raise RecordingError(f"{source}: frame.normalised_from_recording is not a "
                                 "similarity")
        R = sR / scale
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6):
            raise RecordingError(f"{source}: frame.normalised_from_recording is not a "
                                 "similarity (rotation times a scale)")
        centre = np.asarray(doc.get("recording_centre", -R.T @ m[:3, 3] / scale), dtype=float)
        return cls(scale, R, m[:3, 3].copy(), centre, str(doc.get("how", "")))


def look_at_point(c2w: np.ndarray) -> tuple[np.ndarray, float]:
    """The point nearest (least squares) to every camera's optical axis, and the smallest
    singular value of the system, which is near 0 when the axes are nearly parallel."""
    centres = c2w[:, :3, 3]
    dirs = c2w[:, :3, 2]
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    proj = np.eye(3)[None] - dirs[:, :, None] * dirs[:, None, :]
    A = proj.sum(axis=0)
    b = np.einsum("nij,nj->i", proj, centres)
    point = np.linalg.lstsq(A, b, rcond=None)[0]
    return point, float(np.linalg.svd(A / len(c2w), compute_uv=False)[-1])


def fit_frame(
    c2w: np.ndarray,
    up: np.ndarray | None = None,
    box: np.ndarray | None = None,
) -> SceneFrame:
    """Choose the normalised frame for a camera track.

    Args:
        c2w: (n, 4, 4) camera-to-world poses (OpenCV axes) in the recording's frame.
        up: (3,) the recording frame's up direction; None: the cameras' mean up (-y axis).
        box: (2, 3) opposite corners of the region of interest in the recording frame;
            None: centre on where the cameras look.

    Raises:
        RecordingError: the cameras look in parallel directions and no box is given, or the
            track has no extent.
    """
    c2w = np.asarray(c2w, dtype=np.float64)
    if box is not None:
        box = np.asarray(box, dtype=np.float64).reshape(2, 3)
        centre = box.mean(axis=0)
        how = "centre of the given box"
    else:
        centre, conditioning = look_at_point(c2w)
        ahead = np.einsum("ni,ni->n", centre[None] - c2w[:, :3, 3], c2w[:, :3, 2])
        if conditioning < 1e-3 or np.mean(ahead > 0) < 0.9:
            raise RecordingError(
                "poses: the cameras do not look at a common region (their optical axes are "
                "nearly parallel, or the nearest point lies behind them); give the region "
                "with --box")
        how = "point nearest to the cameras' optical axes"
    if up is None:
        up_vec = -c2w[:, :3, 1].mean(axis=0)
        how += "; up: the cameras' mean up direction"
    else:
        up_vec = np.asarray(up, dtype=np.float64).reshape(3)
        how += "; up: given"
    if np.linalg.norm(up_vec) < 1e-6:
        raise RecordingError("poses: the cameras' up directions cancel out; give --up")
    up_vec = up_vec / np.linalg.norm(up_vec)
    R, _ = Rotation.align_vectors([[0.0, 1.0, 0.0]], [up_vec])
    R = R.as_matrix()
    reach = float(np.linalg.norm(c2w[:, :3, 3] - centre, axis=1).max())
    if box is not None:
        reach = max(reach, float(np.linalg.norm(box - centre, axis=1).max()))
    if not reach > 0:
        raise RecordingError("poses: every camera sits at the centre; the track has no extent")
    scale = CAMERA_RADIUS / reach
    return SceneFrame(scale=scale, rotation=R, translation=-scale * R @ centre, centre=centre,
                      how=how)


def box_crop(frame: SceneFrame, box: np.ndarray, margin: float = 0.05) -> dict[str, float]:
    """The crop cylinder (about normalised +y) that holds a recording-frame box, grown by
    ``margin`` of its size: preset fields ``crop_r``, ``crop_y_min``, ``crop_y_max``."""
    box = np.asarray(box, dtype=np.float64).reshape(2, 3)
    corners = np.array([[box[i, 0], box[j, 1], box[k, 2]]
                        for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    pts = frame.to_normalised(corners)
    r = float(np.hypot(pts[:, 0], pts[:, 2]).max())
    y0, y1 = float(pts[:, 1].min()), float(pts[:, 1].max())
    grow = margin * max(r, y1 - y0)
    return {"crop_r": r + grow, "crop_y_min": y0 - grow, "crop_y_max": y1 + grow}


def read_scene_frame(root) -> SceneFrame | None:
    """The ``frame`` that ``hybridneus convert`` saved in ``<root>/scene.json``, or None for
    a dataset without one (published and simulated scenes live in their normalised frame)."""
    import json
    from pathlib import Path

    path = Path(root) / "scene.json"
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RecordingError(f"{path}: cannot read ({exc})") from None
    if not isinstance(doc, dict) or doc.get("frame") is None:
        return None
    if not isinstance(doc["frame"], dict):
        raise RecordingError(f"{path}: 'frame' must be an object")
    return SceneFrame.from_json(doc["frame"], str(path))
