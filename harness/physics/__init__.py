"""Physics trials: extruded shapes, a parallel-jaw gripper, one trial and its rules
(engine-neutral), and the engines that run it: pybullet (the default) and MuJoCo."""

import ctypes
import os
import sys


def _import_pybullet_quietly():
    """pybullet writes its build time to stderr when first imported; users of the
    command line would see it above every result. Import it with fd 2 pointed at
    /dev/null (an import error still raises, and is reported after the restore)."""
    if "pybullet" in sys.modules:
        return
    sys.stderr.flush()
    saved = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        import pybullet  # noqa: F401

        ctypes.CDLL(None).fflush(None)  # the message may sit in C's stdio buffer
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


_import_pybullet_quietly()
