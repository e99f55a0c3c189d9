"""A figure is an output like a number: checks that what a figure labels can be seen.

* :func:`text_overlaps`: pairs of visible, non-empty texts (titles, labels, tick labels,
  legend entries, colour-bar ticks) whose rendered boxes overlap;
* :func:`hidden_lines`: labelled lines fully covered by an opaque solid line drawn above them
  (a later or higher-zorder line at least as wide whose stroke contains every point);
* :func:`repeated_phrases`: texts that say the same words twice;
* :func:`assert_readable`: all three empty, and every axes with labelled lines no flatter than
  ``min_aspect`` (height / width on the page).
"""

from __future__ import annotations

import re

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.text import Text


def _renderer(fig):
    fig.canvas.draw()
    return fig.canvas.get_renderer()


def _tick_labels(fig):
    """(ids of every tick label, ids of the tick labels actually drawn: ticks in view)."""
    every, drawn = set(), set()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            for tick in axis.get_major_ticks() + axis.get_minor_ticks():
                every |= {id(tick.label1), id(tick.label2)}
            for tick in axis._update_ticks():
                drawn |= {id(tick.label1), id(tick.label2)}
    return every, drawn


def _texts(fig):
    every, drawn = _tick_labels(fig)
    out = []
    for t in fig.findobj(Text):
        if not t.get_visible() or not t.get_text().strip():
            continue
        if id(t) in every and id(t) not in drawn:
            continue
        ax = t.axes
        if ax is not None and not ax.get_visible():
            continue
        out.append(t)
    return out


def text_overlaps(fig, tol_px: float = 0.5) -> list[tuple[str, str]]:
    """Pairs (text a, text b) whose window extents overlap by more than ``tol_px`` pixels in
    both directions."""
    r = _renderer(fig)
    texts = _texts(fig)
    boxes = []
    for t in texts:
        bb = t.get_window_extent(r)
        # ticks outside the axes' view are not drawn even when "visible"
        if not np.all(np.isfinite([bb.x0, bb.x1, bb.y0, bb.y1])) or bb.width == 0:
            boxes.append(None)
            continue
        boxes.append(bb)
    clashes = []
    for i in range(len(texts)):
        for j in range(i + 1, len(texts)):
            a, b = boxes[i], boxes[j]
            if a is None or b is None:
                continue
            dx = min(a.x1, b.x1) - max(a.x0, b.x0)
            dy = min(a.y1, b.y1) - max(a.y0, b.y0)
            if dx > tol_px and dy > tol_px:
                clashes.append((texts[i].get_text(), texts[j].get_text()))
    return clashes


def _points_px(line: Line2D) -> np.ndarray:
    xy = np.column_stack([line.get_xdata(), line.get_ydata()]).astype(float)
    xy = xy[np.all(np.isfinite(xy), axis=1)]
    return line.get_transform().transform(xy) if len(xy) else xy


def _distance_to_polyline(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Distance (px) of points p (n, 2) to the polyline q (m, 2)."""
    if len(q) == 1:
        return np.linalg.norm(p - q[0], axis=1)
    a, b = q[:-1], q[1:]
    ab = b - a
    t = np.einsum("nmk,mk->nm", p[:, None, :] - a[None], ab) / np.maximum(
        np.einsum("mk,mk->m", ab, ab), 1e-300
    )
    t = np.clip(t, 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(p[:, None, :] - closest, axis=2).min(axis=1)


def hidden_lines(fig) -> list[str]:
    """Labels of labelled lines that an opaque solid line drawn over them covers entirely."""
    _renderer(fig)
    px_per_pt = fig.dpi / 72.0
    hidden = []
    for ax in fig.axes:
        lines = list(ax.get_lines())
        order = sorted(range(len(lines)), key=lambda i: (lines[i].get_zorder(), i))
        rank = {i: r for r, i in enumerate(order)}
        for i, line in enumerate(lines):
            label = line.get_label()
            if label.startswith("_") or not line.get_visible():
                continue
            p = _points_px(line)
            if len(p) == 0:
                continue
            w_self = line.get_linewidth() * px_per_pt
            for j, other in enumerate(lines):
                if j == i or rank[j] < rank[i] or not other.get_visible():
                    continue
                if other.get_linestyle() not in ("-", "solid") or (other.get_alpha() or 1.0) < 1:
                    continue
                w = other.get_linewidth() * px_per_pt
                if w < w_self:
                    continue
                q = _points_px(other)
                if len(q) and np.all(_distance_to_polyline(p, q) <= 0.5 * w):
                    hidden.append(label)
                    break
    return hidden


def repeated_phrases(fig, words: int = 4) -> list[str]:
    """Texts in which a run of ``words`` words occurs twice."""
    bad = []
    for t in _texts(fig):
        tokens = re.findall(r"\w+", t.get_text().lower())
        grams = [tuple(tokens[k : k + words]) for k in range(len(tokens) - words + 1)]
        if len(grams) != len(set(grams)):
            bad.append(t.get_text())
    return bad


def assert_readable(fig, min_aspect: float = 0.2) -> None:
    """AssertionError naming what cannot be read (see the module docstring)."""
    assert not text_overlaps(fig), f"overlapping texts: {text_overlaps(fig)}"
    assert not hidden_lines(fig), f"labelled lines hidden under others: {hidden_lines(fig)}"
    assert not repeated_phrases(fig), f"texts repeating themselves: {repeated_phrases(fig)}"
    r = _renderer(fig)
    for ax in fig.axes:
        labelled = [ln for ln in ax.get_lines() if not ln.get_label().startswith("_")]
        if not labelled:
            continue
        bb = ax.get_window_extent(r)
        assert bb.height >= min_aspect * bb.width, (
            f"axes '{ax.get_title() or ax.get_ylabel()}' is a strip ({bb.width:.0f} x "
            f"{bb.height:.0f} px)"
        )
        assert ax.get_legend() is not None, (
            f"axes '{ax.get_ylabel()}' labels lines but has no legend"
        )
