"""Polygon margins of the certifier against a dense-sampling oracle written independently of ``verify.geometry``.

Oracle: the boundary sampled every ``h`` metres (distance to the nearest sample overestimates the true distance by
at most ``h / 2``) and matplotlib's ``Path.contains_points`` for the inside test. For the robot disc: its rim
sampled densely, every rim point tested for containment (inside a region) or the rim against the polygon (touching
an obstacle). Polygons: random star-shaped ones (angles sorted around a centre: always simple) and rectangles, in
both vertex orders.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import assume, example, given
from hypothesis import strategies as st
from matplotlib.path import Path as MplPath

from tubempc.scenario import scenario_from_dict
from verify.geometry import polygon_signed_distance, region_margins, workspace_margin

H = 2e-4  # boundary sampling step of the oracle (m)

coord = st.floats(-3.0, 3.0, allow_nan=False, allow_infinity=False)


@st.composite
def star_polygons(draw: st.DrawFn) -> list[tuple[float, float]]:
    n = draw(st.integers(3, 9))
    cx, cy = draw(coord), draw(coord)
    angles = sorted(draw(st.lists(st.floats(0.0, 2 * math.pi, exclude_max=True), min_size=n, max_size=n,
                                  unique=True)))
    gaps = np.diff([*angles, angles[0] + 2 * math.pi])
    if gaps.min() < 0.05 or gaps.max() >= 0.9 * math.pi:
        # the centre must see every edge from the inside (gaps < pi) for the ring to be simple: otherwise take a
        # regular polygon
        angles = [2 * math.pi * k / n for k in range(n)]
    radii = draw(st.lists(st.floats(0.3, 2.0), min_size=n, max_size=n))
    pts = [(cx + r * math.cos(a), cy + r * math.sin(a)) for a, r in zip(angles, radii, strict=True)]
    return pts if draw(st.booleans()) else pts[::-1]


@st.composite
def rectangles(draw: st.DrawFn) -> list[tuple[float, float]]:
    x0, y0 = draw(coord), draw(coord)
    w, h = draw(st.floats(0.2, 3.0)), draw(st.floats(0.2, 3.0))
    pts = [(x0, y0), (x0 + w, y0), (x0 + w, y0 + h), (x0, y0 + h)]
    if draw(st.booleans()):  # a fifth vertex mid-edge: the general edge-by-edge path instead of the closed form
        pts.insert(1, (x0 + 0.5 * w, y0))
    return pts if draw(st.booleans()) else pts[::-1]


def _boundary(poly: list[tuple[float, float]]) -> np.ndarray:
    out = []
    for (ax, ay), (bx, by) in zip(poly, [*poly[1:], poly[0]], strict=True):
        m = max(2, math.ceil(math.hypot(bx - ax, by - ay) / H) + 1)
        t = np.linspace(0.0, 1.0, m)
        out.append(np.stack([ax + t * (bx - ax), ay + t * (by - ay)], axis=1))
    return np.concatenate(out)


def _oracle_sd(poly: list[tuple[float, float]], pts: np.ndarray) -> np.ndarray:
    b = _boundary(poly)
    d = np.sqrt(((pts[:, None, :] - b[None, :, :]) ** 2).sum(axis=2)).min(axis=1)
    inside = MplPath(np.array(poly)).contains_points(pts)
    return np.where(inside, d, -d)


@given(st.one_of(star_polygons(), rectangles()), st.lists(st.tuples(coord, coord), min_size=1, max_size=12))
@example([(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)], [(0.5, 0.5), (2.0, 0.5), (1.0, 1.0), (0.5, -0.3)])
@example([(0.9999999999999998, -1.0), (0.5, 6.123233995736766e-17), (1.0, 1.0), (2.0, 0.0)], [(0.0, 0.0)])
@example([(0.0, 0.9375), (1.0, 0.9375), (1.0, -0.0625), (0.0, -0.0625)], [(0.0, 0.0)])  # on an edge
def test_signed_distance_matches_the_dense_oracle(poly: list[tuple[float, float]],
                                                  points: list[tuple[float, float]]) -> None:
    pts = np.array(points)
    got = polygon_signed_distance(pts[:, 0], pts[:, 1], tuple(poly))
    want = _oracle_sd(poly, pts)
    # the oracle's distance is at most H/2 too large; the sign is checked where the point is clearly off the edge
    assert np.all(np.abs(np.abs(got) - np.abs(want)) <= H / 2 + 1e-9), (got, want)
    clear = np.abs(want) > H  # farther from the boundary than the oracle's own error
    assert np.array_equal(np.sign(got[clear]), np.sign(want[clear])), (got, want)


@given(st.one_of(star_polygons(), rectangles()), coord, coord, st.floats(0.05, 0.5), st.booleans())
def test_disc_inside_and_intersects_agree_with_the_rim(poly: list[tuple[float, float]], px: float, py: float,
                                                       eta: float, unsafe: bool) -> None:
    """Region margin > 0 <=> the robot disc is inside (safe) / intersects (unsafe) the polygon, per the oracle."""
    data = {"name": "p", "workspace": {"x": [-6.0, 6.0], "y": [-6.0, 6.0]}, "robot": {"radius": eta},
            "inputs": {"max_abs": [0.2, 0.2, 0.2]}, "spec": "G[0,inf) a",
            "regions": [{"name": "P", "polygon": [list(p) for p in poly], "labels": ["a"], "unsafe": unsafe}]}
    sc = scenario_from_dict(data)
    margin = float(region_margins(np.array([px]), np.array([py]), sc)[0, 0])
    rim_t = np.linspace(0.0, 2 * math.pi, 4000, endpoint=False)
    rim = np.stack([px + eta * np.cos(rim_t), py + eta * np.sin(rim_t)], axis=1)
    path = MplPath(np.array(poly))
    slack = eta * (1 - math.cos(math.pi / 4000)) + H  # rim sampling and boundary sampling errors
    if unsafe:
        # intersects: the centre inside, or the rim within eta of the boundary
        touching = path.contains_points([(px, py)])[0] or _oracle_sd(poly, np.array([[px, py]]))[0] >= -eta
        if margin > slack:
            assert touching
        elif margin < -slack:
            assert not touching
    else:
        all_in = bool(path.contains_points(rim).all()) and path.contains_points([(px, py)])[0]
        if margin > slack:
            assert all_in
        elif margin < -slack:
            assert not all_in


@given(rectangles(), st.lists(st.tuples(coord, coord), min_size=1, max_size=12), st.floats(0.05, 0.5))
@example([(1.0, 2.0), (2.0, 2.0), (2.0, 1.0), (1.0, 1.0)], [(0.0, 0.0)], 0.5)  # outside a corner
def test_box_and_polygon_workspaces_agree_inside(rect: list[tuple[float, float]],
                                                 points: list[tuple[float, float]], eta: float) -> None:
    """A rectangle given as a polygon and as a box: equal margins wherever the disc centre is inside the box
    (outside, the box formula min(x - x0, ...) is nearer 0 than the signed distance near a corner, same sign)."""
    xs, ys = [p[0] for p in rect], [p[1] for p in rect]
    # a workspace narrower than the robot disc is refused by the scenario model (the robot could be nowhere)
    assume(min(max(xs) - min(xs), max(ys) - min(ys)) >= 2 * eta)
    base = {"name": "w", "robot": {"radius": eta}, "inputs": {"max_abs": [0.2, 0.2, 0.2]}, "spec": "G[0,inf) a",
            "regions": [{"name": "A", "center": [0.0, 0.0], "radius": 1.0, "labels": ["a"]}]}
    box = scenario_from_dict({**base, "workspace": {"x": [min(xs), max(xs)], "y": [min(ys), max(ys)]}})
    poly = scenario_from_dict({**base, "workspace": {"polygon": [list(p) for p in rect]}})
    pts = np.array(points)
    mb = workspace_margin(pts[:, 0], pts[:, 1], box)
    mp = workspace_margin(pts[:, 0], pts[:, 1], poly)
    inside = mb + eta > 0
    assert np.allclose(mb[inside], mp[inside], atol=1e-12)
    assert np.all(mb[~inside] >= mp[~inside] - 1e-12)
    assert np.array_equal(mb > 0, mp > 0)
