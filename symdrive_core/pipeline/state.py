"""Persistent run state (``state.json``), so a killed run resumes without redoing work.

Each output file is written atomically, so a file that exists is complete; the state records
the inputs' fingerprint (a changed input invalidates everything) and which stages finished.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from ..io.atomic import write_text_atomic


@dataclass
class RunState:
    path: Path
    inputs_hash: str
    completed: list[str] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    metrics: dict[str, dict] = field(default_factory=dict)  # what each stage added to the report

    @staticmethod
    def load_raw(out_dir: Path) -> dict | None:
        p = Path(out_dir) / "state.json"
        try:
            return json.loads(p.read_text())
        except (OSError, json.JSONDecodeError):
            return None

    @classmethod
    def open(cls, out_dir: Path, inputs_hash: str, stage_dirs: list[str]) -> RunState:
        """Resume the state in ``out_dir``; stale outputs from other inputs are removed."""
        out_dir = Path(out_dir)
        _remove_partial_files(out_dir)
        raw = cls.load_raw(out_dir)
        if raw is not None and raw.get("inputs_hash") == inputs_hash:
            return cls(out_dir / "state.json", inputs_hash, list(raw.get("completed", [])),
                       dict(raw.get("seconds", {})), dict(raw.get("metrics", {})))
        for d in stage_dirs:
            shutil.rmtree(out_dir / d, ignore_errors=True)
        state = cls(out_dir / "state.json", inputs_hash)
        state.save()
        return state

    def finish(self, stage: str, seconds: float, metrics: dict | None = None) -> None:
        if stage not in self.completed:
            self.completed.append(stage)
        self.seconds[stage] = seconds
        self.metrics[stage] = metrics or {}
        self.save()

    def save(self) -> None:
        write_text_atomic(self.path, json.dumps({"inputs_hash": self.inputs_hash, "completed": self.completed,
                                                 "seconds": self.seconds, "metrics": self.metrics}, indent=1) + "\n")


def _remove_partial_files(out_dir: Path) -> None:
    """Temporaries a killed run left behind (``.<name>.<random>.part<ext>``, see io.atomic)."""
    for p in sorted(out_dir.rglob(".*.part*"), reverse=True):
        if p.is_dir():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
