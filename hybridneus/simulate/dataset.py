"""``simulate_dataset``: mesh -> rendered views -> colour events -> EventNeRF layout on disk.

Output (written through :func:`hybridneus.fileio.atomic_dir`, so a failed run leaves
nothing under the final name)::

    OUT/scene.json          what was simulated, the transform, and a reader "preset"
    OUT/gt_mesh.ply         the normalised mesh in world coordinates
    OUT/<split>/intrinsics/r_00000.txt   4x4 (or 5x4 with k1 k2) row-major
    OUT/<split>/pose/r_00000.txt         4x4 camera-to-world, OpenCV axes, row-major
    OUT/<split>/rgb/r_00000.png          the rendered frame (sRGB)
    OUT/<split>/events/events.npz        x int16, y int16, t float64, p int8 (np.savez)

Splits: ``train`` (the spiral), ``validation`` (a circle at 30 degrees elevation) and ``test``
(an evenly wound spiral between 60 and 5 degrees, shifted 45 degrees in azimuth); each has
its own event stream simulated along its own trajectory.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from hybridneus.fileio import atomic_dir
from hybridneus.simulate import generated
from hybridneus.simulate.capture import CaptureErrors, written_poses
from hybridneus.simulate.events import (
    EventChunk,
    EventModel,
    EventSimulator,
    NoiseConfig,
    SimulationError,
)
from hybridneus.simulate.procedural import builtin_scene
from hybridneus.simulate.render import PinholeCamera, Renderer, Shading
from hybridneus.simulate.scene_mesh import SceneMesh, load_mesh, normalization_for
from hybridneus.simulate.trajectory import (
    Trajectory,
    circle,
    even_spiral,
    look_at_origin,
    seiffert_spiral,
)

BUILTIN_PREFIX = "builtin:"
#: NeRF++ normalisation: the farthest camera sits at 1 / 1.1 of the unit sphere.
CAMERA_RADIUS = 1.0 / 1.1


@dataclass(frozen=True)
class SimulationConfig:
    """Everything that defines a simulated dataset (all recorded in scene.json).

    Attributes:
        n_views: training views along the spiral. Default: 999.
        revolutions: turns of the training spiral. Default: 8.
        spiral: ``seiffert`` (constant speed, the paper's), ``even`` (constant elevation
            change per turn, from the pole to the equator) or ``circle`` (constant
            ``elevation_deg``, like a turntable capture; one revolution wraps around).
        elevation_deg: elevation of the ``circle`` trajectory. Default: 30 degrees.
        width, height: image size. Default: 346 x 260 (DAVIS 346).
        fov_y_deg: vertical field of view; ``fx = fy = (height / 2) / tan(fov_y / 2)``,
            ``cx, cy = width / 2, height / 2``. Default: 55 degrees, which fits the object's
            bounding sphere (radius 0.4 at distance 0.909) in the frame height with ~5% margin.
        object_radius: bounding-sphere radius of the normalised object. Default: 0.4.
        camera_radius: distance of every camera from the origin. Default: 1 / 1.1.
        distortion: (k1, k2) radial distortion; nonzero writes 5x4 intrinsics.
        supersample: rays per pixel along each axis. Default: 2 (4 rays per pixel).
        events: thresholds and log mapping (:class:`EventModel`).
        noise: sensor noise (:class:`NoiseConfig`), off by default.
        shading: light and background (:class:`Shading`); the background also goes into the
            preset of scene.json.
        seed: seed of the noise generators (each split derives its own).
        val_views, test_views: views of the validation and test splits (0 skips a split).
        batch_views: views per ``cast_rays`` call.
        n_threads: ray-casting threads (0 = all cores).
        write_rgb: write ``rgb/r_*.png`` (the reader only needs their names).
        capture: errors of the training split's written poses (:class:`CaptureErrors`).
    """

    n_views: int = 999
    revolutions: float = 8.0
    spiral: str = "seiffert"
    elevation_deg: float = 30.0
    width: int = 346
    height: int = 260
    fov_y_deg: float = 55.0
    object_radius: float = 0.4
    camera_radius: float = CAMERA_RADIUS
    distortion: tuple[float, float] = (0.0, 0.0)
    supersample: int = 2
    events: EventModel = field(default_factory=EventModel)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    shading: Shading = field(default_factory=Shading)
    seed: int = 0
    val_views: int = 100
    test_views: int = 200
    batch_views: int = 8
    n_threads: int = 0
    write_rgb: bool = True
    capture: CaptureErrors = field(default_factory=CaptureErrors)

    def __post_init__(self) -> None:
        if self.n_views < 2:
            raise ValueError(f"n_views must be >= 2, got {self.n_views}")
        if self.spiral not in ("seiffert", "even", "circle"):
            raise ValueError(f"spiral must be 'seiffert', 'even' or 'circle', got {self.spiral!r}")
        if not -90.0 < self.elevation_deg < 90.0:
            raise ValueError(f"elevation_deg must be in (-90, 90), got {self.elevation_deg}")
        if not (0 < self.object_radius < self.camera_radius <= 1.0):
            raise ValueError("need 0 < object_radius < camera_radius <= 1, got "
                             f"{self.object_radius}, {self.camera_radius}")
        if min(self.width, self.height) < 2 or self.supersample < 1:
            raise ValueError("width, height must be >= 2 and supersample >= 1")
        if not 0 < self.fov_y_deg < 170:
            raise ValueError(f"fov_y_deg must be in (0, 170), got {self.fov_y_deg}")
        for name in ("val_views", "test_views"):
            v = getattr(self, name)
            if v != 0 and v < 2:
                raise ValueError(f"{name} must be 0 (skip) or >= 2, got {v}")


@dataclass
class SplitResult:
    """Counts and timings of one simulated split."""

    name: str
    trajectory: Trajectory
    n_events: int
    n_positive: int
    render_s: float
    events_s: float
    write_s: float


def split_trajectories(config: SimulationConfig) -> dict[str, Trajectory]:
    """The trajectory of each split that ``config`` asks for."""
    if config.spiral == "seiffert":
        train = seiffert_spiral(config.n_views, config.revolutions)
    elif config.spiral == "even":
        train = even_spiral(config.n_views, config.revolutions)
    else:
        train = circle(config.n_views, config.elevation_deg, config.revolutions)
    out = {"train": train}
    if config.val_views:
        out["validation"] = circle(config.val_views, elevation_deg=30.0, azimuth_offset_deg=15.0)
    if config.test_views:
        out["test"] = even_spiral(config.test_views, revolutions=2.0, elevation_start_deg=60.0,
                                  elevation_end_deg=5.0, azimuth_offset_deg=45.0)
    return out


def resolve_mesh(mesh: str | os.PathLike | SceneMesh) -> tuple[SceneMesh, str]:
    """Load ``mesh`` (a path, ``builtin:<name>``, ``generated:<kind>:<seed>`` or a SceneMesh);
    return it and a scene name."""
    if isinstance(mesh, SceneMesh):
        name = Path(mesh.source).stem if mesh.source else "mesh"
        return mesh, name.replace(BUILTIN_PREFIX, "")
    text = str(mesh)
    if text.startswith(BUILTIN_PREFIX):
        name = text[len(BUILTIN_PREFIX):]
        return builtin_scene(name), name
    if text.startswith(generated.PREFIX):
        kind, seed = generated.parse_source(text)
        return generated.generated_scene(kind, seed), f"{kind}{seed}"
    return load_mesh(text), Path(text).stem


def crop_cylinder(vertices: np.ndarray, margin: float = 0.05) -> tuple[float, float, float]:
    """(crop_r, crop_y_min, crop_y_max): a y-axis cylinder around the vertices plus ``margin``,
    clipped to the unit sphere's box."""
    r = float(np.sqrt(vertices[:, 0] ** 2 + vertices[:, 2] ** 2).max()) + margin
    y0 = float(vertices[:, 1].min()) - margin
    y1 = float(vertices[:, 1].max()) + margin
    return min(r, 1.0), max(y0, -1.0), min(y1, 1.0)


