"""Event windows and training ray batches.

Time: view ``i`` of ``N`` sits at ``t_i = i / (N - 1) * T`` with ``T = max(t)``. A window is
the half-open interval ``[t0, t1)``; its event frame is ``E[y, x] = sum(p + polarity_offset)``
over the events inside. A batch picks one view ``i`` uniformly, sets ``t1 = t_i`` and draws
``t0`` from ``U[t1 - L_max, t1)`` with ``L_max = max_window * T / (N - 1)`` (the EventNeuS
paper; ``window="per_load"`` instead draws an integer length ``w_i`` in 1..max_window per view
once, as the EventNeRF reference code). Cyclic captures wrap: a window that starts before
``t = 0`` continues from ``T`` backwards, and its start camera is that at ``t0 + T``. For
non-cyclic captures ``t0`` is clamped to 0 and view 0 is never ``t1``. The camera at ``t0``
is interpolated between the two views around it (slerp of rotation, lerp of position).

Window queries never rescan the stream: events are sorted by time, so ``searchsorted``
gives the index range, and per-pixel counts come from one ``bincount`` of that slice, or,
for long slices, from cumulative count images stored every ``M`` events plus two short
``bincount`` calls for the ends (see :class:`EventCounter`).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Literal

import numpy as np
import torch

from hybridneus.data.dataset import SplitData
from hybridneus.data.events import EventStream
from hybridneus.data.presets import ScenePreset
from hybridneus.data.rays import camera_rays, interpolate_pose
from hybridneus.errors import ConfigError, DatasetError


class EventCounter:
    """Per-pixel negative/positive event counts for any index range ``[i0, i1)``.

    Short ranges use one ``np.bincount`` over the range. Long ranges subtract two of the
    cumulative count images kept every ``stride`` events and add the counts of the two ends.
    The checkpoint images are int32 ``(n_checkpoints, height * width * 2)`` and take at most
    ``max_bytes``; they are built on the first long query.

    Args:
        events: the stream.
        width: image width.
        height: image height.
        max_bytes: memory budget for the checkpoints. Default: 128 MiB.
        min_stride: smallest number of events between checkpoints. Default: 2**16.
    """

    def __init__(
        self,
        events: EventStream,
        width: int,
        height: int,
        max_bytes: int = 128 << 20,
        min_stride: int = 1 << 16,
    ) -> None:
        self.code = events.pixel_code(width)
        self.n_bins = 2 * width * height
        n = self.code.shape[0]
        max_ckpt = max(int(max_bytes // (self.n_bins * 4)), 2)
        self.stride = max(min_stride, -(-n // (max_ckpt - 1)))
        self._cum: np.ndarray | None = None

    def _build(self) -> np.ndarray:
        n = self.code.shape[0]
        k = n // self.stride
        dtype = np.int32 if n < np.iinfo(np.int32).max else np.int64
        cum = np.zeros((k + 1, self.n_bins), dtype=dtype)
        for j in range(k):
            seg = self.code[j * self.stride : (j + 1) * self.stride]
            np.add(cum[j], np.bincount(seg, minlength=self.n_bins), out=cum[j + 1])
        return cum

    def counts(self, i0: int, i1: int) -> np.ndarray:
        """(height * width, 2) counts [negative, positive] of events ``i0 .. i1 - 1``."""
        if i1 <= i0:
            return np.zeros((self.n_bins // 2, 2), dtype=np.int64)
        if i1 - i0 <= 2 * self.stride:
            c = np.bincount(self.code[i0:i1], minlength=self.n_bins)
            return c.reshape(-1, 2)
        if self._cum is None:
            self._cum = self._build()
        k0 = -(-i0 // self.stride)
        k1 = min(i1 // self.stride, self._cum.shape[0] - 1)
        c = self._cum[k1].astype(np.int64) - self._cum[k0]
        c += np.bincount(self.code[i0 : k0 * self.stride], minlength=self.n_bins)
        c += np.bincount(self.code[k1 * self.stride : i1], minlength=self.n_bins)
        return c.reshape(-1, 2)


def event_counter(split: SplitData) -> EventCounter:
    """The split's :class:`EventCounter`, built once and kept in ``split.events.cache``."""
    key = ("counter", split.width, split.height)
    counter = split.events.cache.get(key)
    if counter is None:
        counter = EventCounter(split.events, split.width, split.height)
        split.events.cache[key] = counter
    return counter


