"""Planar-face errors: the RMS distance of a mesh to the planes of its ground truth's faces."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from hybridneus.evaluation.planes import planar_faces, plane_errors, plane_rms


def _box(extents=(1.0, 0.6, 0.4), subdivisions: int = 3) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=extents)
    for _ in range(subdivisions):
        box = box.subdivide()
    return box


def test_a_box_has_six_planar_faces_and_a_sphere_none():
    faces = planar_faces(_box())
    assert len(faces) == 6
    areas = [_box().area_faces[f].sum() for f in faces]
    assert np.all(np.diff(areas) < 1e-9)  # largest first
    assert planar_faces(trimesh.creation.icosphere(subdivisions=3)) == []


def test_the_truth_itself_scores_zero_and_a_shifted_face_its_shift():
    gt = _box()
    faces = plane_errors(gt, gt, n_samples=20_000)
    assert len(faces) == 6 and plane_rms(faces) < 1e-6
    assert all(0.8 < f.coverage < 1.2 for f in faces)
    # push the +z face out by 0.01 (the unit cube's side is the box's longest, 1.0)
    moved = gt.copy()
    top = moved.vertices[:, 2] > 0.19
    moved.vertices[top, 2] += 0.01
    faces = plane_errors(moved, gt, n_samples=20_000)
    by_normal = {tuple(np.round(f.normal).astype(int)): f for f in faces}
    assert by_normal[(0, 0, 1)].offset == pytest.approx(0.01, abs=1e-4)
    assert by_normal[(0, 0, 1)].rms == pytest.approx(0.01, abs=1e-4)
    assert by_normal[(0, 0, -1)].rms < 1e-6


def test_lumps_raise_the_rms_but_not_the_offset():
    gt = _box(subdivisions=5)
    lumpy = gt.copy()
    v = lumpy.vertices
    front = v[:, 2] > 0.19
    # lumps of height 0.01 that average to zero over the face, kept away from its rim
    bump = 0.01 * np.sin(v[:, 0] * 40) * np.sin(v[:, 1] * 40)
    inner = (np.abs(v[:, 0]) < 0.4) & (np.abs(v[:, 1]) < 0.2)
    lumpy.vertices[front, 2] += (bump * inner)[front]
    faces = plane_errors(lumpy, gt, n_samples=50_000)
    front_face = next(f for f in faces if f.normal[2] > 0.9)
    assert front_face.rms > 0.003 and abs(front_face.offset) < 0.002
    assert plane_rms(faces) > plane_rms(plane_errors(gt, gt, n_samples=50_000)) + 0.001


def test_a_lost_face_counts_no_samples_and_a_floater_does_not_count():
    gt = _box()
    # the prediction: the box without its +z face's triangles, plus a far floater
    keep = gt.face_normals[:, 2] < 0.9
    pred = trimesh.util.concatenate([gt.submesh([np.flatnonzero(keep)], append=True),
                                     trimesh.creation.icosphere(radius=0.05).apply_translation(
                                         (0.0, 0.0, 0.5))])
    faces = plane_errors(pred, gt, n_samples=20_000)
    top = next(f for f in faces if f.normal[2] > 0.9)
    assert top.samples < 0.05 * max(f.samples for f in faces) and top.coverage < 0.1
    assert plane_rms(faces) < 1e-3  # the floater lies beyond max_distance


def test_a_face_no_camera_sees_is_left_out_of_the_pooled_rms():
    gt = _box()
    sunk = gt.copy()
    bottom = sunk.vertices[:, 1] < -0.29
    sunk.vertices[bottom, 1] -= 0.02  # the -y face stands out by 0.02
    ring = np.stack([np.cos(np.linspace(0, 6, 12)), np.full(12, 0.3),
                     np.sin(np.linspace(0, 6, 12))], 1) * 1.5  # all above the box
    faces = plane_errors(sunk, gt, n_samples=20_000, cameras=ring)
    by_normal = {tuple(np.round(f.normal).astype(int)): f for f in faces}
    assert by_normal[(0, -1, 0)].views == 0 and by_normal[(0, 1, 0)].views == 12
    assert by_normal[(0, -1, 0)].offset == pytest.approx(0.02, abs=1e-3)
    assert plane_rms(faces) < 1e-3  # the unseen bottom is left out
    assert plane_rms(plane_errors(sunk, gt, n_samples=20_000)) > 0.005  # counted without