def _intrinsics_matrix(camera: PinholeCamera) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = camera.K
    if camera.k1 != 0.0 or camera.k2 != 0.0:
        m = np.vstack([m, [camera.k1, camera.k2, 0.0, 0.0]])
    return m


def _write_matrix(path: Path, matrix: np.ndarray) -> None:
    np.savetxt(path, matrix, fmt="%.10g")


class _FrameConsumer:
    """Turns rendered batches into events and files; runs beside the renderer in a thread."""

    def __init__(self, split_dir: Path, c2w: np.ndarray, intr: np.ndarray,
                 config: SimulationConfig, seed: int) -> None:
        self.split_dir, self.c2w, self.intr = split_dir, c2w, intr
        self.config, self.seed = config, seed
        self.sim: EventSimulator | None = None
        self.chunks: list[EventChunk] = []
        self.n_events = 0
        self.events_s = self.write_s = 0.0

    def __call__(self, start: int, frames: np.ndarray) -> None:
        import cv2

        t1 = time.perf_counter()
        for frame in frames:
            if self.sim is None:
                self.sim = EventSimulator(frame, self.config.events, self.config.noise,
                                          seed=self.seed)
            else:
                self.chunks.append(self.sim.step(frame))
                self.n_events += len(self.chunks[-1])
        t2 = time.perf_counter()
        for i, frame in enumerate(frames):
            k = start + i
            _write_matrix(self.split_dir / "intrinsics" / f"r_{k:05d}.txt", self.intr)
            _write_matrix(self.split_dir / "pose" / f"r_{k:05d}.txt", self.c2w[k])
            if self.config.write_rgb:
                img = np.round(frame * 255.0).astype(np.uint8)
                cv2.imwrite(str(self.split_dir / "rgb" / f"r_{k:05d}.png"), img[..., ::-1],
                            [cv2.IMWRITE_PNG_COMPRESSION, 1])
        self.events_s += t2 - t1
        self.write_s += time.perf_counter() - t2