def _index_ranges(
    t: np.ndarray, t0: float, t1: float, t_max: float
) -> list[tuple[int, int]]:
    """Index ranges of events in ``[t0, t1)``; ``t0 < 0`` also takes ``[t0 + t_max, end]``."""
    if t0 < 0:
        start = int(np.searchsorted(t, t0 + t_max, side="left"))
        return [(start, t.shape[0]), (0, int(np.searchsorted(t, t1, side="left")))]
    return [(int(np.searchsorted(t, t0, side="left")), int(np.searchsorted(t, t1, side="left")))]


def offset_of(split: SplitData, preset) -> float | np.ndarray:
    """The polarity offset ``split``'s event frames take: its pixels' own where it holds
    them, else the ``preset``'s."""
    return split.pixel_offset if split.pixel_offset is not None else preset.polarity_offset


def event_frame(
    split: SplitData, t0: float, t1: float, polarity_offset: float | np.ndarray = 0.0
) -> np.ndarray:
    """Accumulated events of the window ``[t0, t1)`` (times as stored in the npz).

    Args:
        split: the split.
        t0: window start. A negative ``t0`` (>= -T) wraps (cyclic captures): the window is
            ``[t0 + T, T]`` plus ``[0, t1)`` with ``T = max(t)``.
        t1: window end (exclusive).
        polarity_offset: added to each event's polarity (-1/+1): one value, or one per
            pixel ((height * width,), row-major).

    Returns:
        (height, width) float32 ``E[y, x] = sum(p + polarity_offset)``; an event at
        column x, row y lands in ``E[y, x]``.
    """
    if t0 < -split.t_max:
        raise ValueError(f"event_frame: t0={t0} is more than one loop (T={split.t_max}) back")
    counter = event_counter(split)
    c = None
    for i0, i1 in _index_ranges(split.events.t, t0, t1, split.t_max):
        part = counter.counts(i0, i1)
        c = part if c is None else c + part
    frame = c[:, 1] * (1.0 + polarity_offset) + c[:, 0] * (polarity_offset - 1.0)
    return frame.astype(np.float32).reshape(split.height, split.width)


def bayer_mask(xy: np.ndarray, mosaic: str = "RGGB") -> np.ndarray:
    """(n, 3) float32 colour weights of pixels ``xy`` (n, 2) = (column, row) under the
    sensor's ``mosaic`` (:func:`hybridneus.data.mosaic.mosaic_weights`).

    RGGB: R at (even row, even column), G at (even, odd) and (odd, even), B at (odd, odd).
    """
    from hybridneus.data.mosaic import mosaic_weights

    return mosaic_weights(xy, mosaic)


@dataclass
class RayBatch:
    """One training batch: the same pixels seen at the window start and end.

    Attributes:
        origins0: (n_rays, 3) float32 ray origins of the camera at ``t0``.
        dirs0: (n_rays, 3) float32 unit directions at ``t0``.
        origins1: (n_rays, 3) float32 ray origins of the camera at ``t1``.
        dirs1: (n_rays, 3) float32 unit directions at ``t1``.
        target: (n_rays,) float32 ``C * E[y, x]`` (E with the polarity offset).
        bayer: (n_rays, 3) float32 channel weights of each pixel (one-hot under a Bayer
            layout, thirds on a monochrome sensor).
        xy: (n_rays, 2) int64 pixel (column, row).
        view0: continuous view index of ``t0`` (wrapped into [0, N - 1]).
        view1: view index of ``t1`` (an integer value).
        t0: window start as a fraction of ``T`` (wrapped into [0, 1]).
        t1: window end as a fraction of ``T``.
    """

    origins0: torch.Tensor
    dirs0: torch.Tensor
    origins1: torch.Tensor
    dirs1: torch.Tensor
    target: torch.Tensor
    bayer: torch.Tensor
    xy: torch.Tensor
    view0: float
    view1: float
    t0: float = 0.0
    t1: float = 0.0

    def to(self, device: str | torch.device) -> RayBatch:
        """Copy of the batch with every tensor on ``device``."""
        values = {}
        for f in fields(self):
            v = getattr(self, f.name)
            values[f.name] = v.to(device) if isinstance(v, torch.Tensor) else v
        return RayBatch(**values)

    def __len__(self) -> int:
        return int(self.target.shape[0])


