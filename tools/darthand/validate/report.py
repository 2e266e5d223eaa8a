"""A `Report` as text (for people) or JSON (schemas/validation_report.schema.json, for machines)."""

from __future__ import annotations

import json

from darthand.validate.findings import Report, counts

WIDTH = 8


def render_text(report: Report) -> str:
    """One header line per package, one line per finding, and a summary line."""
    lines = []
    for pkg in report.packages:
        c = counts(pkg.findings)
        parts = [f"{n} {s}{'s' if n != 1 else ''}" for s, n in c.items() if n]
        state = {"clean": "clean", "problems": "PROBLEMS", "unreadable": "UNREADABLE"}[pkg.status]
        lines.append(f"{pkg.path} ({pkg.format}): {state}" + (f", {', '.join(parts)}" if parts else "") +
                     f" [{pkg.seconds:.2f} s]")
        rule_width = max((len(f.rule) for f in pkg.findings), default=0)
        for f in pkg.findings:
            lines.append(f"  {f.severity:<{WIDTH}}{f.rule:<{rule_width + 2}}{f.path}: {f.message}")
    statuses = [p.status for p in report.packages]
    lines.append(f"{len(statuses)} package{'s' if len(statuses) != 1 else ''}: {statuses.count('clean')} clean, "
                 f"{statuses.count('problems')} with problems, {statuses.count('unreadable')} unreadable")
    return "\n".join(lines)


def render_json(report: Report) -> str:
    return json.dumps(report.as_dict(), indent=2)
