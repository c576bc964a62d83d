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
    lines.append("  (error: energy norm against the exact solution, else the estimator's eta (an estimate, not a "
                 "bound), else |‖u_h‖ - ‖u_finest‖| in the energy norm within each group; * = on its group's "
                 "Pareto front of error against seconds)")
    shown = _shown(directory)
    lines.append(f"  wrote {shown}/sweep.csv, sweep.json, sweep.png; each point in {shown}/points/")
    return "\n".join(_printable(line) for line in lines)


def _plot_sweep(path: Path, table: dict) -> None:
    """sweep.png: each point's error against its seconds, one colour per group, the Pareto fronts drawn."""
    from contactfem.plots import plot_sweep

    plot_sweep(path, table, units=_base_units(table))


def _base_units(table: dict) -> dict | None:
    """The units of the sweep's base case (its ``units`` block), or None when the sweep sets
    them point by point or the base case cannot be read again."""
    from contactfem.case.files import read_text_file
    from contactfem.case.model import Units
    from contactfem.case.yaml_loader import load_yaml
    from contactfem.errors import ContactFemError

    if table.get("units"):
        return table["units"]
    if any(key == "units" or key.startswith("units.") for key in table.get("keys", [])):
        return None
    try:
        path = Path(table["case"]["file"])
        data = load_yaml(read_text_file(path), path.name)
        block = data.get("units") or {} if isinstance(data, dict) else {}
        return Units(length=str(block.get("length", "m")), force=str(block.get("force", "N"))).to_dict()
    except (ContactFemError, OSError, KeyError, TypeError, AttributeError):
        return None
