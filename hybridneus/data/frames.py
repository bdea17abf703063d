"""Ray batches from the RGB frames of a split (``<split>/rgb/``).

Events are the product's supervision; frames are used to train the same model on what a
conventional camera would have seen, the upper bound the benchmark suite compares against
(``train.supervision = "rgb"``). Pixel values are compared with the rendered colour directly
(the colour that the event loss maps through ``log(c^2.2 + eps)``), so the frames must be the
display-referred (sRGB, 8-bit) images of the same cameras, as the simulator writes them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from hybridneus.data.dataset import SplitData
from hybridneus.data.rays import camera_rays
from hybridneus.errors import DatasetError


@dataclass
class FrameBatch:
    """Random pixels of one frame.

    Attributes:
        origins: (n_rays, 3) float32 ray origins.
        dirs: (n_rays, 3) float32 unit directions.
        color: (n_rays, 3) float32 target RGB in [0, 1].
        xy: (n_rays, 2) int64 pixel (column, row).
        view: the frame's view index.
    """

    origins: torch.Tensor
    dirs: torch.Tensor
    color: torch.Tensor
    xy: torch.Tensor
    view: int


def load_frames(
    split: SplitData, width: int, height: int, views: list[int] | None = None
) -> np.ndarray:
    """RGB frames of a split as one (n, height, width, 3) uint8 array: those of ``views``
    (view indices), or all of them.

    Raises:
        DatasetError: no ``rgb/`` folder, an unreadable file, or a frame of the wrong size.
    """
    import cv2

    if split.rgb_paths is None:
        raise DatasetError(f"{split.path}: no rgb/ frames (needed for RGB supervision)")
    paths = split.rgb_paths if views is None else [split.rgb_paths[v] for v in views]
    frames = np.empty((len(paths), height, width, 3), dtype=np.uint8)
    for i, path in enumerate(paths):
        image = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if image is None:
            raise DatasetError(f"{path}: not a readable image")
        if image.shape[:2] != (height, width):
            raise DatasetError(
                f"{path}: frame is {image.shape[1]}x{image.shape[0]}, the scene is "
                f"{width}x{height}"
            )
        frames[i] = image[..., ::-1]
    return frames


class FrameRaySampler:
    """Draws batches of random pixels from random training frames.

    Args:
        split: the split (its ``rgb_paths`` must be set).
        width: image width of the scene preset.
        height: image height.
        seed: numpy random seed.
        device: device of the returned tensors.
    """

    def __init__(
        self,
        split: SplitData,
        width: int,
        height: int,
        seed: int = 0,
        device: str | torch.device = "cpu",
    ) -> None:
        self.split = split
        self.frames = load_frames(split, width, height)
        self.width, self.height = width, height
        self.rng = np.random.default_rng(seed)
        self.device = torch.device(device)

    def sample(self, n_rays: int) -> FrameBatch:
        """``n_rays`` uniformly random pixels of one uniformly random frame."""
        i = int(self.rng.integers(0, self.frames.shape[0]))
        idx = self.rng.integers(0, self.width * self.height, size=n_rays)
        xy = np.stack([idx % self.width, idx // self.width], axis=1)
        sp = self.split
        o, d = camera_rays(sp.intrinsics[i], sp.distortion[i], sp.c2w[i], xy, device=self.device,
                           lens=sp.lens)
        color = self.frames[i, xy[:, 1], xy[:, 0]].astype(np.float32) / 255.0
        return FrameBatch(
            origins=o,
            dirs=d,
            color=torch.as_tensor(color, device=self.device),
            xy=torch.as_tensor(xy, dtype=torch.int64, device=self.device),
            view=i,
        )
