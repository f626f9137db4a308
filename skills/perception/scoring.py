"""Scoring detections against the twin's ground truth (used by `cell perceive` and the bench
only; ground truth never reaches a skill)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from skills.axes import XY
from skills.perception.bin_parts import Detection

#: m, the farthest a detection's centre may lie from a part's true centre (in the floor plane)
#: and still be scored as that part: a bench tolerance of about one outer size of the
#: catalogue's smaller parts (30-35 mm), well past a good detection's error, short of a neighbour
MATCH_GATE = 0.03


@dataclass(frozen=True)
class Truth:
    name: str
    center: np.ndarray
    yaw: float  #: towards the open end (+x of the part)
    open_ends: int
    standing: bool = False  #: on an end: scored by its place (no yaw), matched only so
    open_up: bool = True  #: standing: its open end (+x) is the one on top


@dataclass(frozen=True)
class Match:
    truth: Truth
    detection: Detection
    pos_err: float  #: m, in the floor plane
    yaw_err: float  #: rad, modulo the part's symmetry (pi for a tube)
    end_right: bool | None  #: for one-open-end parts: the right end chosen; None for tubes


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi  # exact: a full turn


def score(
    truths: list[Truth], detections: list[Detection], gate: float = MATCH_GATE
) -> tuple[list[Match], int, int]:
    """Greedy nearest matching within ``gate`` (m), a standing part only to a detection that
    says it stands. Returns (matches, missed, false positives)."""
    pairs = []
    for i, t in enumerate(truths):
        for j, d in enumerate(detections):
            dist = float(np.linalg.norm(t.center[XY] - d.center[XY]))
            if dist < gate and t.standing == d.standing:
                pairs.append((dist, i, j))
    pairs.sort()
    used_t, used_d, matches = set(), set(), []
    for dist, i, j in pairs:
        if i in used_t or j in used_d:
            continue
        used_t.add(i)
        used_d.add(j)
        t, d = truths[i], detections[j]
        direct = abs(_wrap(d.yaw - t.yaw))
        if t.standing:  # round about its axis: no yaw; the end on top read right or not
            err = 0.0
            right = None if t.open_ends == 2 else d.open_end_seen == t.open_up  # exact: a tube
        elif t.open_ends == 2:  # exact: both ends open, a tube
            err, right = min(direct, math.pi - direct), None
        else:
            axis_err = min(direct, math.pi - direct)
            err, right = axis_err, direct < 0.5 * math.pi  # exact: a right angle
        matches.append(Match(t, d, dist, err, right))
    return matches, len(truths) - len(matches), len(detections) - len(matches)
