"""The lift model against the physics (``gpis-harness bench lift``): bars gripped across
their width at growing offsets from their centre of mass, where the analytic P_L and the
simulated success fall through 0.5; hang bars, which the weight turns in the plates, at
growing lengths, where success falls as their hang nears the lifted table (and heads
with a handle: a disk, wedges, regular polygons gripped on their vertices or faces); the
calibration rectangle's bar gripped through its centre at 0-90 degrees to its length,
where the plates squeeze it flush (SqueezeCase); the same bar with a V-notch in one end,
whose walls a plate meets with its corners (NotchCase); two loads the model leaves out, at
falling grip forces (LoadCase); and the friction levers Bullet's contact manifolds give
the jaw plates on the library's trial set.

A bar is a fully observed rectangle (its true shape: no shape uncertainty), so the
offset is the only thing that changes along a sweep. Trials and the analytic estimate
use the same approach-noise deviates; the analytic estimate adds pressure deviates (the
lift model's lever draws, harness.lift) and more draws than the trials, so its curve is
smooth.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from harness.grasp import SDFBatch
from harness.lift import clearance, patch_height
from harness.physics.simulate import make_trials, truth_polygon
from harness.physics.engines import make_runner
from harness.protocol import Protocol
from harness.quality import EvaluationDraws, evaluate_draws
from harness.scene import Scene, parse_scene
from harness.seeding import stream
from harness.settings import GRAVITY, resolve

#: Approach noise of the sweeps (m): small, so that the offset is what varies.
SIGMA_G = 0.001
#: Offsets are this far apart (m).
STEP = 0.005
#: Analytic draws per offset (the first ``trials`` are the trials' own).
ANALYTIC_DRAWS = 400
#: The jaws start this far outside the bar's faces (m).
CLEARANCE = 0.01
#: A trial whose object turned in the gripper by more than this (rad) turned.
TURNED = 0.3


@dataclass(frozen=True)
class Bar:
    """A bar (m, kg/m^3, N) lying along x, gripped across its width by jaws whose line of
    action crosses the bar at an offset from its centre."""

    length: float
    density: float
    friction: float
    force: float
    width: float = 0.03
    thickness: float = 0.03

    @property
    def label(self) -> str:
        return (f"{self.length * 100:g} x {self.width * 100:g} x {self.thickness * 100:g} cm, "
                f"{self.density:g} kg/m^3, mu {self.friction:g}, {self.force:g} N")

    @property
    def mass(self) -> float:
        return self.density * self.length * self.width * self.thickness

    def scene(self, cells: int = 40, extent: float = 0.2) -> Scene:
        shape = {"type": "rectangle", "width": self.length, "height": self.width, "center": [0.0, 0.0]}
        return _solid("bar", shape, self.thickness, self.density, self.friction, self.force, f"<bar {self.label}>",
                      cells=cells, extent=extent)

    def offsets(self) -> np.ndarray:
        """From the centre to 5 mm short of the bar's end."""
        return np.arange(0.0, 0.5 * self.length - STEP + 1e-9, STEP)

    def grasp(self, offset: float) -> np.ndarray:
        half = 0.5 * self.width + CLEARANCE
        return np.array([[offset, -half], [offset, half]])


def _solid(name: str, shape: dict, thickness: float, density: float, friction: float, force: float,
           source: str, cells: int = 40, extent: float = 0.2) -> Scene:
    """A fully observed test object (a scene of ``shape``) on a grid of ``cells`` cells
    over ``extent`` (20 cm: 5 mm cells by default), with the built-in parallel jaw (10 cm
    opening, 1 cm plates) at ``force``."""
    data = {"name": name, "grid": {"size": cells, "extent": extent}, "shape": shape, "sensor": {"noise": 0.0005},
            "physics": {"thickness": thickness, "density": density, "friction": friction},
            "gripper": {"opening": 0.1, "jaw_width": 0.01, "force": force}}
    return parse_scene(data, source, Path("."))


#: The validation rows: lengths, densities, frictions, grip forces, thicknesses and
#: widths chosen so that each bar stops being lifted within its length (a bar short and
#: light enough to hang clear of the table at every offset tells nothing).
BARS = (
    Bar(0.18, 1000.0, 0.5, 8.0),
    Bar(0.18, 2000.0, 0.5, 20.0),
    Bar(0.18, 700.0, 0.4, 6.0, thickness=0.02),
    Bar(0.16, 3000.0, 0.8, 10.0),
    Bar(0.16, 1500.0, 0.4, 12.0, width=0.04),
    Bar(0.14, 2500.0, 0.5, 20.0, thickness=0.05),
    Bar(0.14, 4000.0, 0.6, 12.0),
    Bar(0.12, 6000.0, 0.5, 10.0),
)


@dataclass(frozen=True)
class SlideCase:
    """A ring gripped on its rim (one jaw in its hole, one outside) or a disk gripped
    across, the jaws' line of action at a growing offset from the centre: beyond the
    plates' half-width the plates meet the walls by their edges, and the walls' pushes
    slide the object across the closing line (harness.squeeze): the ring towards its
    radial line, into force closure, the disk away from the plates, out of the jaws."""

    kind: str  # "ring" or "disk"
    friction: float = 0.2
    force: float = 20.0
    radius: float = 0.04
    hole: float = 0.025
    thickness: float = 0.03
    density: float = 1000.0

    @property
    def label(self) -> str:
        what = (f"ring {self.radius * 200:g} / {self.hole * 200:g} cm, a jaw in the hole" if self.kind == "ring"
                else f"disk {self.radius * 200:g} cm")
        return f"{what}, mu {self.friction:g}, {self.force:g} N"

    @property
    def mass(self) -> float:
        inner = self.hole if self.kind == "ring" else 0.0
        return self.density * self.thickness * math.pi * (self.radius**2 - inner**2)

    def scene(self) -> Scene:
        shape = ({"type": "ring", "outer_radius": self.radius, "inner_radius": self.hole} if self.kind == "ring"
                 else {"type": "disk", "radius": self.radius})
        return _solid(self.kind, shape, self.thickness, self.density, self.friction, self.force,
                      f"<{self.kind} {self.label}>", cells=80)

    def offsets(self) -> np.ndarray:
        """From the centre line to 24 mm off it, every 2 mm."""
        return np.arange(0.0, 0.0241, 0.002)

    def grasp(self, offset: float) -> np.ndarray:
        if self.kind == "ring":  # from below the rim to the middle of the hole's lower half
            return np.array([[offset, -self.radius - CLEARANCE], [offset, -0.5 * self.hole]])
        return np.array([[offset, -self.radius - CLEARANCE], [offset, self.radius + CLEARANCE]])


#: The slide's controlled cases: 3 cm thick, 1000 kg/m^3, mu 0.2 (a friction cone of 11
#: degrees), 20 N; and the ring on slippery jaws, mu 0.1 (5.7 degrees), which no grasp of
#: its rim near the radial line holds in force closure: the walls slide it to where their
#: pushes cancel, and hold it there.
SLIDES = (SlideCase("ring"), SlideCase("disk", radius=0.03), SlideCase("ring", friction=0.1))


