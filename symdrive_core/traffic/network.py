"""A SUMO network that lies exactly on the scene's road, built with netconvert from plain XML.

One edge per driving direction. Each edge's ``shape`` is the middle of that direction's lanes
(``spreadType="center"``), offset sideways from the road's centre line, so SUMO's lane centres
are the scene's lane centres. Normalisation is disabled and the net's own ``netOffset`` is read
back, so SUMO coordinates map to the scene frame exactly.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..scene.road import Road, offset_polyline
from .sumo_run import run_tool

NETCONVERT_TIMEOUT_S = 60.0


@dataclass(frozen=True)
class Network:
    path: Path
    edges: dict[str, int]  # edge id -> number of lanes
    offset: np.ndarray  # [2] SUMO x, y = scene x, y + offset


def _shape(xy: np.ndarray) -> str:
    return " ".join(f"{x:.4f},{y:.4f}" for x, y in xy)


def build_network(road: Road, speed: float, workdir: Path) -> Network:
    """Write nodes/edges, run netconvert, return the network (``speed`` in m/s, may be 0)."""
    line = road.centerline[:, :2]
    directions = [("forward", road.forward_lanes, offset_polyline(line, road.lane_offset(True)))]
    if road.oncoming:
        directions.append(("oncoming", road.oncoming, offset_polyline(line, road.lane_offset(False))[::-1]))
    nodes, edges = ET.Element("nodes"), ET.Element("edges")
    for name, lanes, shape in directions:
        for end, (x, y) in (("start", shape[0]), ("end", shape[-1])):
            ET.SubElement(nodes, "node", id=f"{name}_{end}", x=f"{x:.4f}", y=f"{y:.4f}")
        ET.SubElement(edges, "edge", id=name, attrib={
            "from": f"{name}_start", "to": f"{name}_end", "numLanes": str(lanes), "speed": f"{speed:.4f}",
            "width": f"{road.lane_width:.4f}", "spreadType": "center", "shape": _shape(shape)})
    workdir.mkdir(parents=True, exist_ok=True)
    ET.ElementTree(nodes).write(workdir / "road.nod.xml")
    ET.ElementTree(edges).write(workdir / "road.edg.xml")
    net = workdir / "road.net.xml"
    run_tool("netconvert", ["-n", "road.nod.xml", "-e", "road.edg.xml", "-o", net.name,
                            "--offset.disable-normalization", "true", "--no-turnarounds", "true",
                            "--no-warnings", "true"], NETCONVERT_TIMEOUT_S, workdir)
    location = ET.parse(net).getroot().find("location")
    offset = np.array([float(v) for v in location.get("netOffset", "0,0").split(",")])
    return Network(net, {name: lanes for name, lanes, _ in directions}, offset)


def lane_length(net: Network, edge: str) -> float:
    """Length SUMO gives the edge's lanes (shorter than the road by the junction shapes)."""
    root = ET.parse(net.path).getroot()
    for e in root.iter("edge"):
        if e.get("id") == edge:
            return float(e.find("lane").get("length"))
    raise KeyError(edge)
