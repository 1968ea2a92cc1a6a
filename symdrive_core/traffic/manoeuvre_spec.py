"""The declarative manoeuvre spec: what a chosen vehicle does, and when.

A JSON file::

    {"manoeuvres": [
      {"kind": "cut_in", "vehicle": "veh3", "at": 2.0, "direction": "left", "gap": 6.0, "duration": 1.5},
      {"kind": "lane_change", "vehicle": {"near": [40.0, -1.75]}, "at": 1.0, "direction": "right",
       "aggressive": true, "duration": 1.5},
      {"kind": "hard_brake", "vehicle": "veh7", "at": 3.0, "deceleration": 7.0, "speed": 0.0, "hold": 2.0}
    ]}

* ``at``: scene time in seconds (the manifest's frame timestamps).
* ``vehicle``: a vehicle id from an earlier run with the same seed, or ``{"near": [x, y]}``: the
  vehicle whose box centre is nearest that scene point at time ``at``.
* ``cut_in``: the vehicle first adjusts its speed until its rear is ``gap`` metres ahead of the
  nearest vehicle behind it in the lane on ``direction`` (the vehicle being cut off), then moves
  there aggressively, taking ``duration`` seconds sideways.
* ``lane_change``: move to the adjacent lane on ``direction`` in ``duration`` seconds; aggressive
  changes only avoid immediate collisions, others wait for a safe gap.
* ``hard_brake``: brake at ``deceleration`` m/s^2 down to ``speed``, hold it ``hold`` seconds.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError

DIRECTIONS = ("left", "right")
DEFAULTS = {
    "cut_in": {"gap": 6.0, "duration": 1.5},
    "lane_change": {"aggressive": False, "duration": 3.0},
    "hard_brake": {"deceleration": 7.0, "speed": 0.0, "hold": 2.0},
}


@dataclass(frozen=True)
class Manoeuvre:
    kind: str
    vehicle: str | tuple[float, float]  # id, or a scene point (nearest vehicle)
    at: float
    direction: str | None = None
    gap: float | None = None
    duration: float | None = None
    aggressive: bool = True
    deceleration: float | None = None
    speed: float | None = None
    hold: float | None = None


def _number(v, where, path, positive=False, minimum=None) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or v != v or v in (float("inf"), float("-inf")):
        raise InputError(path, f"expected a number, got {v!r}", where)
    if positive and v <= 0:
        raise InputError(path, f"expected a positive number, got {v!r}", where)
    if minimum is not None and v < minimum:
        raise InputError(path, f"expected a number >= {minimum}, got {v!r}", where)
    return float(v)


def _vehicle(v, where, path):
    if isinstance(v, str) and v:
        return v
    if isinstance(v, dict) and set(v) == {"near"} and isinstance(v["near"], list) and len(v["near"]) == 2:
        return tuple(_number(x, f"{where}.near[{i}]", path) for i, x in enumerate(v["near"]))
    raise InputError(path, 'expected a vehicle id or {"near": [x, y]}', where)


def parse_manoeuvres(data, path) -> list[Manoeuvre]:
    if not isinstance(data, dict) or not isinstance(data.get("manoeuvres"), list):
        raise InputError(path, 'expected {"manoeuvres": [...]}', "manoeuvres")
    out = []
    for i, m in enumerate(data["manoeuvres"]):
        w = f"manoeuvres[{i}]"
        if not isinstance(m, dict):
            raise InputError(path, "expected an object", w)
        kind = m.get("kind")
        if kind not in DEFAULTS:
            raise InputError(path, f"expected one of {', '.join(DEFAULTS)}, got {kind!r}", f"{w}.kind")
        allowed = {"kind", "vehicle", "at", "direction", *DEFAULTS[kind]}
        unknown = sorted(set(m) - allowed)
        if unknown:
            raise InputError(path, f"unknown field(s) for {kind}: {', '.join(unknown)}", w)
        for key in ("vehicle", "at"):
            if key not in m:
                raise InputError(path, "required field is missing", f"{w}.{key}")
        fields = {**DEFAULTS[kind], **{k: v for k, v in m.items() if k in DEFAULTS[kind]}}
        direction = None
        if kind != "hard_brake":
            direction = m.get("direction")
            if direction not in DIRECTIONS:
                raise InputError(path, f"expected left or right, got {direction!r}", f"{w}.direction")
        if "aggressive" in fields and not isinstance(fields["aggressive"], bool):
            raise InputError(path, "expected true or false", f"{w}.aggressive")
        out.append(Manoeuvre(
            kind=kind, vehicle=_vehicle(m["vehicle"], f"{w}.vehicle", path),
            at=_number(m["at"], f"{w}.at", path), direction=direction,
            gap=_number(fields["gap"], f"{w}.gap", path, minimum=0.0) if "gap" in fields else None,
            duration=_number(fields["duration"], f"{w}.duration", path, positive=True)
            if "duration" in fields else None,
            aggressive=fields.get("aggressive", True),
            deceleration=_number(fields["deceleration"], f"{w}.deceleration", path, positive=True)
            if "deceleration" in fields else None,
            speed=_number(fields["speed"], f"{w}.speed", path, minimum=0.0) if "speed" in fields else None,
            hold=_number(fields["hold"], f"{w}.hold", path, minimum=0.0) if "hold" in fields else None))
    return out


def load_manoeuvres(path: str | Path) -> list[Manoeuvre]:
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc.strerror}") from None
    except json.JSONDecodeError as exc:
        raise InputError(path, f"not valid JSON: {exc.msg} at line {exc.lineno}") from None
    return parse_manoeuvres(data, path)