def _simulate_split(name: str, traj: Trajectory, renderer: Renderer, config: SimulationConfig,
                    split_dir: Path, seed: int, progress=None, task=None) -> SplitResult:
    from concurrent.futures import ThreadPoolExecutor

    c2w = look_at_origin(traj.directions, traj.azimuth, config.camera_radius)
    for sub in ("intrinsics", "pose", "rgb", "events"):
        (split_dir / sub).mkdir(parents=True, exist_ok=True)
    n = traj.n_views
    written = c2w
    if name == "train" and config.capture.any():  # events from the truth, poses as recorded
        written = written_poses(c2w, config.capture)
        (split_dir / "pose_true").mkdir()
        for k in range(n):
            _write_matrix(split_dir / "pose_true" / f"r_{k:05d}.txt", c2w[k])
    consumer = _FrameConsumer(split_dir, written, _intrinsics_matrix(renderer.camera), config,
                              seed)
    render_s = 0.0
    # Batch b is turned into events and files while batch b + 1 renders (numpy, OpenCV and
    # Open3D release the GIL in their heavy parts); at most one batch waits at a time.
    with ThreadPoolExecutor(max_workers=1) as pool:
        pending = None
        for start in range(0, n, config.batch_views):
            stop = min(n, start + config.batch_views)
            t0 = time.perf_counter()
            frames, _ = renderer.render(c2w[start:stop])
            render_s += time.perf_counter() - t0
            if pending is not None:
                pending.result()
            pending = pool.submit(consumer, start, frames)
            if progress is not None:
                progress.update(task, advance=stop - start,
                                info=f"{name}: {consumer.n_events:,} events")
        pending.result()
    chunks = consumer.chunks
    events_s, write_s = consumer.events_s, consumer.write_s
    if not chunks or len(chunks[-1]) == 0:
        raise SimulationError(
            f"{name}: no events in the final frame interval ({n - 2} -> {n - 1}); the reader "
            "places view i at i/(N-1)*max(t), so max(t) must be N-1 - use more motion "
            "(fewer views, more revolutions), a lower threshold or a textured object")
    events = EventChunk.concatenate(chunks)
    # The reader maps view N-1 to max(t): pin the latest event (of the final interval,
    # t in (N-2, N-1]) to exactly N-1 so that frame and event clocks agree.
    events.t[-1] = float(n - 1)
    t0 = time.perf_counter()
    np.savez(split_dir / "events" / "events.npz", x=events.x, y=events.y, t=events.t,
             p=events.p)
    write_s += time.perf_counter() - t0
    return SplitResult(name, traj, len(events), int((events.p > 0).sum()), render_s, events_s,
                       write_s)


