"""CPU ray-casting renderer (Open3D ``RaycastingScene``) with textures and Lambertian shading.

Shading model (all in linear light, gamma 2.2 as in the event model):
``linear = albedo**2.2 * (ambient + diffuse * max(0, n . l))`` with a fixed world-space light
``l`` (default from above-front-right, ``normalize(0.4, 1.0, 0.6)``), ``ambient = 0.35``,
``diffuse = 0.65``; or, with ``headlight``, a light at the camera (``l`` = the reversed ray,
so the shading changes with the view, as with a flash or a ring light). Surfaces are
two-sided: the geometric normal is flipped to face the camera, since many meshes are not
closed. Each pixel averages ``supersample**2`` rays on a
regular sub-pixel grid in linear light, then is encoded back to sRGB with ``x**(1/2.2)``.
Rays that miss take the background colour (sRGB 159/255 by default).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybridneus.simulate.scene_mesh import SceneMesh

GAMMA = 2.2


@dataclass(frozen=True)
class PinholeCamera:
    """Intrinsics shared by every view: ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``.

    ``k1, k2`` follow the reference code's approximate radial model: the normalised ray
    ``[(u + 0.5 - cx) / fx, (v + 0.5 - cy) / fy]`` is divided by ``1 + k1 r^2 + k2 r^4``
    with ``r`` the undivided normalised radius; pixel centres are at +0.5.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    k1: float = 0.0
    k2: float = 0.0

    @classmethod
    def from_fov(cls, width: int, height: int, fov_y_deg: float, k1: float = 0.0,
                 k2: float = 0.0) -> PinholeCamera:
        """Square pixels with a vertical field of view ``fov_y_deg``; ``cx, cy = W/2, H/2``."""
        f = 0.5 * height / np.tan(np.deg2rad(fov_y_deg) / 2.0)
        return cls(width, height, float(f), float(f), width / 2.0, height / 2.0, k1, k2)

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def directions(self, supersample: int = 1) -> np.ndarray:
        """Camera-space ray directions (z = 1 before distortion) on a sub-pixel grid.

        Args:
            supersample: rays per pixel along each axis; sub-pixel centres sit at
                ``(i + 0.5) / supersample`` inside the pixel, so ``supersample = 1`` gives
                exactly the pixel centres ``u + 0.5``.

        Returns:
            (height, width, supersample**2, 3) float64 directions.
        """
        s = int(supersample)
        offs = (np.arange(s) + 0.5) / s
        du, dv = np.meshgrid(offs, offs, indexing="xy")
        u = np.arange(self.width)[None, :, None] + du.reshape(1, 1, -1)
        v = np.arange(self.height)[:, None, None] + dv.reshape(1, 1, -1)
        x = (u - self.cx) / self.fx
        y = (v - self.cy) / self.fy
        x, y = np.broadcast_arrays(x, y)
        if self.k1 != 0.0 or self.k2 != 0.0:
            r2 = x * x + y * y
            denom = 1.0 + self.k1 * r2 + self.k2 * r2 * r2
            x, y = x / denom, y / denom
        return np.stack([x, y, np.ones_like(x)], axis=-1)


@dataclass(frozen=True)
class Shading:
    """Light and background of the renderer.

    Attributes:
        light_dir: world-space direction towards the light (normalised on use); ignored with
            ``headlight``.
        ambient, diffuse: ``linear = albedo**2.2 * (ambient + diffuse * max(0, n . l))``;
            ``ambient=1, diffuse=0`` renders the albedo unlit.
        background: sRGB colour in [0, 1] of rays that miss.
        headlight: light from the camera itself instead of ``light_dir``.
    """

    light_dir: tuple[float, float, float] = (0.4, 1.0, 0.6)
    ambient: float = 0.35
    diffuse: float = 0.65
    background: tuple[float, float, float] = (159 / 255, 159 / 255, 159 / 255)
    headlight: bool = False

    def __post_init__(self) -> None:
        if len(self.light_dir) != 3 or not np.all(np.isfinite(self.light_dir)) \
                or not np.any(self.light_dir):
            raise ValueError(f"light direction must be 3 finite numbers, not all 0: "
                             f"{self.light_dir}")
        if not (self.ambient >= 0 and self.diffuse >= 0) or self.ambient + self.diffuse <= 0:
            raise ValueError(f"ambient and diffuse must be >= 0 with a positive sum: "
                             f"{self.ambient}, {self.diffuse}")
        if len(self.background) != 3 or not all(0.0 <= c <= 1.0 for c in self.background):
            raise ValueError(f"background must be 3 sRGB values in [0, 1]: {self.background}")


