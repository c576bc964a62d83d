"""The summary a finished solve prints on stdout."""

from __future__ import annotations

from pathlib import Path

from contactfem.cli.exits import _printable, _shown


def _steps(count: int) -> str:
    return f"{count} step" if count == 1 else f"{count} steps"


def _summary(report: dict, written: list[Path]) -> str:
    from contactfem.plots import zone_text

    zone = report["contact_zone"]
    signs = report["sign_conditions"]
    intervals = zone_text(tuple(i["abscissa"]) for i in zone["intervals"])
    timings = report["timings"]
    lines = [
        f"{report['case']['title']} — method {report['method']['equation']} {report['method']['name']}",
        f"  mesh         {report['mesh']['nodes']} nodes, {report['mesh']['triangles']} triangles, "
        f"{report['unknowns']['displacement']} unknowns",
        f"  Newton       {_steps(report['solver']['iterations'])} ({report['solver']['backend']})",
        f"  contact      {zone['active_nodes']} of {zone['contact_nodes']} nodes active; zone along ΓC: {intervals}",
        f"  force        {report['contact_force']['normal']:.6g} (normal, total)",
        f"  signs        min multiplier {signs['min_multiplier']:.3g}, "
        f"max u_n - g {signs['max_normal_displacement_minus_gap']:.3g}",
        f"  equilibrium  relative residual {report['equilibrium']['relative_force_residual']:.1e}",
        _certificate_line(report["solver"].get("certificate")),
        *_accuracy_lines(report.get("accuracy")),
        *_force_lines(report.get("boundary_forces")),
        *_platen_lines(report.get("platens")),
        *_path_lines(report.get("load_path")),
        *_parallel_lines(report.get("parallel")),
        "  time         " + ", ".join(f"{k} {v:.2f} s" for k, v in timings.items()),
    ]
    for warning in report.get("warnings", []):
        lines.append(f"  warning      {warning}")
    errors = report.get("errors")
    if errors:
        shown = ", ".join(f"{name} {errors[key]:.3g}" if errors[key] is not None else f"{name} n/a"
                          for name, key in (("L2", "displacement_l2"), ("energy", "displacement_energy"),
                                            ("multiplier L2", "multiplier_l2")))
        lines.append(f"  exact error  {shown}")
    if written:
        lines.append(f"  wrote        {', '.join(_shown(p) for p in written)}")
    return "\n".join(_printable(line) for line in lines)


def _accuracy_lines(accuracy: dict | None) -> list[str]:
    """The estimated errors in one line: the energy norm's, then each contact quantity's
    (relative), how many coarser levels they came from; none is a guaranteed bound."""
    if not accuracy:
        return []
    energy = accuracy["energy"]
    relative = f" ({100 * energy['relative']:.2g}%)" if energy.get("relative") else ""
    shown = [f"energy {energy['estimate']:.3g}{relative}" if energy["estimate"] is not None else "energy n/a"]
    for name, label in (("contact_force", "force"), ("contact_width", "width"), ("peak_pressure", "peak pressure")):
        entry = accuracy["quantities"][name]
        if entry["estimate"] is not None:
            relative = f" ({100 * entry['relative']:.2g}%)" if entry.get("relative") is not None else ""
            shown.append(f"{label} ±{entry['estimate']:.2g}{relative}")
    levels = len(accuracy["levels"])
    lines = [f"  accuracy     estimated, not bounds: {', '.join(shown)}; from {levels} coarser "
             f"level{'' if levels == 1 else 's'}, +{accuracy['cost']['share_of_unknowns']:.0%} unknowns"]
    target = accuracy.get("target")
    if target:
        reached = "n/a" if target["reached"] is None else f"{100 * target['reached']:.3g}%"
        verdict = "met" if target["met"] else f"not met: {target['stop_reason'].replace('_', ' ')}"
        lines.append(f"  target       {target['quantity'].replace('_', ' ')} {100 * target['target']:.3g}%: "
                     f"reached {reached} ({verdict}) in {len(target['steps'])} solves, "
                     f"{target['unknowns']:,} unknowns, {target['seconds']:.3g} s")
    return lines


def _force_lines(forces: dict | None) -> list[str]:
    """One line per boundary part that carries a force: its condition, force and moment."""
    if not forces:
        return []
    lines = []
    for name, entry in forces["parts"].items():
        fx, fy = entry["force"]
        if fx == 0 and fy == 0 and entry["moment"] == 0:
            continue
        label = "forces" if not lines else ""
        lines.append(f"  {label:<12} {name} ({entry['condition']}): ({fx:.6g}, {fy:.6g}), moment {entry['moment']:.6g}")
    total = forces["total"]
    lines.append(f"  {'':<12} sum: relative {total['relative_force_residual']:.1e} "
                 f"(moments about ({forces['moment_about'][0]:.4g}, {forces['moment_about'][1]:.4g}))")
    return lines


def _platen_lines(platens: dict | None) -> list[str]:
    """One line per platen: how it is driven, its advance into the body and its force."""
    lines = []
    for name, entry in (platens or {}).items():
        label = "platens" if not lines else ""
        driven = "force" if entry["control"] == "force" else "displacement"
        lines.append(f"  {label:<12} {name} ({driven} {entry['prescribed']:.6g}): advance {entry['advance']:.6g}, "
                     f"force {entry['force']:.6g}")
    return lines


def _parallel_lines(parallel: dict | None) -> list[str]:
    """A distributed solve in one line: ranks, solver and the largest peak memory of a rank."""
    if not parallel:
        return []
    return [f"  ranks        {parallel['ranks']} (petsc {parallel['solver']}), peak memory per rank up to "
            f"{parallel['max_peak_rss_bytes'] / 2**30:.2f} GiB"]


def _path_lines(path: dict | None) -> list[str]:
    """The load path in one line: its steps and their cost, and the contact force along it."""
    if not path:
        return []
    curves = path["curves"]
    return [f"  load path    {len(curves['factor'])} steps, factors {curves['factor'][0]:.4g} to "
            f"{curves['factor'][-1]:.4g}: {path['factorizations']} factorisation{'' if path['factorizations'] == 1 else 's'}, "
            f"{path['seconds']:.2f} s; "
            f"contact force {curves['contact_force'][0]:.6g} to {curves['contact_force'][-1]:.6g}, "
            f"width {curves['contact_width'][0]:.4g} to {curves['contact_width'][-1]:.4g}"]


def _certificate_line(certificate: dict | None) -> str:
    """The kernel's certificate in one line: each condition's relative value against its tolerance."""
    if certificate is None:
        return "  certificate  none (no iteration ran)"
    checks = certificate["checks"]
    shown = ", ".join(f"{name.replace('_', ' ')} {checks[name]['value']:.1e}"
                      + ("" if checks[name]["passed"] else f" > {checks[name]['tolerance']:.1e}")
                      for name in ("equilibrium", "force_sign", "penetration", "complementarity")
                      if name in checks and checks[name]["value"] is not None)
    verdict = "passed" if certificate["passed"] else "FAILED (" + ", ".join(certificate["failed"]) + ")"
    return f"  certificate  {verdict}: {shown} (relative to the force and displacement scales)"
