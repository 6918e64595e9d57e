"""Robust statistics of a wear run's monitors: windowed means and percentile peaks beside the raw maxima.

A single record of an explicit wear run is not predictable (a density change of 1e-9 relative moves the sleeve's
torque at 57 degrees by up to 2 %: a discrete slip event), a mean over a window of the motion is (0.1 % or less).
So every monitor is also reported as its mean over windows of the motion, on the run's axis (an elbow or knee
angle [deg], else the body time [s]), and as a percentile of its records beside the largest one:

    mean over a window  = the records' values with coordinate a <= x <= b, averaged with trapezoid weights on x
    percentile peak     = the PEAK_PERCENTILE-th percentile of |value| over the motion's records

Windows: the scene's [output] windows, else DEFAULT_ANGLE_WINDOW_START deg to the end for an angle axis (the
thesis's sleeve figures start their comparison at 20 degrees: the start-up transient is below it) and the whole
motion for a time axis.
"""
from __future__ import annotations

import numpy as np

from fabricfem.wear.contract import WearHistory

PEAK_PERCENTILE = 95.0
DEFAULT_ANGLE_WINDOW_START = 20.0    # deg


def default_windows(history: WearHistory, angle_axis: bool) -> list[tuple[float, float]]:
    """The default windows of a history's motion (module docstring)."""
    motion = [s.coordinate for s in history.steps if s.phase == "motion"]
    if not motion:
        return []
    end = max(motion)
    start = DEFAULT_ANGLE_WINDOW_START if angle_axis and end > DEFAULT_ANGLE_WINDOW_START else min(motion)
    return [(start, end)]


def window_mean(x: np.ndarray, y: np.ndarray, window: tuple[float, float]) -> float:
    """Trapezoid mean of y over the records with window[0] <= x <= window[1] (nan with fewer than 2 records)."""
    a, b = window
    inside = (x >= a - 1e-9) & (x <= b + 1e-9)
    if inside.sum() < 2:
        return float("nan")
    xs, ys = x[inside], y[inside]
    return float(np.trapz(ys, xs) / (xs[-1] - xs[0])) if xs[-1] > xs[0] else float(np.mean(ys))


def motion_statistics(history: WearHistory, windows: list[tuple[float, float]]) -> dict:
    """{"windows": [[a, b], ...], "torque_<name>": {"mean": [per window], "p95_abs_Nm": ..., "max_abs_Nm": ...},
    "pressure": {"mean": [...], "p95_peak_Pa": ..., "max_peak_Pa": ...}} over the motion's records."""
    motion = [s for s in history.steps if s.phase == "motion"]
    if not motion:
        return {}
    x = np.array([s.coordinate for s in motion])
    out: dict = {"windows": [list(map(float, w)) for w in windows], "peak_percentile": PEAK_PERCENTILE}
    for name in history.monitors:
        tau = np.array([s.torques[name] for s in motion])
        out[f"torque_{name}"] = {"mean_Nm": [window_mean(x, tau, w) for w in windows],
                                 "p95_abs_Nm": float(np.percentile(np.abs(tau), PEAK_PERCENTILE)),
                                 "max_abs_Nm": float(np.max(np.abs(tau)))}
    peak = np.array([s.peak_pressure for s in motion])
    out["pressure"] = {"mean_peak_Pa": [window_mean(x, peak, w) for w in windows],
                       "p95_peak_Pa": float(np.percentile(peak, PEAK_PERCENTILE)), "max_peak_Pa": float(peak.max())}
    return out


def statistics_rows(stats: dict) -> list[list]:
    """Rows (quantity, window start, window end, windowed mean, percentile peak, largest) of statistics.csv."""
    rows = []
    for key, entry in stats.items():
        if not isinstance(entry, dict):
            continue
        means = entry.get("mean_Nm", entry.get("mean_peak_Pa", []))
        p95 = entry.get("p95_abs_Nm", entry.get("p95_peak_Pa"))
        top = entry.get("max_abs_Nm", entry.get("max_peak_Pa"))
        for (a, b), mean in zip(stats["windows"], means):
            rows.append([key, a, b, mean, p95, top])
    return rows
