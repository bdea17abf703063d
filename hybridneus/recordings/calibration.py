"""Camera calibrations in the common file forms: intrinsics, lens model, image size.

Read forms (picked from the content, not the suffix):

- Kalibr camchain YAML: ``camN: {camera_model: pinhole, intrinsics: [fx, fy, cx, cy],
  distortion_model: radtan | equidistant | none, distortion_coeffs, resolution: [w, h]}``;
- OpenCV ``FileStorage`` YAML/JSON: ``camera_matrix`` (or ``K``), ``distortion_coefficients``
  (or ``D``, ``dist``), ``image_width``, ``image_height``;
- DSEC's ``cam_to_cam.yaml``: ``intrinsics: {camN: {camera_matrix: [fx, fy, cx, cy],
  distortion_model, distortion_coeffs, resolution: [w, h]}}`` (``cam0`` and ``cam3`` are its
  event cameras, ``camRectN`` their rectified forms);
- plain JSON/YAML: ``fx fy cx cy width height`` with optional ``model`` and ``coeffs`` (or
  ``k1 k2 p1 p2 k3``).

Lens models follow OpenCV: ``radtan`` is ``cv2.undistortPoints``' (k1, k2, p1, p2[, k3, ...]),
``equidistant`` is ``cv2.fisheye``'s Kannala-Brandt (k1..k4).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hybridneus.errors import RecordingError
from hybridneus.recordings.documents import parse_mapping, read_text

MODELS = ("pinhole", "radtan", "equidistant")
_MODEL_NAMES = {
    "none": "pinhole", "pinhole": "pinhole", "": "pinhole",
    "radtan": "radtan", "plumb_bob": "radtan", "opencv": "radtan", "brown": "radtan",
    "rational_polynomial": "radtan",
    "equidistant": "equidistant", "kb4": "equidistant", "fisheye": "equidistant",
    "kannala_brandt": "equidistant", "kannala-brandt": "equidistant",
}


@dataclass(frozen=True)
class Calibration:
    """One camera's intrinsics.

    Attributes:
        width: image width in pixels.
        height: image height in pixels.
        K: (3, 3) pinhole matrix in OpenCV's convention, as the file gives it: the centre
            of pixel ``(0, 0)`` is at image coordinates ``(0, 0)``. The EventNeRF layout puts
            pixel centres at ``+0.5``; :meth:`layout_K` converts.
        model: ``pinhole``, ``radtan`` or ``equidistant``.
        coeffs: the model's coefficients in OpenCV's order (empty for pinhole).
        source: the file it came from.
    """

    width: int
    height: int
    K: np.ndarray
    model: str = "pinhole"
    coeffs: tuple[float, ...] = ()
    source: str = ""

    @property
    def distorted(self) -> bool:
        """Whether the lens model bends rays at all."""
        return self.model != "pinhole" and any(c != 0 for c in self.coeffs)

    def layout_K(self) -> np.ndarray:
        """(3, 3) K for the EventNeRF layout, whose pixel centres sit at ``+0.5``: the same
        rays as OpenCV's K with the principal point moved by half a pixel."""
        K = self.K.copy()
        K[0, 2] += 0.5
        K[1, 2] += 0.5
        return K

    def to_json(self) -> dict:
        return {"width": self.width, "height": self.height, "K": self.K.tolist(),
                "model": self.model, "coeffs": list(self.coeffs), "source": self.source}


def read_calibration(path: str | Path, camera: str | None = None) -> Calibration:
    """Read a calibration file (see the module docstring for the forms).

    Args:
        path: the file.
        camera: which camera of a Kalibr camchain or a DSEC ``cam_to_cam.yaml`` (``cam0`` by
            default, or the only one).

    Raises:
        RecordingError: unreadable file, unknown form, missing or non-finite values, a lens
            model other than pinhole/radtan/equidistant.
    """
    path = Path(path)
    doc = _load(path)
    cams = {k: v for k, v in doc.items() if isinstance(v, dict) and "intrinsics" in v}
    listed = doc.get("intrinsics")
    if not cams and isinstance(listed, dict):  # DSEC: the cameras under one intrinsics key
        cams = {k: _dsec_camera(v) for k, v in listed.items()
                if isinstance(v, dict) and "camera_matrix" in v}
    if cams:
        name = camera or ("cam0" if "cam0" in cams else None)
        if name is None and len(cams) == 1:
            name = next(iter(cams))
        if name not in cams:
            raise RecordingError(f"{path}: camera {name!r} not in the camchain "
                                 f"(have {', '.join(cams)}; pick one with --camera)")
        return _from_kalibr(cams[name], f"{path}:{name}")
    return _from_flat(doc, str(path))