@dataclass(frozen=True)
class PushCase:
    """The push's controlled case (docs/lift.md, "The push"): a bar 8 cm x 6 mm x 2.4 cm
    gripped across its width along a line ``alpha`` (degrees) off its wall's normal
    through a point ``offset`` (m) from its middle, the gripper's centre moved by a
    distance D along the closing line, so that the nearer plate pushes the bar about D
    across the table before the other arrives (harness.push). The sweep's 'offset' is D."""

    alpha: float
    offset: float
    bar: Bar

    @property
    def label(self) -> str:
        return (f"bar {self.bar.length * 100:g} x {self.bar.width * 1000:g} mm, {self.mass * 1000:.1f} g, "
                f"{self.alpha:g} deg, {self.offset * 1000:g} mm off the middle")

    @property
    def mass(self) -> float:
        return self.bar.mass

    def scene(self) -> Scene:
        """On 1 mm cells: the bar is 6 mm wide."""
        return self.bar.scene(cells=120, extent=0.12)

    def offsets(self) -> np.ndarray:
        """The pushes D (m)."""
        return np.array([0.0, 0.005, 0.01, 0.02, 0.03])

    def grasp(self, push: float) -> np.ndarray:
        a = math.radians(self.alpha)
        u = np.array([math.sin(a), math.cos(a)])
        centre = np.array([self.offset, 0.0]) + push * u
        return np.array([centre - 0.045 * u, centre + 0.045 * u])


#: The push's controlled cases: square to the wall and 23 degrees off it (friction 0.5, a
#: cone of 26.6 degrees), 20 and 35 mm from the middle, 3.5 g and 27.6 g.
PUSHES = tuple(PushCase(alpha, offset, Bar(0.08, density, 0.5, 20.0, width=0.006, thickness=0.024))
               for density in (300.0, 2400.0)
               for alpha, offset in ((0.0, 0.02), (0.0, 0.035), (23.0, 0.02), (23.0, 0.035)))


@dataclass(frozen=True)
class SqueezeCase:
    """The squeeze's controlled case (docs/lift.md, "The squeeze's limit on the calibration
    rectangle"): a bar gripped through its centre along a line at an angle (degrees) to its
    length, the calibration rectangle's grasp turned. The 1 cm plates meet its ends up to about 10 degrees, its
    corners around the diagonal (26.6 degrees for 6 x 3 cm) and its long sides from about
    40 degrees; where a side's wall lies beyond the friction cone the plates' couple turns
    the bar on the table (harness.squeeze) towards the nearest local minimum of its width,
    flush with its sides, so the turn the squeeze needs is largest just past the corners
    (both engines turn it 37-46 degrees from 40). The sweep's 'offset' is the angle."""

    bar: Bar

    @property
    def label(self) -> str:
        return f"bar {self.bar.label}, {self.mass * 1000:.0f} g, through its centre"

    @property
    def mass(self) -> float:
        return self.bar.mass

    def scene(self) -> Scene:
        return self.bar.scene()

    def offsets(self) -> np.ndarray:
        """The angles (degrees) to the bar's length."""
        return np.array([0.0, 10.0, 20.0, 25.0, 30.0, 35.0, 40.0, 45.0, 50.0, 60.0, 70.0, 90.0])

    def grasp(self, angle: float) -> np.ndarray:
        a = math.radians(angle)
        reach = 0.5 * math.hypot(self.bar.length, self.bar.width) + CLEARANCE
        u = np.array([math.cos(a), math.sin(a)])
        return np.array([-reach * u, reach * u])


#: The squeeze's controlled cases: the calibration rectangle's 6 x 3 cm (3 cm thick,
#: friction 0.5, a cone of 26.6 degrees, 20 N), light (54 g) and heavy (432 g, 8000
#: kg/m^3: the table's friction against the plates' couple grows with the weight).
SQUEEZES = tuple(SqueezeCase(Bar(0.06, density, 0.5, 20.0)) for density in (1000.0, 8000.0))


@dataclass(frozen=True)
class NotchCase:
    """A plate on two walls (docs/lift.md, "A plate on two walls"): the calibration
    rectangle's 6 x 3 cm bar (3 cm thick) with a V-notch ``2 half_open`` wide and ``depth``
    deep in the middle of one end, gripped along its length ``offset`` (m) off the notch's
    middle, so that the 1 cm plate meets the notch's two walls with its corners (within
    about 1 mm of the middle) or one wall and the end beyond the notch. On a 1 mm grid, the
    bar 0.3 mm off the nodes (a node on a wall has no exact gradient)."""

    depth: float
    density: float
    half_open: float = 0.006
    friction: float = 0.5
    force: float = 20.0
    length: float = 0.06
    width: float = 0.03
    thickness: float = 0.03
    shift: float = -0.0003

    @property
    def mass(self) -> float:
        notch = self.half_open * self.depth
        return self.density * self.thickness * (self.length * self.width - notch)

    @property
    def label(self) -> str:
        return (f"bar {self.length * 100:g} x {self.width * 100:g} cm, notch {2 * self.half_open * 1e3:g} mm wide, "
                f"{self.depth * 1e3:g} mm deep, {self.mass * 1000:.0f} g")

    def scene(self) -> Scene:
        x0, x1, b = -0.5 * self.length + self.shift, 0.5 * self.length + self.shift, 0.5 * self.width
        outline = [(x0, -b), (x1, -b), (x1, b), (x0, b), (x0, self.half_open), (x0 + self.depth, 0.0),
                   (x0, -self.half_open)]
        return _solid("notch", {"type": "polygon", "exterior": [list(p) for p in outline]}, self.thickness,
                      self.density, self.friction, self.force, f"<notch {self.label}>", cells=100, extent=0.1)

    def offsets(self) -> np.ndarray:
        return np.array([0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0]) * 1e-3

    def grasp(self, offset: float) -> np.ndarray:
        reach = 0.5 * self.length + CLEARANCE
        return np.array([[self.shift - reach, offset], [self.shift + reach, offset]])


#: The notch cases: walls at 45 degrees (6 mm deep) and 26.6 degrees (12 mm) to the
#: closing line, both beyond the friction cone of 0.5 (26.6 degrees) from one normal per
#: plate; light (1000 kg/m^3) and heavy (8000).
NOTCHES = (NotchCase(0.006, 1000.0), NotchCase(0.012, 1000.0), NotchCase(0.006, 8000.0))


