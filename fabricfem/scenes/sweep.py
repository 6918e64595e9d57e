"""`fabricfem sweep SCENE --vary key=v1,v2,... [--vary ...]`: the variants of a scene as one MPI batch.

Each `--vary` names a dotted scene key (`fabric.E1`, `dynamics.dt_fraction`, `mesh.nx`, `load.0.value` for an
array of tables) and its values, parsed as TOML values (`1e6`, `true`, `"triangle"`, `[0, 0, -9.81]`; a bare word
is a string). The variants are the cartesian product of the lists, in the order given (the last key varies
fastest). Each is the scene with those keys replaced, validated completely (fabricfem.scenes.build.validate)
before anything runs: a bad key or value is refused naming the variant and the key. A variant runs into its own
folder `<out>/<name>/` (name from its key=value pairs) with fabricfem.scenes.run.run_scene as one batch
(fabricfem.scenes.batch.run_batch: sub-communicators of `ranks_per_variant` ranks, longest first by
`estimated_cost` to the least loaded group). Resumable: a variant whose folder holds a summary.json with status
"completed" and the variant's scene hash (run.scene_sha256) is read back, not rerun. Rank 0 writes `<out>/sweep.csv` (the variant's
keys, its status and the scalar entries of its summary.json; numeric lists flattened as `<key>_<i>`) and
`<out>/sweep.png` (one summary quantity against the first varied key, one curve per combination of the others; by
default the scene's [accuracy] quantity or the largest of the quantities it monitors, e.g. a drape's probe_uz_m;
axes with units, a title naming the scene). The probe's displacement is in the table once, as probe_u{x,y,z}_m.
"""
from __future__ import annotations

import copy
import dataclasses
import itertools
import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from mpi4py import MPI

from fabricfem.parameters import param_doc
from fabricfem.scenes.batch import Job, completed, groups_of, read_summary, run_batch, write_table
from fabricfem.scenes.build import estimated_cost, scene_name, validate
from fabricfem.scenes.contract import SECTIONS_OF
from fabricfem.scenes.dynamic import monitor_unit
from fabricfem.scenes.run import run_scene, scene_sha256
from fabricfem.scenes.schema import Scene, SceneError, accuracy_quantities

# summary.json entries that describe the run, not its result (left out of the default plot quantity)
BOOKKEEPING = {"ranks", "ndofs", "wall_s", "time_integration_wall_s", "peak_memory_mib", "peak_memory_total_mib",
               "steps", "load_steps", "dt_s", "dt_crit_s", "end_time_s", "newton_iterations"}
# summary.json lists whose values the summary also gives one by one under these names (left out of sweep.csv)
DUPLICATES = {"probe_displacement_m": ("probe_ux_m", "probe_uy_m", "probe_uz_m")}
# the unit of a summary entry from its name's suffix, the longer suffixes first
UNIT_SUFFIXES = (("_N_per_m", "N/m"), ("_Nm", "N m"), ("_mmHg", "mmHg"), ("_kPa", "kPa"), ("_Pa", "Pa"),
                 ("_mib", "MiB"), ("_J", "J"), ("_N", "N"), ("_m", "m"), ("_s", "s"))


@dataclass
class Variant:
    """One variant of a sweep: its name (folder), its varied {key: value} and its validated scene."""

    name: str
    values: dict
    scene: Scene


