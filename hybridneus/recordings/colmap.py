"""Camera poses from a COLMAP model (text or binary), read by pycolmap, timed by image."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from hybridneus.errors import RecordingError
from hybridneus.recordings.poses import PoseTrack, make_track


def is_colmap_model(path: str | Path) -> bool:
    """Whether ``path`` is a COLMAP model folder (``images.bin`` or ``images.txt``)."""
    path = Path(path)
    return path.is_dir() and any((path / f"images{s}").is_file() for s in (".bin", ".txt"))


def read_colmap_track(
    path: str | Path,
    frame_times: str | Path | None = None,
    time_scale: float = 1.0,
    **conventions,
) -> PoseTrack:
    """Camera poses from a COLMAP model (text or binary, read by pycolmap).

    COLMAP stores world-to-camera poses in OpenCV axes and knows no times: each image's
    time comes from ``frame_times`` (rows ``NAME TIME``) or else from the image's file stem
    read as a number (``1650000000123456.png``), times ``time_scale`` seconds.

    Args:
        path: the model folder (``cameras``, ``images``, ``points3D`` .bin or .txt).
        frame_times: optional table of image name and time.
        time_scale: seconds per unit of those times.
        **conventions: ``hand_eye`` and ``opengl`` of :func:`make_track` (the poses are
            always world-to-camera).
    """
    path = Path(path)
    need_module = _import_pycolmap(path)
    try:
        model = need_module.Reconstruction(str(path))
    except Exception as exc:  # pycolmap raises RuntimeError/ValueError on unreadable models
        text = str(exc).strip().splitlines()
        raise RecordingError(f"{path}: cannot read as a COLMAP model "
                             f"({text[0] if text else type(exc).__name__})") from None
    names, mats = [], []
    for image in model.images.values():
        pose = image.cam_from_world
        pose = pose() if callable(pose) else pose  # a method since pycolmap 3.12
        if pose is None:
            continue
        names.append(image.name)
        mats.append(np.asarray(pose.matrix(), dtype=np.float64))
    if not names:
        raise RecordingError(f"{path}: the COLMAP model has no registered images")
    times = _image_times(path, names, frame_times) * time_scale
    order = np.argsort(times, kind="stable")
    mats = np.asarray(mats)[order]
    R = mats[:, :3, :3]
    q = Rotation.from_matrix(R).as_quat()
    conventions.pop("world_to_camera", None)
    return make_track(times[order], q, mats[:, :3, 3], str(path), world_to_camera=True,
                      **conventions)


def _import_pycolmap(path: Path):
    from hybridneus.recordings.stream import need

    return need("pycolmap", path, "a COLMAP model")


def _image_times(model: Path, names: list[str], frame_times: str | Path | None) -> np.ndarray:
    if frame_times is None:
        try:
            return np.array([float(Path(n).stem) for n in names])
        except ValueError:
            bad = next(n for n in names if not _is_number(Path(n).stem))
            raise RecordingError(
                f"{model}: image {bad!r} has no time in its name; give --frame-times (rows "
                "of image name and time)") from None
    table = Path(frame_times)
    try:
        lines = table.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{table}: cannot read ({exc})") from None
    known: dict[str, float] = {}
    for i, line in enumerate(lines, 1):
        parts = line.replace(",", " ").split()
        if not parts or parts[0].startswith("#"):
            continue
        if len(parts) != 2 or not _is_number(parts[1]):
            if not known and i == 1:
                continue  # a header
            raise RecordingError(f"{table}: line {i} is not 'NAME TIME': {line[:60]!r}")
        known[parts[0]] = float(parts[1])
        known.setdefault(Path(parts[0]).name, float(parts[1]))
    missing = [n for n in names if n not in known and Path(n).name not in known]
    if missing:
        raise RecordingError(f"{table}: no time for {len(missing)} of the model's images "
                             f"(first: {missing[0]!r})")
    return np.array([known.get(n, known.get(Path(n).name)) for n in names])


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


__all__ = ["is_colmap_model", "read_colmap_track"]
