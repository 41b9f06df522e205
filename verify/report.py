"""The verification report: merged into OUT/report.json and printed as a table."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from linkd.errors import InputError
from linkd.outdir import write_atomic

from .checks import Check

REPORT = "report.json"
KEY = "verification"


@dataclass
class Report:
    """All checks of one verification; it passes only when every check passes."""

    checks: list[Check]
    seconds: float
    thresholds: dict[str, float] = field(default_factory=dict)
    mujoco: str = ""

    @property
    def passed(self) -> bool:
        return bool(self.checks) and all(c.passed for c in self.checks)

    @property
    def failed(self) -> list[str]:
        """Names of the checks that did not pass."""
        return [c.name for c in self.checks if not c.passed]

    def check(self, name: str) -> Check:
        """The check named `name` (one of runner.CHECKS)."""
        return next(c for c in self.checks if c.name == name)

    def to_dict(self) -> dict[str, Any]:
        return {
            "passed": self.passed,
            "failed": self.failed,
            "seconds": round(self.seconds, 3),
            "mujoco": self.mujoco,
            "thresholds": self.thresholds,
            "checks": [
                {
                    "name": c.name,
                    "status": c.status,
                    "figure": _finite(c.figure),
                    "threshold": c.threshold,
                    "detail": c.detail,
                    **{k: _finite(v) for k, v in c.figures.items()},
                }
                for c in self.checks
            ],
        }


def _finite(value: Any) -> Any:
    """JSON has no inf or NaN: write them as null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_report(out_dir: str | Path, report: Report) -> Path:
    """Merge the report into OUT/report.json under "verification", atomically."""
    path = Path(out_dir) / REPORT
    content: dict[str, Any] = {}
    if path.exists():
        try:
            content = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputError(f"{path}: cannot read the existing report ({exc})") from None
        if not isinstance(content, dict):
            raise InputError(f"{path}: the existing report is not a JSON object")
    content[KEY] = report.to_dict()
    write_atomic(path, json.dumps(content, indent=2) + "\n")
    return path


def print_report(report: Report, console: Any = None) -> None:
    """A table of the checks, then the verdict (colours only on a terminal)."""
    from rich.console import Console
    from rich.table import Table

    console = console or Console()
    table = Table(title="linkd verify", show_lines=False)
    for column in ("check", "result", "figure", "threshold", "detail"):
        table.add_column(column, overflow="fold")
    style = {"pass": "green", "fail": "bold red", "skip": "yellow"}
    for c in report.checks:
        figure = "" if c.figure is None else f"{c.figure:.3g}"
        result = f"[{style[c.status]}]{c.status.upper()}[/]"
        table.add_row(c.name, result, figure, c.threshold, c.detail)
    console.print(table)
    if report.passed:
        console.print(f"[green]verified[/] in {report.seconds:.2f} s")
    else:
        console.print(f"[bold red]failed[/]: {', '.join(report.failed)}")