def _dsec_camera(cam: dict) -> dict:
    """A DSEC ``cam_to_cam.yaml`` camera in a Kalibr camchain's terms (the same four
    intrinsics in the same order, the same distortion keys)."""
    out = {"intrinsics": cam["camera_matrix"],
           "distortion_model": cam.get("distortion_model", "none"),
           "distortion_coeffs": cam.get("distortion_coeffs", [])}
    if "resolution" in cam:
        out["resolution"] = cam["resolution"]
    return out


def _load(path: Path) -> dict:
    text = read_text(path)
    if text.lstrip().startswith("%YAML"):
        return _opencv_storage(path)
    return parse_mapping(path, text)


def _opencv_storage(path: Path) -> dict:
    """An OpenCV FileStorage YAML (``%YAML:1.0``, ``!!opencv-matrix``), read by OpenCV."""
    import cv2

    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except cv2.error as exc:
        raise RecordingError(f"{path}: OpenCV cannot parse it ({str(exc).splitlines()[0]})") \
            from None
    doc: dict = {}
    try:
        root = fs.root()
        for key in root.keys():
            node = fs.getNode(key)
            if node.isMap():
                mat = node.mat()  # an !!opencv-matrix; other maps are not calibration data
                if mat is not None:
                    doc[key] = mat
            elif node.isSeq():
                doc[key] = [node.at(i).real() for i in range(node.size())]
            elif node.isString():
                doc[key] = node.string()
            else:
                doc[key] = node.real()
    finally:
        fs.release()
    return doc


def _numbers(value, n: int | tuple[int, ...], what: str, source: str) -> np.ndarray:
    if isinstance(value, dict) and "data" in value:
        value = value["data"]
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise RecordingError(f"{source}: {what} is not a list of numbers") from None
    counts = (n,) if isinstance(n, int) else n
    if arr.size not in counts:
        want = " or ".join(str(c) for c in counts)
        raise RecordingError(f"{source}: {what} has {arr.size} values, expected {want}")
    if not np.isfinite(arr).all():
        raise RecordingError(f"{source}: {what} holds a non-finite value")
    return arr


def _size(value, source: str, what: str) -> int:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise RecordingError(f"{source}: {what} is not a number ({value!r})") from None
    if not v.is_integer() or v < 1:
        raise RecordingError(f"{source}: {what} must be a positive integer, got {value!r}")
    return int(v)


def _model(name, coeffs: np.ndarray, source: str) -> tuple[str, tuple[float, ...]]:
    key = str(name if name is not None else "").strip().lower()
    if key not in _MODEL_NAMES:
        raise RecordingError(f"{source}: lens model {name!r} is not supported (known: radtan/"
                             "plumb_bob, equidistant/kb4/fisheye, none)")
    model = _MODEL_NAMES[key]
    if model == "pinhole" and np.any(coeffs != 0):
        model = "radtan"  # OpenCV files give coefficients without naming the model
    if model == "equidistant" and coeffs.size != 4:
        raise RecordingError(f"{source}: equidistant (kb4) needs 4 coefficients, got "
                             f"{coeffs.size}")
    if model == "radtan" and coeffs.size not in (4, 5, 8, 12, 14):
        raise RecordingError(f"{source}: radtan needs 4, 5, 8, 12 or 14 coefficients "
                             f"(OpenCV's order k1 k2 p1 p2 [k3 ...]), got {coeffs.size}")
    return model, tuple(float(c) for c in coeffs) if model != "pinhole" else ()


def _check_K(K: np.ndarray, width: int, height: int, source: str) -> None:
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if not (fx > 0 and fy > 0):
        raise RecordingError(f"{source}: focal lengths must be positive (fx={fx}, fy={fy})")
    if not (0 <= cx <= width and 0 <= cy <= height):
        raise RecordingError(f"{source}: principal point ({cx:g}, {cy:g}) lies outside the "
                             f"{width}x{height} image")
    if abs(K[0, 1]) > 0.05 * fx:
        raise RecordingError(f"{source}: skew {K[0, 1]:g} is implausible for fx={fx:g}")


def _from_kalibr(cam: dict, source: str) -> Calibration:
    model = str(cam.get("camera_model", "pinhole")).lower()
    if model != "pinhole":
        raise RecordingError(f"{source}: camera_model {model!r} is not supported (pinhole "
                             "with radtan or equidistant distortion is)")
    fx, fy, cx, cy = _numbers(cam["intrinsics"], 4, "intrinsics", source)
    if "resolution" not in cam:
        raise RecordingError(f"{source}: no resolution [width, height]")
    res = cam["resolution"]
    if not isinstance(res, list | tuple) or len(res) != 2:
        raise RecordingError(f"{source}: resolution must be [width, height]")
    w, h = _size(res[0], source, "width"), _size(res[1], source, "height")
    coeffs = _numbers(cam.get("distortion_coeffs", []), (0, 4, 5, 8), "distortion_coeffs",
                      source)
    name, co = _model(cam.get("distortion_model", "none"), coeffs, source)
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    _check_K(K, w, h, source)
    return Calibration(w, h, K, name, co, source)


