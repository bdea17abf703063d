"""Metrics: Chamfer distance / F-score and SDF-MAE between meshes, PSNR / SSIM of images; pictures
of where a mesh is wrong.

Public API::

    from hybridneus.evaluation import chamfer_distance, sdf_mae, color_corrected_psnr_ssim

See docs/evaluation.md for the exact protocols.
"""

from hybridneus.evaluation.error_map import (
    error_image,
    save_error_image,
    vertex_errors,
)
from hybridneus.evaluation.geometry import (
    PROTOCOLS,
    ChamferResult,
    SdfMaeResult,
    chamfer_distance,
    chamfer_floor,
    normalize_eventneus,
    normalize_pair,
    sdf_mae,
    unit_cube_transform,
)
from hybridneus.evaluation.images import (
    ImageMetrics,
    apply_log_color_correction,
    color_corrected_psnr_ssim,
    fit_log_color_correction,
    psnr,
    ssim,
)
from hybridneus.evaluation.inside import (
    inside_mask,
    signed_distance,
    unsigned_distance,
    winding_number,
    winding_number_exact,
)
from hybridneus.evaluation.parts import PartResult, part_completeness

__all__ = [
    "PROTOCOLS",
    "ChamferResult",
    "ImageMetrics",
    "PartResult",
    "SdfMaeResult",
    "apply_log_color_correction",
    "chamfer_distance",
    "chamfer_floor",
    "color_corrected_psnr_ssim",
    "error_image",
    "fit_log_color_correction",
    "inside_mask",
    "normalize_eventneus",
    "normalize_pair",
    "part_completeness",
    "psnr",
    "save_error_image",
    "sdf_mae",
    "signed_distance",
    "ssim",
    "unit_cube_transform",
    "unsigned_distance",
    "vertex_errors",
    "winding_number",
    "winding_number_exact",
]
