"""The figures of a diagnosis, shared by its two reports (the Markdown one with PNGs beside
it, report.py, and the self-contained HTML one, html_report.py): each function draws one
matplotlib Figure from the typed results (Ladder, Recording) and returns it, the caller
saves it as a file or embeds it. Lengths in mm; angles in the unit asked for (`ANGLE_UNITS`).
Matplotlib is imported inside `pyplot()`, with the Agg backend (no display)."""

from __future__ import annotations

import io
from collections.abc import Callable, Sequence
from types import TracebackType
from typing import TYPE_CHECKING, Any

import numpy as np

from robot_calib.diagnosis.ladder import Ladder, Rung
from robot_calib.diagnosis.names import wrap_name
from robot_calib.diagnosis.signatures import arc_angle_errors
from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.measurements import Recording
from robot_calib.model import corrected

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: angle unit -> factor from rad
ANGLE_UNITS = {"urad": 1e6, "deg": float(np.degrees(1.0))}
COLOURS = ("#4878a8", "#c44e52", "#55a868", "#8172b2", "#ccb974", "#64b5cd")


def pyplot() -> Any:  # noqa: ANN401 - the matplotlib.pyplot module
    """matplotlib.pyplot on the Agg backend (files only, no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


#: points a figure draws at most (a seeded random subset above; statistics use all):
#: a screen shows no more, and matplotlib's cost grows with every marker
MAX_DRAWN = 1500
MAX_ARROWS = 500  # 3D arrows of the residual-vector figure
#: the quantity and unit of the residual-vector figure's colour bars
COLOUR_BAR_LABEL = "|residual| [mm]"


def drawn(n: int, limit: int = MAX_DRAWN) -> IntArray:
    """Indices (sorted) of at most `limit` of n points to draw, the same every time."""
    if n <= limit:
        return np.arange(n)
    return np.sort(np.random.default_rng(0).choice(n, limit, replace=False))


def insample_residuals(rung: Rung, recording: Recording) -> Array:
    """A rung's in-sample residuals (n, 3) [m] on `recording`: its calibration's, less its
    learned correction's prediction for the hybrid rung."""
    cal = rung.calibration
    return corrected(cal.residuals, recording.poses, cal.correction)


class FigureCache:
    """PNG bytes of the figures of one report set, each drawn once, here: the Markdown
    report and the HTML page show the same figures (drawing them twice cost seconds).
    `robot_calib.flows.figures.FiguresAside` draws them in other processes instead."""

    def __init__(self, dpi: int = 100) -> None:
        self.dpi = dpi
        self._png: dict[str, bytes | None] = {}

    def png(self, key: str, draw: Callable[[], Figure | None]) -> bytes | None:
        """The PNG of figure `key`, drawn by `draw` the first time (None: no figure)."""
        if key not in self._png:
            self._png[key] = render_png(draw, self.dpi)
        return self._png[key]

    def draw_aside(self, *groups: Sequence[tuple[str, Callable[[], Figure | None]]]) -> None:
        """Figures the caller will ask for ((key, draw) each, as `png` takes them): here,
        each is drawn when asked."""
        del groups

    def close(self, abort: bool = False) -> None:
        """Nothing to end here (`FiguresAside` reaps its processes)."""
        del abort

    def __enter__(self) -> FigureCache:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close(abort=kind is not None)


def render_png(draw: Callable[[], Figure | None], dpi: int) -> bytes | None:
    """The PNG bytes of the figure `draw` makes (None: no figure), at `dpi`."""
    fig = draw()
    if fig is None:
        return None
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi)
    pyplot().close(fig)
    return buffer.getvalue()


