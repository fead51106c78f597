"""Triangle rasterisation against a per-pixel brute force (shtools.runtime.raster).

The brute force solves each triangle's barycentrics at every pixel centre of the
image with ``np.linalg.solve`` (no boxes, no broadcasting blocks), so it checks the
box-size blocks, the pixel-by-pixel path and the batching alike.
"""

import numpy as np
import pytest

from shtools.export import raster as preview
from shtools.export.raster import Camera, rasterize
from shtools.runtime import raster
from shtools.runtime.raster import EDGE_EPS, depth_buffer, triangle_fragments


def _brute_force(sx, sy, width, height):
    """Sets of (triangle, px, py) covered, and those within 1e-9 of an edge's slack."""
    px, py = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    covered, borderline = set(), set()
    for t in range(len(sx)):
        corners = np.stack([sx[t], sy[t], np.ones(3)])  # (3, 3): [x; y; 1] per corner
        if abs(np.linalg.det(corners)) < 1e-9:
            continue
        rhs = np.stack([px.ravel(), py.ravel(), np.ones(px.size)])
        bary = np.linalg.solve(corners, rhs)  # (3, pixels)
        low = bary.min(axis=0)
        cells = np.stack([np.full(px.size, t), px.ravel() - 0.5, py.ravel() - 0.5], 1)
        for cell in map(tuple, cells[low >= -EDGE_EPS].astype(int)):
            covered.add(cell)
        # within rounding of the slack, either answer is right
        for cell in map(tuple, cells[np.abs(low + EDGE_EPS) < 1e-9].astype(int)):
            borderline.add(cell)
    return covered, borderline


def _fragments(sx, sy, width, height, **kwargs):
    parts = list(triangle_fragments(sx, sy, width, height, **kwargs))
    t, px, py, bary = (np.concatenate(column) for column in zip(*parts, strict=True))
    return t, px, py, bary


@pytest.mark.parametrize("budget", [raster.FRAGMENT_BUDGET, 500])
def test_fragments_are_the_pixels_inside_each_triangle(budget, monkeypatch):
    rng = np.random.default_rng(7)
    W, H = 48, 40
    # many small triangles of a few box sizes (blocks), a few large ones (expanded),
    # some partly off screen, one degenerate
    small = rng.uniform(-4, 50, (300, 1, 2)) + rng.normal(0, 2.5, (300, 3, 2))
    large = rng.uniform(-10, 60, (6, 3, 2))
    flat = np.array([[[5.0, 5.0], [10.0, 10.0], [15.0, 15.0]]])
    corners = np.concatenate([small, large, flat])
    sx, sy = corners[..., 0], corners[..., 1]
    monkeypatch.setattr(raster, "GROUP_MIN_CANDIDATES", 64)  # blocks at this small size
    t, px, py, bary = _fragments(sx, sy, W, H, budget=budget)
    got = set(zip(t.tolist(), px.tolist(), py.tolist(), strict=True))
    assert len(got) == len(t), "a pixel appears twice for one triangle"
    covered, borderline = _brute_force(sx, sy, W, H)
    assert got - borderline == covered - borderline
    # the barycentrics reproduce the pixel centre (rounding: coordinates ~50 px)
    x = np.einsum("pk,pk->p", bary, sx[t])
    y = np.einsum("pk,pk->p", bary, sy[t])
    np.testing.assert_allclose(x, px + 0.5, atol=1e-9)
    np.testing.assert_allclose(y, py + 0.5, atol=1e-9)


def test_blocks_and_expansion_give_the_same_fragments(monkeypatch):
    rng = np.random.default_rng(3)
    corners = rng.uniform(0, 200, (400, 1, 2)) + rng.normal(0, 4, (400, 3, 2))
    sx, sy = corners[..., 0], corners[..., 1]

    def cells():
        t, px, py, bary = _fragments(sx, sy, 200, 160)
        order = np.lexsort((py, px, t))
        return np.column_stack([t, px, py])[order], bary[order]

    monkeypatch.setattr(raster, "GROUP_MIN_CANDIDATES", 1)  # every size a block
    blocks = cells()
    monkeypatch.setattr(raster, "GROUP_MIN_CANDIDATES", 10**12)  # every pixel repeated
    expanded = cells()
    np.testing.assert_array_equal(blocks[0], expanded[0])
    np.testing.assert_array_equal(blocks[1], expanded[1])  # the same operations, bit for bit


