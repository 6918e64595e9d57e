#!/usr/bin/env bash
# Idempotent set-up for a fresh Debian bookworm machine:
#   1. Debian packages (dolfinx 0.5.2 stack, gmsh, meshio + h5py, OpenMPI) via apt, as root or with sudo;
#   2. a virtual environment .venv from /usr/bin/python3 --system-site-packages;
#   3. the project installed editable, numpy and scipy pinned to Debian's (numpy 2 breaks petsc4py); ezc3d (C3D
#      files) comes with it: should pip ever want another numpy for it, install it with --no-deps instead;
#   4. optional test data: Debian assimp-testmodels (CMU motion-capture BVH files in
#      /usr/share/assimp/models/BVH/, used by the mocap-roundtrip verify case), only as root with apt-get;
#      its absence never fails the bootstrap (the case and test skip the CMU rows);
#   5. optional test package: opensim (OpenSim's readers of torque.sto), pip --no-deps; its absence fails nothing.
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
cd "$here"
VENV="${FABRICFEM_VENV:-$here/.venv}"
# h5py (meshio reads the HDF5 data of XDMF files with it) must be Debian's, built against the HDF5 1.10 that
# dolfinx loads: a pip wheel of h5py bundles another HDF5 and fails to import after dolfinx ("Not a datatype").
# python3-h5py-mpi is the flavour Debian's h5py picks under mpirun.
DEBS="python3-dolfinx python3-petsc4py python3-mpi4py python3-gmsh python3-meshio python3-venv \
python3-dolfinx-mpc python3-scipy openmpi-bin python3-h5py python3-h5py-mpi"

missing=""
for p in $DEBS; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
if [ -n "$missing" ]; then
  echo "[bootstrap] installing Debian packages:$missing"
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $missing
fi

if [ ! -x "$VENV/bin/python" ]; then
  echo "[bootstrap] creating $VENV"
  /usr/bin/python3 -m venv --system-site-packages "$VENV"
fi

stamp="$VENV/.fabricfem-installed"
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  numpy_version="$(/usr/bin/python3 -c 'import numpy; print(numpy.__version__)')"
  scipy_version="$(/usr/bin/python3 -c 'import scipy; print(scipy.__version__)')"
  # scipy pinned to Debian's too: a newer scipy from pip (scikit-image's latest wants one) changes the numbers of
  # the verified cases (the generalized-alpha dissipation test measured 3 % off with scipy 1.15), and pip then
  # picks the scikit-image release that accepts Debian's scipy
  printf 'numpy==%s\nscipy==%s\n' "$numpy_version" "$scipy_version" > "$VENV/constraints.txt"
  echo "[bootstrap] installing fabricfem (editable), numpy pinned to $numpy_version"
  "$VENV/bin/python" -m pip install -q --disable-pip-version-check -c "$VENV/constraints.txt" -e ".[dev]"
  touch "$stamp"
fi

if [ ! -d /usr/share/assimp/models/BVH ] && [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "[bootstrap] installing optional test data: assimp-testmodels (CMU BVH files)"
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends assimp-testmodels \
    || echo "[bootstrap] assimp-testmodels not installed (optional: the CMU rows of mocap-roundtrip are skipped)"
fi

if ! "$VENV/bin/python" -c "import opensim" 2>/dev/null; then
  echo "[bootstrap] installing optional test package: opensim (reads torque.sto in tests/test_wear_run_files.py)"
  # --no-deps: its wheel declares numpy>=2.1, the Debian numpy pinned above is 1.24 (enough for reading .sto files)
  "$VENV/bin/python" -m pip install -q --disable-pip-version-check --no-deps opensim \
    || echo "[bootstrap] opensim not installed (optional: the OpenSim reader test is skipped)"
fi

# h5py through --system-site-packages (Debian's; see DEBS), importable next to dolfinx
if ! "$VENV/bin/python" -c "import dolfinx, h5py" 2>/dev/null; then
  echo "[bootstrap] h5py does not import next to dolfinx in $VENV: install Debian's python3-h5py and remove any" \
       "pip-installed h5py ($VENV/bin/python -m pip uninstall h5py)" >&2
  exit 1
fi