class Renderer:
    """Ray-cast a :class:`SceneMesh` from many cameras sharing one :class:`PinholeCamera`.

    Camera-space ray directions are computed once and rotated per view; several views go
    into one ``cast_rays`` call.

    Args:
        mesh: the (already normalised) scene.
        camera: intrinsics.
        supersample: rays per pixel along each axis (2 -> 4 rays per pixel).
        shading: light and background.
        n_threads: Open3D threads (0 = all cores).
    """

    def __init__(self, mesh: SceneMesh, camera: PinholeCamera, supersample: int = 2,
                 shading: Shading | None = None, n_threads: int = 0) -> None:
        try:
            import open3d as o3d
        except ImportError as exc:  # pragma: no cover - depends on the platform
            raise ImportError(
                "the simulator needs Open3D: pip install open3d-cpu (Linux x86-64) or open3d; "
                "on Debian also apt-get install libusb-1.0-0 libgl1 libegl1"
            ) from exc
        self.mesh = mesh
        self.camera = camera
        self.supersample = int(supersample)
        self.shading = shading or Shading()
        self.n_threads = int(n_threads)
        self._o3d = o3d
        self._scene = o3d.t.geometry.RaycastingScene(nthreads=self.n_threads)
        self._scene.add_triangles(
            o3d.core.Tensor(np.ascontiguousarray(mesh.vertices, np.float32)),
            o3d.core.Tensor(np.ascontiguousarray(mesh.faces, np.uint32)),
        )
        dirs = camera.directions(self.supersample).astype(np.float32)  # (h, w, s, 3)
        flat = dirs.transpose(2, 0, 1, 3).reshape(-1, 3)
        offs = (np.arange(self.supersample) + 0.5) / self.supersample - 0.5
        # Same sample order as PinholeCamera.directions: column offset varies fastest.
        self._sub_offsets = [(du, dv) for dv in offs for du in offs]
        #: Build undistorted rays with Open3D (fast); distorted ones with numpy.
        self.use_open3d_rays = camera.k1 == 0.0 and camera.k2 == 0.0
        self._dirs_h = np.concatenate([flat, np.ones((flat.shape[0], 1), np.float32)], axis=1)
        # Appearance in linear light, so that interpolation and shading are physical.
        self._corner_lin = np.ascontiguousarray(mesh.corner_colors, np.float32) ** GAMMA
        self._face_lin = np.ascontiguousarray(self._corner_lin[:, 0])
        self._face_varying = np.any(self._corner_lin != self._corner_lin[:, :1], axis=(1, 2))
        self._any_varying = bool(self._face_varying.any())
        self._corner_uv = np.ascontiguousarray(mesh.corner_uv, np.float32)
        self._face_tex = np.asarray(mesh.face_texture, np.int32)
        self._tex_lin = [np.ascontiguousarray(t, np.float32) ** GAMMA for t in mesh.textures]
        light = np.asarray(self.shading.light_dir, np.float32)
        self._light = light / np.linalg.norm(light)
        self._bg_lin = np.asarray(self.shading.background, np.float32) ** GAMMA

    def render(self, c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Render views.

        Args:
            c2w: (n_views, 4, 4) camera-to-world poses (OpenCV axes).

        Returns:
            - frames: (n_views, height, width, 3) float32 sRGB in [0, 1].
            - coverage: (n_views, height, width) float32 fraction of a pixel's rays that hit.
        """
        c2w = np.asarray(c2w, np.float64).reshape(-1, 4, 4)
        n = c2w.shape[0]
        h, w, s = self.camera.height, self.camera.width, self.supersample**2
        hw = h * w
        # Sub-pixel samples lead, pixels follow: (n, s, h*w) keeps each sample plane contiguous.
        rays = self._rays(c2w)
        out = self._scene.cast_rays(self._o3d.core.Tensor.from_numpy(rays), nthreads=self.n_threads)
        t_hit = out["t_hit"].numpy().reshape(-1)
        hit_idx = np.flatnonzero(np.isfinite(t_hit))
        # Per-pixel sums over the hits only (bincount), background for the misses.
        target = (hit_idx // (s * hw)) * hw + hit_idx % hw
        count = np.bincount(target, minlength=n * hw).astype(np.float32)
        linear = np.empty((n * hw, 3), np.float32)
        if hit_idx.size:
            prim = out["primitive_ids"].numpy().reshape(-1)[hit_idx].astype(np.int64)
            bary = out["primitive_uvs"].numpy().reshape(-1, 2)[hit_idx]
            normals = out["primitive_normals"].numpy().reshape(-1, 3)[hit_idx]
            ray_dirs = rays.reshape(-1, 6)[hit_idx, 3:]
            colors = self._shade(prim, bary, normals, ray_dirs)
            for c in range(3):
                linear[:, c] = np.bincount(target, weights=colors[:, c], minlength=n * hw)
        else:
            linear[:] = 0.0
        linear += (s - count)[:, None] * self._bg_lin
        linear *= 1.0 / s
        np.clip(linear, 0.0, 1.0, out=linear)
        frames = (linear ** (1.0 / GAMMA)).reshape(n, h, w, 3)
        coverage = (count / s).reshape(n, h, w)
        return frames, coverage

    def _rays(self, c2w: np.ndarray) -> np.ndarray:
        """Rays (n_views, supersample**2 * height * width, 6): origin, direction."""
        n = c2w.shape[0]
        h, w, s = self.camera.height, self.camera.width, self.supersample**2
        if self.use_open3d_rays:
            # Open3D builds pinhole rays in parallel C++ with the same convention (direction
            # K^-1 [u + 0.5, v + 0.5, 1]); a sub-pixel offset is a shifted principal point.
            o3d = self._o3d
            rays = np.empty((n, s, h * w, 6), np.float32)
            w2c = np.linalg.inv(c2w)
            for i in range(n):
                extrinsic = o3d.core.Tensor(w2c[i])
                for j, (du, dv) in enumerate(self._sub_offsets):
                    K = self.camera.K.copy()
                    K[0, 2] -= du
                    K[1, 2] -= dv
                    r = o3d.t.geometry.RaycastingScene.create_rays_pinhole(
                        o3d.core.Tensor(K), extrinsic, w, h)
                    rays[i, j] = r.numpy().reshape(-1, 6)
            return rays.reshape(n, s * h * w, 6)
        # One matmul writes whole contiguous rays: [d, 1] @ [[0, R^T], [o, 0]] = [o, R d].
        # (Filling origin and direction columns separately is slower: strided writes.)
        lift = np.zeros((n, 4, 6), np.float32)
        lift[:, :3, 3:] = c2w[:, :3, :3].transpose(0, 2, 1)
        lift[:, 3, :3] = c2w[:, :3, 3]
        return np.matmul(self._dirs_h[None], lift)

    def _shade(self, prim: np.ndarray, bary: np.ndarray, normals: np.ndarray,
               ray_dirs: np.ndarray) -> np.ndarray:
        """Linear colour (n_hits, 3) of hits given triangle ids and barycentric (u, v)."""
        # Open3D's barycentric (u, v) weight vertices 1 and 2; vertex 0 gets 1 - u - v.
        w1 = bary[:, 0:1]
        w2 = bary[:, 1:2]
        w0 = 1.0 - w1 - w2
        # Most faces have one colour at all corners: gather it and interpolate only the rest.
        albedo = np.take(self._face_lin, prim, axis=0)
        if self._any_varying:
            sel = np.flatnonzero(self._face_varying[prim])
            if sel.size:
                cc = self._corner_lin[prim[sel]]
                albedo[sel] = w0[sel] * cc[:, 0] + w1[sel] * cc[:, 1] + w2[sel] * cc[:, 2]
        if self._tex_lin:
            ftex = self._face_tex[prim]
            for ti, tex in enumerate(self._tex_lin):
                sel = np.flatnonzero(ftex == ti)
                if sel.size == 0:
                    continue
                cuv = self._corner_uv[prim[sel]]
                uv = w0[sel] * cuv[:, 0] + w1[sel] * cuv[:, 1] + w2[sel] * cuv[:, 2]
                albedo[sel] *= sample_bilinear(tex, uv)
        n_dot_d = np.einsum("ij,ij->i", normals, ray_dirs)
        if self.shading.headlight:
            # The light sits at the eye, so a two-sided surface always faces it.
            cos = np.abs(n_dot_d) / np.linalg.norm(ray_dirs, axis=1)
        else:
            # Two-sided: flipping the normal towards the camera flips the sign of n.l.
            n_dot_l = normals @ self._light
            cos = np.where(n_dot_d > 0, -n_dot_l, n_dot_l)
            np.maximum(cos, 0.0, out=cos)
        albedo *= (self.shading.ambient + self.shading.diffuse * cos)[:, None]
        return albedo


def sample_bilinear(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear texture lookup with wrap-around (repeat) addressing.

    Args:
        texture: (tex_h, tex_w, 3) float32 image, row 0 at the top.
        uv: (n, 2) texture coordinates, origin at the bottom-left (v up), texel centres at
            ``(i + 0.5) / size``.

    Returns:
        (n, 3) float32 colours.
    """
    th, tw = texture.shape[:2]
    x = uv[:, 0].astype(np.float32) * np.float32(tw) - np.float32(0.5)
    y = (np.float32(1.0) - uv[:, 1].astype(np.float32)) * np.float32(th) - np.float32(0.5)
    x0f = np.floor(x)
    y0f = np.floor(y)
    fx = (x - x0f)[:, None]
    fy = (y - y0f)[:, None]
    x0 = x0f.astype(np.int64) % tw
    y0 = y0f.astype(np.int64) % th
    x1 = x0 + 1
    x1[x1 == tw] = 0
    y1 = (y0 + 1) * tw
    y1[y1 == th * tw] = 0
    y0 *= tw
    flat = texture.reshape(-1, 3)
    top = np.take(flat, y0 + x0, axis=0)
    top += (np.take(flat, y0 + x1, axis=0) - top) * fx
    bottom = np.take(flat, y1 + x0, axis=0)
    bottom += (np.take(flat, y1 + x1, axis=0) - bottom) * fx
    top += (bottom - top) * fy
    return top
