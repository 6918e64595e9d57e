"""The recorder of a wear run: what `fabricfem run` writes while a garment moves on its wearer.

Under the output folder: cloth.xdmf (garment displacement [m] and contact pressure on the body [Pa] per record,
ParaView), body_NNNN.vtp + body.pvd (the posed body surfaces per record), torque.csv (SleeveHistory.HEADER),
torque.png, and pressure renders at the requested angles. It reads the run only through the wearer contract
(fabricfem.wear.contract.WearRun).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from dolfinx import fem
from dolfinx import io as dio

from fabricfem import io as fio
from fabricfem.wear.outputs import body_surface, plot_torque, render_pressure


class WearRecorder:
    """Writes the records of one WearRun into `out` (all ranks construct it and call `record` and `close`)."""

    def __init__(self, run, out: Path, render_angles: list[float], render: bool = True, body_samples: int = 24):
        self.run, self.out = run, Path(out)
        self.render, self.samples = render, body_samples
        self.pending = sorted(render_angles)
        comm = run.comm
        if comm.rank == 0:
            self.out.mkdir(parents=True, exist_ok=True)
        comm.barrier()
        model = run.model
        self.u_out = fem.Function(model.V2, name="displacement")
        self.p_out = fem.Function(fem.FunctionSpace(model.mesh, ("Lagrange", 2)), name="contact_pressure")
        self.xdmf = dio.XDMFFile(comm, str(self.out / "cloth.xdmf"), "w")
        self.xdmf.write_mesh(model.mesh)
        self.frames: list[tuple[float, str]] = []
        self.renders: list[str] = []     # names of the pressure renders written

    def record(self, step) -> None:
        """Write the record of `step` (its angle [deg] is the time coordinate of the files)."""
        run = self.run
        self.u_out.interpolate(run.model.displacement())
        self.p_out.interpolate(run.pressure_field())
        self.xdmf.write_function(self.u_out, step.angle)
        self.xdmf.write_function(self.p_out, step.angle)
        if run.comm.rank == 0:
            import pyvista as pv  # optional heavy package, loaded only when a render is made
            points, triangles = body_surface(run.posed_bodies(step.angle), self.samples)
            name = f"body_{len(self.frames):04d}.vtp"
            faces = np.hstack([np.full((len(triangles), 1), 3), triangles]).ravel()
            pv.PolyData(points, faces).save(str(self.out / name))
            self.frames.append((step.angle, name))
        while self.render and self.pending and step.angle >= self.pending[0] - 1e-9:
            angle = self.pending.pop(0)
            name = f"pressure_{angle:04.1f}deg.png"
            title = f"{run.config.name}: elbow {step.angle:.1f} deg, contact pressure [Pa]"
            render_pressure(self.out / name, run, title, step.angle)
            self.renders.append(name)

    def close(self, history) -> None:
        """Close the XDMF file and write torque.csv, body.pvd and torque.png."""
        self.xdmf.close()
        comm, config = self.run.comm, self.run.config
        fio.write_csv(self.out / "torque.csv", history.HEADER, history.rows(), comm)
        if comm.rank == 0:
            with open(self.out / "body.pvd", "w") as f:
                f.write('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n<Collection>\n')
                for angle, name in self.frames:
                    f.write(f'  <DataSet timestep="{angle}" file="{name}"/>\n')
                f.write("</Collection>\n</VTKFile>\n")
        plot_torque(self.out / "torque.png", {f"mu = {config.contact.friction}": (history.angles, history.torques)},
                    f"{config.name}: elbow resisting torque")