@dataclass(frozen=True)
class LoadCase:
    """An object gripped where its weight has no torque about the grasp axis, at falling
    grip forces, for the two loads the model leaves out (docs/lift.md, "What it does not
    model"). ``kind`` "tip": a ring (8 cm across, a 5 cm hole, 3 cm thick) gripped on its
    rim along its radial line, one jaw in the hole, so that its centre of mass lies
    beyond the plates along the closing line and the weight tips it about the horizontal
    axis across that line. "yaw": a long light bar (35 cm x 2 cm x 3 cm) gripped at its
    middle across its width, which the shake's turn about the vertical (``shake_turn`` at
    ``shake_frequency``) loads about the vertical."""

    kind: str
    density: float
    friction: float
    forces: tuple
    #: The "yaw" bar's length and width (m); both cases are 3 cm thick.
    bar: tuple = (0.35, 0.02)
    thickness: float = 0.03

    @property
    def ring(self) -> SlideCase:
        return SlideCase("ring", self.friction, density=self.density, thickness=self.thickness)

    @property
    def label(self) -> str:
        what = ("ring 8 / 5 cm on its rim" if self.kind == "tip" else "bar 35 x 2 x 3 cm at its middle")
        return f"{what}, {self.density:g} kg/m^3, mu {self.friction:g}"

    def scene(self, force: float) -> Scene:
        if self.kind == "tip":
            return replace(self.ring, force=force).scene()
        length, width = self.bar
        shape = {"type": "rectangle", "width": length, "height": width, "center": [0.0, 0.0]}
        return _solid("bar", shape, self.thickness, self.density, self.friction, force,
                      f"<{self.label}, {force:g} N>", cells=80, extent=0.4)

    def grasp(self) -> np.ndarray:
        if self.kind == "tip":
            return self.ring.grasp(0.0)
        half = 0.5 * self.bar[1] + CLEARANCE
        return np.array([[0.0, -half], [0.0, half]])

    def ratio(self, force: float, settings, protocol: Protocol) -> float:
        """The load over the largest resistance rigid plates offer it before the object
        moves (closed forms of the case's dimensions). "tip": the weight's moment about
        the axis across the closing line at the grasp centre, lambda W r (r: the ring's
        centre beyond the rim's middle), against the jaws' force F over the whole patch
        height h (the pressure at the top of one plate and the bottom of the other) plus
        the plates' unequal share of the load across the grasp width w,
        (mu F - lambda W / 2) w. "yaw": the shake's moment about the vertical, I theta
        omega^2, against the plates' friction across the grasp width,
        w sqrt((mu F)^2 - (W / 2)^2), plus F times the plate's width (the pressure at
        opposite edges of the two plates)."""
        mu = self.friction
        if self.kind == "tip":
            outer, hole = self.ring.radius, self.ring.hole
            load = settings.load_factor * GRAVITY * self.ring.mass
            resist = force * patch_height(settings) + max(0.0, mu * force - load / 2) * (outer - hole)
            return load * 0.5 * (outer + hole) / resist
        length, width = self.bar
        mass = self.density * self.thickness * length * width
        demand = mass * (length**2 + width**2) / 12 * protocol.shake_turn * (2 * math.pi * protocol.shake_frequency)**2
        across = math.sqrt(max(0.0, (mu * force)**2 - (GRAVITY * mass / 2)**2))
        return demand / (width * across + force * settings.jaw_width)


#: The loads' controlled cases: near the weight's slip at the weakest force, far from it
#: at the strongest (docs/lift.md, "Loads the model leaves out").
LOAD_CASES = (LoadCase("tip", 2000.0, 0.8, (1.75, 2.0, 2.5, 3.0, 4.0, 6.0, 10.0)),
              LoadCase("yaw", 476.0, 0.5, (1.5, 1.75, 2.0, 2.5, 3.0, 4.0, 6.0)))


def load_validate(cases=LOAD_CASES, trials: int = 12, seed: int = 0, engine: str = "pybullet") -> dict:
    """Per case and grip force: the load ratio (LoadCase.ratio), the weight's share of
    the plates' friction (lambda W / (2 mu F)), simulated success, the outcomes and the
    median turn in the gripper (rad), and the analytic P_L and P_F."""
    protocol = Protocol.of(engine)
    rows = []
    with make_runner(protocol) as runner:
        for case in cases:
            points = []
            for force in case.forces:
                scene = case.scene(force)
                settings, approach, draws = _exact_draws(scene, max(trials, ANALYTIC_DRAWS), seed, "load", case.label,
                                                         f"{force:g} N")
                polygon = truth_polygon(scene)
                results = runner.run(make_trials(settings, case.grasp(), [polygon], approach[:trials]))
                analytic = evaluate_draws(case.grasp(), draws, settings)
                weight = GRAVITY * case.density * polygon.area * settings.thickness
                points.append({"force": force, "ratio": case.ratio(force, settings, protocol),
                               "slip": settings.load_factor * weight / (2 * case.friction * force),
                               "success": float(np.mean([r.outcome == "success" for r in results])),
                               "outcomes": dict(Counter(r.outcome for r in results)),
                               "turn_median": float(np.median([r.pivot for r in results])),
                               "p_l": float(analytic.lifted.mean()), "p_f": float(analytic.closure.mean())})
            rows.append({"case": case.label, "kind": case.kind, "points": points})
    return {"engine": engine, "trials_per_force": trials, "rows": rows}


def _exact_draws(scene: Scene, n: int, seed: int, *keys):
    """The scene's settings at the sweeps' approach noise, and n draws of its true shape
    with approach and pressure deviates from the stream (seed, "lift-bench", *keys)."""
    settings = resolve(scene, {"sigma_g": SIGMA_G})
    approach = stream(seed, "lift-bench", *keys, "approach").standard_normal((n, 2, 2))
    pressure = stream(seed, "lift-bench", *keys, "pressure").random((n, 2))
    truth = SDFBatch(scene.grid, np.repeat(scene.true_sdf[None], n, axis=0),
                     np.repeat(scene.true_sdf_gradient[None], n, axis=0))
    return settings, approach, EvaluationDraws(truth, approach, np.zeros(n), pressure, 1.0)


def sweep(bar: Bar, trials: int = 12, seed: int = 0, runner=None) -> list[dict]:
    """Per offset: simulated success, the fraction of trials that turned (pivot above
    TURNED), the outcomes and the angles of the turned trials that ended held; the
    analytic P_L and the analytic fraction of draws that turn."""
    scene = bar.scene()
    settings, approach, draws = _exact_draws(scene, max(trials, ANALYTIC_DRAWS), seed, bar.label)
    offsets = bar.offsets()
    polygon = truth_polygon(scene)
    batch = [t for d in offsets for t in make_trials(settings, bar.grasp(d), [polygon], approach[:trials])]
    own = runner is None
    runner = runner or make_runner()
    try:
        results = runner.run(batch)
    finally:
        if own:
            runner.close()
    rows = []
    for k, d in enumerate(offsets):
        mine = results[k * trials:(k + 1) * trials]
        analytic = evaluate_draws(bar.grasp(d), draws, settings)
        rows.append({"offset": float(d), "success": float(np.mean([r.outcome == "success" for r in mine])),
                     "turned": float(np.mean([r.pivot > TURNED for r in mine])),
                     "p_l": float(analytic.lifted.mean()), "p_f": float(analytic.closure.mean()),
                     "turns": float(analytic.pivots.mean()),
                     "outcomes": dict(Counter(r.outcome for r in mine)),
                     "held_turns": [float(r.pivot) for r in mine if r.outcome == "success" and r.pivot > TURNED]})
    return rows


