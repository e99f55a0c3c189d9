"""Drawing of vessel lumens (x-y outline of a union of tubes), shared by Vessel and
VesselNetwork without either importing the other."""

from __future__ import annotations

import numpy as np


def _draw_lumens(ax, vessels, **kwargs) -> None:
    """Outline of the union of the vessels' lumens (x-y projection) with dashed centrelines."""
    import shapely

    shapes, cuts = [], []
    for v in vessels:
        shape, cut = v._shadow()
        shapes.append(shape)
        cuts.extend(cut)
    outline = shapely.union_all(shapes).boundary
    if cuts:
        outline = outline.difference(
            shapely.union_all([shapely.Point(c).buffer(1.0001 * r, quad_segs=32) for c, r in cuts])
        )
    kwargs.setdefault("color", "k")
    kwargs.setdefault("linewidth", 1.2)
    for line in getattr(outline, "geoms", [outline]):
        if line.is_empty:
            continue
        xy = np.asarray(line.coords)
        ax.plot(xy[:, 0], xy[:, 1], **kwargs)
    for v in vessels:
        c = v._centerline_xy()
        ax.plot(c[:, 0], c[:, 1], linestyle="--", linewidth=0.6, color=kwargs["color"], alpha=0.5)
    ax.autoscale_view()
