"""The scaled arc length of fabricfem.solvers.arclength: one ds traces the same path on meshes of different size,
and the worked example of docs/guide.md (the snap-through of a shallow arch) runs as written."""
import re
from pathlib import Path

import numpy as np
import pytest

from fabricfem.solvers.arclength import arc_length

ROOT = Path(__file__).resolve().parents[1]
SECTION = "## Tracing a snap-through (arc length)"


def guide_example() -> tuple[str, str]:
    """The first python block of the section SECTION of docs/guide.md, and the line the guide says it prints."""
    text = (ROOT / "docs" / "guide.md").read_text()
    assert SECTION in text, "the worked example is missing from docs/guide.md"
    section = text.split(SECTION, 1)[1]
    code = re.search(r"```python\n(.*?)```", section, flags=re.S).group(1)
    printed = re.search(r"It prints\n\n```\n(.*?)\n```", section, flags=re.S).group(1)
    return code, printed


@pytest.fixture(scope="module")
def example():
    """The guide's block executed once: its namespace and what it printed."""
    code, printed = guide_example()
    lines = []
    namespace = {"print": lambda *args: lines.append(" ".join(str(a) for a in args))}
    exec(compile(code, "docs/guide.md", "exec"), namespace)
    return namespace, lines, printed


def test_guide_example_prints_what_the_guide_says(example):
    """The block passes the limit point (the load rises to a maximum, then falls while the crown goes on down)
    and prints the line the guide quotes."""
    namespace, lines, printed = example
    assert lines == [printed]
    path = np.array(namespace["path"])
    k = int(np.argmax(path[:, 0]))
    assert 0 < k < len(path) - 1 and path[-1, 0] < 0.8 * path[k, 0]
    assert np.all(np.diff(path[:, 1]) > 0)                  # the crown moves down all the way


def test_same_ds_traces_the_same_path_on_two_meshes(example):
    """The example's half arch on 8 and on 24 cells (255 and 735 unknowns) with the same ds = 0.1: both converge
    through the limit point at the same step, with limit loads within 0.5 % and crown deflections at each step
    within 2 % of the rise (the paths are sampled alike). The state vector's norm alone (the former step) made
    the steps of the finer mesh sqrt(735 / 255) = 1.7 times shorter in displacement."""
    snap_through, rise = example[0]["snap_through"], example[0]["RISE"]
    coarse, fine = (np.array(snap_through(n, ds=0.1, max_steps=30)) for n in (8, 24))
    assert len(coarse) == len(fine) == 30
    k = int(np.argmax(coarse[:, 0]))
    assert 0 < k < 29 and int(np.argmax(fine[:, 0])) == k
    assert fine[k, 0] == pytest.approx(coarse[k, 0], rel=5e-3)
    assert np.max(np.abs(fine[:, 1] - coarse[:, 1])) < 0.02 * rise


def test_u_ref_is_checked_and_reported():
    """u_ref must be a positive length; the one used is reported by every step."""
    from fabricfem.materials import Fabric
    from fabricfem.meshes import plate
    from fabricfem.shell import ShellModel
    model = ShellModel(plate(1.0, 0.1, 4, 1, cell="quadrilateral"), Fabric.isotropic(1e6, 0.0, 1e-3))
    model.clamp("left")
    model.add_edge_traction("right", (0.0, 0.0, -1e-3))
    with pytest.raises(ValueError, match="^u_ref:"):
        arc_length(model, ds=0.1, max_steps=1, u_ref=0.0)
    steps = arc_length(model, ds=0.1, max_steps=2, u_ref=0.25)
    assert [s.u_ref for s in steps] == [0.25, 0.25]