def _pick(doc: dict, names: tuple[str, ...]):
    return next((doc[n] for n in names if n in doc), None)


def _from_flat(doc: dict, source: str) -> Calibration:
    K_value = _pick(doc, ("K", "camera_matrix", "intrinsic_matrix", "cameraMatrix", "intrinsics"))
    if K_value is not None and np.asarray(
            K_value.get("data") if isinstance(K_value, dict) else K_value,
            dtype=object).size == 9:
        K = _numbers(K_value, 9, "camera matrix", source).reshape(3, 3)
    elif all(k in doc for k in ("fx", "fy", "cx", "cy")):
        K = np.array([[_f(doc, "fx", source), float(doc.get("skew", 0.0)), _f(doc, "cx", source)],
                      [0, _f(doc, "fy", source), _f(doc, "cy", source)], [0, 0, 1.0]])
    else:
        raise RecordingError(
            f"{source}: no intrinsics (expected a Kalibr camchain, an OpenCV camera_matrix / "
            "K, or fx fy cx cy)")
    if not np.allclose(K[2], [0, 0, 1]):
        raise RecordingError(f"{source}: the camera matrix's last row must be 0 0 1")
    w = _pick(doc, ("width", "image_width", "imageWidth", "cols"))
    h = _pick(doc, ("height", "image_height", "imageHeight", "rows"))
    size = doc.get("resolution") or doc.get("image_size") or doc.get("imageSize")
    if (w is None or h is None) and isinstance(size, list | tuple) and len(size) == 2:
        w, h = size
    if w is None or h is None:
        raise RecordingError(f"{source}: no image size (width and height, or resolution)")
    w, h = _size(w, source, "width"), _size(h, source, "height")
    coeffs_value = _pick(doc, ("coeffs", "distortion_coefficients", "distortion_coeffs", "D",
                               "dist", "dist_coeffs", "distCoeffs", "distortion"))
    if isinstance(coeffs_value, dict) and "coeffs" in coeffs_value:
        name = coeffs_value.get("model", doc.get("model"))
        coeffs_value = coeffs_value["coeffs"]
    else:
        name = _pick(doc, ("model", "distortion_model", "lens"))
    if coeffs_value is None:
        named = [k for k in ("k1", "k2", "p1", "p2", "k3") if k in doc]
        coeffs_value = [float(doc.get(k, 0.0)) for k in ("k1", "k2", "p1", "p2", "k3")] \
            if named else []
    if name is not None and str(name).strip().lower() not in _MODEL_NAMES:
        _model(name, np.zeros(0), source)  # names the unsupported model before any count
    coeffs = _numbers(coeffs_value, (0, 4, 5, 8, 12, 14), "distortion coefficients", source)
    model, co = _model(name if name is not None else ("radtan" if coeffs.size else "none"),
                       coeffs, source)
    _check_K(K, w, h, source)
    return Calibration(w, h, K, model, co, source)


def _f(doc: dict, key: str, source: str) -> float:
    try:
        v = float(doc[key])
    except (TypeError, ValueError):
        raise RecordingError(f"{source}: {key} is not a number ({doc[key]!r})") from None
    if not np.isfinite(v):
        raise RecordingError(f"{source}: {key} is not finite")
    return v


def check_lens(calib: Calibration, size: tuple[int, int]) -> None:
    """Refuse a lens whose undistortion does not invert over the whole image (coefficients
    far from any real lens), before anything is written."""
    from hybridneus.data.lens import Lens
    from hybridneus.errors import DatasetError

    lens = Lens(calib.model, calib.coeffs, calib.layout_K(), *size)
    try:
        table = lens.table
    except DatasetError:
        table = None
    if table is not None:
        back = lens.project(table.reshape(-1, 2)).reshape(size[1], size[0], 2)
        u, v = np.meshgrid(np.arange(size[0]) + 0.5, np.arange(size[1]) + 0.5)
        err = float(np.abs(back - np.stack([u, v], -1)).max())
    if table is None or not err < 0.01:
        raise RecordingError(
            f"{calib.source}: the {calib.model} lens {list(calib.coeffs)} does not invert over "
            f"the {size[0]}x{size[1]} image (rays would be wrong); check the coefficients")
    # the undistorted image's width against the pinhole's: a real lens stays within a few
    # times (a 170-degree fisheye: about 8); coefficients in the wrong units or order do not
    row = table[size[1] // 2, :, 0]
    K = calib.layout_K()
    ratio = float((row[-1] - row[0]) / ((size[0] - 1) / K[0, 0]))
    if not 0.2 < ratio < 20.0:
        raise RecordingError(
            f"{calib.source}: the {calib.model} lens {list(calib.coeffs)} makes the image "
            f"{ratio:.3g} times as wide as without it, far from any real lens (coefficients "
            "in the wrong units or order?)")