@dataclass(frozen=True)
class HangBar:
    """Bars of one mass that the weight turns in the plates, gripped across their width
    ``short`` from one end: the far end reaches length - short beyond the grasp axis, so
    the longer the bar (its density falling to keep the mass), the nearer its hang comes
    to the lifted table, until it reaches it. The lift model calls a turned bar lifted
    when that reach is less than the clearance, the lift height plus the grasp axis's
    height above the table (harness.lift, "Turning and hanging"). ``rounded``: the bar is
    a capsule, its ends half disks of the bar's half width (the grip then lies on the
    rounded end when ``short`` is less than that radius, or next to it)."""

    mass: float
    friction: float
    force: float
    short: float = 0.012
    width: float = 0.03
    thickness: float = 0.03
    rounded: bool = False

    @property
    def label(self) -> str:
        return (f"{self.mass * 1e3:g} g, {self.width * 100:g} x {self.thickness * 100:g} cm"
                f"{', rounded ends' if self.rounded else ''}, gripped "
                f"{self.short * 1e3:g} mm from its end, mu {self.friction:g}, {self.force:g} N")

    def bar(self, length: float) -> Bar:
        return Bar(length, self.mass / (length * self.width * self.thickness), self.friction, self.force,
                   self.width, self.thickness)

    def offset(self, length: float) -> float:
        return 0.5 * length - self.short

    # What hang_sweep asks of a hang case (HangBar and the head-and-handle cases alike).

    @property
    def lengths(self) -> tuple:
        return HANG_LENGTHS

    def scene(self, length: float) -> Scene:
        if not self.rounded:
            return self.bar(length).scene()
        r = 0.5 * self.width
        area = (length - 2 * r) * self.width + math.pi * r * r
        shape = {"type": "capsule", "start": [r - 0.5 * length, 0.0], "end": [0.5 * length - r, 0.0], "radius": r}
        return _solid("capsule", shape, self.thickness, self.mass / (area * self.thickness), self.friction,
                      self.force, f"<capsule {self.label}, {length * 100:g} cm>")

    def grasp(self, length: float) -> np.ndarray:
        return self.bar(length).grasp(self.offset(length))

    def reach(self, length: float) -> float:
        """The far end's reach beyond the grasp axis (m)."""
        return length - self.short

    def com_offset(self, length: float) -> float:
        """The centre of mass's distance from the grasp axis (m)."""
        return self.offset(length)


#: The hang bars' lengths (m): from a hang about 7 cm clear of the lifted table to 5 cm into it.
HANG_LENGTHS = tuple(np.round(np.arange(0.06, 0.1751, 0.005), 3))
#: A heavy and a light bar, both turned by their weight from 12 cm on (where they hang near the table).
HANG_BARS = (HangBar(0.4, 0.5, 10.0), HangBar(0.1, 0.5, 3.0))
#: Square against rounded ends, at a weak grip (200 g, 5 N): gripped 12 mm from the end (the
#: 1 cm plates over the flat wall's last 2 mm and the 15 mm arc; the approach noise puts a
#: share of the draws' plates on an edge), and 20 mm from it, on parallel walls. The
#: posterior samples' outlines round the ends of thin parts, and both engines lose turned
#: objects gripped near such ends more than on the true outline (docs/lift.md, "Why P_L
#: misses where it does").
END_CASES = tuple(HangBar(0.2, 0.5, 5.0, short=short, rounded=rounded)
                  for short in (0.012, 0.02) for rounded in (False, True))


class _HeadAndHandle:
    """A hang case made of a head gripped across at x = 0 and a straight handle (a capsule
    of half width ``half_width``) from x = ``neck`` to ``neck`` + length, whose weight turns
    it in the plates; the mass is kept by the density. The far end reaches neck + length
    + half_width beyond the grasp axis. Subclasses give the head (its scene part and its
    geometry), how far it reaches behind the axis (``back``) and its half width at the
    plates (``grip``)."""

    name = ""

    def _head(self) -> tuple[dict, object]:
        raise NotImplementedError

    def _shape(self, length: float):
        import shapely
        from shapely.geometry import LineString

        handle = LineString([(self.neck, 0), (self.neck + length, 0)]).buffer(self.half_width, quad_segs=32)
        return shapely.union_all([self._head()[1], handle])

    def _centre(self, length: float) -> float:
        """Where the grasp axis lies (x, m) once the shape is centred on the grid."""
        return -0.5 * (length + self.half_width + (self.neck - self.back))

    def scene(self, length: float) -> Scene:
        shape = {"type": "union", "offset": [self._centre(length), 0.0],
                 "parts": [self._head()[0], {"type": "capsule", "start": [self.neck, 0.0],
                                             "end": [self.neck + length, 0.0], "radius": self.half_width}]}
        density = self.mass / (self._shape(length).area * self.thickness)
        return _solid(self.name, shape, self.thickness, density, self.friction, self.force,
                      f"<{self.name} {self.label}, {length * 100:g} cm>")

    def grasp(self, length: float) -> np.ndarray:
        x, half = self._centre(length), self.grip + CLEARANCE
        return np.array([[x, -half], [x, half]])

    def reach(self, length: float) -> float:
        return self.neck + length + self.half_width

    def com_offset(self, length: float) -> float:
        return self._shape(length).centroid.x


@dataclass(frozen=True)
class HangHandle(_HeadAndHandle):
    """The hang test on a curved wall: a disk (``radius``) gripped across its centre, with
    a handle from its centre (:class:`_HeadAndHandle`). The plates touch the disk's curved
    wall along a line across the thickness (no flat patch)."""

    mass: float
    friction: float
    force: float
    radius: float = 0.015
    half_width: float = 0.006
    thickness: float = 0.03
    name = "handle"
    neck = 0.0

    @property
    def label(self) -> str:
        return (f"{self.mass * 1e3:g} g disk r {self.radius * 1e3:g} mm + handle, {self.thickness * 100:g} cm "
                f"thick, mu {self.friction:g}, {self.force:g} N")

    @property
    def lengths(self) -> tuple:
        return HANDLE_LENGTHS

    @property
    def back(self) -> float:
        return self.radius

    @property
    def grip(self) -> float:
        return self.radius

    def _head(self) -> tuple[dict, object]:
        from shapely.geometry import Point

        return ({"type": "disk", "radius": self.radius, "center": [0.0, 0.0]},
                Point(0, 0).buffer(self.radius, quad_segs=64))


#: The handle's lengths (m): from a hang about 6 cm clear of the lifted table to 3 cm into it.
HANDLE_LENGTHS = tuple(np.round(np.arange(0.05, 0.1451, 0.005), 3))


@dataclass(frozen=True)
class HangWedge(_HeadAndHandle):
    """The hang test on edge contacts: a head ``2 head`` long between two walls inclined
    to the plates (slope ``slope`` each, widening towards the handle with ``sense`` +1,
    away from it with -1; ``square`` keeps the first wall square to the plates), ``2 half``
    wide at the grasp, gripped across its middle, with a handle from its far end
    (:class:`_HeadAndHandle`). The plates meet an inclined wall with the edge towards
    which it approaches (harness.grasp.edge_contacts)."""

    mass: float
    friction: float
    force: float
    slope: float
    sense: int = 1
    square: bool = False
    half: float = 0.015
    head: float = 0.015
    half_width: float = 0.006
    thickness: float = 0.03
    name = "wedge"

    @property
    def label(self) -> str:
        walls = "one wall" if self.square else "walls"
        towards = "towards" if self.sense > 0 else "away from"
        return (f"{self.mass * 1e3:g} g wedge + handle, {walls} {self.slope:g} wider {towards} it, "
                f"{self.thickness * 100:g} cm thick, mu {self.friction:g}, {self.force:g} N")

    @property
    def lengths(self) -> tuple:
        return WEDGE_LENGTHS

    @property
    def neck(self) -> float:
        return self.head

    @property
    def back(self) -> float:
        return self.head

    @property
    def grip(self) -> float:
        return self.half + self.head * self.slope

    def _head(self) -> tuple[dict, object]:
        from shapely.geometry import Polygon

        t, h, b = self.sense * self.slope, self.head, self.half
        t1 = 0.0 if self.square else t
        outline = [(-h, -(b - h * t1)), (h, -(b + h * t1)), (h, b + h * t), (-h, b - h * t)]
        return {"type": "polygon", "exterior": [list(p) for p in outline]}, Polygon(outline)


