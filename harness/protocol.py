"""The trial protocol: every constant of a physics trial (the engine, time step, solver
iterations, lift, hold, shake, the contact checks), a pure value below the grasp
settings and the engines that run it."""

from __future__ import annotations

from dataclasses import dataclass, replace


@dataclass(frozen=True)
class Protocol:
    """Every constant of a trial (SI units). ``engine`` names the simulator
    (harness.physics.trial.ENGINES); the time step and solver iterations are the
    engine's own, chosen by its fidelity study in docs/physics.md (make one with
    :meth:`of`). ``friction_anchor`` and ``convex_clipping`` are Bullet's alone;
    ``cone_friction`` chooses the elliptic cone over the pyramid in MuJoCo too.
    ``body_refinement`` is how many times finer than the belief's grid a posterior
    sample's body is outlined (harness.physics.bodies.field_polygon; docs/physics.md,
    "The sample's body")."""

    engine: str = "pybullet"
    time_step: float = 1.0 / 480.0
    solver_iterations: int = 50
    lift_height: float = 0.10
    lift_time: float = 0.4           # minimum-jerk profile: peak acceleration 5.77 h / T^2 (3.6 m/s^2)
    hold_time: float = 0.1
    shake_time: float = 0.5          # one full circle at 2 Hz
    shake_frequency: float = 2.0     # Hz
    shake_amplitude: float = 0.02    # m, in the plane, circular, under a sin^2 envelope
    shake_turn: float = 0.25         # rad, about the vertical through the grasp centre
    table_friction: float = 0.5      # the object carries 1, so this is object-table friction
    friction_anchor: bool = True     # Bullet's friction anchors: static friction without creep
    cone_friction: bool = True       # the exact Coulomb cone; False: Bullet's pyramid (faster, anisotropic)
    table_hull: bool = True          # the object meets the table through its convex hull's foot, not its pieces
    convex_clipping: bool = False    # Bullet: contacts by clipping the convex pieces' faces (SAT), not GJK's points
    check_interval: float = 1.0 / 60.0  # s between contact checks while lifting and shaking
    held_distance: float = 0.001     # m: a jaw this close to the object touches it
    lost_distance: float = 0.005     # m: an object this far from both jaws ...
    lost_time: float = 0.03          # s: ... for this long is lost
    stall_fraction: float = 0.05     # a jaw slower than this fraction of closing speed ...
    stall_time: float = 0.02         # ... for this long has stalled
    closing_slack: float = 0.5       # s allowed beyond the time to close fully
    max_speed: float = 10.0          # m/s: faster means the simulation blew up
    max_spin: float = 200.0          # rad/s: likewise
    skip_free_travel: bool = True    # start the jaws SKIP_MARGIN short of the first contact
    body_refinement: int = 2         # a posterior sample's body is outlined on cells this many times finer

    @classmethod
    def of(cls, engine: str = "pybullet", **overrides) -> "Protocol":
        """The protocol of ``engine`` with its own time step and solver iterations, the
        other constants shared, then ``overrides``."""
        own = ENGINE_DEFAULTS.get(engine)
        if own is None:
            raise ValueError(f"unknown physics engine '{engine}'")
        return replace(cls(), engine=engine, **{**own, **overrides})

    def steps(self, seconds: float) -> int:
        return max(1, int(round(seconds / self.time_step)))

    def finer(self, factor: int) -> "Protocol":
        """The same protocol with a time step ``factor`` times smaller."""
        return replace(self, time_step=self.time_step / factor)


#: Each engine's time step (s) and solver iterations, from its fidelity study
#: (docs/physics.md: "Time step and iterations" for Bullet, "MuJoCo" for MuJoCo).
ENGINE_DEFAULTS = {"pybullet": {"time_step": 1.0 / 480.0, "solver_iterations": 50},
                   "mujoco": {"time_step": 0.002, "solver_iterations": 50}}
#: The simulators behind the seam (harness.physics.trial.make_runner); the first is the default.
ENGINES = tuple(ENGINE_DEFAULTS)
