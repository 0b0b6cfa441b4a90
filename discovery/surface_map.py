"""The residual drawn on the surface the flight was beside: position along it against height.

A wall that ends, a window, a ledge: where the model misses depends on *where on the
structure* the vehicle was, which no single distance shows. :func:`surface_coordinates`
places every sample on the scene's nearest surface (its wall planes and, for bodies,
PyBullet's nearest point, :class:`wall_env.surfaces.SurfaceQuery`): the vehicle's height,
and its position along the surface, measured horizontally along a flat surface, or around
a curved one (a pier: the arc length on a circle fitted to the nearest points).
:func:`plot_surface_map` writes ``residual_on_surface.png``: the held-out force residual
along the surface's normal toward it (positive: a pull toward the structure the model
misses), averaged in cells of that map, for the nominal and the discovered model. A
wall's top edge shows as the height where the pull stops; a window as a hole in it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["surface_coordinates", "plot_surface_map", "MAP_CELLS"]

MAP_CELLS = (24, 14)  # along the surface x height
_FLAT_SPREAD = np.radians(20.0)  # horizontal normals within this spread: a flat surface
_REACH = 5.0  # m, how far from the vehicle a body's surface is looked for


def _nearest_surface(scene: Any, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest surface point ``(n, 3)``, outward normal ``(n, 3)`` and distance ``(n,)`` of the scene's walls and
    bodies to the points ``p`` (``inf`` where there is none)."""
    n = len(p)
    point, normal, distance = np.zeros((n, 3)), np.zeros((n, 3)), np.full(n, np.inf)
    for wall in scene.walls:
        w_n, w_c = np.asarray(wall.normal), np.asarray(wall.point)
        d = (p - w_c) @ w_n
        closer = np.abs(d) < distance
        point[closer], normal[closer], distance[closer] = p[closer] - d[closer, None] * w_n, w_n, np.abs(d[closer])
    if scene.has_bodies:
        from wall_env.surfaces import SurfaceQuery
        from wall_env.vehicle import VehicleParams

        query = SurfaceQuery(scene, VehicleParams(), _REACH)
        try:
            b_c, b_n, b_d = query.nearest(p)
        finally:
            query.close()
        closer = b_d < distance
        point[closer], normal[closer], distance[closer] = b_c[closer], b_n[closer], b_d[closer]
    return point, normal, distance


def _circle(xy: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares circle through points ``(n, 2)``: centre and radius."""
    A = np.column_stack([2 * xy, np.ones(len(xy))])
    b = (xy**2).sum(axis=1)
    (cx, cy, c), *_ = np.linalg.lstsq(A, b, rcond=None)
    return np.array([cx, cy]), float(np.sqrt(max(c + cx**2 + cy**2, 0.0)))


def surface_coordinates(scenes: list[Any], positions: list[np.ndarray]
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """Per sample (segments concatenated): position along the nearest surface (m), height (m), the surface's
    outward normal ``(n, 3)``, and how "along" was measured (``"flat"`` or ``"around"``)."""
    points, normals = [], []
    for scene, p in zip(scenes, positions):
        c, n, _ = _nearest_surface(scene, np.asarray(p, dtype=float))
        points.append(c)
        normals.append(n)
    c, n = np.concatenate(points), np.concatenate(normals)
    height = np.concatenate(positions)[:, 2]
    horizontal = n[:, :2] / np.maximum(np.linalg.norm(n[:, :2], axis=1), 1e-12)[:, None]
    sideways = np.linalg.norm(n[:, :2], axis=1) > 0.5  # beside a wall, not over a ledge or a floor
    if not sideways.any():
        return np.zeros(len(c)), height, n, "flat"
    angle = np.unwrap(np.arctan2(horizontal[:, 1], horizontal[:, 0])[sideways])
    low, high = np.quantile(angle, [0.02, 0.98])
    if high - low <= _FLAT_SPREAD:
        mean = horizontal[sideways].mean(axis=0)
        tangent = np.array([-mean[1], mean[0]]) / np.linalg.norm(mean)  # z x n: along the surface, to its left
        return c[:, :2] @ tangent, height, n, "flat"
    centre, radius = _circle(c[sideways, :2])
    around = np.unwrap(np.arctan2(c[:, 1] - centre[1], c[:, 0] - centre[0]))
    return radius * around, height, n, "around"


def plot_surface_map(found: Any, out_dir: str | Path) -> Path | None:
    """``residual_on_surface.png`` of a fitted :class:`~discovery.workflow.Discovery` (None without walls or
    bodies in its scenes)."""
    from matplotlib.figure import Figure

    segments = found.data_.segments
    if not any(seg.scene.walls or seg.scene.has_bodies for seg in segments):
        return None
    along, height, normal, how = surface_coordinates([seg.scene for seg in segments],
                                                     [seg.states.p_world for seg in segments])
    fig = Figure(figsize=(11, 4.2))
    axes = fig.subplots(1, 2, sharey=True)
    pulls = [(-(found.residual_before_ * normal).sum(axis=1), "nominal model"),
             (-(found.residual_after_ * normal).sum(axis=1), "discovered model")]
    edges_a = np.linspace(along.min(), along.max() + 1e-9, MAP_CELLS[0] + 1)
    edges_h = np.linspace(height.min(), height.max() + 1e-9, MAP_CELLS[1] + 1)
    limit = max(float(np.quantile(np.abs(pulls[0][0]), 0.98)), 1e-6)
    images = []
    for ax, (pull, title) in zip(axes, pulls):
        total, _, _ = np.histogram2d(along, height, [edges_a, edges_h], weights=pull)
        count, _, _ = np.histogram2d(along, height, [edges_a, edges_h])
        mean = np.where(count >= 3, total / np.maximum(count, 1), np.nan)
        images.append(ax.pcolormesh(edges_a, edges_h, mean.T, cmap="RdBu_r", vmin=-limit, vmax=limit))
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("position along the surface (m)" if how == "flat" else "position around the surface (m)")
    axes[0].set_ylabel("height (m)")
    fig.suptitle("held-out force residual toward the nearest surface, on the surface (cells of 3 samples or more)")
    fig.colorbar(images[0], ax=list(axes), label="mean pull toward the surface the model misses (N)")
    path = Path(out_dir) / "residual_on_surface.png"
    fig.savefig(path, dpi=90)
    return path