@dataclass(frozen=True)
class HangHead(_HeadAndHandle):
    """The hang test on a vertex: a regular polygon head of ``sides`` sides (even) gripped
    across two opposite vertices, so that each plate presses a vertical edge of the prism
    whose faces meet at (sides - 2) 180 / sides degrees (a line contact over the thickness
    with no width, as on the corners of posterior samples' outlines; ``half`` the
    vertices' radius), or, with ``vertex`` False, across two opposite faces (``half`` the
    faces' distance from the centre); a handle from inside the head
    (:class:`_HeadAndHandle`)."""

    mass: float
    friction: float
    force: float
    sides: int = 4
    vertex: bool = True
    half: float = 0.015
    half_width: float = 0.006
    thickness: float = 0.03
    name = "head"

    @property
    def label(self) -> str:
        where = f"vertices ({180 - 360 / self.sides:g} deg)" if self.vertex else "faces"
        return (f"{self.mass * 1e3:g} g {self.sides}-gon head on its {where} + handle, "
                f"{self.thickness * 100:g} cm thick, mu {self.friction:g}, {self.force:g} N")

    @property
    def lengths(self) -> tuple:
        return HANDLE_LENGTHS

    @property
    def neck(self) -> float:
        return 0.5 * self.half

    @property
    def back(self) -> float:
        return self.half

    @property
    def grip(self) -> float:
        return self.half

    def _head(self) -> tuple[dict, object]:
        from shapely.geometry import Polygon

        n = self.sides
        # Vertices at +-y (vertex) or faces normal to y (the vertices half a side further round).
        turn, radius = (0.0, self.half) if self.vertex else (math.pi / n, self.half / math.cos(math.pi / n))
        angles = 0.5 * math.pi + turn + 2.0 * math.pi * np.arange(n) / n
        outline = [(float(radius * math.cos(a)), float(radius * math.sin(a))) for a in angles]
        return {"type": "polygon", "exterior": [list(p) for p in outline]}, Polygon(outline)


#: Vertices against faces at a weak grip (200 g, 5 N, mu 0.5; the weak regime's force): a
#: square, a hexagon and an octagon gripped across their vertices (90, 120 and 135 degrees)
#: and the square across its faces (docs/lift.md, "Sharp edges").
CORNER_CASES = (*(HangHead(0.2, 0.5, 5.0, sides) for sides in (4, 6, 8)), HangHead(0.2, 0.5, 5.0, 4, vertex=False))


#: The wedges' lengths (m): from a hang about 5.5 cm clear of the lifted table to 1.5 cm into it.
WEDGE_LENGTHS = tuple(np.round(np.arange(0.04, 0.1101, 0.005), 3))
#: Wedges whose inclined walls the plates press with their edges (300 g at 10 N, walls at
#: a slope of 0.1, 5.7 degrees): widening towards the handle, away from it, and one wall
#: inclined, the other square.
HANG_WEDGES = (HangWedge(0.3, 0.5, 10.0, 0.1, 1), HangWedge(0.3, 0.5, 10.0, 0.1, -1),
               HangWedge(0.3, 0.5, 10.0, 0.1, 1, square=True))
#: The hang cases of bench lift: the two bars, the heavy handle (400 g at 10 N, as the heavy
#: bar) and the wedges.
HANG_CASES = HANG_BARS + (HangHandle(0.4, 0.5, 10.0),) + HANG_WEDGES
#: A turned bar held at a smaller angle than this (rad) has come to rest short of the hang.
AT_REST = 1.4
#: Hang bars whose hang the model calls at least this clear of the lifted table (m) should all be held.
CLEAR_GAP = 0.02
#: The hang bars run again in Bullet at a time step this many times finer (docs/lift.md,
#: "Hang bars": the default step drops heavy swinging bars that a finer one holds).
HANG_FINER = 4


def hang_sweep(hang: "HangBar | _HeadAndHandle", trials: int = 12, seed: int = 0, runner=None) -> list[dict]:
    """Per length: the model's gap between the hanging bar and the lifted table
    (clearance - reach, m), simulated success, the share of trials that turned, the
    outcomes, and for the turned trials that ended held the median angle and, of those
    that came to rest short of the hang (below AT_REST), the median slide down the
    plates (m: the lift height less the centre of mass's rise and its fall d sin(angle)
    from the turn; a bar still swinging has no such angle); the analytic P_L and the
    share of draws that turn."""
    rows = []
    own = runner is None
    runner = runner or make_runner()
    try:
        for length in hang.lengths:
            length = float(length)
            d = hang.com_offset(length)
            scene = hang.scene(length)
            settings, approach, draws = _exact_draws(scene, max(trials, ANALYTIC_DRAWS), seed, "hang", hang.label,
                                                     int(round(length * 1e3)))
            grasp = hang.grasp(length)
            results = runner.run(make_trials(settings, grasp, [truth_polygon(scene)], approach[:trials]))
            analytic = evaluate_draws(grasp, draws, settings)
            held = [r for r in results if r.outcome == "success" and r.pivot > TURNED]
            slides = [settings.lift_height - r.rise - d * math.sin(r.pivot) for r in held if r.pivot < AT_REST]
            turned = [r for r in results if r.pivot > TURNED]
            rows.append({"length": length, "offset": d, "gap": clearance(settings) - hang.reach(length),
                         "success": float(np.mean([r.outcome == "success" for r in results])),
                         "turned": float(np.mean([r.pivot > TURNED for r in results])),
                         "turned_trials": len(turned),
                         "turned_successes": sum(r.outcome == "success" for r in turned),
                         "p_l": float(analytic.lifted.mean()), "p_f": float(analytic.closure.mean()),
                     "turns": float(analytic.pivots.mean()),
                         "outcomes": dict(Counter(r.outcome for r in results)),
                         "held_turn_median": float(np.median([r.pivot for r in held])) if held else None,
                         "slide_median": float(np.median(slides)) if slides else None})
    finally:
        if own:
            runner.close()
    return rows


