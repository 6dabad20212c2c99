"""The plots of a sweep's aggregates: metrics against a swept parameter, a safety metric against its price, the
bars' crossing rate against the paper's bound; and the metrics a sweep's summary shows by default.

Every plot draws the per-cell means of :func:`ijoy_jax.sweep.aggregate` with their 95% confidence intervals
and returns the matplotlib figure (drawn in a notebook; inspect its axes), writing it as a PNG when given a
path; ``ijoy sweep summarize`` prints the same metrics (:func:`summary_metrics`) as a table.
"""

from __future__ import annotations

import numpy as np

from ijoy_jax.sweep.columns import PARAMETER_PREFIXES, UNITS
from ijoy_jax.sweep.schema import ROBOT_DEFAULTS

__all__ = [
    "PAPER_ACTIONS",
    "PHYSICS_PLOT_METRICS",
    "PLOT_METRICS",
    "SELECTOR_PLOT_METRICS",
    "action_counts",
    "b_max",
    "plot",
    "plot_crossing",
    "plot_tradeoff",
    "summary_metrics",
]

PAPER_ACTIONS = 496
"""Actions per foot in the paper's HRP-2 action set (``ijoy_jax.robots.hrp2(density=1.0)``)."""


def action_counts(densities, reach=None, model: str = "biped") -> np.ndarray:
    """Actions per foot of ``model``'s action set at each density (:func:`ijoy_jax.sweep.models.actions`:
    HRP-2's by default; the G1's lattice has the same counts at the paper's reach), as float64.

    ``reach`` (m): a number, or one per density (a sweep's ``robot.reach`` column); None: the paper's 0.20.

    Example:
      >>> action_counts([0.4, 1.0, 2.0]).tolist(), action_counts([1.0], reach=0.30).tolist()
      ([52.0, 496.0, 3307.0], [720.0])
    """
    from ijoy_jax import robots
    from ijoy_jax.sweep import models

    d = np.asarray(densities, np.float64)
    r = np.broadcast_to(np.asarray(robots.PAPER_REACH if reach is None else reach, np.float64), d.shape)
    pairs = list(zip(d.ravel().tolist(), r.ravel().tolist(), strict=True))
    sizes = {p: len(models.actions(model, *p)) for p in dict.fromkeys(pairs)}
    return np.array([sizes[p] for p in pairs], np.float64).reshape(d.shape)


PLOT_METRICS = (
    "distance_along",
    "mean_deviation",
    "steps_in_place",
    "stopped",
    "footholds_on_obstacles",
    "footholds_near_obstacles",
)
"""A perfect-robot sweep's summary (:func:`summary_metrics`), in order: progress along the command (m), deviation
from it (m), steps marking time, the fraction of walks stopped (no valid step), footholds on and near obstacles."""

SELECTOR_PLOT_METRICS = PLOT_METRICS
"""A sweep over the selector's options (``selector.*``) is a perfect-robot sweep: the same summary, whose
progress, marking time, stops and footholds near obstacles are what a better selector changes."""

PHYSICS_PLOT_METRICS = (
    "fell",
    "distance_along",
    "collided",
    "placement_error_mean",
    *(m for m in PLOT_METRICS if m != "distance_along"),
)
"""A ``walker = "mjx"`` sweep's summary: the fall rate and the collision rate on either side of progress (the
safety beside its price), the mean touch-down error (m), then the rest of :data:`PLOT_METRICS`."""


def summary_metrics(agg) -> tuple[str, ...]:
    """The metrics a sweep's summary shows by default, in order: the columns of the table ``ijoy sweep summarize``
    prints and the panels of :func:`plot`, one definition for both so they cannot disagree.

    :data:`PHYSICS_PLOT_METRICS` for a ``walker = "mjx"`` sweep (aggregates with ``fell``), else
    :data:`PLOT_METRICS`, keeping those the aggregates hold (results written before
    ``footholds_near_obstacles`` existed lack it).

    Args:
      agg: :func:`aggregate` output (columns ``m.mean`` per metric ``m``).

    Returns:
      the metric names, a tuple of str.

    Example:
      >>> import pandas as pd
      >>> summary_metrics(pd.DataFrame(columns=["distance_along.mean", "stopped.mean", "fell.mean"]))
      ('fell', 'distance_along', 'stopped')
    """
    return tuple(m for m in (PHYSICS_PLOT_METRICS if "fell.mean" in agg else PLOT_METRICS) if f"{m}.mean" in agg)


_TITLES = {"collided": "collision rate (rollouts touching an obstacle)", "fell": "fall rate (rollouts that fell)"}


