"""Pictures drawn with matplotlib (Agg, no display): Fig.-5-style stable-grasp regions and the
contact trace of a watched pivot."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from drivers.parts import Section
from skills.mechanics.contact import Frictions, contact_wrenches  # noqa: E402


def frictionless_equilibrium_curve(
    section: Section, l_a: float, n: int = 400
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Where Eq. 7 holds without friction: ``det[S H G] = 0`` with a positive null vector.

    Without friction the three contact normals must meet in a point and balance with positive
    forces; that is a curve in the (alpha, beta) plane, which a grid almost never hits. Returned
    as ``(alpha, beta, det)`` with ``det`` set to NaN where the null vector has mixed signs, ready
    for a zero contour.
    """
    al = np.linspace(1e-3, 0.5 * math.pi - 1e-3, n)
    be = np.linspace(0.0, 0.5 * math.pi, n)
    a_g, b_g = np.meshgrid(al, be, indexing="xy")
    w = contact_wrenches(section, l_a, a_g, b_g, Frictions(0.0, 0.0, 0.0), normalized=True)
    m = w[..., :, [0, 2, 4]]  # S, H, G (the two friction edges coincide)
    det = np.linalg.det(m)
    null = np.cross(m[..., 0, :], m[..., 1, :])  # orthogonal to two rows: the null vector at det=0
    same_sign = (null > 0).all(-1) | (null < 0).all(-1)
    return al, be, np.where(same_sign, det, np.nan)


