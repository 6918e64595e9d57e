"""The wall split of one `fabricfem run SCENE` measured from outside the code, so that two commits are measured the
same way (docs/findings/2026-11-27-output-cost.md):

    PYTHONPATH=<worktree of the commit> .venv/bin/python scripts/wall_split.py OUT [SCENE]   # scenes/sleeve.toml
    NULL_OUTPUT=1 ... scripts/wall_split.py OUT        # the records and checkpoints not written: the loop's floor

prints one JSON line "SPLIT {...}" on stderr [s]: imports (process start -> fabricfem.cli imported), build
(build_wear_run), setup (process start -> GarmentRun.run), loop (GarmentRun.run), output_in_loop (WearRecorder.record
and Checkpoint.save inside the loop), after (loop end -> run_wear's return), the loop's process CPU (all threads) and
main-thread CPU, and the run's own summary.json wall_split where the commit writes one. Linux only (/proc/self/stat).
"""
import contextlib
import io
import json
import os
import sys
import time


def age() -> float:
    """Seconds since this process started."""
    with open("/proc/self/stat") as f:
        ticks = float(f.read().rsplit(")", 1)[1].split()[19])
    return time.clock_gettime(time.CLOCK_BOOTTIME) - ticks / os.sysconf("SC_CLK_TCK")


acc = {"output": 0.0}


def wrap(owner, name: str, fn) -> None:
    original = getattr(owner, name)
    setattr(owner, name, lambda *a, **k: fn(original, *a, **k))


from fabricfem.cli import main  # noqa: E402  (after the clock functions: the import is measured)

acc["imports"] = age()
from fabricfem.scenes import run as scene_run  # noqa: E402
from fabricfem.wear import checkpoint, garment, recorder  # noqa: E402


def timed_output(f, *a, **k):
    tic = time.perf_counter()
    try:
        return f(*a, **k)
    finally:
        acc["output"] += time.perf_counter() - tic


def timed_loop(f, *a, **k):
    acc["loop_start"], cpu, main_cpu = age(), time.process_time(), time.thread_time()
    result = f(*a, **k)
    acc["loop_end"], acc["output_loop"] = age(), acc["output"]
    acc["loop_cpu"], acc["loop_main_cpu"] = time.process_time() - cpu, time.thread_time() - main_cpu
    return result


def timed_build(f, *a, **k):
    start = age()
    result = f(*a, **k)
    acc["build"] = age() - start
    return result


def timed_wear(f, *a, **k):
    result = f(*a, **k)
    acc["after_end"] = age()
    return result


if os.environ.get("NULL_OUTPUT"):
    recorder.WearRecorder.record = lambda self, step: None
    checkpoint.Checkpoint.save = lambda self, *a, **k: None
wrap(recorder.WearRecorder, "record", timed_output)
wrap(checkpoint.Checkpoint, "save", timed_output)
wrap(garment.GarmentRun, "run", timed_loop)
wrap(scene_run, "run_wear", timed_wear)
wrap(scene_run, "build_wear_run", timed_build)
out = sys.argv[1]
sys.argv = ["fabricfem", "run", sys.argv[2] if len(sys.argv) > 2 else "scenes/sleeve.toml", "--out", out]
with contextlib.redirect_stdout(io.StringIO()):
    try:
        main()
    except SystemExit:
        pass
split = {"imports_s": acc["imports"], "build_s": acc["build"], "setup_s": acc["loop_start"],
         "loop_s": acc["loop_end"] - acc["loop_start"], "output_in_loop_s": acc["output_loop"],
         "after_s": acc["after_end"] - acc["loop_end"], "loop_cpu_s": acc["loop_cpu"],
         "loop_main_cpu_s": acc["loop_main_cpu"]}
with open(os.path.join(out, "summary.json")) as f:
    split["summary_wall_split"] = json.load(f).get("wall_split")
print("SPLIT " + json.dumps(split), file=sys.stderr)