def hang_validate(bars=HANG_CASES, trials: int = 12, seed: int = 0, engine: str = "pybullet",
                  finer: int = 1) -> dict:
    """Every hang bar's sweep and the gaps (m) at which simulated success and P_L fall
    through 0.5 as the bar lengthens; their difference (success's less P_L's: positive
    when the physics needs more room than the model gives); the success of the bars
    whose hang the model calls at least CLEAR_GAP clear, and their failures. ``finer``:
    the engine's time step divided by this (a convergence check)."""
    rows = []
    protocol = Protocol.of(engine)
    protocol = protocol.finer(finer) if finer > 1 else protocol
    with make_runner(protocol) as runner:
        for hang in bars:
            points = hang_sweep(hang, trials, seed, runner)
            x = [p["length"] for p in points]

            def gap_at(values):
                at = crossing(x, values)
                return None if at is None else (points[0]["gap"] + points[0]["length"] - at)

            sim, model = gap_at([p["success"] for p in points]), gap_at([p["p_l"] for p in points])
            clear = [p for p in points if p["gap"] >= CLEAR_GAP]
            failed = Counter()
            for p in clear:
                failed.update({k: v for k, v in p["outcomes"].items() if k != "success"})
            rows.append({"bar": hang.label, "success_gap": sim, "p_l_gap": model,
                         "difference": None if sim is None or model is None else sim - model,
                         "clear_success": float(np.mean([p["success"] for p in clear])) if clear else None,
                         "clear_p_l": float(np.mean([p["p_l"] for p in clear])) if clear else None,
                         "clear_turned": sum(p["turned_trials"] for p in clear),
                         "clear_turned_success": (sum(p["turned_successes"] for p in clear)
                                                  / max(1, sum(p["turned_trials"] for p in clear))),
                         "clear_failures": dict(failed), "points": points})
    return {"engine": engine, "time_step": protocol.time_step, "trials_per_length": trials, "rows": rows}


@dataclass(frozen=True)
class FootedDisk:
    """The centre of mass off the middle of the contacts along the grasp axis (docs/lift.md,
    "A clean case both engines lose"): a disk gripped across its centre (line contacts on
    its curved wall), a handle along x (the turn's lever) and at the handle's end a foot
    along the closing axis (y) of each length in ``feet``: from the handle's edge outward
    (an L: the centre of mass moves off the contacts' middle along the grasp axis) or
    centred on the handle (``centred``, a T: the control, the same area beyond the handle,
    so the same weight and lever, and no offset along the axis). The density is fixed, so
    the foot adds weight."""

    centred: bool
    handle: float = 0.08
    density: float = 3000.0
    friction: float = 0.5
    force: float = 5.0
    radius: float = 0.015
    width: float = 0.012
    thickness: float = 0.03
    feet: tuple = (0.0, 0.02, 0.04, 0.06)

    @property
    def label(self) -> str:
        return (f"{'T' if self.centred else 'L'}: disk r {self.radius * 1e3:g} mm, handle {self.handle * 100:g} cm, "
                f"{self.thickness * 100:g} cm thick, {self.density:g} kg/m^3, mu {self.friction:g}, {self.force:g} N")

    def parts(self, foot: float) -> list[dict]:
        r, w = self.radius, self.width
        parts = [{"type": "disk", "radius": r, "center": [0.0, 0.0]},
                 {"type": "rectangle", "width": self.handle + 0.002, "height": w,
                  "center": [r + self.handle / 2 - 0.001, 0.0]}]
        if foot > 0:  # the L's overlaps the handle by 1 mm, so that the union is one piece;
            # the T's spans the handle's width and foot / 2 beyond each edge: the same area
            # beyond the handle as the L's, so the same weight and lever
            height, y = (foot + w, 0.0) if self.centred else (foot + 0.002, w / 2 + foot / 2 - 0.001)
            parts.append({"type": "rectangle", "width": w, "height": height, "center": [r + self.handle - w / 2, y]})
        return parts

    def scene(self, foot: float) -> Scene:
        return _solid("footed", {"type": "union", "parts": self.parts(foot)}, self.thickness, self.density,
                      self.friction, self.force, f"<{self.label}, foot {foot * 100:g} cm>", cells=100, extent=0.25)

    def grasp(self) -> np.ndarray:
        half = self.radius + CLEARANCE
        return np.array([[0.0, -half], [0.0, half]])


#: The L and its T control (docs/lift.md, "A clean case both engines lose").
FOOTED_CASES = (FootedDisk(False), FootedDisk(True))


def footed_validate(cases=FOOTED_CASES, trials: int = 24, seed: int = 0, engine: str = "pybullet") -> dict:
    """Per case and foot: the centre of mass's lever across the grasp axis and its offset
    along it (m, from the true outline), simulated success, the share of trials that
    turned and the success of those, the outcomes, and P_L."""
    rows = []
    with make_runner(Protocol.of(engine)) as runner:
        for case in cases:
            points = []
            for foot in case.feet:
                scene = case.scene(foot)
                settings, approach, draws = _exact_draws(scene, max(trials, ANALYTIC_DRAWS), seed, "footed",
                                                         case.label, int(round(foot * 1e3)))
                polygon = truth_polygon(scene)
                results = runner.run(make_trials(settings, case.grasp(), [polygon], approach[:trials]))
                turned = [r for r in results if r.pivot > TURNED]
                centre = polygon.centroid
                points.append({"foot": foot, "lever": float(centre.x), "axial": float(centre.y),
                               "success": float(np.mean([r.outcome == "success" for r in results])),
                               "turned": len(turned) / len(results),
                               "turned_success": (float(np.mean([r.outcome == "success" for r in turned]))
                                                  if turned else None),
                               "outcomes": dict(Counter(r.outcome for r in results)),
                               "p_l": float(evaluate_draws(case.grasp(), draws, settings).lifted.mean())})
            rows.append({"case": case.label, "points": points})
    return {"engine": engine, "trials_per_foot": trials, "rows": rows}


def _footed_lines(res: dict) -> list[str]:
    lines = [f"off-axis cases ({res['engine']}, {res['trials_per_foot']} trials per foot): a disk gripped across "
             f"its centre, a handle, a foot along the closing axis (L) or across the handle's end (T); per foot "
             f"(cm): the centre of mass's offset along the grasp axis (cm), success, turned, P_L"]
    for r in res["rows"]:
        lines.append(f"  {r['case']}:")
        for p in r["points"]:
            fails = ", ".join(f"{k} {v}" for k, v in sorted(p["outcomes"].items()) if k != "success")
            lines.append(f"    foot {p['foot'] * 100:3.0f}  offset {p['axial'] * 100:4.1f}  success {p['success']:4.2f}"
                         f"  turned {p['turned']:4.2f}  P_L {p['p_l']:4.2f}" + (f"  ({fails})" if fails else ""))
    return lines


def crossing(offsets, values) -> float | None:
    """Where ``values`` first falls through 0.5 along ``offsets`` (linear between the two
    offsets around the fall), or None when it never does."""
    for i in range(1, len(offsets)):
        if values[i - 1] >= 0.5 > values[i]:
            return float(offsets[i - 1] + (values[i - 1] - 0.5) / (values[i - 1] - values[i])
                         * (offsets[i] - offsets[i - 1]))
    return None


def _relative(model: float | None, sim: float | None) -> float | None:
    return None if model is None or sim is None else (model - sim) / sim


