"""What a finished sweep shows: its table on stdout and sweep.png, error against seconds."""

from __future__ import annotations

from pathlib import Path

from contactfem.cli.exits import _printable, _shown


def _sweep_summary(table: dict, directory: Path) -> str:
    engine = table["engine"]
    where = ("this process" if engine["kind"] == "serial" else
             f"{engine['workers']} Dask workers" + (f" at {engine['scheduler']}" if engine["scheduler"] else ""))
    counts = table["counts"]
    rows = table["points"]
    width = min(max([len(r["label"]) for r in rows] + [6]), 60)
    lines = [f"{table['sweep']['title']}: {counts['points']} points ({counts['solved']} solved on {where}, "
             f"{counts['reused']} reused) in {table['wall_seconds']:.1f} s"
             + (f" (and {engine['startup_seconds']:.1f} s to start the cluster)" if engine["startup_seconds"] else ""),
             (f"  {'#':>4}  {'values':<{width}}  {'status':<13}{'unknowns':>9}{'Newton':>7}{'seconds':>9}"
              f"{'contact force':>15}{'error':>11}  front")]
    for r in rows:
        def number(value, spec):
            return format(value, spec) if value is not None else "-"
        label = r["label"] if len(r["label"]) <= width else r["label"][: width - 3] + "..."
        lines.append(f"  {r['index']:>4}  {label:<{width}}  {r['status']:<13}{number(r['unknowns'], 'd'):>9}"
                     f"{number(r['iterations'], 'd'):>7}{number(r['seconds'].get('total'), '.2f'):>9}"
                     f"{number(r['contact_force'], '.6g'):>15}{number(r['error'], '.3e'):>11}"
                     f"  {'*' if r['pareto'] else ''}")
    lines.append("  (error: energy norm against the exact solution, or |‖u_h‖ - ‖u_finest‖| in the energy norm "
                 "within each group; * = on its group's Pareto front of error against seconds)")
    shown = _shown(directory)
    lines.append(f"  wrote {shown}/sweep.csv, sweep.json, sweep.png; each point in {shown}/points/")
    return "\n".join(_printable(line) for line in lines)


def _plot_sweep(path: Path, table: dict) -> None:
    """sweep.png: each point's error against its seconds, one colour per group, the Pareto fronts drawn."""
    import itertools

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    from contactfem.io.atomic import atomic_path
    from contactfem.sweep import pareto_series

    series = list(pareto_series(table))
    figure, axes = plt.subplots(figsize=(8.5, 6))
    colours = itertools.cycle(plt.rcParams["axes.prop_cycle"].by_key()["color"])
    for (group, rows, front), colour in zip(series, colours):
        axes.scatter([r["seconds"]["total"] for r in rows], [r["error"] for r in rows], s=24, color=colour,
                     label=group or "all points", zorder=3)
        axes.plot([r["seconds"]["total"] for r in front], [r["error"] for r in front], "-", color=colour, lw=1.2)
        axes.scatter([r["seconds"]["total"] for r in front], [r["error"] for r in front], s=90,
                     facecolors="none", edgecolors="black", lw=1.0, zorder=4)
        for r in front:
            axes.annotate(str(r["index"]), (r["seconds"]["total"], r["error"]), textcoords="offset points",
                          xytext=(5, 4), fontsize=7)
    kinds = {r["error_kind"] for _, rows, _ in series for r in rows}
    if series:
        axes.set_xscale("log")
        axes.set_yscale("log")
        seconds = FuncFormatter(lambda value, _: f"{value:g}")
        axes.xaxis.set_major_formatter(seconds)
        axes.xaxis.set_minor_formatter(seconds)
        axes.tick_params(axis="x", which="minor", labelsize=7)
        axes.scatter([], [], s=90, facecolors="none", edgecolors="black", label="Pareto front (point number)")
        axes.legend(fontsize=7, loc="best")
    else:
        axes.text(0.5, 0.5, "no point has an error to plot\n(one solved point per group, or none solved)",
                  ha="center", va="center", transform=axes.transAxes)
    axes.set_xlabel("seconds per point (meshing, assembly, solve, report)")
    axes.set_ylabel("energy-norm error ‖u − u_h‖" if kinds == {"exact"} else
                    "|‖u_h‖ − ‖u_finest‖|, energy norm (finest point of the group)" if kinds == {"finest"} else
                    "error (energy norm)")
    failed = sum(r["status"] != "ok" for r in table["points"])
    axes.set_title(f"{table['sweep']['title']}: error against time"
                   + (f" ({failed} point(s) without figures)" if failed else ""), fontsize=10)
    axes.grid(True, which="both", alpha=0.3)
    figure.tight_layout()
    try:
        with atomic_path(path) as temporary:
            figure.savefig(temporary, format="png", dpi=110)
    finally:
        plt.close(figure)
