"""The XML annotation files that come with a recorded drive (KITTI raw's ``tracklet_labels.xml``,
KITTI-360's 3D boxes) -> their elements' text.

One reader for both, so a file too large to be annotations, one that is not XML and an element
without its text are refused the same way: naming the file and the element
(``tracklets.item[3].poses``, ``object12.transform``).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from ..errors import InputError
from ..io import check_regular


def parse(path: Path, field: str, limit: int, what: str) -> ET.Element:
    """The root element of the XML file ``path``; one over ``limit`` bytes is no ``what`` (``a
    tracklet file``) and is not parsed. Errors name ``field``."""
    path = Path(path)
    if check_regular(path, field).st_size > limit:
        raise InputError(path, f"larger than {limit} bytes: not {what}", field)
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise InputError(path, f"not valid XML: {exc}", field) from None


def text(node: ET.Element, tag: str, path: Path, where: str) -> str:
    """The stripped text of ``node``'s child ``tag``; none, or only white space, is missing
    (at ``where.tag``)."""
    child = node.find(tag)
    if child is None or child.text is None or not child.text.strip():
        raise InputError(path, "missing", f"{where}.{tag}")
    return child.text.strip()