class EventWindowSampler:
    """Draws event windows and ray batches from one split.

    Args:
        split: the split to sample.
        preset: scene settings (threshold, polarity offset, max window, cyclic, neg ratio).
        seed: random seed (numpy ``default_rng``).
        window: ``"per_iteration"`` (start drawn from ``U[t1 - L_max, t1)`` for every batch,
            as the EventNeuS paper) or ``"per_load"`` (integer length in 1..max_window drawn
            once per view, as the EventNeRF reference code).
        device: device of the returned tensors.

    Raises:
        DatasetError: the split has fewer than 2 views.
        ConfigError: unknown ``window`` mode.

    Example:
        >>> sampler = EventWindowSampler(ds.splits["train"], ds.preset)  # doctest: +SKIP
        >>> batch = sampler.sample(1024)  # doctest: +SKIP
    """

    def __init__(
        self,
        split: SplitData,
        preset: ScenePreset,
        seed: int = 0,
        window: Literal["per_iteration", "per_load"] = "per_iteration",
        device: str | torch.device = "cpu",
    ) -> None:
        if window not in ("per_iteration", "per_load"):
            raise ConfigError(f"window: expected 'per_iteration' or 'per_load', got {window!r}")
        if split.n_views < 2:
            raise DatasetError(f"{split.path}: need at least 2 views for event windows")
        self.split = split
        self.preset = preset
        self.window = window
        self.device = torch.device(device)
        self.rng = np.random.default_rng(seed)
        self.n_views = split.n_views
        self.t_max = split.t_max
        self.dt = self.t_max / (self.n_views - 1)
        # A window never spans more than one full loop of the capture.
        self.l_max = min(preset.max_window * self.dt, self.t_max)
        self.per_load_len = self.rng.integers(1, preset.max_window + 1, size=self.n_views)
        first = 0 if preset.cyclic else 1
        self.views = np.arange(first, self.n_views)

    def draw_window(self) -> tuple[int, float, float]:
        """Pick a view and a window: ``(view1, t0, t1)`` (``t0 < 0`` means it wraps)."""
        i = int(self.rng.choice(self.views))
        t1 = i * self.dt
        if self.window == "per_iteration":
            t0 = t1 - self.l_max + self.rng.random() * self.l_max
        else:
            t0 = t1 - min(int(self.per_load_len[i]) * self.dt, self.t_max)
        if not self.preset.cyclic:
            t0 = max(t0, 0.0)
        return i, t0, t1

    def frame(self, t0: float, t1: float) -> np.ndarray:
        """(height, width) float32 event frame of ``[t0, t1)`` with the preset's offset."""
        return event_frame(self.split, t0, t1, offset_of(self.split, self.preset))

    def pose_at(self, t: float) -> tuple[np.ndarray, int]:
        """Camera-to-world (4, 4) at time ``t`` in [0, T] and the nearest view index."""
        s = min(max(t / self.dt, 0.0), self.n_views - 1.0)
        a = int(np.floor(s))
        b = min(a + 1, self.n_views - 1)
        w = s - a
        c2w = interpolate_pose(self.split.c2w[a], self.split.c2w[b], w)
        return c2w, int(round(s))

    def pick_pixels(self, frame: np.ndarray, n_rays: int) -> np.ndarray:
        """(n_rays, 2) int64 pixels (column, row): ``1 - neg_ratio`` of them from E != 0."""
        h, w = frame.shape
        active = np.flatnonzero(frame.reshape(-1))
        n_pos = int(round((1.0 - self.preset.neg_ratio) * n_rays)) if active.size else 0
        idx = np.empty(n_rays, dtype=np.int64)
        idx[:n_pos] = active[self.rng.integers(0, active.size, size=n_pos)]
        idx[n_pos:] = self.rng.integers(0, h * w, size=n_rays - n_pos)
        return np.stack([idx % w, idx // w], axis=1)

    def sample(self, n_rays: int) -> RayBatch:
        """A batch of ``n_rays`` pixels of one random window.

        Returns:
            :class:`RayBatch` on the sampler's device.
        """
        i, t0, t1 = self.draw_window()
        frame = self.frame(t0, t1)
        xy = self.pick_pixels(frame, n_rays)
        t0_wrapped = t0 + self.t_max if t0 < 0 else t0
        c2w0, k0 = self.pose_at(t0_wrapped)
        sp = self.split
        o0, d0 = camera_rays(sp.intrinsics[k0], sp.distortion[k0], c2w0, xy,
                             device=self.device, lens=sp.lens)
        o1, d1 = camera_rays(sp.intrinsics[i], sp.distortion[i], sp.c2w[i], xy,
                             device=self.device, lens=sp.lens)
        target = self.preset.threshold * frame[xy[:, 1], xy[:, 0]]
        return RayBatch(
            origins0=o0,
            dirs0=d0,
            origins1=o1,
            dirs1=d1,
            target=torch.as_tensor(target, dtype=torch.float32, device=self.device),
            bayer=torch.as_tensor(bayer_mask(xy, self.preset.mosaic),
                                  device=self.device),
            xy=torch.as_tensor(xy, dtype=torch.int64, device=self.device),
            view0=t0_wrapped / self.dt,
            view1=float(i),
            t0=t0_wrapped / self.t_max,
            t1=t1 / self.t_max,
        )
