"""The report's interactive figures, built with plotly: the training curves and the mesh.

plotly draws both in the browser from its own bundled script (no server, no network), so
the page needs no plotting code of its own.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

#: The mesh viewer's face budget: a marching-cubes mesh at 300^3 holds about a million
#: faces, which a browser turns slowly; decimation to this keeps the shape and the page small.
VIEWER_FACES = 60_000

# (row title, columns, log y): what each panel of the curves shows.
_PANELS: tuple[tuple[str, tuple[str, ...], bool], ...] = (
    ("losses", ("loss/",), True),
    ("sharpness inv_s", ("inv_s",), True),
    ("opacity, occupied share", ("opacity", "occupied"), False),
    ("learning rate", ("lr",), True),
    ("step time, s", ("step_seconds",), False),
)


def curves_figure(metrics: dict[str, list[float]]):
    """The training curves of a run (``metrics.csv`` by column) against the step: the loss
    of every term, the sharpness, the rendered opacity and occupied share, the learning rate
    and the step time, one panel each (panels without data are left out).

    Returns:
        a ``plotly.graph_objects.Figure``, or None when there are no rows.
    """
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    steps = metrics.get("step")
    if not steps:
        return None
    panels = []
    for title, prefixes, log in _PANELS:
        cols = [c for c in metrics if c != "step" and any(
            c == p or (p.endswith("/") and c.startswith(p)) for p in prefixes)]
        cols = [c for c in cols if any(math.isfinite(v) and (v > 0 or not log)
                                       for v in metrics[c])]
        if cols:
            panels.append((title, cols, log))
    if not panels:
        return None
    fig = make_subplots(rows=len(panels), cols=1, shared_xaxes=True, vertical_spacing=0.04,
                        subplot_titles=[p[0] for p in panels])
    for row, (_title, cols, log) in enumerate(panels, start=1):
        for col in cols:
            values = np.asarray(metrics[col], dtype=float)
            if log:
                values = np.where(values > 0, values, np.nan)
            fig.add_trace(go.Scatter(x=steps, y=values, name=col, mode="lines",
                                     legendgroup=str(row)), row=row, col=1)
        if log:
            fig.update_yaxes(type="log", row=row, col=1)
    fig.update_xaxes(title_text="step", row=len(panels), col=1)
    fig.update_layout(height=220 * len(panels) + 80, hovermode="x unified",
                      margin={"l": 60, "r": 20, "t": 40, "b": 40},
                      legend={"groupclick": "toggleitem"}, template="plotly_white")
    return fig


def mesh_figure(path: str | Path, max_faces: int = VIEWER_FACES):
    """An interactive view of a mesh file with its vertex colours (grey without), reduced to
    about ``max_faces`` faces (:func:`viewer_mesh`).

    Returns:
        ``(figure, faces shown, faces in the file)``.
    """
    import plotly.graph_objects as go

    from hybridneus.meshing import load_mesh

    mesh = load_mesh(path)
    n_file = len(mesh.faces)
    if n_file > max_faces:
        mesh = viewer_mesh(mesh, max_faces)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)
    colours = None
    if mesh.visual.kind == "vertex":
        rgb = np.asarray(mesh.visual.vertex_colors)[:, :3]
        colours = [f"rgb({r},{g},{b})" for r, g, b in rgb]
    # Rounded to a thousandth of the mesh's extent: invisible, and the page is half as big.
    digits = max(0, 3 - int(math.floor(math.log10(max(np.ptp(v, axis=0).max(), 1e-9)))))
    v = np.round(v, digits)
    trace = go.Mesh3d(x=v[:, 0], y=v[:, 1], z=v[:, 2], i=f[:, 0], j=f[:, 1], k=f[:, 2],
                      vertexcolor=colours, color=None if colours else "lightgrey",
                      flatshading=False, hoverinfo="skip",
                      lighting={"ambient": 0.55, "diffuse": 0.6, "specular": 0.1,
                                "roughness": 0.8},
                      lightposition={"x": 1000, "y": 2000, "z": 3000})
    fig = go.Figure(trace)
    fig.update_layout(height=600, margin={"l": 0, "r": 0, "t": 0, "b": 0},
                      scene={"aspectmode": "data", "xaxis": {"visible": False},
                             "yaxis": {"visible": False}, "zaxis": {"visible": False},
                             "camera": {"up": {"x": 0, "y": 1, "z": 0}}})
    return fig, len(f), n_file


def viewer_mesh(mesh, max_faces: int):
    """``mesh`` (a trimesh, vertex colours kept) with at most about ``max_faces`` faces, fast
    enough for a report: vertex clustering on a grid whose cell gives about that many faces
    for the mesh's area (2.5 faces a cell crossed, as measured on spheres and scans), then
    quadric decimation
    (:func:`hybridneus.meshing.postprocess.decimate_mesh`) of what is still over. Quadric
    decimation alone of a 300^3 mesh takes seconds; clustering a tenth of that, and at this
    size the two are alike to the eye."""
    import pymeshlab

    from hybridneus.meshing.postprocess import (
        _from_meshset,
        _to_meshset,
        _vertex_colors,
        decimate_mesh,
    )

    colours = _vertex_colors(mesh)
    ms = _to_meshset(mesh, colours)
    cell = math.sqrt(2.5 * float(mesh.area) / max_faces)
    ms.meshing_decimation_clustering(threshold=pymeshlab.PureValue(cell))
    ms.meshing_remove_unreferenced_vertices()
    out = _from_meshset(ms, colours is not None)
    if len(out.faces) > 1.2 * max_faces:
        out = decimate_mesh(out, max_faces)
    return out


__all__ = ["VIEWER_FACES", "curves_figure", "mesh_figure", "viewer_mesh"]