def parse_value(text: str):
    """A TOML value (`1e6`, `true`, `"a"`, `[1, 2]`), or the text itself when it is not one (a bare word)."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text.strip()


def _split_values(text: str) -> list[str]:
    """Split `v1,v2,...` at the commas outside brackets and quotes."""
    parts, depth, quote, start = [], 0, "", 0
    for i, c in enumerate(text):
        if quote:
            quote = "" if c == quote else quote
        elif c in "\"'":
            quote = c
        elif c in "[{":
            depth += 1
        elif c in "]}":
            depth -= 1
        elif c == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    parts.append(text[start:])
    return [p.strip() for p in parts if p.strip()]


def parse_vary(text: str) -> tuple[str, list]:
    """(key, values) of one `--vary key=v1,v2,...`; ValueError naming it when malformed."""
    key, sep, values = text.partition("=")
    key = key.strip()
    if not sep or not key or not _split_values(values):
        raise ValueError(f"--vary {text!r}: expected key=v1,v2,... (e.g. fabric.E1=1e6,2e6)")
    return key, [parse_value(v) for v in _split_values(values)]


def set_key(data: dict, key: str, value) -> None:
    """Replace the dotted `key` of scene data (`section.key`, `section.index.key` in an array of tables); the
    section must exist (and an indexed table); SceneError naming the key otherwise."""
    parts = key.split(".")
    if len(parts) < 2:
        raise SceneError(f"{key}: a sweep key is section.key (e.g. fabric.E1)")
    node = data
    for i, part in enumerate(parts[:-1]):
        where = ".".join(parts[:i + 1])
        if isinstance(node, list):
            if not part.isdigit() or int(part) >= len(node):
                raise SceneError(f"{key}: [[{'.'.join(parts[:i])}]] has {len(node)} table(s); write "
                                 f"{'.'.join(parts[:i])}.<0..{len(node) - 1}>.key")
            node = node[int(part)]
        elif isinstance(node, dict) and part in node:
            node = node[part]
        elif isinstance(node, dict) and i == 0:
            node = node.setdefault(part, {})     # an optional section left out of the scene (defaults)
        else:
            raise SceneError(f"{key}: the scene has no {where}")
        if isinstance(node, list) and i == len(parts) - 2:
            raise SceneError(f"{key}: [[{where}]] is an array of tables; write {where}.<index>.{parts[-1]}")
    node[parts[-1]] = value


def variant_name(values: dict) -> str:
    """Folder name of a variant: its key=value pairs joined by '_' (characters other than letters, digits and
    `.=+-` replaced by '-')."""
    pairs = "_".join(f"{k}={v}" for k, v in values.items())
    return re.sub(r"[^A-Za-z0-9.=+\-_]", "-", pairs)


def variants(base: Scene, varies: list[tuple[str, list]], out: str | Path) -> list[Variant]:
    """The cartesian product of `varies` over the base scene, each validated (fabricfem.scenes.build.validate)
    with its output folder `<out>/<name>`; SceneError naming the variant and the key."""
    keys = [k for k, _ in varies]
    if len(set(keys)) != len(keys):
        raise SceneError(f"--vary: a key is given twice: {keys}")
    result = []
    for combination in itertools.product(*(values for _, values in varies)):
        values = dict(zip(keys, combination))
        name = variant_name(values)
        data = copy.deepcopy(base.data)
        try:
            for key, value in values.items():
                set_key(data, key, value)
            data.setdefault("output", {})["dir"] = str(Path(out) / name)
            scene = validate(data, source=f"variant {name}", path=base.path)
        except SceneError as exc:
            raise SceneError(f"variant {name}: {exc}") from None
        result.append(Variant(name, values, scene))
    return result


def finished(variant: Variant) -> bool:
    """True when the variant's folder holds a completed run of exactly this scene (status and scene hash)."""
    return completed(Path(variant.scene["output"]["dir"]), scene_sha256(variant.scene))


def scalar_entries(summary: dict) -> dict:
    """The scalar entries of a summary (numbers, strings, booleans), numeric lists flattened as <key>_<i> (not those
    also given one by one, DUPLICATES: the probe's displacement is its probe_u{x,y,z}_m), and the scalar entries of
    a wear run's per-monitor tables as <table>.<key> (torque_elbow.peak_Nm, torque_elbow.window_mean_Nm,
    pressure.peak_Pa: the names `--accuracy` takes)."""
    row = {}
    for key, value in summary.items():
        if isinstance(value, (int, float, str, bool)) or value is None:
            row[key] = value
        elif isinstance(value, dict) and (key.startswith("torque_") or key == "pressure"):
            row.update({f"{key}.{k}": v for k, v in value.items() if isinstance(v, (int, float, str, bool))})
        elif isinstance(value, list) and value and all(isinstance(v, (int, float)) for v in value) and \
                not all(name in summary for name in DUPLICATES.get(key, ("",))):
            row.update({f"{key}_{i}": v for i, v in enumerate(value)})
    return row


def run_sweep(base: Scene, varies: list[tuple[str, list]], out: str | Path, ranks_per_variant: int = 1,
              plot: str | None = None, comm: MPI.Comm = MPI.COMM_WORLD) -> list[dict]:
    """Run the variants of `base` (module docstring) and write <out>/sweep.csv and sweep.png (rank 0).
    Returns the table's rows (on every rank): {"variant", <keys>, "status", <summary entries>}. A variant that
    fails is recorded with its status ("failed: ...") and the others go on; ValueError naming
    --ranks-per-variant when it does not divide the number of ranks."""
    out = Path(out)
    groups = groups_of(comm, ranks_per_variant)
    todo = variants(base, varies, out)
    if comm.rank == 0:
        print(f"sweep: {len(todo)} variants of {base.path or 'the scene'} on {groups} group(s) of "
              f"{ranks_per_variant} rank(s) into {out}", flush=True)
    jobs = [Job(v.name, estimated_cost(v.scene), lambda sub, v=v: run_scene(v.scene, sub).status,
                lambda v=v: finished(v)) for v in todo]
    statuses = run_batch(jobs, comm, ranks_per_variant, "sweep")   # failures that left no summary.json
    rows = []
    for v in todo:
        summary = read_summary(Path(v.scene["output"]["dir"]))
        status = statuses.get(v.name, summary.get("status", "missing"))
        rows.append({"variant": v.name, **v.values, "status": status,
                     **{k: val for k, val in scalar_entries(summary).items() if k not in v.values and k != "status"}})
    if comm.rank == 0:
        write_table(out / "sweep.csv", rows)
        quantity = plot or default_quantity(rows, {"variant", *todo[0].values}, preferred_quantities(base))
        numeric = sorted({k for row in rows for k, v in row.items() if isinstance(v, (int, float))})
        if quantity is not None and quantity not in numeric:
            print(f"sweep: --plot {quantity!r} is not a numeric entry of the variants' summary.json (no plot); "
                  f"entries: {numeric}", flush=True)
            quantity = None
        if quantity is not None:
            plot_sweep(out / "sweep.png", rows, [k for k, _ in varies], quantity, base)
        print(f"sweep: wrote {out}/sweep.csv" + (f", sweep.png ({quantity})" if quantity else ""), flush=True)
    return rows


