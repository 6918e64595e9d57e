"""Fabric meshes: gmsh-built 2D manifolds in 3D with material directions.

Every mesh is a :class:`FabricMesh` (coordinates in metres) carrying the
warp direction E1 (first material direction), the reference normal N and,
derived from them, the weft direction E2 = N x E1.
"""
from .gmsh_io import FabricMesh, mesh_from_gmsh, model_to_mesh
from .plate import plate
from .revolved import annulus, spherical_cap
from .tube import cylindrical_panel, tube

__all__ = ["FabricMesh", "mesh_from_gmsh", "model_to_mesh", "plate", "tube", "cylindrical_panel", "annulus",
           "spherical_cap"]

# Woven unit cells (3D hexahedral yarn meshes, [Man2006, ch. 4.3])
from .unit_cell import MeshResolution, UnitCellMesh, unit_cell  # noqa: E402
from .yarn_geometry import PlainWeave, YarnFamily, YarnPath, amplitude_from_crimp, check_weave  # noqa: E402

__all__ += ["MeshResolution", "UnitCellMesh", "unit_cell", "PlainWeave", "YarnFamily", "YarnPath",
            "amplitude_from_crimp", "check_weave"]

# Sewing patterns: panels, stitches, readers (GarmentCode JSON, TOML) and their meshing and placement
from .pattern import (  # noqa: E402
           Edge,
           Panel,
           Pattern,
           Stitch,
           check_pattern,
           pattern_from_dict,
           read_garmentcode,
           read_pattern_toml,  # noqa: E402
)
from .pattern_mesh import GarmentMesh, SeamPairs, mesh_pattern, wrap_on_cylinder  # noqa: E402

__all__ += ["Edge", "Panel", "Pattern", "Stitch", "check_pattern", "pattern_from_dict", "read_garmentcode",
            "read_pattern_toml", "GarmentMesh", "SeamPairs", "mesh_pattern", "wrap_on_cylinder"]
