"""The trial protocol: every constant of a physics trial (the engine, time step, solver
iterations, lift, hold, shake, the contact checks), a pure value below the grasp
settings and the engines that run it."""

from __future__ import annotations

from dataclasses import dataclass, replace


#: Bullet's jaw pads are compliant (docs/physics.md, "A compliant pad in Bullet"): each
#: contact point of a plate is a spring of PAD_STIFFNESS (N/m) and a damper of PAD_DAMPING
#: (N s/m). The pad is the one MuJoCo's contact softness models: about 2 mm of silicone
#: rubber (E about 1 MPa), E A / t about 4e4 N/m for a plate's patch of 0.8 cm^2, which
#: Bullet's manifold on a flat face carries as two points' worth (a plate sinks F / (2 k):
#: 0.5 mm at 20 N, tested; MuJoCo's pad 0.2-0.6 mm). The damper is critical,
#: 2 sqrt(k m), for an object of 0.1 kg. Chosen from the pad's physics before any trial's
#: outcome was looked at; rigid contacts (pad_stiffness 0) give the plates Bullet's short
#: point-contact levers.
PAD_STIFFNESS = 2.0e4
PAD_DAMPING = 90.0


@dataclass(frozen=True)
class Protocol:
    """Every constant of a trial (SI units). ``engine`` names the simulator
    (harness.physics.trial.ENGINES); the time step and solver iterations are the
    engine's own, chosen by its fidelity study in docs/physics.md (make one with
    :meth:`of`). ``friction_anchor``, ``convex_clipping`` and the pads' ``pad_stiffness`` and
    ``pad_damping`` are Bullet's alone;
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
    pad_stiffness: float = PAD_STIFFNESS  # Bullet: N/m per contact point of the jaws' pads; 0: rigid
    pad_damping: float = PAD_DAMPING      # Bullet: N s/m per contact point of the jaws' pads
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
#: (docs/physics.md: "Time step and iterations" for Bullet, "MuJoCo" for MuJoCo); MuJoCo's
#: pads are soft through its contacts' solref (harness.physics.mujoco_engine), so the
#: Bullet pad's spring is not used there.
ENGINE_DEFAULTS = {"pybullet": {"time_step": 1.0 / 480.0, "solver_iterations": 50},
                   "mujoco": {"time_step": 0.002, "solver_iterations": 50, "pad_stiffness": 0.0,
                              "pad_damping": 0.0}}
#: The simulators behind the seam (harness.physics.trial.make_runner); the first is the default.
ENGINES = tuple(ENGINE_DEFAULTS)
