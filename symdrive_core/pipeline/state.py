"""Persistent run state (``state.json``), so a killed run resumes without redoing work.

Each output file is written atomically, so a file that exists is complete; the state records
the run's cache key (see cache_key: a changed input, option or code invalidates everything) and
which stages finished. What is deleted when the key changes is exactly what runs in this folder
wrote (the journal of :class:`~.outputs.OutputTree`), never a file of someone else's.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from ..io.atomic import write_text_atomic
from .outputs import RUN_RECORDS, STATE, OutputError, OutputTree


@dataclass
class RunState:
    path: Path
    inputs_hash: str
    completed: list[str] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    metrics: dict[str, dict] = field(default_factory=dict)  # what each stage added to the report

    @staticmethod
    def load_raw(out_dir: Path) -> dict | None:
        p = Path(out_dir) / STATE
        try:
            raw = json.loads(p.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError):
            return None
        return raw if isinstance(raw, dict) else None

    @classmethod
    def open(cls, tree: OutputTree, inputs_hash: str, force: bool = False) -> RunState:
        """Resume the state in the tree's folder (the caller holds its lock). Under another key,
        what earlier runs wrote there is removed first. A folder holding files no run wrote is
        refused unless ``force`` (they are left alone either way)."""
        foreign = tree.foreign_files()
        if foreign and not force:
            raise OutputError(f"{tree.root}: holds {len(foreign)} file(s) that no symdrive run wrote here "
                              f"(first: {foreign[0]}); choose a new or empty --out, or pass --force to run "
                              f"beside them (they are never deleted or written over)")
        if taken := sorted(set(foreign) & RUN_RECORDS):
            raise OutputError(f"{tree.root}: {taken[0]} is there and no symdrive run wrote it: a run writes its own "
                              "there; choose a new or empty --out")
        raw = cls.load_raw(tree.root)
        if raw is not None and raw.get("inputs_hash") == inputs_hash:
            tree.remove_temporaries()
            return cls(tree.path(STATE), inputs_hash, list(raw.get("completed", [])),
                       dict(raw.get("seconds", {})), dict(raw.get("metrics", {})))
        for record in RUN_RECORDS:  # of other inputs, and a run's (checked above), claimed or not (older runs)
            (tree.root / record).unlink(missing_ok=True)
        tree.remove_written()
        state = cls(tree.path(STATE), inputs_hash)
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
