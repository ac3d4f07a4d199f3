"""One figure per sweep: success rate and SPL per scene family with their 95 % bootstrap intervals, and the
histogram of times to find (matplotlib, Agg: no display needed)."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

__all__ = ["sweep_figure"]


def sweep_figure(summary: Sequence[dict], find_times_s: Sequence[float], path: str | Path,
                 title: str = "Rescue sweep") -> Path:
    """Write a PNG to ``path`` from :func:`ssl_sim.stats.summarize` rows and every find's time (s)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fams = [r for r in summary if r["family"] != "all"] or list(summary)
    names = [f"{r['family']}\n(n={r['scenarios']})" for r in fams]
    fig, axes = plt.subplots(1, 3, figsize=(max(10.0, 3.0 + 1.6 * len(fams) * 2), 4.2))
    x = np.arange(len(fams))
    for ax, m, label in ((axes[0], "success", "success rate (all victims found)"), (axes[1], "spl", "SPL")):
        mean = np.array([np.nan if r[m] is None else r[m] for r in fams], float)
        lo = np.array([np.nan if r[f"{m}_lo"] is None else r[f"{m}_lo"] for r in fams], float)
        hi = np.array([np.nan if r[f"{m}_hi"] is None else r[f"{m}_hi"] for r in fams], float)
        ax.bar(x, np.nan_to_num(mean), color="tab:blue" if m == "success" else "tab:green", alpha=0.8)
        ok = np.isfinite(mean)
        ax.errorbar(x[ok], mean[ok], yerr=[mean[ok] - lo[ok], hi[ok] - mean[ok]], fmt="none", ecolor="k", capsize=4)
        ax.set_xticks(x, names, rotation=30, ha="right", fontsize=8)
        ax.set_ylim(0, 1.05)
        ax.set_ylabel(label)
        ax.set_title(f"{label}, 95 % interval")
    t = np.asarray([v for v in find_times_s if v is not None], float)
    ax = axes[2]
    if t.size:
        ax.hist(t, bins=min(30, max(5, t.size // 3)), color="tab:orange", alpha=0.85)
    else:
        ax.text(0.5, 0.5, "no finds", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("time to find (s)")
    ax.set_ylabel("finds")
    ax.set_title(f"time to find ({t.size} finds)")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