def warm_up(plt: Any) -> None:  # noqa: ANN401 - the matplotlib.pyplot module
    """Draw a small figure of the kinds the reports draw (a logarithmic histogram with a
    legend beside it, markers, a 3D panel with a colour bar, tight layout) at their
    resolution: matplotlib loads its fonts, caches their glyphs and imports its 3D
    toolkit once, before the figures are asked for (their first drawing cost 0.1-0.15 s
    more each)."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    values = np.geomspace(1e-3, 1.0, 50)
    fig = plt.figure(figsize=(6, 2))
    ax = fig.add_subplot(1, 3, 1)
    ax.hist(values, bins=np.geomspace(1e-3, 1.0, 10), histtype="step", label="model\n(rms)")
    ax.axvline(0.1, ls=":")
    ax.set_xscale("log")
    ax.set_xlabel("error [mm] 0.1234")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax = fig.add_subplot(1, 3, 2)
    ax.plot(values, values, ".", ms=2, label="geometric")
    ax.legend(fontsize=7)
    ax = fig.add_subplot(1, 3, 3, projection="3d")
    ax.quiver(values[:5], values[:5], values[:5], values[:5], values[:5], values[:5])
    fig.colorbar(ScalarMappable(Normalize(0.0, 1.0)), ax=ax, label="|residual| [mm]")
    fig.suptitle("warm-up 0.1 mm")
    fig.tight_layout()
    fig.savefig(io.BytesIO(), format="png", dpi=100)
    plt.close(fig)


def compared_rungs(ladder: Ladder) -> tuple[Rung, ...]:
    """The rungs a before/after figure compares: geometric and the best (one if equal)."""
    return (ladder.rungs[0], ladder.rungs[-1])[: len(ladder.rungs)]


#: a ladder figure whose values (bars, floor, bound) span more than this ratio is drawn on
#: a logarithmic axis: on a linear one a 0.02 mm rung beside a 50 mm one is invisible
LOG_AXIS_RATIO = 10.0


def ladder_yscale(values_mm: Sequence[float]) -> str:
    """'log' when the positive `values_mm` [mm] (the rungs' held-out rms, the noise floor,
    the learnable bound) span more than LOG_AXIS_RATIO, else 'linear'."""
    positive = [v for v in values_mm if v > 0 and np.isfinite(v)]
    if len(positive) < 2:
        return "linear"
    return "log" if max(positive) > LOG_AXIS_RATIO * min(positive) else "linear"


def ladder_figure(ladder: Ladder, floor_mm: float | None) -> Figure:
    """Held-out rms [mm] of every rung as bars, the noise floor and the learnable bound as
    lines labelled where they are drawn; on a log axis when the values span more than
    LOG_AXIS_RATIO (`ladder_yscale`)."""
    plt = pyplot()
    names = [wrap_name(r.model, 20) for r in ladder.rungs]
    heights = [r.heldout.absolute_rms_mm for r in ladder.rungs]
    lines = [] if floor_mm is None else [(floor_mm, "noise floor", "k", "--")]
    if ladder.learnable is not None and ladder.learnable.bounds:
        lines.append(
            (
                ladder.learnable.holdout_abs_rms_mm,
                "learnable bound\n(residual model)",
                COLOURS[1],
                ":",
            )
        )
    rows = max(name.count("\n") + 1 for name in names)
    longest = max(len(line) for name in names for line in name.split("\n"))
    per_bar = max(1.5, 0.07 * longest)  # [in]: the longest label line fits its slot
    fig, ax = plt.subplots(figsize=(max(7.0, 1.2 + per_bar * len(names)), 3.2 + 0.15 * rows))
    every = [v for v in heights + [value for value, *_ in lines] if v > 0]
    scale = ladder_yscale(every)
    ax.set_yscale(scale)
    bars = ax.bar(range(len(names)), heights, color=COLOURS[0])
    ax.bar_label(bars, fmt="%.4f mm", fontsize=8)
    if scale == "log":  # bars from below the lowest value, room above for their labels
        ax.set_ylim(min(every) / 3.0, max(every) * 3.0)
    else:
        ax.set_ylim(0.0, max(every, default=1.0) * 1.15)
    # each line labelled beside the axes (never over a bar or its label): the lower line's
    # label below its line, the other's above, so two close lines keep readable labels
    lowest = min((value for value, *_ in lines), default=0.0)
    for value, label, colour, style in lines:
        ax.axhline(value, color=colour, ls=style, lw=1.2)
        below = value == lowest and len(lines) > 1
        ax.annotate(
            f"{label}\n{value:.4f} mm",
            (1.0, value),
            xycoords=("axes fraction", "data"),
            xytext=(4, -2 if below else 2),
            textcoords="offset points",
            ha="left",
            va="top" if below else "bottom",
            fontsize=8,
            color=colour,
        )
    ax.set_xticks(range(len(names)), names, fontsize=8)
    ax.set_ylabel("held-out rms error [mm]" + (" (log scale)" if scale == "log" else ""))
    ax.set_title(f"the ladder (scored on {ladder.scored_on})")
    fig.tight_layout()
    return fig


def angle_figure(ladder: Ladder, recording: Recording, unit: str = "urad") -> Figure | None:
    """The geometric model's residual along each sweep's arc, as a joint-angle error in
    `unit` (a key of ANGLE_UNITS), against the joint's reading [deg], split by approach
    direction; None without circle sweeps."""
    geo = ladder.rungs[0].calibration
    arcs = arc_angle_errors(geo.model, geo.parameters, recording, geo.residuals)
    if not arcs:
        return None
    plt = pyplot()
    fig, axes = plt.subplots(2, 3, figsize=(10, 5.5), sharey=False)
    for ax, (j, (idx, err, _)) in zip(axes.ravel(), arcs.items()):
        q = np.degrees(recording.poses.q[idx, j - 1])
        forth = recording.poses.direction[idx, j - 1] > 0
        ax.plot(q[forth], err[forth] * ANGLE_UNITS[unit], ".", ms=3, label="approached +")
        ax.plot(q[~forth], err[~forth] * ANGLE_UNITS[unit], ".", ms=3, label="approached -")
        ax.set_title(f"joint {j}", fontsize=9)
        ax.set_xlabel("reading [deg]", fontsize=8)
        ax.set_ylabel(f"arc error [{unit}]", fontsize=8)
    for ax in axes.ravel()[len(arcs) :]:
        ax.set_visible(False)
    axes.ravel()[0].legend(fontsize=7)
    fig.suptitle("geometric model: residual along each sweep's arc vs the joint angle")
    fig.tight_layout()
    return fig


def points_in_base(ladder: Ladder, points: Array) -> tuple[Array, Array]:
    """Points (n, 3) [m] of the tracker frame in the robot base frame [m] (the geometric
    calibration's tracker pose), and the rotation (3, 3) base -> tracker (a vector v in the
    tracker frame is `v @ rotation` in the base frame)."""
    geo = ladder.rungs[0].calibration
    base2tracker = geo.model.base2tracker(geo.parameters)
    return (points - base2tracker[:3, 3]) @ base2tracker[:3, :3], base2tracker[:3, :3]


def residual_map_figure(ladder: Ladder, recording: Recording) -> Figure:
    """|residual| [mm] of the geometric model and of the best rung (in-sample) against the
    measured point's reach (distance from joint 1's axis) and height in the robot base
    frame, and against every joint's reading: where in the workspace the error lives."""
    plt = pyplot()
    in_base, _ = points_in_base(ladder, recording.points)
    axes_x = {
        "reach [mm]": np.hypot(in_base[:, 0], in_base[:, 1]) * 1e3,
        "height [mm]": in_base[:, 2] * 1e3,
    }
    for j in range(recording.poses.q.shape[1]):
        axes_x[f"joint {j + 1} reading [deg]"] = np.degrees(recording.poses.q[:, j])
    n_cols = 4
    n_rows = -(-len(axes_x) // n_cols)
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(12, 2.6 * n_rows), sharey=True)
    rows = drawn(len(recording))
    norms = [
        (wrap_name(rung.model), np.linalg.norm(insample_residuals(rung, recording), axis=1) * 1e3)
        for rung in compared_rungs(ladder)
    ]
    for ax, (label, x) in zip(np.ravel(axes), axes_x.items()):
        for model, norm in norms:
            ax.plot(x[rows], norm[rows], ".", ms=2, label=model)
        ax.set_xlabel(label, fontsize=8)
    for ax in np.ravel(axes)[len(axes_x) :]:
        ax.set_visible(False)
    np.ravel(axes)[0].set_ylabel("|residual| [mm]", fontsize=8)
    np.ravel(axes)[0].legend(fontsize=7)
    fig.suptitle("in-sample |residual| against reach, height (robot base frame) and readings")
    fig.tight_layout()
    return fig


