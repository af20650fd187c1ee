"""Simple-polygon validation for scenario regions and workspaces: vertices -> a problem in words, or None.

input: a sequence of ``(x, y)`` vertices (open ring: the last vertex is not a repeat of the first) -> output: a
description of why it is not a simple polygon (too few vertices, repeated vertex, zero area, two edges that cross or
touch) or None. Exact predicates on floats (orientation signs), no tolerance: a polygon whose edges touch is refused.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = ["disc_within_polygon", "polygon_bounds", "polygon_problem", "polygon_within_polygon", "signed_area"]

Point = tuple[float, float]


def signed_area(vertices: Sequence[Point]) -> float:
    """Shoelace area: positive for counter-clockwise vertex order."""
    n = len(vertices)
    total = 0.0
    for i in range(n):
        x0, y0 = vertices[i]
        x1, y1 = vertices[(i + 1) % n]
        total += x0 * y1 - x1 * y0
    return 0.5 * total


def polygon_bounds(vertices: Sequence[Point]) -> tuple[float, float, float, float]:
    """``(x_min, y_min, x_max, y_max)``."""
    xs = [p[0] for p in vertices]
    ys = [p[1] for p in vertices]
    return min(xs), min(ys), max(xs), max(ys)


def _orient(a: Point, b: Point, c: Point) -> float:
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def _on_segment(a: Point, b: Point, p: Point) -> bool:
    return min(a[0], b[0]) <= p[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= p[1] <= max(a[1], b[1])


def _segments_meet(a: Point, b: Point, c: Point, d: Point) -> bool:
    o1, o2, o3, o4 = _orient(a, b, c), _orient(a, b, d), _orient(c, d, a), _orient(c, d, b)
    if ((o1 > 0 and o2 < 0) or (o1 < 0 and o2 > 0)) and ((o3 > 0 and o4 < 0) or (o3 < 0 and o4 > 0)):
        return True
    return ((o1 == 0 and _on_segment(a, b, c)) or (o2 == 0 and _on_segment(a, b, d))
            or (o3 == 0 and _on_segment(c, d, a)) or (o4 == 0 and _on_segment(c, d, b)))


def polygon_problem(vertices: Sequence[Point]) -> str | None:
    """Why ``vertices`` is not a simple polygon, or None when it is one."""
    n = len(vertices)
    if n < 3:
        return f"a polygon needs at least 3 vertices, got {n}"
    if len(set(vertices)) != n:
        dup = next(p for p in vertices if vertices.count(p) > 1)
        return f"vertex {list(dup)} is repeated (give each corner once; the ring closes by itself)"
    if all(_orient(vertices[0], vertices[1], p) == 0 for p in vertices[2:]):
        return "the polygon has zero area (its vertices are collinear)"
    edges = [(vertices[i], vertices[(i + 1) % n]) for i in range(n)]
    for i in range(n):
        a, b = edges[i]
        # an edge and the next one share a vertex: they must not fold back onto each other
        c, d = edges[(i + 1) % n]
        if _orient(a, b, d) == 0 and (_on_segment(a, b, d) or _on_segment(b, d, a)):
            return f"edges {i} and {(i + 1) % n} overlap"
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue  # adjacent through the closing edge
            c, d = edges[j]
            if _segments_meet(a, b, c, d):
                return (f"its edges cross or touch: edge {i} {_edge(a, b)} and edge {j} {_edge(c, d)} (the polygon "
                        "is not simple; list the vertices in order around its boundary)")
    if signed_area(vertices) == 0.0:
        return "the polygon has zero area"
    return None


def _edge(a: Point, b: Point) -> str:
    return f"[{a[0]:g}, {a[1]:g}]-[{b[0]:g}, {b[1]:g}]"


def _inside(p: Point, vertices: Sequence[Point]) -> bool:
    """Even-odd rule (a point on the boundary may go either way; callers check the boundary distance)."""
    x, y = p
    inside = False
    n = len(vertices)
    for i in range(n):
        (x0, y0), (x1, y1) = vertices[i], vertices[(i + 1) % n]
        if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
            inside = not inside
    return inside


def _boundary_distance(p: Point, vertices: Sequence[Point]) -> float:
    best = math.inf
    n = len(vertices)
    for i in range(n):
        (ax, ay), (bx, by) = vertices[i], vertices[(i + 1) % n]
        ex, ey = bx - ax, by - ay
        t = max(0.0, min(1.0, ((p[0] - ax) * ex + (p[1] - ay) * ey) / (ex * ex + ey * ey)))
        best = min(best, math.hypot(p[0] - ax - t * ex, p[1] - ay - t * ey))
    return best


def disc_within_polygon(center: Point, radius: float, vertices: Sequence[Point]) -> bool:
    """The closed disc lies inside the polygon (touching the boundary from inside allowed)."""
    return _inside(center, vertices) and _boundary_distance(center, vertices) >= radius


def polygon_within_polygon(inner: Sequence[Point], outer: Sequence[Point]) -> bool:
    """Every vertex of ``inner`` is inside or on ``outer`` and no edges cross properly (so ``inner`` is inside)."""
    for p in inner:
        if not (_inside(p, outer) or _boundary_distance(p, outer) == 0.0):
            return False
    n, m = len(inner), len(outer)
    for i in range(n):
        a, b = inner[i], inner[(i + 1) % n]
        for j in range(m):
            c, d = outer[j], outer[(j + 1) % m]
            o1, o2, o3, o4 = _orient(a, b, c), _orient(a, b, d), _orient(c, d, a), _orient(c, d, b)
            if o1 * o2 < 0 and o3 * o4 < 0:
                return False
    return True