def validate(bars=BARS, trials: int = 12, seed: int = 0, engine: str = "pybullet") -> dict:
    """Every bar's sweep and its crossings: where P_L and simulated success fall through
    0.5, and where the analytic and the simulated share of draws that did not turn do;
    the relative errors and the largest of them; per bar, the median angle at which the
    turned trials that ended held had stopped, and the simulated failures by outcome.
    ``engine``: the simulator of the trials (the analytic side does not depend on it)."""
    rows = []
    with make_runner(Protocol.of(engine)) as runner:
        for bar in bars:
            points = sweep(bar, trials, seed, runner)
            x = [p["offset"] for p in points]
            sim = crossing(x, [p["success"] for p in points])
            model = crossing(x, [p["p_l"] for p in points])
            sim_turn = crossing(x, [1 - p["turned"] for p in points])
            model_turn = crossing(x, [1 - p["turns"] for p in points])
            held = [a for p in points for a in p["held_turns"]]
            failed = Counter()
            for p in points:
                failed.update({k: v for k, v in p["outcomes"].items() if k != "success"})
            rows.append({"bar": bar.label, "mass_kg": bar.mass, "success_at": sim, "p_l_at": model,
                         "error": _relative(model, sim), "turning_at": sim_turn, "model_turning_at": model_turn,
                         "turning_error": _relative(model_turn, sim_turn),
                         "held_turn_median": float(np.median(held)) if held else None, "failures": dict(failed),
                         "points": points})

    def largest(key):
        values = [abs(r[key]) for r in rows if r[key] is not None]
        return max(values) if values else None

    return {"engine": engine, "trials_per_offset": trials, "analytic_draws": max(trials, ANALYTIC_DRAWS),
            "sigma_g": SIGMA_G,
            "rows": rows, "largest_error": largest("error"), "largest_turning_error": largest("turning_error"),
            "missing": sum(r["error"] is None for r in rows)}


def manifold_levers(grasps_per_scene: int = 6, seed: int = 0) -> dict:
    """The friction lever of each jaw plate's contact manifold on the library trial set,
    once the jaws have stalled: sum_k N_k r_k / sum_k N_k over the manifold's points (r_k:
    distance from the plate's pressure centre across the grasp axis), as a fraction of
    the lift model's largest lever (the patch's half-diagonal, here for a line contact
    over the plate's reach: half the patch height). Quartiles and the share of plates
    held by a single point."""
    import pybullet as pb

    from harness.lift import PLATE_CLEARANCE
    from harness.bench.physics_study import library_trials
    from harness.physics.bullet import _Slot
    from harness.physics.trial import approach_blocked

    trial_set = library_trials(grasps_per_scene, seed)
    fractions, single = [], 0
    with make_runner() as runner:
        for trial in trial_set.trials:
            if trial.polygon.is_empty or approach_blocked(trial):
                continue
            runner._reset_world()
            slot = _Slot(runner, 0, trial, (0.0, 0.0), runner.protocol, None)
            while slot.phase == "close" and slot.result is None:
                slot.before_step()
                pb.stepSimulation(physicsClientId=runner.client)
                slot.after_step()
            if slot.result is not None:
                continue
            axis = np.array([*trial.axis, 0.0])
            half = 0.5 * (trial.thickness - PLATE_CLEARANCE)
            points = pb.getContactPoints(slot.obj, slot.grip, physicsClientId=runner.client)
            for jaw in trial.gripper.jaw_links:
                mine = [(np.array(p[5]), p[9]) for p in points if p[4] == jaw and p[9] > 1e-6]
                if not mine:
                    continue
                where = np.array([q for q, _ in mine])
                force = np.array([f for _, f in mine])
                rel = where - (where * force[:, None]).sum(axis=0) / force.sum()
                rel -= np.outer(rel @ axis, axis)
                fractions.append(float((np.linalg.norm(rel, axis=1) * force).sum() / force.sum() / half))
                single += len(mine) == 1
    f = np.array(fractions)
    return {"plates": len(f), "quartiles": [float(q) for q in np.percentile(f, [25, 50, 75])] if len(f) else [],
            "mean": float(f.mean()) if len(f) else math.nan, "single_point": single / max(len(f), 1),
            "beyond_largest": float(np.mean(f > 1.0)) if len(f) else math.nan}


@dataclass(frozen=True)
class Settings:
    """Trials per offset of the bar sweeps and the seed."""

    trials: int = 16
    seed: int = 0


def benchmark(settings: Settings = Settings()) -> dict:
    """The bar sweeps (where P_L and simulated success fall through 0.5) and the friction
    levers of Bullet's contact manifolds on the library trial set; the bar sweeps again
    in MuJoCo; and the other controlled cases (slides, pushes, squeezes, notches, hangs, loads, the
    off-axis L and T) in both engines."""
    return {**validate(trials=settings.trials, seed=settings.seed),
            "slide": validate(SLIDES, trials=settings.trials, seed=settings.seed),
            "push": validate(PUSHES, trials=settings.trials, seed=settings.seed),
            "squeeze": validate(SQUEEZES, trials=settings.trials, seed=settings.seed),
            "notch": validate(NOTCHES, trials=settings.trials, seed=settings.seed),
            "hang": hang_validate(trials=settings.trials, seed=settings.seed),
            "hang_fine": hang_validate(trials=settings.trials, seed=settings.seed, finer=HANG_FINER),
            "ends": hang_validate(END_CASES, trials=settings.trials, seed=settings.seed),
            "corners": hang_validate(CORNER_CASES, trials=settings.trials, seed=settings.seed),
            "manifold_levers": manifold_levers(seed=settings.seed),
            "loads": load_validate(trials=settings.trials, seed=settings.seed),
            "footed": footed_validate(seed=settings.seed),
            "mujoco": {**validate(trials=settings.trials, seed=settings.seed, engine="mujoco"),
                       "slide": validate(SLIDES, trials=settings.trials, seed=settings.seed, engine="mujoco"),
                       "push": validate(PUSHES, trials=settings.trials, seed=settings.seed, engine="mujoco"),
                       "squeeze": validate(SQUEEZES, trials=settings.trials, seed=settings.seed, engine="mujoco"),
                       "notch": validate(NOTCHES, trials=settings.trials, seed=settings.seed, engine="mujoco"),
                       "hang": hang_validate(trials=settings.trials, seed=settings.seed, engine="mujoco"),
                       "ends": hang_validate(END_CASES, trials=settings.trials, seed=settings.seed, engine="mujoco"),
                       "corners": hang_validate(CORNER_CASES, trials=settings.trials, seed=settings.seed,
                                                engine="mujoco"),
                       "loads": load_validate(trials=settings.trials, seed=settings.seed, engine="mujoco"),
                       "footed": footed_validate(seed=settings.seed, engine="mujoco")}}