def time_figure(ladder: Ladder, recording: Recording) -> Figure:
    """|residual| [mm] (in-sample) of geometric and the best rung against time [s]."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 3.2))
    rows = drawn(len(recording))
    for rung in compared_rungs(ladder):
        norm = np.linalg.norm(insample_residuals(rung, recording), axis=1) * 1e3
        ax.plot(recording.poses.time[rows], norm[rows], ".", ms=3, label=wrap_name(rung.model))
    ax.set_xlabel("time since the first measurement [s]")
    ax.set_ylabel("|residual| [mm]")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def drift_figure(recording: Recording) -> Figure | None:
    """The reference reflectors' displacement from their first place [mm] against time
    [min] as read (dots) and as the tracker's fitted drift moves them (lines), one colour
    per reflector, per source with references; None without any."""
    sources = [r for r in recording.references if r.drift is not None]
    if not sources:
        return None
    plt = pyplot()
    fig, axes = plt.subplots(1, len(sources), figsize=(7, 3.2), squeeze=False)
    for ax, refs in zip(axes[0], sources):
        assert refs.drift is not None
        seconds = np.asarray(refs.stamp_ns, dtype=np.float64) * 1e-9
        minutes = (seconds - seconds[0]) / 60.0
        start = np.asarray(refs.drift.start_m)[:, None]
        read = np.linalg.norm(refs.points - start, axis=2) * 1e3
        fitted = np.linalg.norm(refs.drift.expected(seconds) - start, axis=2) * 1e3
        for k, name in enumerate(refs.names):
            line = ax.plot(minutes, fitted[k], "-", lw=1.5, label=f"{name} (drift)")[0]
            ax.plot(minutes, read[k], ".", ms=2, color=line.get_color(), alpha=0.5)
        ax.set_title(recording.sources[refs.source].rsplit("/", 1)[-1], fontsize=8)
        ax.set_xlabel("time since the first read [min]")
        ax.set_ylabel("|reference - first place| [mm]")
        ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def error_histogram_figure(errors_mm: Sequence[tuple[str, Array]], scored_on: str) -> Figure:
    """Histograms of the per-point error [mm] of each (model, errors (m,) [mm]) on
    logarithmic bins (models differ by orders of magnitude), with each model's rms; the
    legend to the right of the axes, where it covers no bar."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 3.4))
    every = np.concatenate([e for _, e in errors_mm])
    low = max(float(every[every > 0].min()) if np.any(every > 0) else 1e-4, 1e-5)
    high = max(float(every.max()), 2 * low)
    bins = np.geomspace(low, high, 40)
    for k, (model, errors) in enumerate(errors_mm):
        rms = float(np.sqrt(np.mean(errors**2)))
        colour = COLOURS[k % len(COLOURS)]
        ax.hist(
            np.clip(errors, low, high),
            bins=bins,
            histtype="step",
            lw=1.6,
            color=colour,
            label=f"{wrap_name(model)}\n(rms {rms:.4f} mm)",
        )
        ax.axvline(rms, color=colour, ls=":", lw=1)
    ax.set_xscale("log")
    ax.set_xlabel("per-point error |predicted - measured| [mm] (log scale)")
    ax.set_ylabel("points")
    ax.set_title(f"per-point error, {scored_on}", fontsize=10)
    ax.legend(
        fontsize=8,
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        borderaxespad=0.0,
        labelspacing=0.8,
    )
    fig.tight_layout()
    return fig