def preferred_quantities(base: Scene) -> list[str]:
    """The summary entries a sweep of `base` plots by default: its [accuracy] quantity, else the quantities it
    monitors (fabricfem.scenes.schema.accuracy_quantities: a static probe's components, a dynamic scene's
    monitors, a wear scene's torques and pressures), as summary.json keys."""
    accepted = accuracy_quantities(base.data)
    chosen = base.get("accuracy", {}).get("quantity")
    return [accepted[chosen]] if chosen in accepted else list(accepted.values())


def default_quantity(rows: list[dict], exclude: set[str], preferred: list[str] = ()) -> str | None:
    """The plot's quantity without --plot: of the `preferred` entries numeric in every row, the one of the largest
    magnitude when they share one unit (a probe's components: the direction it moves most), else the first; without
    such entries the first numeric summary entry that is not bookkeeping (BOOKKEEPING, memory) nor in `exclude` (the
    varied keys); None when there is none."""
    numeric = [k for k in preferred if all(_number(row.get(k)) for row in rows)]
    if numeric:
        if len({_unit(k) for k in numeric}) > 1:
            return numeric[0]
        return max(numeric, key=lambda k: max(abs(row[k]) for row in rows))
    for key in dict.fromkeys(k for row in rows for k in row if k not in exclude):
        values = [row.get(key) for row in rows]
        if (key not in BOOKKEEPING and not key.startswith("peak_memory") and
                all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values if v is not None)
                and any(v is not None for v in values)):
            return key
    return None


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _unit(quantity: str) -> str | None:
    """The unit of a summary entry from its name (UNIT_SUFFIXES; a strain's "-"), None when it has none."""
    if "strain" in quantity:
        return "-"
    return next((unit for suffix, unit in UNIT_SUFFIXES if quantity.endswith(suffix)), None)


def quantity_label(base: Scene, quantity: str) -> str:
    """`quantity` (a summary.json entry of the sweep of `base`) with its unit: a dynamic monitor's final value
    (final_<name>) with the monitor's (fabricfem.scenes.dynamic.monitor_unit), else from its name (`_unit`)."""
    monitors = {m["name"]: m for m in base.get("dynamics", {}).get("monitors", [])}
    name = quantity.removeprefix("final_")
    unit = monitor_unit(monitors[name]) if quantity.startswith("final_") and name in monitors else _unit(quantity)
    return f"{quantity} [{unit}]" if unit else quantity


def key_label(base: Scene, key: str) -> str:
    """A varied dotted scene key with its unit as the scene reference gives it (the last bracket without a comma
    in the key's documentation, e.g. "fabric.E1 [Pa]"; the key alone when it has none)."""
    parts = key.split(".")
    classes = SECTIONS_OF.get(base.kind, {}).get(parts[0], ())
    docs = [param_doc(f) for cls in classes for f in dataclasses.fields(cls) if f.name == parts[-1]]
    units = re.findall(r"\[([^\[\],]+)\]", docs[0]) if docs else []
    return f"{key} [{units[-1]}]" if units else key


def plot_sweep(path: Path, rows: list[dict], keys: list[str], quantity: str, base: Scene):
    """PNG of `quantity` against the first varied key, one curve per combination of the other keys, the axes
    labelled with their units (`key_label`, `quantity_label`) under a title naming the scene; returns the
    matplotlib Figure (closed)."""
    import matplotlib  # optional heavy package, loaded only when a plot is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    first, others = keys[0], keys[1:]
    curves: dict[str, list[tuple]] = {}
    for row in rows:
        label = ", ".join(f"{k}={row[k]}" for k in others) or quantity
        x, y = row[first], row.get(quantity)
        if isinstance(y, (int, float)) and math.isfinite(y):
            curves.setdefault(label, []).append((x, y))
    fig, ax = plt.subplots(figsize=(7, 4.5))
    numeric = all(isinstance(row[first], (int, float)) for row in rows)
    for label, points in curves.items():
        xs, ys = zip(*(sorted(points) if numeric else points))
        ax.plot(xs if numeric else [str(x) for x in xs], ys, "o-", label=label)
    ax.set_xlabel(key_label(base, first))
    ax.set_ylabel(quantity_label(base, quantity))
    ax.set_title(f"{scene_name(base)}: {quantity} against {first} ({len(rows)} variants)")
    ax.grid(True, alpha=0.3)
    if len(curves) > 1:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig
