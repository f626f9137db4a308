"""How fast can the pivot go? Tact time and success of the pivot at several Tilt speeds and
settle times, beside the regrasp baseline, on the same parts and seeds as `cell compare`.

Why: `cell compare` runs the pivot as the paper describes it, quasi-static (the Tilt bounded by
the part's turning rate), and finds it slower than the regrasp. Both methods are to be tuned with
equal care; this measures how much of the gap the Tilt's speed explains. Run by hand:

    python bench/pivot_speed.py --part bushing medicine_bottle cookie_can --trials 10 \
        --config 0.01,1.0 0.03,1.0 0.05,0.5

Each ``--config`` is ``tilt_speed_m_s,settle_s`` (``settle_s``: the longest the Tilt waits for
the wrist to read steady): the arc at that TCP speed for every part (the
part's turning-rate bound, ``tilt_rate_deg_s``, set to its largest value so the speed given is
the one run). Prints one line per part and configuration:
successes, mean tact over successes (simulated s, measured as in `cell compare`), and the ratio
to the regrasp's mean tact on the same seeds.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time

#: deg/s, the largest ``skills.pivot.tilt_rate_deg_s`` takes: with it the TCP speed asked decides
MAX_RATE_DEG_S = 180.0


def _fields(values: dict[str, float]) -> dict[str, float]:
    """PivotParams fields from configuration keys (``skills.pivot``), converted and checked
    by the same code the cell uses."""
    from skills.params import apply_config
    from skills.pivot import PivotParams

    base = PivotParams(l_a=0.5, alpha=0.3)
    tuned = apply_config(base, values)
    return {
        f.name: getattr(tuned, f.name)
        for f in dataclasses.fields(tuned)
        if getattr(tuned, f.name) != getattr(base, f.name)
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--part", nargs="+", default=["bushing"])
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument("--seed", type=int, default=100, help="first seed (as `cell compare`)")
    ap.add_argument("--config", nargs="+", default=["0.01,1.0", "0.05,0.5"])
    args = ap.parse_args()

    from lab.pivot_cmd import build_setup, pivot_args
    from lab.pivot_run import run_trial
    from lab.regrasp_run import GripperProbe, run_regrasp_trial

    seeds = [args.seed + i for i in range(args.trials)]
    for part in args.part:
        setup, _plan, _forced = build_setup(pivot_args(part, args.trials, None, None, True))
        t0 = time.perf_counter()
        base: list[float] = []
        for seed in seeds:
            probe = GripperProbe()
            if run_regrasp_trial(setup, seed, on_frame=probe, frame_every=1).success:
                base.append(probe.tact_time)
        regrasp = statistics.mean(base) if base else float("nan")
        print(f"{part}: regrasp {len(base)}/{len(seeds)} tact {regrasp:.2f} s", flush=True)
        for spec in args.config:
            speed, settle = (float(v) for v in spec.split(","))
            # The configuration's keys, as a cell YAML's skills.pivot section would give them.
            values = {"tilt_speed_m_s": speed, "tilt_rate_deg_s": MAX_RATE_DEG_S,
                      "settle_s": settle}
            tuned = dataclasses.replace(
                setup, params={**setup.params, **_fields(values)}
            )
            tacts, fails = [], []
            for seed in seeds:
                probe = GripperProbe()
                r = run_trial(tuned, seed, on_frame=probe, frame_every=1)
                if r.success:
                    tacts.append(probe.tact_time)
                else:
                    fails.append(f"{seed}:{r.phase}")
            mean = statistics.mean(tacts) if tacts else float("nan")
            print(
                f"{part}: pivot tilt {speed:.3f} m/s settle {settle:.1f} s: "
                f"{len(tacts)}/{len(seeds)} tact {mean:.2f} s ratio {mean / regrasp:.2f}"
                + (f"  failed {' '.join(fails)}" if fails else ""),
                flush=True,
            )
        print(f"{part}: {time.perf_counter() - t0:.0f} s wall", flush=True)


if __name__ == "__main__":
    main()
