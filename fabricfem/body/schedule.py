"""Segment activity in time: named groups of body segments switched off over time intervals.

A group (e.g. "feet": the two foot segments) is off for t_off <= t < t_on in each of its intervals
[s] and on otherwise (donning a pair of trousers removes the feet and restores them [Man2006, sec. 5.4]).
`t_on = inf` keeps the group off to the end. `fabricfem.body.pose.Body.active(t)` applies it.

With `regrow_time` T_g > 0 a segment that comes back at t_on regrows about its centre: its radii are scaled by

    g(t) = g_0 + (1 - g_0) smoothstep((t - t_on) / T_g),   g_0 = REGROW_FROM,

so that the cloth hanging where it reappears (a trouser hem round the ankle) is pushed aside over T_g instead of
being projected out of it in one step.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise
from typing import Mapping, Sequence

import numpy as np

from fabricfem.body.blend import smoothstep

REGROW_FROM = 0.2    # g_0: a returning segment's size when it reappears, relative to its full size


@dataclass(frozen=True)
class SegmentSchedule:
    """Groups of segments and the intervals in which they are off.

    Args:
        groups: group name -> (segment names, [(t_off, t_on), ...]) with t_off < t_on [s]
            (t_off finite, t_on finite or inf); the intervals of a group must not overlap.
    """

    groups: Mapping[str, tuple[Sequence[str], Sequence[tuple[float, float]]]]
    regrow_time: float = 0.0

    def __post_init__(self):
        if not (isinstance(self.regrow_time, (int, float)) and math.isfinite(self.regrow_time)
                and self.regrow_time >= 0.0):
            raise ValueError(f"regrow_time must be a time >= 0 [s], got {self.regrow_time!r}")
        clean = {}
        for name, entry in self.groups.items():
            if not (isinstance(entry, (tuple, list)) and len(entry) == 2):
                raise ValueError(f"groups[{name!r}] must be (segment names, intervals), got {entry!r}")
            segments, intervals = entry
            if isinstance(segments, str) or len(segments) == 0:
                raise ValueError(f"groups[{name!r}]: segment names must be a non-empty list, got {segments!r}")
            spans = []
            for span in intervals:
                t_off, t_on = (float(v) for v in span)
                if not (math.isfinite(t_off) and t_off < t_on and not math.isnan(t_on)):
                    raise ValueError(f"groups[{name!r}]: interval {span!r} must be (t_off, t_on) with finite "
                                     f"t_off < t_on [s]")
                spans.append((t_off, t_on))
            spans.sort()
            if any(b[0] < a[1] for a, b in pairwise(spans)):
                raise ValueError(f"groups[{name!r}]: intervals overlap: {spans}")
            clean[name] = (tuple(segments), tuple(spans))
        object.__setattr__(self, "groups", clean)

    @property
    def segments(self) -> tuple[str, ...]:
        """Every segment named by some group (each once)."""
        return tuple(dict.fromkeys(s for names, _ in self.groups.values() for s in names))

    def inactive(self, t: float) -> set[str]:
        """Segments off at time t [s]: those of a group with t_off <= t < t_on for one of its intervals."""
        if not math.isfinite(t):
            raise ValueError(f"t must be a finite time [s], got {t!r}")
        return {s for names, spans in self.groups.values() if any(a <= t < b for a, b in spans) for s in names}

    def sizes(self, names: Sequence[str], t: float) -> np.ndarray:
        """Size factor g(t) of each named segment at time t [s] (module docstring): 1 for a segment that is on and
        has regrown (or with regrow_time 0); the factor of an off segment is irrelevant (it takes no contact)."""
        g = np.ones(len(names))
        if self.regrow_time == 0.0:
            return g
        for segments, spans in self.groups.values():
            back = [b for _, b in spans if math.isfinite(b) and b <= t]     # the latest return before t
            ramp = smoothstep((t - max(back)) / self.regrow_time) if back else 1.0
            g[np.isin(names, segments)] = REGROW_FROM + (1.0 - REGROW_FROM) * ramp
        return g