def simulate_dataset(
    mesh: str | os.PathLike | SceneMesh,
    out: str | os.PathLike,
    config: SimulationConfig | None = None,
    progress: bool = False,
) -> dict:
    """Simulate a colour event camera around a mesh and write an EventNeRF-layout dataset.

    Args:
        mesh: a mesh file (OBJ+MTL+textures, PLY, OFF, GLB), ``"builtin:device"`` /
            ``"builtin:thin"``, ``"generated:<kind>:<seed>"``
            (:mod:`hybridneus.simulate.generated`), or a :class:`SceneMesh`.
        out: output directory; replaced atomically when the run succeeds.
        config: the simulation settings; defaults to the paper's (999 views, 8 revolutions
            of Seiffert's spiral, 346 x 260, C = 0.2).
        progress: show a rich progress bar (frames/s and ETA) on stderr.

    Returns:
        The content written to ``scene.json`` (a dict).

    Raises:
        MeshError: the mesh cannot be read or has no triangles.
        SimulationError: a split has no events in its final interval.
    """
    from hybridneus.progress import make_progress

    config = config or SimulationConfig()
    source_mesh, scene_name = resolve_mesh(mesh)
    norm = normalization_for(source_mesh, config.object_radius)
    world = source_mesh.transformed(norm.scale, np.asarray(norm.translation))
    k1, k2 = config.distortion
    camera = PinholeCamera.from_fov(config.width, config.height, config.fov_y_deg, k1, k2)
    shading = config.shading
    renderer = Renderer(world, camera, config.supersample, shading, config.n_threads)
    trajs = split_trajectories(config)
    crop_r, crop_y0, crop_y1 = crop_cylinder(world.vertices[np.unique(world.faces)])
    total = sum(t.n_views for t in trajs.values())
    started = time.perf_counter()
    results: list[SplitResult] = []
    with atomic_dir(out) as tmp, make_progress("frames", disable=not progress) as bar:
        task = bar.add_task(f"simulate {scene_name}", total=total)
        for si, (name, traj) in enumerate(trajs.items()):
            results.append(_simulate_split(name, traj, renderer, config, tmp / name,
                                           seed=config.seed * 1000 + si, progress=bar, task=task))
        gt = world.to_trimesh()
        gt.merge_vertices()  # seams of separately built parts: watertight where it can be
        gt.export(tmp / "gt_mesh.ply")
        info = _scene_json(config, source_mesh, scene_name, norm, camera, shading, results,
                           (crop_r, crop_y0, crop_y1), time.perf_counter() - started)
        (tmp / "scene.json").write_text(json.dumps(info, indent=2) + "\n")
    return info


