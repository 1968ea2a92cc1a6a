"""nuScenes' relational tables (``DATAROOT/VERSION/<table>.json``), read as the devkit reads them.

Each table is a JSON list of records, each with a ``token`` that other records point at
(``sample_data.ego_pose_token`` -> ``ego_pose``). A table is read when first asked for, and every
field is read through :class:`Table`, so a missing table, a missing or malformed field and a token
that points nowhere are each one :class:`InputError` naming the file and the field
(``sample_data.json: [<token>].ego_pose_token: ...``). Quaternions are nuScenes' ``w, x, y, z``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import open_regular
from ..rotations import quat_to_matrix


@dataclass
class Table:
    name: str
    path: Path
    records: dict[str, dict]  # token -> record, in file order

    def record(self, token: str) -> dict:
        return self.records[token]

    def value(self, token: str, key: str):
        rec = self.records[token]
        if key not in rec:
            raise InputError(self.path, "required field is missing", f"[{token}].{key}")
        return rec[key]

    def fail(self, token: str, key: str, message: str):
        raise InputError(self.path, message, f"[{token}].{key}")

    def text(self, token: str, key: str) -> str:
        v = self.value(token, key)
        if not isinstance(v, str):
            self.fail(token, key, f"expected a string, got {v!r}")
        return v

    def file(self, token: str, key: str, root: Path) -> Path:
        """The file a record names (``sample_data.filename``) under ``root``: a table is data from
        elsewhere, so a name that leads outside ``root`` (absolute, ``..``, a link out) is refused,
        never followed."""
        from ..scene import is_inside

        rel = self.text(token, key)
        if "\x00" in rel:
            self.fail(token, key, f"{rel!r} holds a NUL byte: no file has that name")
        full = Path(root) / rel
        if not rel or Path(rel).is_absolute() or not is_inside(full, root):
            self.fail(token, key, f"{rel!r} lies outside DATAROOT {root}")
        return full

    def integer(self, token: str, key: str, minimum: int = 0) -> int:
        v = self.value(token, key)
        if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
            self.fail(token, key, f"expected an integer >= {minimum}, got {v!r}")
        return v

    def flag(self, token: str, key: str) -> bool:
        v = self.value(token, key)
        if not isinstance(v, bool):
            self.fail(token, key, f"expected true or false, got {v!r}")
        return v

    def numbers(self, token: str, key: str, shape: tuple[int, ...], what: str) -> np.ndarray:
        """Finite numbers nested as ``shape`` (a list of 3, a 3x3 list of lists), float64."""
        v = self.value(token, key)
        a = np.zeros(0)
        if all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in _leaves(v)):
            try:
                a = np.array(v, dtype=np.float64)
            except (ValueError, OverflowError):  # ragged lists, integers beyond a float
                pass
        if a.shape != shape:
            got = f"{len(v)} values" if isinstance(v, list) else repr(v)
            self.fail(token, key, f"expected {what}, got {got}")
        if not np.isfinite(a).all():
            self.fail(token, key, f"expected {what}, got {a[~np.isfinite(a)][0]}")
        return a

    def rotation(self, token: str, key: str = "rotation") -> np.ndarray:
        q = self.numbers(token, key, (4,), "4 numbers (a quaternion w, x, y, z)")
        if np.linalg.norm(q) < 1e-8:
            self.fail(token, key, "zero quaternion (expected unit w, x, y, z)")
        return quat_to_matrix(q)

    def rigid(self, token: str) -> np.ndarray:
        """The [4, 4] transform of a record's ``translation`` and ``rotation`` (an ego pose: the
        vehicle in the global frame; a calibrated sensor: the sensor in the vehicle's frame)."""
        T = np.eye(4)
        T[:3, :3] = self.rotation(token)
        T[:3, 3] = self.numbers(token, "translation", (3,), "3 numbers (x, y, z in metres)")
        return T


def _leaves(v):
    if isinstance(v, list):
        for x in v:
            yield from _leaves(x)
    else:
        yield v


class Tables:
    """The tables of one version folder, each read once, when first asked for."""

    def __init__(self, root: Path):
        if not root.is_dir():
            raise InputError(root, "no such folder: DATAROOT/VERSION holds nuScenes' tables (v1.0-mini, "
                                   "v1.0-trainval, ...)", "--version")
        self.root = root
        self._tables: dict[str, Table] = {}

    def __getitem__(self, name: str) -> Table:
        if name not in self._tables:
            self._tables[name] = _read(self.root / f"{name}.json", name)
        return self._tables[name]

    def follow(self, table: Table, token: str, key: str, target: str) -> tuple[str, dict]:
        """(token, record) of the ``target`` record that field ``key`` of ``table``'s record
        ``token`` points at."""
        ref = table.text(token, key)
        records = self[target].records
        if ref not in records:
            table.fail(token, key, f"points nowhere: {target}.json has no record {ref!r}")
        return ref, records[ref]


def _read(path: Path, name: str) -> Table:
    if not path.exists():
        raise InputError(path, f"table not found: nuScenes' {name} table", name)
    with open_regular(path, name) as f:
        raw = f.read()
    try:
        data = json.loads(raw.decode("utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise InputError(path, f"not UTF-8 text (byte {exc.start})", name) from None
    except json.JSONDecodeError as exc:
        raise InputError(path, f"not valid JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}", name) from None
    except (RecursionError, ValueError) as exc:
        raise InputError(path, f"not valid JSON: {type(exc).__name__}", name) from None
    if not isinstance(data, list):
        raise InputError(path, f"expected a list of records, got {type(data).__name__}", name)
    records: dict[str, dict] = {}
    for i, rec in enumerate(data):
        token = rec.get("token") if isinstance(rec, dict) else None
        if not isinstance(token, str) or not token:
            raise InputError(path, "expected a record with a token", f"[{i}].token")
        if token in records:
            raise InputError(path, f"duplicate token {token!r}", f"[{i}].token")
        records[token] = rec
    return Table(name, path, records)