#: the height of the quiver figure's suptitle and of a line of its panel titles [in]
SUPTITLE_IN, TITLE_LINE_IN = 0.35, 0.17


def quiver_figure(
    ladder: Ladder, points: Array, residuals: Sequence[tuple[str, Array]], scored_on: str
) -> Figure:
    """3D residual vectors, one panel per (model, residuals (n, 3) [m], predicted -
    measured, tracker frame) at the measured `points` (n, 3) [m, tracker frame], drawn in
    the robot base frame [mm]; every panel at one scale (the largest arrow 0.3 of the
    points' extent, rounded down to 1, 2 or 5 x 10^k), written in the title as
    'arrows x K: 1 mm of error drawn as K mm'; colour: |residual| [mm] from 0 to the
    panel's largest, read on the panel's colour bar."""
    plt = pyplot()
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    rows = drawn(len(points), MAX_ARROWS)  # the scale and the figures in titles from all
    in_base, rotation = points_in_base(ladder, points)
    xyz = in_base * 1e3
    extent = float(np.ptp(xyz, axis=0).max()) or 1.0
    largest = max(float(np.linalg.norm(r, axis=1).max()) for _, r in residuals) * 1e3
    scale = _round_scale(0.3 * extent / largest) if largest > 0 else 1.0
    fig = plt.figure(figsize=(6.0 * len(residuals), 5.0))
    narrow = "\n" if len(residuals) == 1 else " "  # one panel: the suptitle on two lines
    for k, (model, res) in enumerate(residuals):
        arrows = (res @ rotation) * 1e3 * scale  # (n, 3) mm in the base frame, scaled
        norm = np.linalg.norm(res, axis=1) * 1e3
        ax = fig.add_subplot(1, len(residuals), k + 1, projection="3d")
        ax.scatter(*xyz[rows].T, s=3, color="0.6")
        colour_scale = Normalize(0.0, max(float(norm.max()), 1e-12))
        cmap = plt.get_cmap("viridis")
        ax.quiver(
            *xyz[rows].T,
            *arrows[rows].T,
            colors=cmap(colour_scale(norm[rows])),
            arrow_length_ratio=0.2,
            lw=1.3,
        )
        bar = fig.colorbar(ScalarMappable(colour_scale, cmap), ax=ax, shrink=0.6, pad=0.12)
        bar.set_label(COLOUR_BAR_LABEL, fontsize=8)
        bar.ax.tick_params(labelsize=7)
        ax.set_title(
            f"{wrap_name(model, 40)}\nrms {np.sqrt(np.mean(norm**2)):.4f} mm, max "
            f"{norm.max():.4f} mm",
            fontsize=9,
        )
        ax.set_xlabel("x [mm]", fontsize=8)
        ax.set_ylabel("y [mm]", fontsize=8)
        ax.set_zlabel("z [mm]", fontsize=8)
        ax.tick_params(labelsize=7)
    fig.suptitle(
        f"residual vectors at the measured points ({scored_on}, robot base frame);"
        f"{narrow}arrows x {scale:g}: 1 mm of error drawn as {scale:g} mm",
        fontsize=10,
    )
    # Fixed margins, not tight_layout: a 3D panel's labels lie inside its own box, and its
    # tight bounding box cost 0.17 s of the 0.4 s this figure takes. The top margin holds
    # the suptitle and the longest panel title (TITLE_LINE_IN per line).
    lines = max(wrap_name(model, 40).count("\n") for model, _ in residuals) + 2
    lines += narrow.count("\n")  # the suptitle's second line
    top = 1.0 - (SUPTITLE_IN + TITLE_LINE_IN * lines) / fig.get_figheight()
    fig.subplots_adjust(left=0.0, right=0.97, bottom=0.03, wspace=0.08, top=top)
    return fig


def _round_scale(scale: float) -> float:
    """`scale` rounded down to 1, 2 or 5 times a power of ten (a scale people can read)."""
    power = 10.0 ** np.floor(np.log10(scale))
    return float(max(m for m in (1, 2, 5) if m * power <= scale) * power)
