"""The package's import structure (docs/architecture.md): imports only go down the layers, no circles, and
function-level imports only for optional heavy packages, each with its reason on the line."""
import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# optional packages, and heavy ones a run may not need (trimesh: mesh skins only; scipy: gait curves), each
# imported at first use with a comment saying why
OPTIONAL = {"pyvista", "matplotlib", "mpl_toolkits", "gmsh", "slepc4py", "trimesh", "scipy", "vtkmodules", "PIL"}


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


def test_citations_resolve_to_the_references():
    """Every citation key used in code and docs ([Key, place] or [Key]) is listed in docs/references.md; no source
    is cited as "seed 00x" or "thesis 000", and no issue number stands as a citation outside docs/findings."""
    import re
    listed = set(re.findall(r"^\| ([A-Z][A-Za-z]+[0-9]{4}[a-z]?) \|", (ROOT / "docs" / "references.md").read_text(),
                            flags=re.M))
    files = [p for p in (ROOT / "fabricfem").rglob("*.py")] + list((ROOT / "tests").glob("*.py"))
    files += [p for p in (ROOT / "docs").rglob("*.md") if "findings" not in p.parts] + [ROOT / "README.md"]
    unknown, old_style = set(), []
    for path in files:
        text = path.read_text()
        unknown |= set(re.findall(r"\[([A-Z][A-Za-z]+[0-9]{4}[a-z]?)(?:,[^\]]*)?\]", text)) - listed
        if path.name != "test_layers.py" and path.name not in ("verification.md", "reproduction.md"):
            old_style += [f"{path.name}: {m}" for m in re.findall(r"[Ss]eed 00\d|thesis 000|\bissue \d{1,3}\b", text)]
    assert not unknown, sorted(unknown)
    assert not old_style, old_style