def _scene_json(config, source_mesh, scene_name, norm, camera, shading, results, crop,
                seconds) -> dict:
    ev = config.events
    return {
        "format": "hybridneus-simulated-eventnerf",
        "version": 1,
        "scene": scene_name,
        "width": camera.width,
        "height": camera.height,
        "source_mesh": source_mesh.source,
        "n_faces": source_mesh.n_faces,
        "transform": norm.to_json() | {"object_radius": config.object_radius},
        "camera": {
            "width": camera.width, "height": camera.height, "fx": camera.fx, "fy": camera.fy,
            "cx": camera.cx, "cy": camera.cy, "fov_y_deg": config.fov_y_deg,
            "k1": camera.k1, "k2": camera.k2, "radius": config.camera_radius,
            "axes": "OpenCV (x right, y down, z forward); looks at the origin; world +y up",
            "pixel_centers": "+0.5",
        },
        "render": {
            "renderer": "open3d RaycastingScene (CPU)", "supersample": config.supersample,
            "light_dir": list(shading.light_dir), "ambient": shading.ambient,
            "diffuse": shading.diffuse, "background": list(shading.background),
            "headlight": shading.headlight, "gamma": 2.2, "two_sided": True,
        },
        "events": {
            "threshold": ev.threshold, "eps": ev.eps, "polarity_offset": ev.polarity_offset,
            "threshold_pos": ev.threshold * (1 + ev.polarity_offset),
            "threshold_neg": ev.threshold * (1 - ev.polarity_offset),
            "log_mapping": ("log(I**2.2 + eps) of the channel mean of the sRGB frame"
                            if ev.mosaic == "mono" else
                            f"log(I**2.2 + eps) of the {ev.mosaic} mosaic of the sRGB frame"),
            "bayer": ev.mosaic, "interpolation": "linear in time between frames",
            "time_unit": "frame index: view i is at t = i; the latest event is pinned to N-1",
        },
        "noise": config.noise.to_json(),
        "seed": config.seed,
        "splits": {
            r.name: {
                "trajectory": r.trajectory.kind, "trajectory_params": r.trajectory.params,
                "n_views": r.trajectory.n_views, "n_events": r.n_events,
                "n_positive": r.n_positive, "n_negative": r.n_events - r.n_positive,
                "render_s": round(r.render_s, 3), "events_s": round(r.events_s, 3),
                "write_s": round(r.write_s, 3),
            }
            for r in results
        },
        "trajectory": config.spiral,
        "seconds": round(seconds, 3),
        "preset": {
            "group": "simulated", "scene": scene_name, "threshold": ev.threshold,
            "polarity_offset": ev.polarity_offset,
            "max_window": min(50, config.n_views - 1), "cyclic": _wraps(config),
            "neg_ratio": 0.1, "tonemap_eps": ev.eps, "crop_r": crop[0],
            "crop_y_min": crop[1], "crop_y_max": crop[2],
            "background": list(shading.background),
            "width": camera.width, "height": camera.height, "mosaic": ev.mosaic,
        },
        "config": _config_json(config),
    }


def _wraps(config: SimulationConfig) -> bool:
    """Whether the training views close a loop (one turn of a circle): event windows may then
    wrap around the sequence, as the reference code does for 360-degree captures."""
    return config.spiral == "circle" and abs(config.revolutions - 1.0) < 1e-9


def _config_json(config: SimulationConfig) -> dict:
    d = asdict(config)
    d["distortion"] = list(config.distortion)
    return d


def with_overrides(config: SimulationConfig, **changes) -> SimulationConfig:
    """``dataclasses.replace`` that also accepts ``threshold``/``eps``/``polarity_offset``/
    ``mosaic`` (fields of :class:`EventModel`)."""
    ev = {k: changes.pop(k) for k in ("threshold", "eps", "polarity_offset", "mosaic")
          if k in changes}
    if ev:
        changes["events"] = replace(config.events, **ev)
    return replace(config, **changes)
