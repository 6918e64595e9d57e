"""A cache of gmsh's meshes on disk: the cells, facets, tags and coordinates that fabricfem.meshes.gmsh_io reads from a
gmsh model, kept per generator and arguments, so that a run that meshes the same surface again skips gmsh.

Loading gmsh's library alone costs about 0.2 s per process (the dlopen of libgmsh), the meshing of the shipped
sleeve 0.03 s; the cached arrays load in a few milliseconds and give the same dolfinx mesh (the same arrays go into
dolfinx.mesh.create_mesh). The key is the caller's description of the mesh (the generator's source and arguments),
the source of gmsh_io (its extraction), this module's VERSION and the installed gmsh module's file stamp, so that a
change of any of them meshes again. Files: XDG_CACHE_HOME/fenics/fabricfem/meshes/<sha256>.npz (beside the compiled
kernels), written through a temporary name and a rename (two processes meshing at once leave one whole file). An
unreadable file is treated as missing, a failure to write is ignored. FABRICFEM_MESH_CACHE=0 switches the cache off
(the tests do, so that they exercise gmsh).
"""
from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import tempfile
from pathlib import Path

import numpy as np

VERSION = 1
ARRAYS = ("cells", "cell_values", "facets", "facet_values", "x")
SCALARS = ("tdim", "cell_type", "facet_type", "has_cell_tags", "names")


def folder() -> Path:
    """The cache folder (not created)."""
    return Path(os.getenv("XDG_CACHE_HOME", Path.home() / ".cache")) / "fenics" / "fabricfem" / "meshes"


def _gmsh_stamp() -> str:
    """The installed gmsh module's path, size and modification time ('' without gmsh); gmsh is not imported."""
    spec = importlib.util.find_spec("gmsh")
    if spec is None or spec.origin is None:
        return ""
    stat = Path(spec.origin).stat()
    return f"{spec.origin}:{stat.st_size}:{stat.st_mtime_ns}"


def enabled() -> bool:
    """False when FABRICFEM_MESH_CACHE is "0" (every mesh is then made by gmsh)."""
    return os.getenv("FABRICFEM_MESH_CACHE", "1") != "0"


def path_for(key: str) -> Path:
    """The cache file of the mesh described by `key` (a string naming the generator's code and arguments)."""
    digest = hashlib.sha256(f"{VERSION}|{_gmsh_stamp()}|{key}".encode()).hexdigest()
    return folder() / f"{digest}.npz"


def load(path: Path) -> dict | None:
    """The mesh data kept in `path` (the dict of gmsh_io's extraction), or None if missing, unreadable or not of
    that form (cells, facets and coordinates as 2-D arrays)."""
    try:
        with np.load(path, allow_pickle=False) as kept:
            data = {name: kept[name] for name in ARRAYS}
            header = json.loads(str(kept["header"]))
        data.update({name: header[name] for name in SCALARS})
    except Exception:      # noqa: BLE001  (any damage to the file is a miss: the mesh is made again)
        return None
    if not all(data[name].ndim == 2 for name in ("cells", "facets", "x")):
        return None
    return data


def save(path: Path, data: dict) -> None:
    """Keep the mesh data `data` (gmsh_io's extraction) in `path`; a failure to write leaves no file and is
    ignored (the next run meshes again)."""
    temporary = None
    try:
        header = json.dumps({name: data[name] for name in SCALARS}, default=lambda value: value.item())
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, temporary = tempfile.mkstemp(suffix=".npz", dir=path.parent)
        with os.fdopen(handle, "wb") as stream:
            np.savez(stream, header=np.array(header), **{name: np.asarray(data[name]) for name in ARRAYS})
        os.replace(temporary, path)
    except Exception:      # noqa: BLE001  (a cache that cannot be written only costs the next run gmsh)
        if temporary is not None and os.path.exists(temporary):
            os.unlink(temporary)