def plot(agg, out=None, x=None, metrics=None, title: str = ""):
    """Plot aggregates against one swept parameter, one panel per metric (up to 3 columns, titled with the
    metric and its unit), points at the mean over scenarios with 95% CI error bars.

    Args:
      agg: :func:`aggregate` output.
      out: PNG path to write (None: only return the figure).
      x: the parameter on the x axis (default: the swept column with most values).
      metrics: the metrics to plot (one panel each; default :func:`summary_metrics`, the columns of the
        summary table: :data:`PHYSICS_PLOT_METRICS` for a physics sweep, else :data:`PLOT_METRICS`).
      title: figure title.

    Other swept columns become one line each (legend). A robot parameter's
    library default (:data:`ijoy_jax.sweep.ROBOT_DEFAULTS`) is marked by a
    dashed line; values spanning 20x or more get a symlog axis. Action-set
    density is drawn as the number of actions per foot (:func:`action_counts`)
    on a log axis with the paper's 496 (:data:`PAPER_ACTIONS`) marked.

    A physics parameter (``sim.*``) on the x axis has its nominal value
    marked; a rate's interval (a ``fraction`` metric) is clipped to [0, 1].
    So a margin sweep crossed with an execution-error level draws the
    collision and fall rates against the margin, one line per level.

    Aggregates of a bar-crossing sweep (a ``crossed`` metric and a swept
    ``terrain.width``) with the default ``metrics`` and ``x`` go to
    :func:`plot_crossing` instead.

    Returns:
      The matplotlib figure (to show in a notebook, or to inspect: one axes per metric, in order).
    """
    if "crossed.mean" in agg and "terrain.width" in agg and x in (None, "terrain.width") and metrics is None:
        return plot_crossing(agg, out, title=title)
    if metrics is None:
        metrics = summary_metrics(agg)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    params = [c for c in agg.columns if c.startswith(PARAMETER_PREFIXES)]
    if x is None:
        x = max(params, key=lambda c: agg[c].nunique()) if params else "cell"
    others = [c for c in params if c != x]
    ncols = min(3, len(metrics))  # a readable grid, not one long row
    nrows = -(-len(metrics) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.6 * ncols, 3.7 * nrows), squeeze=False)
    for ax in axes.ravel()[len(metrics) :]:
        ax.remove()
    groups = agg.groupby(others, sort=True) if others else [((), agg)]
    # Density is drawn as what it means: the number of actions in the set (HRP-2's lattice), 496 the paper's.
    reach = (lambda g: g["robot.reach"]) if "robot.reach" in agg.columns else (lambda g: None)
    xv = (lambda g: action_counts(g[x], reach(g))) if x == "robot.density" else (lambda g: np.asarray(g[x], np.float64))
    for ax, m in zip(axes.ravel(), metrics, strict=False):
        for key, g in groups:
            g = g.sort_values(x)
            key = key if isinstance(key, tuple) else (key,)
            label = ", ".join(f"{c.partition('.')[2]} = {v:g}" for c, v in zip(others, key, strict=True))
            mean, ci = g[f"{m}.mean"].to_numpy(np.float64), np.nan_to_num(g[f"{m}.ci95"].to_numpy(np.float64))
            # a rate's interval stays within [0, 1] (a mean outside it, which only made-up aggregates have,
            # gets no bar on that side rather than matplotlib's refusal of a negative one)
            lo, hi = (
                (np.clip(mean - ci, 0, 1), np.clip(mean + ci, 0, 1))
                if UNITS.get(m) == "fraction"
                else (mean - ci, mean + ci)
            )
            yerr = [np.maximum(mean - lo, 0.0), np.maximum(hi - mean, 0.0)]
            ax.errorbar(xv(g), mean, yerr=yerr, marker="o", capsize=3, label=label or None)
        if x == "robot.density":
            ax.axvline(PAPER_ACTIONS, color="0.4", ls="--", lw=1, label=f"paper's {PAPER_ACTIONS} actions (HRP-2)")
            ax.set_xscale("log")
            ticks = sorted(set(xv(agg).astype(int).tolist()) | {PAPER_ACTIONS})
            ax.set_xticks(ticks, [str(t) for t in ticks], rotation=45, fontsize=7)
            ax.minorticks_off()
            ax.set_xlabel("actions in the set S, per foot (count)")
        else:
            default = ROBOT_DEFAULTS.get(x.partition(".")[2]) if x.startswith("robot.") else None
            what = "library default"
            if x.startswith("sim."):
                from ijoy_jax.sim import physics

                default, what = getattr(physics.NOMINAL, x.partition(".")[2]), "nominal robot"
            if default is not None:
                ax.axvline(default, color="0.4", ls="--", lw=1, label=f"{what} ({default:g})")
            pos = agg[x][agg[x] > 0] if x in agg else []
            if len(pos) and agg[x].max() >= 20 * pos.min():
                ax.set_xscale("symlog", linthresh=float(pos.min()), linscale=0.5)
                ax.set_xlim(min(0.0, float(agg[x].min())) - 0.3 * float(pos.min()), 1.5 * float(agg[x].max()))
            ax.set_xlabel(f"{x.partition('.')[2] or x} ({UNITS.get(x, '-')})")
            ticks = np.unique(xv(agg)) if x in agg else np.array([])
            if 0 < len(ticks) <= 12 and np.allclose(ticks, np.round(ticks)):
                ax.set_xticks(ticks)  # a count (the lookahead's horizon): no ticks between its values
        ax.set_ylabel(f"mean ({UNITS[m]})")
        ax.set_title(_TITLES.get(m, f"{m.replace('_', ' ')} ({UNITS[m]})"), fontsize=10)
        ax.grid(alpha=0.3)
    if axes[0][0].get_legend_handles_labels()[0]:  # a single series with no default line has nothing to name
        axes[0][0].legend(fontsize=8)
    return _finish(fig, agg, title, out)


