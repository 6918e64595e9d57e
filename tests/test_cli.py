"""The command line (fabricfem.cli): the global flags before and after the command, a handler for every
(sub)command, one-line input errors with exit code 2, --json output, the studies' default output folders, and one
short real run."""
import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fabricfem import cli
from fabricfem import scenes as scene_module
from fabricfem.cli import bench as cli_bench
from fabricfem.cli import study as cli_study
from fabricfem.launch import child_environment
from fabricfem.scenes import SceneError
from fabricfem.scenes.ranks import SERIAL_BELOW_DOFS, estimated_scene_dofs

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = {"run", "plan", "sweep", "scenes", "demo", "verify", "reproduce", "study", "bench"}
STUDIES = {"sleeve", "sleeve-fit", "sleeve-methods", "unit-cell", "fabric-link", "pants", "convergence"}
BENCHES = {"rollup-profile", "stability-map", "speed-accuracy", "sleeve-profile", "accuracy", "unit-cell", "wear",
           "kernel", "commits", "parallel"}


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The subcommand parsers of `parser` by name ({} for a leaf)."""
    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(actions[0].choices) if actions else {}


def _leaves(parser: argparse.ArgumentParser, words: tuple[str, ...] = ()):
    """(words, parser) of every command that runs something: the leaves and `bench` (bench alone is rollup-profile)."""
    children = _subcommands(parser)
    if not children or parser.get_default("handler") is not None:
        yield words, parser
    for name, child in children.items():
        yield from _leaves(child, words + (name,))


@pytest.mark.parametrize("flag", ["--debug", "--verbose", "--json"])
@pytest.mark.parametrize("where", ["before", "after"])
def test_global_flags_before_or_after_the_command(flag, where):
    """`fabricfem run scenes/sleeve.toml --debug` (as README writes it) and `fabricfem --debug run ...` both set the
    flag, and the other flags stay False."""
    argv = [flag, "run", "scenes/sleeve.toml"] if where == "before" else ["run", "scenes/sleeve.toml", flag]
    args = cli.build_parser().parse_args(argv)
    name = flag.lstrip("-")
    assert getattr(args, name) is True
    assert all(getattr(args, other) is False for other in {"debug", "verbose", "json"} - {name})
    assert args.command == "run" and args.scene == "scenes/sleeve.toml"


def test_global_flags_after_a_nested_command():
    """A flag given before the command is not reset by the subcommand; nested commands take them too."""
    args = cli.build_parser().parse_args(["--verbose", "study", "sleeve", "--quick", "--debug"])
    assert (args.verbose, args.debug, args.json, args.quick, args.command) == (True, True, False, True,
                                                                                "study sleeve")
    args = cli.build_parser().parse_args(["bench", "--json", "wear", "--verbose"])
    assert (args.json, args.verbose, args.debug, args.command) == (True, True, False, "bench wear")


def test_every_command_has_its_handler():
    """Every command (and study and bench name) sets a handler and its words; `bench` alone is rollup-profile into
    results/bench."""
    parser = cli.build_parser()
    commands = _subcommands(parser)
    assert set(commands) == COMMANDS
    assert set(_subcommands(commands["study"])) == STUDIES and set(_subcommands(commands["bench"])) == BENCHES
    leaves = dict(_leaves(parser))
    assert len(leaves) == len(COMMANDS) - 2 + len(STUDIES) + 1 + len(BENCHES)
    for words, leaf in leaves.items():
        assert callable(leaf.get_default("handler")), words
        assert leaf.get_default("command") == " ".join(words), words
    assert commands["study"].get_default("handler") is None
    bare = parser.parse_args(["bench"])
    assert (bare.command, bare.out) == ("bench", cli_bench.BENCH_OUT)


@pytest.mark.parametrize("debug", [[], ["--debug"]])
def test_missing_scene_is_one_line_and_exit_2(debug, capsys):
    """An input error: one line on stderr naming the file, exit code 2; with --debug after the command: the
    exception itself."""
    if debug:
        with pytest.raises(SceneError, match="nonexistent.toml"):
            cli.main(["run", "nonexistent.toml", *debug])
        return
    assert cli.main(["run", "nonexistent.toml"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fabricfem run: ") and "nonexistent.toml" in err[0]


@pytest.mark.parametrize("argv", [["verify", "--list", "--json"], ["--json", "reproduce", "--list"]])
def test_list_as_json(argv, capsys):
    """`fabricfem verify --list --json`: a JSON list of names and descriptions alone on stdout."""
    assert cli.main(argv) == 0
    records = json.loads(capsys.readouterr().out)
    assert records and all(set(r) == {"name", "description"} for r in records)


def test_option_errors_name_the_subcommand(capsys):
    """A bad option value: one line beginning with the command's words and naming the option, exit code 2."""
    assert cli.main(["study", "sleeve", "--mesh-frictions", "0.1,x"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fabricfem study sleeve: --mesh-frictions"), err
    assert cli.main(["study", "pants", "--ranks-per-variant", "0"]) == 2
    assert "--ranks-per-variant" in capsys.readouterr().err


def test_study_defaults(monkeypatch):
    """Each study's own default output and mesh (sleeve-fit mesh II, sleeve-methods III); the fit files' prefix."""
    seen = {}
    monkeypatch.setattr(cli_study, "run_pants_study", lambda out, quick, ranks_per_variant: seen.update(pants=out))
    monkeypatch.setattr(cli_study, "run_methods", lambda out, mesh, **kw: seen.update(methods=(out, mesh)))
    monkeypatch.setattr(cli_study, "run_fit_study",
                        lambda out, mesh, prefix, **kw: seen.update(fit=(out, mesh, prefix)))
    assert cli.main(["study", "pants"]) == 0
    assert cli.main(["study", "sleeve-methods"]) == 0
    assert cli.main(["study", "sleeve-fit", "--scales", "1"]) == 0
    assert seen == {"pants": "results/pants_study", "methods": ("results/sleeve_methods_gravity.csv", "III"),
                    "fit": ("results/sleeve_fit", "II", "fit_sensitivity")}
    assert cli.main(["study", "sleeve-fit", "--scales", "1", "--mesh", "I", "--full-quadrature",
                     "--angular-velocity", "90", "--out", "elsewhere"]) == 0
    assert seen["fit"] == ("elsewhere", "I", "fit_sensitivity_omega90_fullquad.meshI")


def test_rollup_run_with_flags_after_the_command(tmp_path, capsys):
    """A real short run (the rolled strip, about 15 s): `fabricfem run scenes/rollup.toml --out DIR --debug --json`
    exits 0 and prints its summary.json alone on stdout."""
    out = tmp_path / "rollup"
    assert cli.main(["run", str(ROOT / "scenes" / "rollup.toml"), "--out", str(out), "--debug", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["status"] == "completed" and summary == json.loads((out / "summary.json").read_text())


def test_plan_as_json(tmp_path, capsys):
    """`fabricfem plan SCENE --accuracy 10% --quantity probe_ux_m --json` (a 16x4 rolled strip, a few seconds): the
    plan alone on stdout as JSON, its levels keyed by the table's columns, the chosen level among them."""
    scene = (ROOT / "scenes" / "rollup.toml").read_text()
    scene = scene.replace("nx = 60", "nx = 16").replace("ny = 3", "ny = 4").replace("results/rollup", str(tmp_path))
    (tmp_path / "strip.toml").write_text(scene)
    assert cli.main(["plan", str(tmp_path / "strip.toml"), "--accuracy", "10%", "--quantity", "probe_ux_m",
                     "--json"]) == 0
    plan = json.loads(capsys.readouterr().out)
    assert plan["quantity"] == "probe_ux_m" and plan["target"] == 0.1
    assert plan["chosen"] in [level["level"] for level in plan["levels"] if level["solved"]]


def test_a_small_scene_under_mpirun_runs_on_rank_0_alone(tmp_path):
    """`mpirun -n 2 fabricfem run` of a scene below SERIAL_BELOW_DOFS (the vibrating cantilever, about 600 dofs)
    runs on rank 0 alone and says so (summary.json: 1 rank); with --all-ranks on both."""
    if shutil.which("mpirun") is None:
        pytest.skip("needs mpirun")
    root = Path(__file__).resolve().parents[1]
    assert estimated_scene_dofs(scene_module.load(root / "scenes" / "cantilever_vibration.toml")) < SERIAL_BELOW_DOFS
    scene = root / "scenes" / "cantilever_vibration.toml"
    command = ["mpirun", "-n", "2", sys.executable, "-m", "fabricfem.cli", "run", str(scene)]
    for extra, ranks in (([], 1), (["--all-ranks"], 2)):
        out = tmp_path / str(ranks)
        done = subprocess.run(command + extra + ["--out", str(out)], capture_output=True, text=True,
                              env=child_environment())
        assert done.returncode == 0, done.stderr
        assert ("rank 0 runs it alone" in done.stdout) == (ranks == 1)
        assert json.loads((out / "summary.json").read_text())["ranks"] == ranks


def test_a_child_does_not_inherit_this_process_s_mpi_job(monkeypatch):
    """This process has started MPI (mpi4py, imported by fabricfem: a singleton job, whose variables live in the C
    environment only): a child started with the inherited environment sees the job's PMIX_ variables (the check
    bites), one started with fabricfem.launch.child_environment() none. The filter itself, for a process started
    under mpirun (its job's variables in os.environ): PMIX_RANK and OMPI_COMM_WORLD_SIZE are dropped, an unrelated
    variable is kept and the mpirun settings are added."""
    code = "import os; print(sorted(k for k in os.environ if k.startswith(('PMIX_', 'OMPI_MCA_ess'))))"
    inherited = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).stdout
    clean = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           env=child_environment()).stdout
    assert "PMIX_RANK" in inherited and clean.strip() == "[]"
    monkeypatch.setenv("PMIX_RANK", "1")
    monkeypatch.setenv("OMPI_COMM_WORLD_SIZE", "2")
    monkeypatch.setenv("FABRICFEM_TEST_KEPT", "yes")
    env = child_environment({"EXTRA": "1"})
    assert "PMIX_RANK" not in env and "OMPI_COMM_WORLD_SIZE" not in env
    assert env["FABRICFEM_TEST_KEPT"] == "yes" and env["EXTRA"] == "1" and env["OMPI_ALLOW_RUN_AS_ROOT"] == "1"


LEAVE_SCRIPT = """
import sys, time
from mpi4py import MPI
from fabricfem.cli.common import leave_together
world = MPI.COMM_WORLD
exit_comm = world.Dup()
if sys.argv[1] == "both" or world.rank == 0:
    print("code", leave_together(exit_comm, 2, "a test error", wait=2.0), flush=True)
else:
    world.bcast(None, root=0)      # rank 0 never sends: a rank left waiting in a collective
"""


@pytest.mark.parametrize("who", ["both", "rank0"])
def test_ranks_leave_together_or_the_job_is_aborted(who, tmp_path):
    """fabricfem.cli.common.leave_together under `mpirun -n 2`: when both ranks stop with the error they leave with
    its code at once; when rank 0 alone stops and rank 1 waits in a collective, rank 0 says so and aborts the job
    after the wait (2 s here) instead of hanging (the subprocess's own bound, 120 s, would catch a hang)."""
    if shutil.which("mpirun") is None:
        pytest.skip("needs mpirun")
    script = tmp_path / "leave.py"
    script.write_text(LEAVE_SCRIPT)
    started = time.monotonic()
    done = subprocess.run(["mpirun", "-n", "2", sys.executable, str(script), who], capture_output=True, text=True,
                          env=child_environment(), timeout=120)
    if who == "both":
        assert done.returncode == 0 and done.stdout.count("code 2") == 2, done.stderr
    else:
        assert done.returncode != 0 and "aborting the MPI job" in done.stderr and "a test error" in done.stderr
        assert time.monotonic() - started < 60
