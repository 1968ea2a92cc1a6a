"""``report.json``: what ran, why, how long, and what was measured (its shape: docs/cli.md).

Only measured numbers go in; a metric that could not be measured is left out.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from ..io.atomic import write_text_atomic

REPORT_VERSION = 1


@dataclass
class Report:
    scene: str
    device: str
    stages: list[dict] = field(default_factory=list)
    metrics: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)

    def stage(self, name: str, ran: bool, reason: str, seconds: float | None = None,
              details: dict | None = None) -> None:
        """One row of ``stages``. A stage's own details come after the row's keys and may not
        replace them (the stage's wall time is ``seconds``, measured by the runner)."""
        row = {"name": name, "ran": ran, "reason": reason}
        if seconds is not None:
            row["seconds"] = round(float(seconds), 3)
        clash = sorted(set(row) & set(details or {}))
        if clash:
            raise ValueError(f"stage {name!r} details may not redefine {', '.join(clash)}")
        row.update(details or {})
        self.stages.append(row)

    def to_json(self) -> dict:
        return {"version": REPORT_VERSION, "scene": self.scene, "device": self.device,
                "stages": self.stages, "metrics": self.metrics, **self.extra}

    def write(self, path: Path) -> Path:
        return write_report_json(path, self.to_json())


def write_report_json(path: Path, report: dict) -> Path:
    """``report`` at ``path`` (an output folder's ``report.json``, as its tree hands it out)."""
    write_text_atomic(Path(path), json.dumps(report, indent=1) + "\n")
    return Path(path)
