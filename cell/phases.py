"""Where the cell's time goes: how long each leaf of the tree ran, from its status changes.

A leaf's run is the time from the tick it turned RUNNING to the tick it turned SUCCESS,
FAILURE or INVALID (halted). The tick loop feeds every status change here (the same changes
the tick log writes), so the table costs nothing per tick where nothing changed, and it needs
no tick log on disk. The tact-time breakdown of ``cell sim`` / ``cell run`` is this table
divided by the parts packed.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class PhaseTime:
    runs: int = 0  #: finished runs (success, failure or halted)
    total_s: float = 0.0  #: s, summed over the finished runs
    failed: int = 0  #: runs that ended FAILURE


@dataclass
class PhaseTimes:
    """Per leaf name: runs and time spent (s of the cell's clock)."""

    phases: dict[str, PhaseTime] = field(default_factory=dict)
    _started: dict[str, float] = field(default_factory=dict)

    def change(self, name: str, status: str, t: float) -> None:
        """``status`` (a py_trees status value) of leaf ``name`` changed at ``t`` (s)."""
        if status == "RUNNING":
            self._started.setdefault(name, t)
            return
        t0 = self._started.pop(name, None)
        if t0 is None:
            return
        phase = self.phases.setdefault(name, PhaseTime())
        phase.runs += 1
        phase.total_s += t - t0
        phase.failed += status == "FAILURE"

    def table(self, parts: int | None = None) -> list[dict[str, float | int | str]]:
        """Rows in the order the leaves first finished: name, runs, total, mean per run and,
        with ``parts`` > 0, per part. Leaves that took no time (conditions) are left out."""
        rows: list[dict[str, float | int | str]] = []
        for name, p in self.phases.items():
            if p.total_s <= 0.0:
                continue
            row: dict[str, float | int | str] = {
                "phase": name,
                "runs": p.runs,
                "failed": p.failed,
                "total_s": round(p.total_s, 3),
                "mean_s": round(p.total_s / p.runs, 3),
            }
            if parts:
                row["per_part_s"] = round(p.total_s / parts, 3)
            rows.append(row)
        return rows
