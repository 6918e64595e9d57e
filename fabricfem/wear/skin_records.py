"""The contact pressure on a mesh skin over a wear run's records (fabricfem.body.skin_pressure).

For a run whose body contact searches a `MeshSkin` (a `[body] type = "mesh"` scene), every record writes the
pressure [Pa] that the cloth nodes in contact put on the skin's vertices at that step (their last step's normal
forces [N], spread by the barycentric coordinates of their feet, over the vertices' lumped areas) into the run's
output folder: `skin_pressure.xdmf` (+ .h5: the rest mesh, per record the pressure and the displacement from the
rest pose) and `skin_pressure_<k>.vtp` (the posed skin with its pressure). Nothing for the other skins.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from fabricfem.body.mesh_skin import MeshSkin
from fabricfem.body.skin_pressure import SkinPressureWriter

STEM = "skin_pressure"


class SkinPressureRecords:
    """`SkinPressureWriter` of the run's mesh skin (`of`: None when the run has none)."""

    def __init__(self, run, out: Path):
        self.run = run
        self.writer = SkinPressureWriter(out, STEM, run.contact.skin, run.comm)

    @classmethod
    def of(cls, run, out: Path) -> SkinPressureRecords | None:
        skin = getattr(getattr(run, "contact", None), "skin", None)
        return cls(run, out) if isinstance(skin, MeshSkin) else None

    def record(self) -> None:
        """Write the pressure of the last step (the contact's node positions [m] and normal forces [N]) on the skin
        posed at the run's time (all ranks call it)."""
        contact = self.run.contact
        force = getattr(contact, "normal_force", None)
        position = getattr(contact, "position", None)
        if force is None or position is None:
            force, position = np.zeros(0), np.zeros((0, 3))
        on = force > 0.0
        self.writer.write(self.run.integrator.t, position[on], force[on])

    def close(self) -> None:
        self.writer.close()
