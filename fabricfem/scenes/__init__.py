"""Scene files: TOML -> validated data (schema) -> objects (build) -> a run (run)."""
from fabricfem.scenes.build import build_fabric, build_mesh, critical_time_step_estimate, load, mesh_spacing, validate  # noqa: F401
from fabricfem.scenes.schema import Scene, SceneError  # noqa: F401
