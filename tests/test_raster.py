"""The off-screen picture of a surface (`plan.raster`): its pixels against shapes whose pictures are known."""
from __future__ import annotations

import numpy as np
import pytest

from breastplan.plan.raster import Camera, draw, framing, lit

RED, BLUE = (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)


def square(x0, z0, side, y, colour):
    """Two triangles covering the square [x0, x0 + side] × [z0, z0 + side] at depth y (display frame, mm)."""
    v = np.array([[x0, y, z0], [x0 + side, y, z0], [x0 + side, y, z0 + side], [x0, y, z0 + side]], float)
    return v, np.array([[0, 1, 2], [0, 2, 3]]), np.tile(colour, (4, 1))


def joined(*meshes):
    vs, fs, cs, n = [], [], [], 0
    for v, f, c in meshes:
        vs.append(v), fs.append(f + n), cs.append(c)
        n += len(v)
    return np.concatenate(vs), np.concatenate(fs), np.concatenate(cs)


def sphere(radius, n=80):
    """A UV sphere (display frame, mm) centred on the origin."""
    theta, phi = np.meshgrid(np.linspace(0, np.pi, n), np.linspace(0, 2 * np.pi, 2 * n, endpoint=False), indexing="ij")
    v = radius * np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(2 * n), indexing="ij")
    a, b = i * 2 * n + j, i * 2 * n + (j + 1) % (2 * n)
    c, d = a + 2 * n, b + 2 * n
    return v, np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])


FRONT = Camera(0.0, np.zeros(3), 1.0, 100, 80)                         # 1 mm a pixel, centred on the origin


def test_a_square_covers_exactly_the_pixels_whose_centres_it_holds():
    """A 20 mm square from the front at 1 mm a pixel: 400 pixels, at the columns and rows its corners give."""
    pic = draw(*square(-10.0, -5.0, 20.0, 0.0, RED), FRONT)
    covered = np.isfinite(pic.depth)
    rows, cols = np.nonzero(covered)
    assert covered.sum() == 400
    assert (cols.min(), cols.max()) == (40, 59)                        # x −10..10 mm → columns 40..59
    assert (rows.min(), rows.max()) == (25, 44)                        # z 15..−5 mm (up is the top) → rows 25..44
    assert (pic.rgb[covered] == (255, 0, 0)).all() and (pic.rgb[~covered] == 255).all()


@pytest.mark.parametrize("radius", [12.0, 30.0, 37.5])
def test_a_spheres_picture_is_a_disc_of_its_radius(radius):
    """Any view of a sphere covers π r² within one pixel's rim, and its depth at the centre is −r."""
    v, f = sphere(radius)
    for azimuth in (0.0, 45.0, -90.0):
        pic = draw(v, f, np.full((len(v), 3), 0.5), Camera(azimuth, np.zeros(3), 1.0, 100, 80))
        area = np.isfinite(pic.depth).sum()
        assert abs(area - np.pi * radius**2) <= 2 * np.pi * radius
        assert pic.depth[40, 50] == pytest.approx(-radius, abs=0.3)


def test_the_nearer_surface_hides_the_farther_whatever_their_order():
    """A red square 10 mm nearer than a blue one it overlaps: red wherever both are, blue only where the red
    is not; the same picture with the triangles in any order."""
    near, far = square(-10, -10, 20, -5.0, RED), square(0, 0, 20, 5.0, BLUE)
    pics = [draw(*joined(near, far), FRONT), draw(*joined(far, near), FRONT)]
    v, f, c = joined(near, far)
    shuffled = np.random.default_rng(0).permutation(len(f))
    pics.append(draw(v, f[shuffled][:, ::-1], c, FRONT))                 # reordered and rewound
    for pic in pics:
        assert (pic.rgb[30:40, 50:60] == (255, 0, 0)).all()            # both: red (z 0..10, x 0..10)
        assert (pic.rgb[20:30, 60:70] == (0, 0, 255)).all()            # blue alone
        assert (pic.rgb == pics[0].rgb).all()


def test_colours_are_interpolated_across_a_triangle():
    """A triangle with red, green and blue corners is their mean at its centroid and each near its corner."""
    v = np.array([[-30.0, 0, -20], [30.0, 0, -20], [0.0, 0, 30]])
    pic = draw(v, np.array([[0, 1, 2]]), np.eye(3), FRONT)
    centroid = pic.rgb[43, 50].astype(float)                           # row 43: z −3 to −4 mm
    assert np.abs(centroid - 255 / 3).max() <= 6
    assert pic.rgb[59, 22].argmax() == 0 and pic.rgb[59, 77].argmax() == 1 and pic.rgb[12, 50].argmax() == 2


def test_the_camera_turns_about_her_vertical_axis():
    """From the front her left (+x) is the picture's right; from her left side (+90°) her front (−y) is
    the picture's left; points hidden behind the surface or off it are not visible."""
    v, f = sphere(20.0)
    side = draw(v, f, np.full((len(v), 3), 0.5), Camera(90.0, np.zeros(3), 1.0, 100, 80))
    front = draw(v, f, np.full((len(v), 3), 0.5), FRONT)
    px, _ = FRONT.project(np.array([[15.0, 0, 0]]))
    assert px[0, 0] == pytest.approx(65.0)
    px, depth = side.camera.project(np.array([[0.0, -15.0, 0], [-15.0, 0, 0]]))
    assert px[0, 0] == pytest.approx(35.0) and depth.tolist() == pytest.approx([0.0, 15.0])
    assert side.visible(np.array([[21.0, 0, 0], [-21.0, 0, 0], [25.0, 0, 30]])).tolist() == [True, False, False]
    assert front.visible(np.array([[0, -21.0, 0], [0, 21.0, 0]])).tolist() == [True, False]


def test_framing_holds_every_point_at_equal_scales():
    """The camera `framing` gives holds all the points inside its margin, at one scale on both axes."""
    points = np.random.default_rng(1).normal([0, 600, 0], [150, 40, 300], (500, 3))
    for azimuth in (0.0, 45.0, -90.0):
        cam = framing([points], azimuth, 300, 400, margin=0.05)
        px, _ = cam.project(points)
        assert px[:, 0].min() >= 300 * 0.05 - 1e-6 and px[:, 0].max() <= 300 * 0.95 + 1e-6
        assert px[:, 1].min() >= 400 * 0.05 - 1e-6 and px[:, 1].max() <= 400 * 0.95 + 1e-6
        assert np.isclose(px[:, 0].max() - px[:, 0].min(), 300 * 0.9) or np.isclose(px[:, 1].max() - px[:, 1].min(), 400 * 0.9)


def test_light_falls_on_either_side_in_proportion_to_how_squarely_it_faces():
    """A square facing the light squarely gets ambient + diffuse; turned 60° away, ambient + diffuse / 2."""
    v, f, _ = square(0, 0, 10, 0.0, RED)
    full = lit(v, f, np.array([200.0, 100, 50]), np.array([0.0, -1, 0]), (0.4, 0.6))
    assert full == pytest.approx(np.tile([200 / 255, 100 / 255, 50 / 255], (4, 1)))
    half = lit(v, f[:, ::-1], np.array([200.0, 100, 50]), np.array([0.0, np.cos(np.pi / 3), np.sin(np.pi / 3)]), (0.4, 0.6))
    assert half == pytest.approx(np.tile(np.array([200, 100, 50]) / 255 * 0.7, (4, 1)))
