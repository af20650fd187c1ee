"""Simple-polygon validation for scenario regions and workspaces: vertices -> a problem in words, or None.

input: a sequence of ``(x, y)`` vertices (open ring: the last vertex is not a repeat of the first) -> output: a
description of why it is not a simple polygon (too few vertices, repeated vertex, zero area, two edges that cross or
touch) or None. Exact predicates on floats (orientation signs), no tolerance: a polygon whose edges touch is refused.
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["polygon_bounds", "polygon_problem", "signed_area"]

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
    if signed_area(vertices) == 0.0:
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
                return f"edges {i} and {j} cross or touch (the polygon is not simple)"
    return None
