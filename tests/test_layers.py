"""The package's import structure (docs/architecture.md): imports only go down the layers, no circles, and
function-level imports only for optional heavy packages, each with its reason on the line."""
import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OPTIONAL = {"pyvista", "matplotlib", "mpl_toolkits", "gmsh", "slepc4py"}


def test_import_linter_contracts_are_kept():
    lint = Path(sys.executable).with_name("lint-imports")
    done = subprocess.run([str(lint)], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr


def test_function_level_imports_only_for_optional_packages_with_a_reason():
    offenders = []
    for path in sorted((ROOT / "fabricfem").rglob("*.py")):
        lines = path.read_text().splitlines()
        for fn in ast.walk(ast.parse("\n".join(lines))):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if isinstance(node, (ast.Import, ast.ImportFrom)):
                    module = node.module if isinstance(node, ast.ImportFrom) else node.names[0].name
                    if module.split(".")[0] not in OPTIONAL or "#" not in lines[node.end_lineno - 1]:
                        offenders.append(f"{path.relative_to(ROOT)}:{node.lineno} {module}")
    assert not offenders, offenders


def test_layers_are_the_folders():
    """forms and meshes are plain subpackages (no package-dir remap), and no top-level folder shadows them."""
    assert (ROOT / "fabricfem" / "forms" / "__init__.py").exists()
    assert (ROOT / "fabricfem" / "meshes" / "__init__.py").exists()
    assert not (ROOT / "forms").exists() and not (ROOT / "meshes").exists()
    assert "package-dir" not in (ROOT / "pyproject.toml").read_text()