def _finish(fig, agg, title, out):
    """Title a sweep figure with its scenarios per point, save it to ``out`` (unless None) and return it."""
    n = int(agg["n"].min()) if len(agg) else 0
    fig.suptitle(f"{title}  (mean and 95% CI over {n} scenarios per point)".strip())
    fig.tight_layout()
    if out is not None:
        fig.savefig(out, dpi=110)
    return fig


def _short(column: str) -> str:
    """A swept column's name without its prefix, for a point's label (``robot.metrics.support_limit`` ->
    ``support_limit``)."""
    return column.rsplit(".", 1)[-1]


def plot_tradeoff(agg, out=None, safety: str = "fell", price: str = "distance_along", title: str = ""):
    """The price of safety: one point per cell, a safety metric (up) against what it costs (across), each with
    its 95% CI.

    Args:
      agg: :func:`aggregate` output with ``{safety}.mean`` and ``{price}.mean`` (e.g. a physics sweep's fall
        rate and progress).
      out: PNG path to write (None: only return the figure).
      safety, price: the metrics on the y and x axes (:data:`UNITS` gives their units).
      title: figure title.

    The first swept column (e.g. the terrain's amplitude, or the family's parameter) picks each point's
    colour; with three or more swept columns the second picks its marker (both in the legend); the others
    label the point, so a reader sees which settings buy safety with progress without labels piling up
    where cells cluster. A fraction metric's interval is clipped to [0, 1].

    Returns:
      The matplotlib figure (one axes).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for m in (safety, price):
        if f"{m}.mean" not in agg:
            known = [c[: -len(".mean")] for c in agg.columns if c.endswith(".mean")]
            raise ValueError(f"{m!r} is not a metric of this sweep; known: {', '.join(known)}")
    # the swept parameters (aggregate groups by them)
    swept = [c for c in agg.columns if c.startswith(PARAMETER_PREFIXES)]
    colour_by = swept[0] if swept else None
    marker_by = swept[1] if len(swept) >= 3 else None
    labels = swept[2:] if marker_by is not None else swept[1:]
    fig, ax = plt.subplots(figsize=(8.0, 5.4))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    markers = "os^Dvp*hX"
    marker_of = {} if marker_by is None else {v: markers[i % len(markers)]
                                              for i, v in enumerate(sorted(agg[marker_by].unique()))}
    groups = [(None, agg)] if colour_by is None else list(agg.groupby(colour_by, sort=True))
    for i, (value, g) in enumerate(groups):
        colour = colours[i % len(colours)]
        name = "all cells" if colour_by is None else f"{_short(colour_by)} = {value:g}"
        parts = [(None, g)] if marker_by is None else list(g.groupby(marker_by, sort=True))
        for mark, part in parts:
            x, y = (part[f"{m}.mean"].to_numpy(np.float64) for m in (price, safety))
            xe, ye = (np.nan_to_num(part[f"{m}.ci95"].to_numpy(np.float64)) for m in (price, safety))
            y_lo, y_hi = y - ye, y + ye
            if UNITS.get(safety) == "fraction":
                y_lo, y_hi = np.clip(y_lo, 0, 1), np.clip(y_hi, 0, 1)
            ax.errorbar(
                x, y, xerr=xe, yerr=[y - y_lo, y_hi - y], fmt=marker_of.get(mark, "o"), capsize=2, color=colour,
                label=name if marker_by is None else None,
            )
            for (_, row), xi, yi in zip(part.iterrows(), x, y, strict=True):
                text = ", ".join(f"{_short(c)} {row[c]:g}" for c in labels)
                if text:
                    ax.annotate(text, (xi, yi), textcoords="offset points", xytext=(4, 3), fontsize=6, color=colour)
        if marker_by is not None:  # the colour's legend entry, drawn once
            ax.plot([], [], "o", color=colour, label=name)
    for mark, shape in marker_of.items():
        ax.plot([], [], shape, color="0.4", label=f"{_short(marker_by)} = {mark:g}")
    ax.set_xlabel(f"{price.replace('_', ' ')} ({UNITS.get(price, '')})")
    ax.set_ylabel(_TITLES.get(safety, f"{safety.replace('_', ' ')} ({UNITS.get(safety, '')})"))
    ax.grid(alpha=0.3)
    if colour_by is not None:
        ax.legend(fontsize=8)
    return _finish(fig, agg, title, out)


def b_max(margin, step_length: float = 0.20, foot_length: float = 0.242):
    """The paper's bound on the bar length a foot can step over: ``2 L - foot length - 2 m`` (metres).

    From a stance beside the bar, the blocked foot lands at most ``L`` ahead of
    the stance foot after starting up to ``L`` behind it (a ``2 L`` swing); its
    grown footprint (length + 2 m) must fit before the bar and then beyond it.
    HRP-2: L = 0.20 m (largest dx of an action), foot length 0.242 m.

    Example:
      >>> round(b_max(0.02), 3)
      0.118
    """
    out = 2.0 * step_length - foot_length - 2.0 * np.asarray(margin, np.float64)
    return float(out) if out.ndim == 0 else out


def plot_crossing(agg, out=None, title: str = "", step_length: float = 0.20, foot_length: float = 0.242):
    """Crossing rate against bar length, one line per safety margin, the paper's bound marked.

    Args:
      agg: :func:`aggregate` output of a sweep over ``terrain.width`` (bar
        length along the walk) and optionally ``robot.margin``, with the
        ``crossed`` metric (bars family).
      out: PNG path to write (None: only return the figure).
      title: figure title.
      step_length, foot_length: L and the foot length in :func:`b_max` (HRP-2's by default).

    Each margin m is drawn in its own colour with the fraction of scenarios
    that crossed (95% CI error bars, clipped to [0, 1]) and a dashed vertical
    line at ``b_max(m)`` (in the legend; a margin with ``b_max <= 0`` admits
    no bar and is noted there).

    Returns:
      The matplotlib figure (one axes).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9.0, 4.8))
    margins = sorted(agg["robot.margin"].unique()) if "robot.margin" in agg else [None]
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    handles = []
    for i, m in enumerate(margins):
        g = (agg if m is None else agg[agg["robot.margin"] == m]).sort_values("terrain.width")
        color = colors[i % len(colors)]
        mean = g["crossed.mean"].to_numpy(np.float64)
        ci = np.nan_to_num(g["crossed.ci95"].to_numpy(np.float64))
        lo, hi = np.clip(mean - ci, 0, 1), np.clip(mean + ci, 0, 1)
        name = "measured" if m is None else f"m = {100 * m:g} cm: measured"
        handles.append(
            ax.errorbar(
                g["terrain.width"] * 100,
                mean,
                yerr=[mean - lo, hi - mean],
                marker="o",
                capsize=3,
                color=color,
                label=name,
            )
        )
        if m is not None:
            bound = float(b_max(m, step_length, foot_length))
            if bound > 0:
                handles.append(
                    ax.axvline(
                        100 * bound,
                        color=color,
                        ls="--",
                        lw=1.2,
                        label=f"m = {100 * m:g} cm: paper's b_max = {100 * bound:.1f} cm",
                    )
                )
            else:
                handles.append(
                    ax.plot(
                        [],
                        [],
                        color=color,
                        ls="--",
                        lw=1.2,
                        label=f"m = {100 * m:g} cm: b_max = {100 * bound:.1f} cm, none crossable",
                    )[0]
                )
    ax.set_xlabel("bar length along the walking direction, b (cm)")
    ax.set_ylabel("scenarios that got past the bar (fraction)")
    ax.set_ylim(-0.05, 1.05)
    ax.grid(alpha=0.3)
    ax.legend(handles=handles, fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    ax.set_title(
        f"dashed: the paper's bound b_max(m) = 2 L - foot length - 2 m (L = {100 * step_length:g} cm, "
        f"foot {100 * foot_length:g} cm)\npoints: mean and 95% CI; below b_max, crossing also depends "
        "on where the foothold lattice meets the bar",
        fontsize=8,
    )
    return _finish(fig, agg, title, out)
