"""Draw a dynamics trace to PNG (matplotlib, Agg backend). Never called during a simulation."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from agv_model.dynamics import State, Trace

_STATE_ORDER = list(State)


def plot_trace(trace: Trace, path: str | Path, title: str = "") -> Path:
    """Speed, lateral error, steering and state against time, one panel each; returns `path`."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(4, 1, figsize=(9, 9), sharex=True,
                             gridspec_kw={"height_ratios": [3, 3, 2, 2]})
    t = trace.time_s
    ax_v, ax_y, ax_s, ax_state = axes
    ax_v.plot(t, trace.speed_mps, color="tab:blue")
    ax_v.set_ylabel("speed (m/s)")
    ax_pos = ax_v.twinx()
    ax_pos.plot(t, trace.position_m, color="tab:gray", linestyle="--", linewidth=1)
    ax_pos.set_ylabel("position (m)", color="tab:gray")
    ax_y.plot(t, trace.lateral_error_m * 1000.0, label="reference point (axle centre)")
    ax_y.plot(t, trace.sensor_error_m * 1000.0, label="line sensor", linewidth=1)
    ax_y.set_ylabel("lateral error (mm)")
    ax_y.legend(loc="upper right", fontsize=8)
    ax_s.plot(t, np.degrees(trace.steer_rad), color="tab:green")
    ax_s.set_ylabel("steer (deg)")
    codes = [_STATE_ORDER.index(s) for s in trace.state]
    ax_state.step(t, codes, where="post", color="tab:purple")
    ax_state.set_yticks(range(len(_STATE_ORDER)), [s.value for s in _STATE_ORDER], fontsize=7)
    ax_state.set_xlabel("time (s)")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
