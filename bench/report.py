"""Markdown tables and matplotlib plots of the benchmark results.

matplotlib is an optional dependency (the ``bench`` extra); without it the
report is written without plots and says so.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib_core.transforms import rpy_deg_from_R

from .accuracy import PARAM_NAMES, Summary, summarize
from .common import fmt_ms

METHOD_NAMES = {
    "angular": "angular cost, eq. 7 (ours)",
    "pixel": "pixel cost, eq. 6",
    "opencv": "OpenCV SQPnP + RefineLM",
}
METHOD_COLORS = {"angular": "tab:blue", "pixel": "tab:orange", "opencv": "tab:green"}


def pooled(results: dict, scene_indices, n: int, method: str) -> Summary:
    """Summary over several scenes at one ``n``."""
    rs = [r for si in scene_indices for r in results.get((si, n, method), [])]
    return summarize(rs, n)


def f(x: float, nd: int = 3) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{nd}f}"


# -------------------------------------------------------------------- tables
def table_one(scene, s: Summary) -> str:
    """Table I layout: truth, mean estimate, mean error and sigma of each parameter."""
    T = scene.T_camera_lidar
    truth = np.concatenate([T[:3, 3], rpy_deg_from_R(T[:3, :3])])
    err = np.concatenate([s.t_err_mean, s.rpy_err_mean])
    sd = np.concatenate([s.t_err_std, s.rpy_err_std])
    names = ["T_x (m)", "T_y (m)", "T_z (m)", "roll (deg)", "pitch (deg)", "yaw (deg)"]
    nd = [4, 4, 4, 3, 3, 3]
    lines = ["| parameter | truth | mean estimate | mean error | sigma |", "|---|---:|---:|---:|---:|"]
    for i, name in enumerate(names):
        lines.append(f"| {name} | {truth[i]:.{nd[i]}f} | {truth[i] + err[i]:.{nd[i]}f} | {err[i]:+.{nd[i] + 1}f} | {sd[i]:.{nd[i] + 1}f} |")
    lines.append(f"| pixel error, reprojection residual at the pairs (paper's measure) | | {f(s.residual_px_mean, 2)} px | | {f(s.residual_px_std, 2)} px |")
    lines.append(f"| pixel error against ground truth (scene points) | | {f(s.gt_px_mean, 3)} px | | {f(s.gt_px_std, 3)} px |")
    return "\n".join(lines)


def error_vs_n_table(results: dict, scene_indices, n_values, method: str) -> str:
    lines = [
        "| n | trials | failed | rotation error mean / p95 (deg) | translation error mean / p95 (cm) | "
        "pixel error vs truth (px) | residual at pairs (px) | solve time (median) |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for n in n_values:
        s = pooled(results, scene_indices, n, method)
        lines.append(
            f"| {n} | {s.trials} | {s.failures} | {f(s.rot_err_mean, 4)} / {f(s.rot_err_p95, 4)} | "
            f"{f(100 * s.trans_err_mean, 3)} / {f(100 * s.trans_err_p95, 3)} | {f(s.gt_px_mean, 3)} | "
            f"{f(s.residual_px_mean, 2)} +/- {f(s.residual_px_std, 2)} | {fmt_ms(s.time_median_s)} |"
        )
    return "\n".join(lines)


def compare_table(results: dict, scene_indices, n: int, methods, times: dict | None = None) -> str:
    """Accuracy of each method at ``n``; ``times`` ((n, method) -> s) replaces the trial-run time."""
    lines = [
        "| method | trials | failed | rotation error mean / p95 (deg) | translation error mean / p95 (cm) | "
        "pixel error vs truth (px) | residual at pairs (px) | time per solve (median) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for m in methods:
        s = pooled(results, scene_indices, n, m)
        if times and (n, m) in times:
            s.time_median_s = times[(n, m)]
        lines.append(
            f"| {METHOD_NAMES[m]} | {s.trials} | {s.failures} | {f(s.rot_err_mean, 4)} / {f(s.rot_err_p95, 4)} | "
            f"{f(100 * s.trans_err_mean, 3)} / {f(100 * s.trans_err_p95, 3)} | {f(s.gt_px_mean, 3)} | "
            f"{f(s.residual_px_mean, 2)} +/- {f(s.residual_px_std, 2)} | {fmt_ms(s.time_median_s)} |"
        )
    return "\n".join(lines)


def crb_table(rows) -> str:
    units = ["deg", "deg", "deg", "mm", "mm", "mm"]
    scale = [1, 1, 1, 1e3, 1e3, 1e3]
    out = []
    for r in rows:
        out.append(f"**{r.label}; {METHOD_NAMES[r.method]}**, {r.draws} solves; "
                   f"equivalent isotropic angular noise {1e3 * r.noise_rad:.3f} mrad. "
                   f"An efficient estimator would reach on average: rotation error "
                   f"{r.floor.get('rotation_deg', float('nan')):.4f} deg, translation error "
                   f"{100 * r.floor.get('translation_m', float('nan')):.3f} cm, pixel error vs truth "
                   f"{r.floor.get('gt_px', float('nan')):.3f} px.\n")
        out.append("| parameter | empirical sigma | empirical RMS error | Cramer-Rao sigma | sigma / bound | "
                   "solver's covariance sigma |")
        out.append("|---|---:|---:|---:|---:|---:|")
        for i, name in enumerate(PARAM_NAMES):
            k = scale[i]
            out.append(f"| {name} ({units[i]}) | {k * r.empirical_std[i]:.4f} | {k * r.empirical_rms[i]:.4f} | "
                       f"{k * r.bound[i]:.4f} | {r.ratio[i]:.2f} | {k * r.solver_sigma[i]:.4f} |")
        out.append("")
    return "\n".join(out)


# --------------------------------------------------------------------- plots
def _plt():
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        return plt
    except ImportError:
        return None


def plot_fig6_fig7(path6: Path, path7: Path, results: dict, scene, n_values, method="angular") -> bool:
    """Paper Fig. 6 (translation) and Fig. 7 (roll, pitch, yaw) on the sample: mean +/- sigma vs n."""
    plt = _plt()
    if plt is None:
        return False
    T = scene.T_camera_lidar
    truth = np.concatenate([T[:3, 3], rpy_deg_from_R(T[:3, :3])])
    sums = [summarize(results.get((0, n, method), []), n) for n in n_values]
    mean = np.array([np.concatenate([s.t_err_mean, s.rpy_err_mean]) for s in sums]) + truth
    sd = np.array([np.concatenate([s.t_err_std, s.rpy_err_std]) for s in sums])
    labels = ["T_x (m)", "T_y (m)", "T_z (m)", "roll (deg)", "pitch (deg)", "yaw (deg)"]
    for path, cols, title in ((path6, range(0, 3), "Fig. 6: translation vs number of pairs"),
                              (path7, range(3, 6), "Fig. 7: rotation vs number of pairs")):
        fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), constrained_layout=True)
        for ax, c in zip(axes, cols):
            ax.axhline(truth[c], color="k", lw=1, ls="--", label="ground truth")
            ax.errorbar(n_values, mean[:, c], yerr=sd[:, c], fmt="o-", ms=3, capsize=2, color="tab:blue",
                        label="mean +/- sigma")
            ax.set_xlabel("number of pairs n")
            ax.set_ylabel(labels[c])
            ax.grid(alpha=0.3)
        axes[0].legend(fontsize=8)
        fig.suptitle(f"{title} (sample scene, {sums[0].trials} trials per n, angular cost)")
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return True


def plot_errors_vs_n(path: Path, results: dict, scene_names, n_values, method="angular", floor=None) -> bool:
    plt = _plt()
    if plt is None:
        return False
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), constrained_layout=True)
    for si, name in enumerate(scene_names):
        sums = [summarize(results.get((si, n, method), []), n) for n in n_values]
        rot = [s.rot_err_mean for s in sums]
        tr = [100 * s.trans_err_mean for s in sums]
        px = [s.gt_px_mean for s in sums]
        for ax, y in zip(axes, (rot, tr, px)):
            ax.plot(n_values, y, "o-", ms=3, label=name)
    titles = ("rotation error (deg)", "translation error (cm)", "pixel error vs ground truth (px)")
    targets = (0.1, 1.0, 1.0)
    if floor and 10 in n_values:
        for ax, v in zip(axes, (floor["rotation_deg"], 100 * floor["translation_m"], floor["gt_px"])):
            ax.plot([10], [v], "kx", ms=9, mew=2, label="Cramer-Rao floor, 1 px clicks (sample, n = 10)")
    for ax, t, tg in zip(axes, titles, targets):
        ax.axhline(tg, color="r", lw=1, ls=":", label="target at n = 10")
        ax.set_yscale("log")
        ax.set_xlabel("number of pairs n")
        ax.set_title(f"mean {t}")
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=8)
    fig.suptitle("Error against ground truth vs number of pairs (angular cost, mean over trials)")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def plot_compare(path: Path, omni: dict, omni_idx, pin: dict, pin_idx, n_values, omni_times=None,
                 pin_times=None) -> bool:
    plt = _plt()
    if plt is None:
        return False
    fig, axes = plt.subplots(2, 3, figsize=(13, 7), constrained_layout=True)
    for row, (res, idx, methods, cam, times) in enumerate(
        ((omni, omni_idx, ("angular", "pixel"), "omnidirectional (OCam) camera", omni_times),
         (pin, pin_idx, ("angular", "pixel", "opencv"), "pinhole variant", pin_times))
    ):
        for m in methods:
            ns = [n for n in n_values if any((si, n, m) in res for si in idx)]
            sums = [pooled(res, idx, n, m) for n in ns]
            kw = dict(color=METHOD_COLORS[m], label=METHOD_NAMES[m], ms=3)
            axes[row, 0].plot(ns, [s.rot_err_mean for s in sums], "o-", **kw)
            axes[row, 1].plot(ns, [100 * s.trans_err_mean for s in sums], "o-", **kw)
            t = [times.get((n, m), np.nan) if times else s.time_median_s for n, s in zip(ns, sums)]
            axes[row, 2].plot(ns, 1e3 * np.asarray(t), "o-", **kw)
        for col, t in enumerate(("rotation error (deg)", "translation error (cm)", "time per solve (ms)")):
            ax = axes[row, col]
            ax.set_yscale("log")
            ax.set_xlabel("number of pairs n")
            ax.set_title(f"{cam}: {t}", fontsize=9)
            ax.grid(alpha=0.3, which="both")
        axes[row, 0].legend(fontsize=8)
    fig.suptitle("Angular cost vs pixel cost vs OpenCV (mean over all scenes and trials)")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def plot_crb(path: Path, rows) -> bool:
    plt = _plt()
    if plt is None:
        return False
    fig, ax = plt.subplots(figsize=(10, 3.8), constrained_layout=True)
    width = 0.8 / max(len(rows), 1)
    x = np.arange(6)
    for i, r in enumerate(rows):
        short = "pure click noise" if r.label.startswith("pure") else "realistic picking"
        ax.bar(x + (i - (len(rows) - 1) / 2) * width, r.ratio, width, label=f"{short}, {r.method} cost")
    ax.axhspan(0.8, 1.2, color="g", alpha=0.12, label="within 20 %")
    ax.axhline(1.0, color="k", lw=1)
    ax.set_xticks(x, PARAM_NAMES)
    ax.set_ylabel("empirical sigma / Cramer-Rao sigma")
    ax.set_ylim(0, 1.75)
    ax.legend(fontsize=8, ncol=3, loc="upper center")
    ax.grid(alpha=0.3, axis="y")
    ax.set_title("Cramer-Rao check (n = 10 pairs, sample scene)")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True