def test_depth_buffer_is_the_nearest_of_overlapping_triangles():
    rng = np.random.default_rng(11)
    W = H = 32
    corners = rng.uniform(-4, 36, (40, 3, 2))
    depth = rng.uniform(1.0, 5.0, (40, 3))
    zb = depth_buffer(corners[..., 0], corners[..., 1], depth, W, H)
    # brute force: perspective depth 1 / (sum_k l_k / z_k) of every covering triangle
    expected = np.full((H, W), np.inf)
    px, py = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    rhs = np.stack([px.ravel(), py.ravel(), np.ones(px.size)])
    for t in range(len(corners)):
        bary = np.linalg.solve(np.stack([corners[t, :, 0], corners[t, :, 1], np.ones(3)]), rhs)
        inside = bary.min(axis=0) >= -EDGE_EPS
        z = 1.0 / (bary.T @ (1.0 / depth[t]))
        flat = expected.ravel()
        flat[inside] = np.minimum(flat[inside], z[inside])
    finite = np.isfinite(expected)
    np.testing.assert_array_equal(np.isfinite(zb), finite)
    # rtol: two float64 evaluations of 1 / (sum l_k / z_k), differently rounded
    np.testing.assert_allclose(zb[finite], expected[finite], rtol=1e-12)


def test_rasterize_shows_the_nearest_surface_in_any_number_of_batches(monkeypatch):
    """Overlapping squares facing the camera at several depths, one colour each."""
    rng = np.random.default_rng(5)
    n, half, W, H = 60, 0.2, 64, 48
    centres = rng.uniform(-1, 1, (n, 3)) * [1.0, 1.0, 0.5]
    offsets = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]])
    verts = (centres[:, None] + offsets).reshape(-1, 3)
    quads = np.arange(len(verts)).reshape(-1, 4)
    faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    square_colors = rng.uniform(0, 1, (n, 3))
    colors = np.repeat(square_colors, 4, axis=0)
    cam = Camera(eye=np.array([0.0, 0.0, 4.0]), target=np.zeros(3))
    one, one_cov = rasterize(verts, faces, colors, cam, W, H, supersample=1)
    monkeypatch.setattr(preview, "FRAGMENT_BUDGET", 700)
    many, many_cov = rasterize(verts, faces, colors, cam, W, H, supersample=1)
    # a pixel's winner and its colour are computed by the same operations in any
    # batch: the same picture, bit for bit
    np.testing.assert_array_equal(many, one)
    np.testing.assert_array_equal(many_cov, one_cov)
    # brute force: the ray through each pixel centre meets square k at depth 4 - z_k
    focal = (H / 2) / np.tan(cam.fov_y / 2)
    px, py = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    ray_x, ray_y = (px - W / 2) / focal, -(py - H / 2) / focal
    distance = 4.0 - centres[:, 2]
    dx = np.abs(ray_x[..., None] * distance - centres[:, 0]) - half  # (H, W, n)
    dy = np.abs(ray_y[..., None] * distance - centres[:, 1]) - half
    inside = (dx <= 0) & (dy <= 0)
    clear = np.all((np.abs(dx) > 1e-6) & (np.abs(dy) > 1e-6), axis=-1)  # off every edge
    nearest = np.argmin(np.where(inside, distance, np.inf), axis=-1)
    hit = inside.any(axis=-1)
    np.testing.assert_array_equal(one_cov[clear], hit[clear].astype(float))
    shown = clear & hit
    assert shown.sum() > 500  # the squares overlap on much of the picture
    # atol: a constant colour through weights that sum to 1 to float64 rounding
    np.testing.assert_allclose(one[shown], square_colors[nearest[shown]], atol=1e-12)


def test_of_coincident_faces_the_lowest_wins_in_any_batch(monkeypatch):
    """Two copies of a square at the same depth, coloured apart: exact depth ties."""
    verts = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    square = np.array([[0, 1, 2], [0, 2, 3]])
    both = np.concatenate([verts, verts])
    colors = np.concatenate([np.full((4, 1), 2.0), np.full((4, 1), 5.0)])
    cam = Camera(eye=np.array([0.0, 0.0, 4.0]), target=np.zeros(3))
    for faces, expected in ((np.concatenate([square, square + 4]), 2.0),
                            (np.concatenate([square + 4, square]), 5.0)):
        for budget in (raster.FRAGMENT_BUDGET, 100):  # one batch, or many
            monkeypatch.setattr(preview, "FRAGMENT_BUDGET", budget)
            img, cov = rasterize(both, faces, colors, cam, 32, 32, supersample=1)
            # the first two faces' colour (to the rounding of weights summing to 1)
            np.testing.assert_allclose(img[cov == 1.0], expected, rtol=1e-12)