def format_lines(res: dict) -> list[str]:
    lines = _bar_lines(res)
    if "slide" in res:
        lines += _slide_lines(res["slide"])
    if "push" in res:
        lines += _slide_lines(res["push"], "push cases", "pushes of")
    if "squeeze" in res:
        lines += _squeeze_lines(res["squeeze"])
    if "notch" in res:
        lines += _notch_lines(res["notch"])
    for key in ("hang", "hang_fine", "ends", "corners"):
        if key in res:
            lines += _hang_lines(res[key])
    m = res["manifold_levers"]
    q = m["quartiles"]
    lines.append(f"Bullet's manifold levers on {m['plates']} plates of the library trial set, as fractions of the "
                 f"largest admissible lever: quartiles {q[0]:.2f} / {q[1]:.2f} / {q[2]:.2f} (uniform: 0.25 / 0.50 / "
                 f"0.75), {m['single_point']:.0%} held by one point, {m['beyond_largest']:.1%} beyond the largest")
    if "loads" in res:
        lines += _load_lines(res["loads"])
    if "footed" in res:
        lines += _footed_lines(res["footed"])
    if "mujoco" in res:
        lines += ["", "the same bars in MuJoCo:", *_bar_lines(res["mujoco"])]
        if "slide" in res["mujoco"]:
            lines += _slide_lines(res["mujoco"]["slide"])
        if "push" in res["mujoco"]:
            lines += _slide_lines(res["mujoco"]["push"], "push cases", "pushes of")
        if "squeeze" in res["mujoco"]:
            lines += _squeeze_lines(res["mujoco"]["squeeze"])
        if "notch" in res["mujoco"]:
            lines += _notch_lines(res["mujoco"]["notch"])
        for key in ("hang", "ends", "corners"):
            if key in res["mujoco"]:
                lines += _hang_lines(res["mujoco"][key])
        if "loads" in res["mujoco"]:
            lines += _load_lines(res["mujoco"]["loads"])
        if "footed" in res["mujoco"]:
            lines += _footed_lines(res["mujoco"]["footed"])
    return lines


def _load_lines(res: dict) -> list[str]:
    """Per load case and grip force: the load ratio, the weight's share of the friction,
    success, the median turn in the gripper, P_L, and the outcomes."""
    lines = [f"loads the model leaves out ({res['engine']}, {res['trials_per_force']} trials per force): "
             f"grip force (N), load ratio, the weight's share of the friction, success, median turn (rad), P_L"]
    for r in res["rows"]:
        lines.append(f"  {r['case']} ({r['kind']}):")
        for p in r["points"]:
            fails = ", ".join(f"{k} {v}" for k, v in sorted(p["outcomes"].items()) if k != "success")
            lines.append(f"    {p['force']:5.2f} N  ratio {p['ratio']:4.2f}  share {p['slip']:4.2f}  success "
                         f"{p['success']:4.2f}  turn {p['turn_median']:4.2f}  P_L {p['p_l']:4.2f}"
                         + (f"  ({fails})" if fails else ""))
    return lines


def _bar_lines(res: dict) -> list[str]:
    def at(v):
        return "never" if v is None else f"{v * 1e3:.1f}"

    def err(v):
        return "-" if v is None else f"{v:+.0%}"

    lines = [f"lift: bars gripped across their width, offsets from the centre of mass every "
             f"{res['rows'][0]['points'][1]['offset'] * 1e3:.0f} mm, {res['trials_per_offset']} trials and "
             f"{res['analytic_draws']} analytic draws per offset, sigma_g {res['sigma_g'] * 1e3:g} mm; offsets (mm) "
             f"where P_L and success fall through 0.5, and where half the draws turn in the model and in the "
             f"simulation; 'held at': the median angle of the turned trials that ended held",
             f"{'bar':<44} {'P_L':>6} {'success':>8} {'error':>6} {'turns':>6} {'turned':>7} {'error':>6}"
             f"  {'held at':>7}  failures"]
    for r in res["rows"]:
        held = "-" if r["held_turn_median"] is None else f"{r['held_turn_median']:.2f} rad"
        fails = ", ".join(f"{k} {v}" for k, v in sorted(r["failures"].items())) or "none"
        lines.append(f"{r['bar']:<44} {at(r['p_l_at']):>6} {at(r['success_at']):>8} {err(r['error']):>6} "
                     f"{at(r['model_turning_at']):>6} {at(r['turning_at']):>7} {err(r['turning_error']):>6}"
                     f"  {held:>7}  {fails}")
    largest = res["largest_error"]
    lines.append(f"largest relative error: P_L vs success {err(largest)}, the model's turning vs the "
                 f"simulation's {err(res['largest_turning_error'])}"
                 + (f"; {res['missing']} rows without a crossing on one side" if res["missing"] else ""))
    return lines


def _slide_lines(res: dict, title: str = "slide cases", what: str = "the jaws' line", where: str = "",
                 scale: float = 1e3, per: str = "offset") -> list[str]:
    """Per slide, push or squeeze case and offset (mm; the push, mm; the angle, degrees):
    simulated success, P_L and P_F (force closure at the first contacts, before any push or
    squeeze). ``where`` names the offsets' unit (default: mm off the centre for the slide
    cases, mm otherwise) and ``scale`` converts them from the results' units."""
    offsets = ", ".join(f"{p['offset'] * scale:g}" for p in res["rows"][0]["points"])
    where = where or ("mm off the centre" if title == "slide cases" else "mm")
    lines = [f"{title} ({res['engine']}): {what} {offsets} {where}, "
             f"{res['trials_per_offset']} trials and {res['analytic_draws']} analytic draws per {per}: "
             f"success / P_L / P_F"]
    for r in res["rows"]:
        lines.append(f"  {r['bar']}: " + "  ".join(f"{p['success']:.2f}/{p['p_l']:.2f}/{p['p_f']:.2f}"
                                                    for p in r["points"]))
    return lines


def _squeeze_lines(res: dict) -> list[str]:
    """The squeeze cases' lines: :func:`_slide_lines` over angles (degrees)."""
    return _slide_lines(res, "squeeze cases", "the jaws' line through the centre at", "degrees to the bar's length",
                        scale=1.0, per="angle")


def _notch_lines(res: dict) -> list[str]:
    """The notch cases' lines: :func:`_slide_lines` over offsets from the notch's middle."""
    return _slide_lines(res, "notch cases", "the jaws' line along the bar", "mm off the notch's middle")


def _hang_lines(res: dict) -> list[str]:
    def cm(v):
        return "never" if v is None else f"{round(v * 100, 1) + 0.0:+.1f}"  # + 0.0: no "-0.0"

    def share(v):
        return "-" if v is None else f"{v:.2f}"

    lines = [f"hang cases ({res['engine']}, step {res['time_step'] * 1e3:.3g} ms): bars (square or rounded ends), "
             f"a disk, wedges and polygon heads with a handle that the weight turns, "
             f"{len(HANG_LENGTHS)} lengths ({len(HANDLE_LENGTHS)} for the handle and the heads, "
             f"{len(WEDGE_LENGTHS)} for the wedges), {res['trials_per_length']} trials each; the gap (cm) "
             f"between the model's hang and the lifted table where success and P_L fall through 0.5, and of "
             f"the lengths whose hang the model calls {CLEAR_GAP * 100:g} cm clear or more: the success, the "
             f"mean P_L and the success of the trials that turned (how many turned)",
             f"{'case':<70} {'P_L':>6} {'success':>8} {'diff':>6}  {'clear':>5}  {'P_L':>5}  {'turned':>10}  "
             f"failures"]
    for r in res["rows"]:
        fails = ", ".join(f"{k} {v}" for k, v in sorted(r["clear_failures"].items())) or "none"
        turned = "-" if not r.get("clear_turned") else f"{r['clear_turned_success']:.2f} ({r['clear_turned']})"
        lines.append(f"{r['bar']:<70} {cm(r['p_l_gap']):>6} {cm(r['success_gap']):>8} {cm(r['difference']):>6}"
                     f"  {share(r['clear_success']):>5}  {share(r.get('clear_p_l')):>5}  {turned:>10}  {fails}")
    return lines
