"""Scene files: shapes, the exact SDF, quantities, the sensor model and every validation
error, each checked against a closed form or a stated statistical tolerance."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import pytest
from shapely.geometry import Point

from harness.cli import main
from harness.geometry import Grid
from harness.scene import load_scene
from harness.sensor import INTERIOR, SPECULAR, TRANSPARENT, SensorModel, observe

REPO = Path(__file__).resolve().parents[1]
SHARED_OBJECTS = Path(__file__).parents[2] / "shared" / "objects"
OBJECT_CSVS = sorted(SHARED_OBJECTS.glob("*.csv")) if SHARED_OBJECTS.is_dir() else []

#: The grid of most small scenes below: 40 x 40 cells over 0.2 m, cell h = 5 mm.
GRID = """\
[grid]
size = 40
extent = 0.2
"""
H = 0.2 / 40

#: A 256-gon inscribed in a circle of radius r (shapely's buffer with quad_segs=64)
#: lies inside the circle by at most its sagitta r (1 - cos(pi/256)) = 7.5e-5 r, and
#: its area is (n/2) r^2 sin(2 pi / n), within (2 pi / n)^2 / 6 = 1.0e-4 of pi r^2.
DISK_SIDES = 256
#: A capsule's two round ends together are a 128-gon (quad_segs=32).
CAPSULE_SIDES = 128


def polygon_area(n: int, r: float) -> float:
    """Area of the regular n-gon inscribed in a circle of radius r."""
    return 0.5 * n * r * r * math.sin(2 * math.pi / n)


def rectangle_sdf(x, y, half_width, half_height):
    """Closed-form signed distance of an axis-aligned rectangle centred on the origin."""
    qx, qy = np.abs(x) - half_width, np.abs(y) - half_height
    outside = np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0))
    inside = np.minimum(np.maximum(qx, qy), 0.0)
    return outside + inside


def shoelace_area(vertices: np.ndarray) -> float:
    x, y = vertices[:, 0], vertices[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)))


@pytest.fixture
def write_scene(tmp_path):
    """Writes a small scene (the 40 x 40 grid above unless ``grid`` is given) and returns its path."""

    def write(body: str, name: str = "scene.toml", grid: str = GRID) -> Path:
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(grid + textwrap.dedent(body), encoding="utf-8")
        return path

    return write


@pytest.fixture
def load(write_scene):
    """Loads a small scene written by ``write_scene``."""

    def load_body(body: str, **kwargs):
        return load_scene(write_scene(body, **kwargs))

    return load_body


@pytest.fixture
def check(capsys):
    """Runs ``gpis-harness scenes check PATH``; returns (exit code, stdout, stderr lines)."""

    def run(path) -> tuple[int, str, list[str]]:
        code = main(["scenes", "check", str(path)])
        out, err = capsys.readouterr()
        return code, out, err.splitlines()

    return run


DISK = """
[shape]
type = "disk"
radius = 0.03
"""


# ---------------------------------------------------------------------------
# The calibration scenes and the exact SDF


def load_calibration(name):
    """A calibration scene, after checking the settings both share: grid extent 0.2 m,
    M = 40, fully observed with 0.5 mm noise, friction 0.5, opening 0.10 m, jaw 0.01 m."""
    scene = load_scene(REPO / "scenes" / f"{name}.toml")
    assert (scene.grid.size, scene.grid.extent) == (40, 0.2)
    assert scene.sensor.noise == pytest.approx(0.0005, rel=1e-12)
    assert scene.sensor.regions == () and scene.sensor.interior_keep == 1.0
    assert scene.physics.friction == 0.5
    assert (scene.gripper.opening, scene.gripper.jaw_width) == (0.10, 0.01)
    return scene


def test_calibration_rectangle_has_the_documented_geometry():
    scene = load_calibration("rectangle")
    assert scene.shape.bounds == pytest.approx((-0.03, -0.015, 0.03, 0.015), abs=1e-15)
    assert scene.shape.area == pytest.approx(0.06 * 0.03, rel=1e-12)


def test_calibration_disk_has_the_documented_geometry():
    scene = load_calibration("disk")
    assert scene.shape.area == pytest.approx(polygon_area(DISK_SIDES, 0.03), rel=1e-12)
    assert scene.shape.centroid.coords[0] == pytest.approx((0.0, 0.0), abs=1e-15)


def test_rectangle_sdf_equals_the_closed_form_on_the_calibration_grid():
    scene = load_scene(REPO / "scenes" / "rectangle.toml")
    c = scene.grid.coords
    expected = np.clip(rectangle_sdf(c[None, :], c[:, None], 0.03, 0.015), -scene.truncation, scene.truncation)
    np.testing.assert_allclose(scene.true_sdf, expected, rtol=0, atol=1e-12)


def test_rectangle_sdf_is_negative_inside_and_indexed_row_y_column_x():
    scene = load_scene(REPO / "scenes" / "rectangle.toml")
    c = scene.grid.coords
    j, i = np.unravel_index(np.argmin(scene.true_sdf), scene.true_sdf.shape)
    # The deepest cells sit on the x axis, 0.015 m - h/2 from the long sides.
    assert abs(c[j]) == pytest.approx(H / 2, abs=1e-15)
    assert scene.true_sdf[j, i] == pytest.approx(-(0.015 - H / 2), abs=1e-12)
    # Row 20, column 26 is the point (0.0325, 0.0025): outside, 2.5 mm from the short side.
    assert scene.true_sdf[20, 26] == pytest.approx(0.0325 - 0.03, abs=1e-12)


def test_disk_sdf_lies_within_the_polygonisation_sagitta_of_the_closed_form():
    scene = load_scene(REPO / "scenes" / "disk.toml")
    c = scene.grid.coords
    exact = np.hypot(c[None, :], c[:, None]) - 0.03
    # The polygon lies inside the circle, so its SDF is larger by 0 to one sagitta.
    sagitta = 0.03 * (1 - math.cos(math.pi / DISK_SIDES))
    excess = scene.true_sdf - np.clip(exact, -scene.truncation, scene.truncation)
    assert excess.min() >= -1e-12
    assert excess.max() <= sagitta + 1e-12
    assert sagitta == pytest.approx(2.26e-6, rel=1e-2)


def test_true_sdf_is_truncated_at_the_default_three_cells(load):
    scene = load(DISK)
    assert scene.truncation == pytest.approx(3 * H, rel=1e-12)
    assert scene.true_sdf.max() == pytest.approx(3 * H, rel=1e-12)
    assert scene.true_sdf.min() == pytest.approx(-3 * H, rel=1e-12)


def test_true_sdf_is_truncated_at_the_given_truncation(load):
    scene = load(DISK, grid=GRID + 'truncation = "2 cells"\n')
    c = scene.grid.coords
    exact = np.hypot(c[None, :], c[:, None]) - 0.03
    assert scene.truncation == pytest.approx(2 * H, rel=1e-12)
    np.testing.assert_allclose(scene.true_sdf, np.clip(exact, -2 * H, 2 * H), rtol=0, atol=3e-6)
    assert np.abs(scene.true_sdf).max() == pytest.approx(2 * H, rel=1e-12)


# ---------------------------------------------------------------------------
# Shapes and their areas


def test_rectangle_area_is_width_times_height(load):
    scene = load('[shape]\ntype = "rectangle"\nwidth = 0.05\nheight = "4 cells"\n')
    assert scene.shape.area == pytest.approx(0.05 * 4 * H, rel=1e-12)


def test_rectangle_angle_turns_it_about_its_own_centre(load):
    scene = load("""
        [shape]
        type = "rectangle"
        width = 0.06
        height = 0.02
        center = [0.01, -0.02]
        angle = 0.5235987755982988
    """)
    half_x = 0.03 * math.cos(math.pi / 6) + 0.01 * math.sin(math.pi / 6)
    half_y = 0.03 * math.sin(math.pi / 6) + 0.01 * math.cos(math.pi / 6)
    expected = (0.01 - half_x, -0.02 - half_y, 0.01 + half_x, -0.02 + half_y)
    assert scene.shape.bounds == pytest.approx(expected, abs=1e-12)
    assert scene.shape.area == pytest.approx(0.06 * 0.02, rel=1e-12)


def test_rotate_turns_about_the_origin_and_offset_then_moves(load):
    scene = load("""
        [shape]
        type = "rectangle"
        width = 0.04
        height = 0.02
        center = [0.02, 0.0]
        rotate = 1.5707963267948966
        offset = [0.01, 0.01]
    """)
    # The centre (0.02, 0) turns to (0, 0.02), then moves to (0.01, 0.03); the width is now along y.
    assert scene.shape.bounds == pytest.approx((0.0, 0.01, 0.02, 0.05), abs=1e-12)


def test_polygon_with_holes_has_the_area_of_its_shell_less_its_holes(load):
    scene = load("""
        [shape]
        type = "polygon"
        exterior = [[-0.03, -0.03], [0.03, -0.03], [0.03, 0.03], [-0.03, 0.03]]
        holes = [[[-0.02, -0.02], [-0.01, -0.02], [-0.01, -0.01], [-0.02, -0.01]],
                 [[0.01, 0.0], [0.02, 0.0], [0.02, 0.02], [0.01, 0.02]]]
    """)
    assert scene.shape.area == pytest.approx(0.06**2 - 0.01**2 - 0.01 * 0.02, rel=1e-12)
    assert len(scene.shape.interiors) == 2


def test_disk_area_is_that_of_the_inscribed_256_gon(load):
    scene = load('[shape]\ntype = "disk"\nradius = "6 cells"\ncenter = [0.01, 0.0]\n')
    r = 6 * H
    assert scene.shape.area == pytest.approx(polygon_area(DISK_SIDES, r), rel=1e-12)
    assert scene.shape.area == pytest.approx(math.pi * r * r, rel=1.1e-4)
    assert scene.shape.centroid.coords[0] == pytest.approx((0.01, 0.0), abs=1e-12)


def test_ring_area_is_the_difference_of_two_256_gons(load):
    scene = load('[shape]\ntype = "ring"\nouter_radius = 0.04\ninner_radius = 0.025\n')
    expected = polygon_area(DISK_SIDES, 0.04) - polygon_area(DISK_SIDES, 0.025)
    assert scene.shape.area == pytest.approx(expected, rel=1e-12)
    assert scene.shape.area == pytest.approx(math.pi * (0.04**2 - 0.025**2), rel=1.1e-4)
    assert len(scene.shape.interiors) == 1


def test_capsule_area_is_a_rectangle_plus_a_128_gon(load):
    scene = load('[shape]\ntype = "capsule"\nstart = [-0.03, -0.01]\nend = [0.03, 0.02]\nradius = 0.01\n')
    length = math.hypot(0.06, 0.03)
    assert scene.shape.area == pytest.approx(2 * 0.01 * length + polygon_area(CAPSULE_SIDES, 0.01), rel=1e-12)
    # The round ends lose (2 pi / 128)^2 / 6 = 4.0e-4 of pi r^2.
    exact = 2 * 0.01 * length + math.pi * 0.01**2
    assert abs(scene.shape.area - exact) <= 4.1e-4 * math.pi * 0.01**2


def test_capsule_with_equal_ends_is_a_disk(load):
    scene = load('[shape]\ntype = "capsule"\nstart = [0.0, 0.0]\nend = [0.0, 0.0]\nradius = 0.02\n')
    assert scene.shape.area == pytest.approx(polygon_area(DISK_SIDES, 0.02), rel=1e-12)


def test_union_area_counts_the_overlap_once_and_removes_the_cutouts(load):
    scene = load("""
        [shape]
        type = "union"
        [[shape.parts]]
        type = "rectangle"
        width = 0.06
        height = 0.02
        [[shape.parts]]
        type = "rectangle"
        width = 0.02
        height = 0.06
        [[shape.cutouts]]
        type = "rectangle"
        width = 0.01
        height = 0.01
        [[shape.cutouts]]
        type = "rectangle"
        width = 0.01
        height = 0.01
        center = [0.025, 0.0]
    """)
    # Cross: 2 x 0.0012 less the 0.0004 overlap; cutouts: a 0.0001 hole in the middle and a
    # 0.0001 notch at the tip of the right arm (it reaches the arm's end, so it is no hole).
    assert scene.shape.area == pytest.approx(0.0012 + 0.0012 - 0.0004 - 0.0001 - 0.0001, rel=1e-12)
    assert len(scene.shape.interiors) == 1
    assert scene.shape.bounds == pytest.approx((-0.03, -0.03, 0.03, 0.03), abs=1e-15)


def test_union_parts_keep_their_own_rotate_and_offset(load):
    # The part is exactly two cells thick: the thinnest that the grid accepts.
    scene = load("""
        [shape]
        type = "union"
        offset = [0.0, 0.01]
        [[shape.parts]]
        type = "rectangle"
        width = 0.04
        height = 0.01
        rotate = 1.5707963267948966
        offset = [0.005, 0.0]
    """)
    assert scene.shape.bounds == pytest.approx((0.0, -0.01, 0.01, 0.03), abs=1e-12)


# ---------------------------------------------------------------------------
# Outlines from CSV files


def write_csv(path: Path, vertices, header: str = "x,y") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(header + "\n" + "".join(f"{x},{y}\n" for x, y in vertices), encoding="utf-8")
    return path


#: An L in CSV units: area 4, centroid (1.25, 0.75), bounding box [0, 3] x [0, 2].
L_SHAPE = [(0, 0), (3, 0), (3, 1), (1, 1), (1, 2), (0, 2)]


def outline_body(path: str, extra: str = "") -> str:
    return f'[shape]\ntype = "outline"\npath = "{path}"\nscale = 0.01\n{extra}'


def test_outline_area_is_the_csv_area_times_scale_squared(tmp_path, load):
    write_csv(tmp_path / "l.csv", L_SHAPE)
    scene = load(outline_body("l.csv"))
    assert scene.shape.area == pytest.approx(4 * 0.01**2, rel=1e-12)


def test_outline_is_centred_on_its_centroid_by_default(tmp_path, load):
    write_csv(tmp_path / "l.csv", L_SHAPE)
    scene = load(outline_body("l.csv"))
    assert scene.shape.centroid.coords[0] == pytest.approx((0.0, 0.0), abs=1e-15)
    # The centroid of the L, (1.25, 0.75) units, moves to the origin.
    assert scene.shape.bounds == pytest.approx((-0.0125, -0.0075, 0.0175, 0.0125), abs=1e-15)


def test_outline_bbox_centring_puts_the_bounding_box_centre_at_the_origin(tmp_path, load):
    write_csv(tmp_path / "l.csv", L_SHAPE)
    scene = load(outline_body("l.csv", 'center = "bbox"\n'))
    assert scene.shape.bounds == pytest.approx((-0.015, -0.01, 0.015, 0.01), abs=1e-15)


def test_outline_without_centring_keeps_the_csv_coordinates_times_scale(tmp_path, load):
    write_csv(tmp_path / "l.csv", [(x - 1, y - 1) for x, y in L_SHAPE])
    scene = load(outline_body("l.csv", 'center = "none"\n'))
    assert scene.shape.bounds == pytest.approx((-0.01, -0.01, 0.02, 0.01), abs=1e-15)


def test_outline_flip_y_mirrors_the_csv_before_centring(tmp_path, load):
    write_csv(tmp_path / "l.csv", [(x - 1, y - 1) for x, y in L_SHAPE])
    flipped = load(outline_body("l.csv", 'center = "none"\nflip_y = true\n'))
    assert flipped.shape.bounds == pytest.approx((-0.01, -0.01, 0.02, 0.01), abs=1e-15)
    # The L's foot (the row y = -1..0 spanning x = -1..2) is now on top: y = 0..1.
    assert flipped.shape.contains(Point(0.015, 0.005))
    assert not flipped.shape.contains(Point(0.015, -0.005))
    centred = load(outline_body("l.csv", "flip_y = true\n"))
    assert centred.shape.centroid.coords[0] == pytest.approx((0.0, 0.0), abs=1e-15)
    # Flipped first, the centroid is at (1.25, -0.75) units when it moves to the origin.
    assert centred.shape.bounds == pytest.approx((-0.0125, -0.0125, 0.0175, 0.0075), abs=1e-15)


def test_outline_path_is_relative_to_the_scene_file_not_the_working_directory(tmp_path, monkeypatch, write_scene):
    write_csv(tmp_path / "outlines" / "square.csv", [(0, 0), (2, 0), (2, 2), (0, 2)], header=" X , Y ")
    scene_path = write_scene(outline_body("../outlines/square.csv"), name="scenes/square.toml")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    scene = load_scene(scene_path)
    assert scene.shape.area == pytest.approx(4e-4, rel=1e-12)


def test_outline_with_a_byte_order_mark_loads(tmp_path, load):
    (tmp_path / "bom.csv").write_bytes(b"\xef\xbb\xbfx,y\r\n0,0\r\n2,0\r\n2,2\r\n0,2\r\n\r\n")
    assert load(outline_body("bom.csv")).shape.area == pytest.approx(4e-4, rel=1e-12)


@pytest.mark.parametrize("csv_path", OBJECT_CSVS or [None],
                         ids=[p.stem for p in OBJECT_CSVS] or ["no-shared-objects"])
def test_every_shared_object_outline_loads_with_its_shoelace_area(csv_path, tmp_path):
    if csv_path is None:
        pytest.skip(f"no shared object outlines: {SHARED_OBJECTS} does not exist beside the repository")
    vertices = np.loadtxt(csv_path, delimiter=",", skiprows=1, ndmin=2)
    scale = 0.01  # about 1 cm per cell of the 25 x 25 tracing grid (see its README)
    path = tmp_path / "object.toml"
    path.write_text(textwrap.dedent(f"""\
        [grid]
        size = 80
        extent = 0.4
        [shape]
        type = "outline"
        path = "{csv_path.resolve().as_posix()}"
        scale = {scale}
    """), encoding="utf-8")
    scene = load_scene(path)
    assert scene.shape.area == pytest.approx(shoelace_area(vertices) * scale**2, rel=1e-12)
    assert scene.shape.centroid.coords[0] == pytest.approx((0.0, 0.0), abs=1e-12)


# ---------------------------------------------------------------------------
# Random shapes


def random_body(seed: int, extra: str = "") -> str:
    return f'[shape]\ntype = "random"\nseed = {seed}\nradius = 0.03\n{extra}'


def test_random_shape_is_the_same_for_the_same_seed(load):
    a, b = load(random_body(11), name="a.toml"), load(random_body(11), name="b.toml")
    assert a.shape.equals_exact(b.shape, 0.0)


def test_random_shapes_of_different_seeds_differ(load):
    a, b = load(random_body(11), name="a.toml"), load(random_body(12), name="b.toml")
    assert a.shape.symmetric_difference(b.shape).area > 0.05 * a.shape.area


def test_random_shape_does_not_depend_on_the_grid_size(load):
    coarse = load(random_body(5), name="coarse.toml")
    fine = load(random_body(5), name="fine.toml", grid="[grid]\nsize = 97\nextent = 0.2\n")
    assert coarse.shape.equals_exact(fine.shape, 0.0)


def test_random_shape_of_zero_amplitude_is_the_disk_of_its_radius(load):
    scene = load(random_body(0, "amplitude = 0.0\n"))
    # Marching squares on a lattice of R/64 and simplification by R/256 lose < 1% of the area.
    assert scene.shape.area == pytest.approx(math.pi * 0.03**2, rel=1e-2)
    assert scene.shape.centroid.coords[0] == pytest.approx((0.0, 0.0), abs=1e-4 * 0.03)


def test_random_shapes_keep_the_size_of_their_radius_for_every_seed(load):
    # xi has zero mean, so |x|^2/R^2 - 1 + 0.5 xi < 0 stays near the disk of radius R:
    # with the lengthscale at its largest still-typical value R, 20 seeds all give an
    # area within [0.5, 1.6] pi R^2 (measured: 0.65 to 1.30).
    ratios = [load(random_body(seed, "lengthscale = 0.03\n"), name=f"r{seed}.toml").shape.area / (math.pi * 0.03**2)
              for seed in range(20)]
    assert 0.5 <= min(ratios) and max(ratios) <= 1.6
    assert 0.85 <= float(np.median(ratios)) <= 1.2


# ---------------------------------------------------------------------------
# Quantities and defaults


@pytest.mark.parametrize("text, metres", [
    ('"2 cells"', 2 * H), ('"1 cell"', H), ('"5 mm"', 0.005), ('"5mm"', 0.005), ('"0.5 cm"', 0.005),
    ('"0.004 m"', 0.004), ('"1e-3 m"', 0.001), ('" 3 cells "', 3 * H), ("0.007", 0.007), ("1", 1.0),
])
def test_length_quantities_convert_to_metres(load, text, metres):
    scene = load(DISK + f"[sensor]\nnoise = {text}\n")
    assert scene.sensor.noise == pytest.approx(metres, rel=1e-12)


@pytest.mark.parametrize("text, square_metres", [
    ('"4 cells^2"', 4 * H**2), ('"25 mm^2"', 25e-6), ('"1 cm^2"', 1e-4), ("0.0002", 2e-4),
])
def test_area_quantities_convert_to_square_metres(load, text, square_metres):
    scene = load(DISK + f"[gpis]\nscale = {text}\n")
    assert scene.gpis.scale == pytest.approx(square_metres, rel=1e-12)


def test_negative_quantities_are_read_where_the_range_allows(load):
    scene = load(DISK + '[gpis]\nprior_mean = "-0.5 cells"\n')
    assert scene.gpis.prior_mean == pytest.approx(-0.5 * H, rel=1e-12)


def test_omitted_fields_take_their_documented_defaults(load):
    scene = load(DISK, name="minimal.toml")
    assert scene.name == "minimal" and scene.description == ""
    s, g, p, gr = scene.sensor, scene.gpis, scene.physics, scene.gripper
    assert (s.noise, s.surface_band, s.interior_depth, s.interior_keep) == pytest.approx(
        (0.5 * H, 1.5 * H, 2 * H, 1.0), rel=1e-12)
    assert s.regions == ()
    assert (g.lengthscale, g.scale, g.prior_mean) == pytest.approx((2.7 * H, 4 * H**2, -H), rel=1e-12)
    assert (g.hyperparameters, g.use_gradients, g.active_set) == ("fixed", True, True)
    assert (g.active_band, g.active_spacing) == pytest.approx((2.5 * H, 2.7 * H), rel=1e-12)
    assert (p.thickness, p.density, p.friction) == (0.03, 400.0, 0.5)
    assert (gr.opening, gr.jaw_width) == (0.10, 0.01)


def test_region_parameters_take_their_documented_defaults(load):
    scene = load(DISK + """
        [[sensor.regions]]
        kind = "transparent"
        half_plane = { normal = [1, 0] }
        [[sensor.regions]]
        kind = "specular"
        half_plane = { normal = [0, 1], offset = "-2 cells" }
    """)
    transparent, specular = scene.sensor.regions
    assert (transparent.value, transparent.noise) == pytest.approx((0.5 * H, math.sqrt(3) * H), rel=1e-12)
    assert (specular.noise, specular.drop_probability) == pytest.approx((2 * H, 0.5), rel=1e-12)
    # The half plane y >= -2 cells: contains (0, -0.009), not (0, -0.011).
    assert specular.geometry.contains(Point(0.0, -0.009))
    assert not specular.geometry.contains(Point(0.0, -0.011))


# ---------------------------------------------------------------------------
# The sensor


#: A large disk on a fine grid (h = 2.5 mm) gives thousands of cells for the statistics.
BIG_DISK_GRID = "[grid]\nsize = 80\nextent = 0.2\n"
BIG_DISK = '[shape]\ntype = "disk"\nradius = 0.06\n'


def read(scene, seed: int):
    return observe(scene.sensor, scene.grid, scene.true_sdf, np.random.default_rng(seed))


def test_observations_are_the_same_for_the_same_generator(load):
    scene = load(DISK + '[sensor]\ninterior_keep = 0.5\n[[sensor.regions]]\nkind = "specular"\n'
                 "half_plane = { normal = [1, 1] }\n")
    a, b, c = read(scene, 3), read(scene, 3), read(scene, 4)
    for field in ("points", "values", "noise_var", "gradients", "gradient_noise_var", "cells", "kind"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert not (len(a) == len(c) and np.array_equal(a.values, c.values))


def test_fully_observed_scene_reads_every_cell_with_the_base_noise(load):
    scene = load(DISK + "[sensor]\nnoise = 0.0005\n")
    obs = read(scene, 0)
    assert len(obs) == 40 * 40
    np.testing.assert_allclose(obs.noise_var, 0.0005**2, rtol=1e-12)
    residual = obs.values - scene.true_sdf.ravel()
    # 1600 normal draws of std 0.5 mm: mean within 4 sigma / sqrt(n), std within 10%.
    assert abs(residual.mean()) <= 4 * 0.0005 / 40
    assert residual.std() == pytest.approx(0.0005, rel=0.1)
    np.testing.assert_array_equal(obs.cells[:, 0] + 40 * obs.cells[:, 1], np.arange(1600))
    np.testing.assert_allclose(obs.points, scene.grid.points[obs.cells[:, 0] + 40 * obs.cells[:, 1]])


def test_occluded_cells_are_absent_and_occlusion_beats_transparency(load):
    scene = load(DISK + """
        [[sensor.regions]]
        kind = "occluded"
        half_plane = { normal = [1, 0] }
        [[sensor.regions]]
        kind = "transparent"
        shape = { type = "rectangle", width = 0.2, height = 0.04 }
    """)
    obs = read(scene, 1)
    assert np.all(obs.points[:, 0] < 0)
    assert len(obs) == 40 * 20  # every cell with x < 0, and no cell with x > 0
    assert np.any(obs.kind == TRANSPARENT)


def test_transparency_beats_specularity_where_their_regions_overlap(load):
    """A surface cell in both a specular and a transparent region that the sensor keeps is
    misread as transparent (its kind and noise), not as specular; specular cells outside
    the transparent region keep their own kind and noise (base^2 + U (2 cells)^2)."""
    scene = load(BIG_DISK + """
        [[sensor.regions]]
        kind = "specular"
        drop_probability = 0.5
        noise = "2 cells"
        half_plane = { normal = [0, 1] }
        [[sensor.regions]]
        kind = "transparent"
        value = "0.5 cells"
        noise = "1 cells"
        half_plane = { normal = [1, 0] }
    """, grid=BIG_DISK_GRID)
    obs = read(scene, 6)
    h = 0.2 / 80
    f = scene.true_sdf.ravel()[obs.cells[:, 0] + 80 * obs.cells[:, 1]]
    x, y = obs.points[:, 0], obs.points[:, 1]
    surface = np.abs(f) < scene.sensor.surface_band
    both, specular = surface & (x > 0) & (y > 0), surface & (x < 0) & (y > 0)
    assert both.sum() > 20 and specular.sum() > 20
    assert np.all(obs.kind[both] == TRANSPARENT)
    np.testing.assert_allclose(obs.noise_var[both], h ** 2, rtol=1e-12)
    assert np.all(obs.kind[specular] == SPECULAR)
    base = scene.sensor.noise ** 2
    assert np.all((obs.noise_var[specular] >= base) & (obs.noise_var[specular] <= base + (2 * h) ** 2))


def test_interior_cells_are_kept_with_the_interior_keep_probability(load):
    scene = load(BIG_DISK + "[sensor]\ninterior_keep = 0.3\n", grid=BIG_DISK_GRID)
    deep = scene.true_sdf.ravel() < -scene.sensor.interior_depth
    n = int(deep.sum())
    assert n > 1400  # about pi (0.055 m)^2 / (2.5 mm)^2 = 1520 cells
    obs = read(scene, 2)
    kept = int(np.sum(obs.kind == INTERIOR))
    assert kept == int(deep[obs.cells[:, 0] + 80 * obs.cells[:, 1]].sum())
    assert len(obs) == 80 * 80 - n + kept  # every other cell is observed
    assert abs(kept / n - 0.3) <= 4 * math.sqrt(0.3 * 0.7 / n)


def test_transparent_cells_read_the_given_value_on_average(load):
    region = """
        [[sensor.regions]]
        kind = "transparent"
        value = "0.5 cells"
        noise = "2 cells"
        half_plane = { normal = [1, 0] }
    """
    h = 0.2 / 80
    for depth, minimum in ((None, 150), ("10 cm", 1000)):
        scene = load(BIG_DISK + region + (f'depth = "{depth}"\n' if depth else ""), grid=BIG_DISK_GRID)
        obs = read(scene, 5)
        hit = obs.kind == TRANSPARENT
        f = scene.true_sdf.ravel()[obs.cells[:, 0] + 80 * obs.cells[:, 1]]
        # Misread: inside the region, below the surface band and above -depth (by
        # default depth = surface band, so only the surface, as in the original).
        floor = -scene.sensor.surface_band if depth is None else -0.1
        np.testing.assert_array_equal(hit, (obs.points[:, 0] > 0) & (f < scene.sensor.surface_band) & (f > floor))
        n = int(hit.sum())
        assert n > minimum
        assert abs(obs.values[hit].mean() - 0.5 * h) <= 4 * 2 * h / math.sqrt(n)
        np.testing.assert_allclose(obs.noise_var[hit], (2 * h) ** 2, rtol=1e-12)


def test_specular_surface_cells_are_dropped_with_the_drop_probability(load):
    scene = load(BIG_DISK + """
        [[sensor.regions]]
        kind = "specular"
        drop_probability = 0.4
        noise = "2 cells"
        shape = { type = "rectangle", width = 0.3, height = 0.3 }
    """, grid=BIG_DISK_GRID)
    h, base = 0.2 / 80, scene.sensor.noise
    surface = np.abs(scene.true_sdf.ravel()) < scene.sensor.surface_band
    n_surface = int(surface.sum())
    kept, spread = 0, []
    for seed in range(10):
        obs = read(scene, seed)
        specular = obs.kind == SPECULAR
        kept += int(specular.sum())
        assert len(obs) == 80 * 80 - n_surface + int(specular.sum())
        spread.append((obs.noise_var[specular] - base**2) / (2 * h) ** 2)
    n = 10 * n_surface
    assert abs((1 - kept / n) - 0.4) <= 4 * math.sqrt(0.4 * 0.6 / n)
    u = np.concatenate(spread)  # U(0, 1): variance base^2 + U noise^2
    assert u.min() >= 0.0 and u.max() <= 1.0
    assert abs(u.mean() - 0.5) <= 4 * math.sqrt(1 / 12 / len(u))


def test_central_differences_of_a_linear_field_equal_its_slope():
    grid = Grid(20, 0.2)
    slope = np.array([0.3, -0.7])
    truth = (grid.points @ slope + 0.01).reshape(20, 20)
    sensor = SensorModel(noise=1e-12, surface_band=1e-12, interior_depth=100.0)
    obs = observe(sensor, grid, truth, np.random.default_rng(0))
    border = (obs.cells == 0).any(axis=1) | (obs.cells == 19).any(axis=1)
    assert np.isnan(obs.gradients[border]).all() and border.sum() == 4 * 20 - 4
    np.testing.assert_allclose(obs.gradients[~border], np.broadcast_to(slope, (18 * 18, 2)), rtol=0, atol=1e-9)
    # Each component is (v+ - v-) / 2h: variance 2 sigma^2 / (4 h^2).
    np.testing.assert_allclose(obs.gradient_noise_var[~border], 1e-24 / (2 * 0.01**2), rtol=1e-12)


def test_gradients_are_missing_next_to_an_unobserved_cell(load):
    # A small occluded square around the single cell centre (0.0025, 0.0025): column 20, row 20.
    scene = load(DISK + '[[sensor.regions]]\nkind = "occluded"\n'
                 "shape = { type = \"rectangle\", width = 0.002, height = 0.002, center = [0.0025, 0.0025] }\n")
    obs = read(scene, 0)
    assert len(obs) == 40 * 40 - 1
    missing = {tuple(c) for c in obs.cells[np.isnan(obs.gradients).any(axis=1)]}
    inner = {c for c in missing if 0 < c[0] < 39 and 0 < c[1] < 39}
    assert inner == {(19, 20), (21, 20), (20, 19), (20, 21)}


# ---------------------------------------------------------------------------
# Validation: exit code 2 and one line naming the file and the field


BOWTIE = '[shape]\ntype = "polygon"\nexterior = [[-0.02, -0.02], [0.02, 0.02], [0.02, -0.02], [-0.02, 0.02]]\n'

INVALID = {
    "missing grid size": ("[grid]\nextent = 0.2\n" + DISK, "grid.size", "missing"),
    "missing shape": (GRID, "shape", "missing"),
    "missing shape field": (GRID + '[shape]\ntype = "rectangle"\nwidth = 0.02\n', "shape.height", "missing"),
    "grid size not an integer": ('[grid]\nsize = "40"\nextent = 0.2\n' + DISK, "grid.size",
                                 "expected an integer, got a string"),
    "grid size a float": ("[grid]\nsize = 40.0\nextent = 0.2\n" + DISK, "grid.size",
                          "expected an integer, got a number"),
    "boolean for a number": (GRID + DISK + "[physics]\nfriction = true\n", "physics.friction",
                             "expected a number, got a boolean"),
    "table for a length": (GRID + DISK + "[sensor]\nnoise = { a = 1 }\n", "sensor.noise",
                           "expected a number or a quantity like '2 cells', got a table"),
    "number for a flag": (GRID + DISK + "[gpis]\nuse_gradients = 1\n", "gpis.use_gradients",
                          "expected true or false, got an integer"),
    "grid size too small": ("[grid]\nsize = 7\nextent = 0.2\n" + DISK, "grid.size", "7 is out of range [8, 1024]"),
    "negative friction": (GRID + DISK + "[physics]\nfriction = -0.1\n", "physics.friction",
                          "-0.1 is out of range [0, 10]"),
    "zero noise": (GRID + DISK + "[sensor]\nnoise = 0\n", "sensor.noise", "0 m is out of range [5e-05, 100]"),
    "noise far below a cell": (GRID + DISK + "[sensor]\nnoise = \"0.001 cells\"\n", "sensor.noise",
                               "5e-06 m is out of range [5e-05, 100]"),
    "occluded everywhere": (GRID + DISK + "[[sensor.regions]]\nkind = \"occluded\"\n"
                            "half_plane = { normal = [0, 1], offset = -100 }\n", "sensor.regions",
                            "the occluded regions cover every cell of the grid"),
    "jaws that barely close": (GRID + DISK + "[gripper]\nclosing_speed = 1e-6\n", "gripper.closing_speed",
                               "1e-06 is out of range [0.001, 10]"),
    "length scale far below a cell": (GRID + DISK + "[gpis]\nlengthscale = 1e-9\n", "gpis.lengthscale",
                                      "1e-09 m is out of range [0.0005, 100]"),
    "the pooled rows' name": ('name = "all"\n' + GRID + DISK, "name", "scene name 'all' is the tables' name"),
    "nan extent": ("[grid]\nsize = 40\nextent = nan\n" + DISK, "grid.extent", "must be finite, got nan"),
    "integer too large for a float": (GRID + DISK + "[physics]\ndensity = 1" + "0" * 400 + "\n",
                                      "physics.density", "must be finite, got inf"),
    "point too far": (GRID + DISK + "center = [1e9, 0]\n", "shape.center", "within 100 m of the origin"),
    "truncation of one cell": ('[grid]\nsize = 40\nextent = 0.2\ntruncation = "1 cell"\n' + DISK,
                               "grid.truncation", "0.005 m is out of range (0.005, 100]"),
    "interior keep above one": (GRID + DISK + "[sensor]\ninterior_keep = 1.5\n", "sensor.interior_keep",
                                "1.5 is out of range [0, 1]"),
    "unknown top-level field": ("colour = 'red'\n" + GRID + DISK, "colour", "unknown field"),
    "unknown nested field": (GRID + DISK + "[gripper]\nfingers = 3\n", "gripper.fingers", "unknown field"),
    "field of another shape type": (GRID + DISK + "width = 0.02\n", "shape.width", "unknown field"),
    "unknown key with a newline": (GRID + DISK + '"a\\nb" = 1\n', 'shape."a\\nb"', "unknown field"),
    "unknown shape type": (GRID + '[shape]\ntype = "circle"\nradius = 0.03\n', "shape.type",
                           "'circle' is not one of polygon, outline, rectangle, disk, ring, capsule, union, random"),
    "self-intersecting polygon": (GRID + BOWTIE, "shape.exterior", "invalid polygon: self-intersection at (0, 0)"),
    "hole outside its shell": (GRID + '[shape]\ntype = "polygon"\n'
                               "exterior = [[0, 0], [0.02, 0], [0.02, 0.02], [0, 0.02]]\n"
                               "holes = [[[0.03, 0.03], [0.04, 0.03], [0.04, 0.04]]]\n",
                               "shape.exterior", "invalid polygon: hole lies outside shell"),
    "polygon of two points": (GRID + '[shape]\ntype = "polygon"\nexterior = [[0, 0], [0.02, 0]]\n',
                              "shape.exterior", "a polygon needs at least 3 points, got 2"),
    "ring inside out": (GRID + '[shape]\ntype = "ring"\nouter_radius = 0.02\ninner_radius = 0.03\n',
                        "shape.inner_radius", "must be smaller than outer_radius"),
    "empty union": (GRID + '[shape]\ntype = "union"\nparts = [{ type = "disk", radius = 0.02 }]\n'
                    'cutouts = [{ type = "disk", radius = 0.03 }]\n', "shape", "shape is empty (zero area)"),
    "disconnected shape": (GRID + '[shape]\ntype = "union"\n'
                           'parts = [{ type = "disk", radius = 0.01, center = [-0.03, 0] },'
                           ' { type = "disk", radius = 0.01, center = [0.03, 0] }]\n',
                           "shape", "shape has 2 disconnected parts; an object must be one piece"),
    "shape outside the grid": (GRID + DISK + "center = [0.07, 0]\n", "shape",
                               "shape outside the grid: it reaches 0.1 m from the centre, the grid allows 0.09 m"),
    "grid too coarse": (GRID + '[shape]\ntype = "rectangle"\nwidth = 0.06\nheight = 0.008\n', "grid.size",
                        "grid too coarse for the shape: its thickest part is 1.60 cells across, needs at least 2"),
    "unknown unit": (GRID + DISK + '[sensor]\nnoise = "3 parsecs"\n', "sensor.noise",
                     "cannot read quantity '3 parsecs' (units: cells, m, cm, mm)"),
    "unit without a number": (GRID + DISK + '[sensor]\nnoise = "cells"\n', "sensor.noise", "cannot read quantity"),
    "length where an area is expected": (GRID + DISK + '[gpis]\nscale = "4 cells"\n', "gpis.scale",
                                         "squared, e.g. '4 cells^2'"),
    "unknown choice": (GRID + DISK + '[gpis]\nhyperparameters = "ML"\n', "gpis.hyperparameters",
                       "'ML' is not one of fixed, ml"),
    "region with shape and half plane": (GRID + DISK + '[[sensor.regions]]\nkind = "occluded"\n'
                                         'half_plane = { normal = [1, 0] }\nshape = { type = "disk", radius = 0.01 }\n',
                                         "sensor.regions[0]", "give exactly one of 'shape' or 'half_plane'"),
    "region without geometry": (GRID + DISK + '[[sensor.regions]]\nkind = "specular"\n',
                                "sensor.regions[0]", "give exactly one of 'shape' or 'half_plane'"),
    "zero normal": (GRID + DISK + '[[sensor.regions]]\nkind = "occluded"\nhalf_plane = { normal = [0, 0] }\n',
                    "sensor.regions[0].half_plane.normal", "must not be the zero vector"),
    "parameter of another region kind": (GRID + DISK + '[[sensor.regions]]\nkind = "occluded"\nvalue = 0.01\n'
                                         'half_plane = { normal = [1, 0] }\n', "sensor.regions[0].value",
                                         "unknown field"),
    "random lengthscale beyond twice the radius": (GRID + '[shape]\ntype = "random"\nseed = 1\nradius = 0.02\n'
                                                   "lengthscale = 0.05\n", "shape.lengthscale",
                                                   "0.05 m is out of range (0, 0.04]"),
    "random seed negative": (GRID + '[shape]\ntype = "random"\nseed = -1\nradius = 0.02\n', "shape.seed",
                             "out of range [0, 9223372036854775807]"),
    "outline missing": (GRID + outline_body("nowhere.csv"), "shape.path", "cannot read: No such file"),
    "outline path with a NUL": (GRID + outline_body("a\\u0000b.csv"), "shape.path",
                                "must not contain a NUL character"),
}


@pytest.mark.parametrize("case", sorted(INVALID))
def test_invalid_scene_exits_2_with_one_line_naming_file_and_field(case, tmp_path, check):
    text, field, message = INVALID[case]
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    code, out, err = check(path)
    assert code == 2
    assert out == ""
    assert len(err) == 1
    assert err[0].startswith(f"gpis-harness: error: {path}: {field}: ")
    assert message in err[0]


@pytest.mark.parametrize("csv_text, message", [
    ("a,b\n0,0\n1,0\n0,1\n", "first line must be the header 'x,y'"),
    ("", "first line must be the header 'x,y'"),
    ("x,y\n0,0\n1,zero\n0,1\n", "line 3: expected two finite numbers"),
    ("x,y\n0,0\n1,0,2\n0,1\n", "line 3: expected two finite numbers"),
    ("x,y\n0,0\nnan,0\n0,1\n", "line 3: expected two finite numbers"),
    ("x,y\n0,0\n1,0\n", "needs at least 3 vertices, has 2"),
    ("x,y\n0,0\n2,2\n2,0\n0,2\n", "invalid polygon: self-intersection at (0.01, 0.01)"),
    ("x,y\n0,0\n1e300,0\n0,1e300\n", "coordinates times scale must be within 100 m of the origin"),
    ("x,y\n" + "1" * 200_000 + ",0\n0,1\n1,1\n", "field larger than field limit"),
])
def test_bad_outline_csv_is_reported_on_the_path_field(tmp_path, check, csv_text, message):
    (tmp_path / "o.csv").write_text(csv_text, encoding="utf-8")
    path = tmp_path / "bad.toml"
    path.write_text(GRID + outline_body("o.csv"), encoding="utf-8")
    code, _, err = check(path)
    assert code == 2 and len(err) == 1
    assert err[0].startswith(f"gpis-harness: error: {path}: shape.path: ")
    assert message in err[0]


def test_outline_csv_that_is_not_utf8_is_reported_on_the_path_field(tmp_path, check):
    (tmp_path / "o.csv").write_bytes(b"x,y\n0,0\n\xff\xfe,0\n0,1\n")
    path = tmp_path / "bad.toml"
    path.write_text(GRID + outline_body("o.csv"), encoding="utf-8")
    code, _, err = check(path)
    assert code == 2 and len(err) == 1
    outline = tmp_path / "o.csv"
    assert err[0] == f"gpis-harness: error: {path}: shape.path: outline {outline}: not a text file (invalid UTF-8)"


@pytest.mark.parametrize("content, message", [
    (b"[grid\nsize = 40\n", "invalid TOML: "),
    (b"[grid]\nsize = 40\nsize = 41\n", "invalid TOML: "),
    (b"\xff\xfe[grid]\n", "not a text file (invalid UTF-8)"),
    (b"a = " + b"[" * 5000 + b"]" * 5000 + b"\n", "invalid TOML: arrays or inline tables nested too deeply"),
])
def test_file_that_is_not_toml_is_reported_without_a_field(tmp_path, check, content, message):
    path = tmp_path / "bad.toml"
    path.write_bytes(content)
    code, _, err = check(path)
    assert code == 2 and len(err) == 1
    assert err[0].startswith(f"gpis-harness: error: {path}: {message}")


def test_missing_scene_file_is_reported(tmp_path, check):
    path = tmp_path / "absent.toml"
    code, _, err = check(path)
    assert (code, err) == (2, [f"gpis-harness: error: {path}: no such scene file"])


def test_valid_scene_checks_ok_with_exit_0(write_scene, check):
    path = write_scene(DISK)
    code, out, err = check(path)
    assert (code, err) == (0, [])
    assert out == f"{path}: ok (scene, grid 40 x 40)\n"