def plot_region_map(
    path: Path,
    part_name: str,
    section: Section,
    l_as: NDArray[np.float64],
    alphas: NDArray[np.float64],
    betas: NDArray[np.float64],
    stable: NDArray[np.bool_],
    frictions: Frictions,
    equation: str,
) -> Path:
    """Write the map: all ``l_a`` outlines overlaid (as in Fig. 5) above one filled panel each."""
    n = len(l_as)
    fig = plt.figure(figsize=(max(6.4, 2.3 * n), 8.4), dpi=110)
    grid = fig.add_gridspec(2, n, height_ratios=[2.2, 1.0])
    ax = fig.add_subplot(grid[0, :])
    colors = plt.get_cmap("plasma")(np.linspace(0.0, 0.85, max(n, 2)))
    a_deg, b_deg = np.degrees(alphas), np.degrees(betas)
    handles = []
    for k, la in enumerate(l_as):
        z = stable[k].T.astype(float)  # rows beta, columns alpha
        col = colors[k]
        label = f"$l_a$ = {la:g} ({int(stable[k].sum())} of {z.size} stable)"
        small = fig.add_subplot(grid[1, k])
        if 0 < z.sum() < z.size:
            ax.contour(a_deg, b_deg, z, levels=[0.5], colors=[col], linewidths=2.0)
        if z.any():
            small.contourf(a_deg, b_deg, z, levels=[0.5, 1.5], colors=[col], alpha=0.55)
        small.set_title(f"$l_a$ = {la:g}", fontsize=9)
        small.set_xlim(0, 90)
        small.set_ylim(0, 90)
        small.set_xticks([0, 45, 90])
        small.set_yticks([0, 45, 90])
        small.tick_params(labelsize=7)
        small.axhline(math.degrees(section.tip_angle), color="0.4", lw=0.8, ls=":")
        small.set_xlabel(r"$\alpha$ [deg]", fontsize=8)
        if k == 0:
            small.set_ylabel(r"$\beta$ [deg]", fontsize=8)
        handles.append(plt.Line2D([], [], color=col, lw=2, label=label))
    if frictions.frictionless and equation == "eq7":
        for k, la in enumerate(l_as):
            al, be, det = frictionless_equilibrium_curve(section, float(la))
            if np.isfinite(det).any() and np.nanmin(det) < 0 < np.nanmax(det):
                ax.contour(
                    np.degrees(al),
                    np.degrees(be),
                    det,
                    levels=[0.0],
                    colors=[colors[k]],
                    linewidths=1.4,
                    linestyles="--",
                )
        handles.append(
            plt.Line2D(
                [],
                [],
                color="k",
                ls="--",
                label="exact Eq. 7 solutions: a curve, missed by any grid",
            )
        )
    ax.axhline(math.degrees(section.tip_angle), color="0.4", lw=0.8, ls=":")
    ax.text(
        1, math.degrees(section.tip_angle) + 0.8, "CoM over G: atan(a/b)", fontsize=7, color="0.3"
    )
    ax.set_xlim(0, 90)
    ax.set_ylim(0, 90)
    ax.set_xlabel(r"$\alpha$ gripper tilt [deg]")
    ax.set_ylabel(r"$\beta$ part tilt [deg]")
    eq_label = "Eq. 7 (form closure)" if equation == "eq7" else "Eq. 8 (gravity)"
    ax.text(
        89,
        1,
        "outlines: boundary of each stable set;\nfilled panels below show which side",
        fontsize=7,
        ha="right",
        va="bottom",
        color="0.3",
    )
    ax.set_title(
        f"{part_name}: stable grasps, {eq_label}\n"
        f"$\\mu_S$={frictions.mu_s:g}, $\\mu_H$={frictions.mu_h:g}, $\\mu_G$={frictions.mu_g:g}; "
        f"a={section.a * 1e3:.1f} mm, b={section.b * 1e3:.1f} mm, "
        f"$\\delta$={section.delta * 1e3:.1f} mm",
        fontsize=9,
    )
    ax.legend(handles=handles, loc="center right", fontsize=8, framealpha=0.9)
    ax.grid(alpha=0.25)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_contact_trace(
    samples: Sequence[Any],
    phase_starts: dict[str, float],
    path: str | Path,
    title: str,
    inner: str = "finger_b",
    outer: str = "finger_a",
) -> Path:
    """The watched pivot over time: each finger touching the part or not, the inner pad tip's
    depth in the hole (mm, below the open end's face) and beta (deg), the phases shaded.

    ``samples``: :class:`sim.judge.WatchSample` (anything with ``t``, ``touch``, ``depth``,
    ``in_hole`` and ``beta_deg``)."""
    t = np.array([s.t for s in samples])
    fig, axes = plt.subplots(3, 1, figsize=(9, 6.5), sharex=True)
    ax_touch, ax_depth, ax_beta = axes
    ax_touch.step(t, [1.2 + s.touch[inner] * 0.8 for s in samples], where="post",
                  label="inner finger (in the hole) touches", color="tab:red")
    ax_touch.step(t, [s.touch[outer] * 0.8 for s in samples], where="post",
                  label="outer finger (S, outer wall) touches", color="tab:blue")
    ax_touch.set_yticks([0.0, 0.8, 1.2, 2.0], ["no", "yes", "no", "yes"])
    ax_touch.set_ylabel("contact")
    ax_touch.legend(loc="center left", fontsize=8)
    depth = np.array([1e3 * s.depth[inner] for s in samples])
    inside = np.array([s.in_hole[inner] for s in samples])
    ax_depth.plot(t, depth, color="tab:red")
    if (~inside).any():
        ax_depth.plot(t[~inside], depth[~inside], "kx", ms=3, label="pad tip out of the hole")
        ax_depth.legend(loc="upper left", fontsize=8)
    ax_depth.axhline(0.0, color="0.5", lw=0.8)
    ax_depth.set_ylabel("inner pad tip depth\nin the hole (mm)")
    ax_beta.plot(t, [s.beta_deg for s in samples], color="tab:green")
    ax_beta.set_ylabel("beta (deg)")
    ax_beta.set_xlabel("simulated time (s)")
    ax_beta.set_ylim(-5, 95)
    names = list(phase_starts)
    colours = {"grasp": "0.92", "tilt": "#dbe9f6", "align": "#fde7cf", "lift": "#dff2dc",
               "recovery": "#f6d5d5"}
    end = float(t[-1]) if len(t) else 0.0
    for i, name in enumerate(names):
        start = phase_starts[name]
        stop = phase_starts[names[i + 1]] if i + 1 < len(names) else end
        for ax in axes:
            ax.axvspan(start, stop, color=colours.get(name, "0.95"), zorder=0)
        ax_touch.text(0.5 * (start + stop), 2.1, name, ha="center", va="bottom", fontsize=9)
    ax_touch.set_ylim(-0.2, 2.45)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
