"""The JSON Schema's numeric bounds and the reader's constants say the same: a bound changed in
one place and not the other fails here (the add-on's Blender has no jsonschema, so the reader's
constants are what it checks)."""

from __future__ import annotations

import pytest

from symdrive_core.io.images import MAX_IMAGE_SIDE
from symdrive_core.scene import manifest
from symdrive_core.scene.schema import manifest_schema

BOUNDS = [
    ("/properties/cameras/items/properties/width", {"minimum": 1, "maximum": MAX_IMAGE_SIDE}),
    ("/properties/cameras/items/properties/height", {"minimum": 1, "maximum": MAX_IMAGE_SIDE}),
    ("/properties/actors/items/properties/instance_id", {"minimum": 1, "maximum": manifest.ID_MAX}),
    ("/properties/actors/items/properties/wlh/anyOf/0/items", {"exclusiveMinimum": 0, "maximum": manifest.WLH_MAX}),
    ("/properties/effects/properties/lateral_offsets/items",
     {"minimum": -manifest.OFFSET_MAX, "maximum": manifest.OFFSET_MAX}),
    ("/properties/effects/properties/shadow_ratio/anyOf/0", {"minimum": 0, "maximum": 1}),
]


def node(pointer: str) -> dict:
    out = manifest_schema()
    for part in pointer.strip("/").split("/"):
        out = out[int(part)] if isinstance(out, list) else out[part]
    return out


@pytest.mark.parametrize("pointer,bounds", BOUNDS)
def test_the_schema_bound_is_the_readers_constant(pointer, bounds):
    assert {k: node(pointer).get(k) for k in bounds} == bounds


@pytest.mark.parametrize("value,ok", [(manifest.OFFSET_MAX, True), (-manifest.OFFSET_MAX, True),
                                      (manifest.OFFSET_MAX * 1.001, False)])
def test_the_reader_refuses_exactly_past_the_bound(make_package, value, ok):
    """The reader's side of one bound, at and just past it, so the pair above is not only equal
    numbers but the same rule."""
    import json

    from symdrive_core.errors import InputError

    path = make_package()
    data = json.loads(path.read_text())
    data["effects"]["lateral_offsets"] = [value]
    path.write_text(json.dumps(data))
    if ok:
        assert manifest.load_manifest(path).effects.lateral_offsets == [value]
    else:
        with pytest.raises(InputError, match="lateral_offsets"):
            manifest.load_manifest(path)
