"""The engines behind the trial protocol: :func:`make_runner` gives the runner of a
protocol's engine (harness.protocol.ENGINES), pybullet (:mod:`harness.physics.bullet`)
or MuJoCo (:mod:`harness.physics.mujoco_engine`). Each runner has ``run(trials,
frames=None, progress=None)`` giving the TrialResults in order, and is a context manager
that closes what the engine holds."""

from __future__ import annotations

from harness.protocol import Protocol


def make_runner(protocol: Protocol | None = None, batch_size: int = 16, early_stop: bool = True):
    """The runner of ``protocol``'s engine (pybullet by default): ``run(trials)`` gives
    the TrialResults in order; a context manager that closes the engine's resources."""
    protocol = protocol or Protocol()
    if protocol.engine == "mujoco":
        from harness.physics.mujoco_engine import MujocoRunner

        return MujocoRunner(protocol, batch_size, early_stop)
    from harness.physics.bullet import BulletRunner

    return BulletRunner(protocol, batch_size, early_stop)
