"""PNG frames of a MuJoCo trial, drawn with matplotlib from the model's geoms (MuJoCo's
own renderer needs an OpenGL context, which a headless machine may not have), and the
plan view of a blocked approach, shared by both engines."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

#: Colours (RGBA) of the object and the gripper, as in Bullet's frames.
OBJECT_RGBA = (0.85, 0.45, 0.15, 1.0)
GRIPPER_RGBA = (0.55, 0.57, 0.6, 1.0)
#: Half the side of the square of table drawn around the grasp (m).
VIEW_HALF = 0.08


class Frames:
    """Snapshots of one MuJoCo trial into ``folder``, one PNG per phase."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)

    def snapshot(self, name: str, slot) -> None:
        """The object and the gripper as they are now (the slot's kinematics current),
        seen from above and from the side like Bullet's frames."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection

        m, d = slot.model, slot.data
        elev, azim = 35.0, math.degrees(slot.heading) - 55.0
        fig = plt.figure(figsize=(6.4, 4.8))
        # Painted from the farthest geom to the nearest, the table first: matplotlib sorts
        # the faces within one collection only, and would paint the table over the object.
        ax = fig.add_subplot(projection="3d", computed_zorder=False)
        cx, cy = slot.centre
        table = [[(cx - VIEW_HALF, cy - VIEW_HALF, 0), (cx + VIEW_HALF, cy - VIEW_HALF, 0),
                  (cx + VIEW_HALF, cy + VIEW_HALF, 0), (cx - VIEW_HALF, cy + VIEW_HALF, 0)]]
        ax.add_collection3d(Poly3DCollection(table, facecolor=(0.8, 0.82, 0.78, 0.6)))
        e, a = math.radians(elev), math.radians(azim)
        towards = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
        drawn = []
        for geom in range(m.ngeom):
            if m.geom(geom).name in ("table", "foot"):
                continue
            faces = _faces(m, d, geom)
            colour = OBJECT_RGBA if m.geom_bodyid[geom] == slot.obj else GRIPPER_RGBA
            drawn.append((float(np.mean([f.mean(axis=0) @ towards for f in faces])), faces, colour))
        for _, faces, colour in sorted(drawn, key=lambda item: item[0]):
            ax.add_collection3d(Poly3DCollection(faces, facecolor=colour, edgecolor=(0, 0, 0, 0.25), linewidths=0.3))
        ax.set_xlim(cx - VIEW_HALF, cx + VIEW_HALF)
        ax.set_ylim(cy - VIEW_HALF, cy + VIEW_HALF)
        ax.set_zlim(0.0, 2 * VIEW_HALF)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=elev, azim=azim)
        ax.set_axis_off()
        ax.set_title(f"MuJoCo: {name}")
        fig.savefig(self.folder / f"{name}.png", dpi=100)
        plt.close(fig)

    def footprint(self, trial) -> None:
        draw_footprint(trial, self.folder)


def _faces(m, d, geom: int) -> list:
    """The triangles (world frame) of a mesh geom, or the six faces of a box geom."""
    import mujoco

    pos, rot = d.geom_xpos[geom], d.geom_xmat[geom].reshape(3, 3)
    if m.geom_type[geom] == mujoco.mjtGeom.mjGEOM_MESH:
        mesh = m.geom_dataid[geom]
        v0, nv = m.mesh_vertadr[mesh], m.mesh_vertnum[mesh]
        f0, nf = m.mesh_faceadr[mesh], m.mesh_facenum[mesh]
        vertices = m.mesh_vert[v0:v0 + nv] @ rot.T + pos
        return [vertices[face] for face in m.mesh_face[f0:f0 + nf]]
    hx, hy, hz = m.geom_size[geom]
    corners = np.array([[sx * hx, sy * hy, sz * hz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    corners = corners @ rot.T + pos
    quads = ((0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5))
    return [corners[list(q)] for q in quads]


def draw_footprint(trial, folder: Path) -> None:
    """A plan view of why the approach was blocked: the object and the pads."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from harness.physics.trial import pad_footprints

    fig, ax = plt.subplots(figsize=(5, 5))
    for geom, colour in [(trial.polygon, "tab:orange"), *[(pad, "tab:grey") for pad in pad_footprints(trial)]]:
        for ring in [geom.exterior, *geom.interiors]:
            xy = np.asarray(ring.coords)
            ax.fill(xy[:, 0], xy[:, 1], color=colour, alpha=0.6 if colour == "tab:grey" else 1.0)
    ax.set_aspect("equal")
    ax.set_title("approach_collision: a jaw pad comes down on the object")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    fig.savefig(Path(folder) / "1-approach_collision.png", dpi=100)
    plt.close(fig)
