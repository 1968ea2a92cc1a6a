import numpy as np

from symdrive_core.world.obj import write_obj


def test_obj_groups_faces_by_material_with_one_based_indices(tmp_path):
    verts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    faces = [(0, 1, 2), (0, 2, 3), (1, 2, 3, 0)]
    write_obj(tmp_path / "m.obj", verts, faces, [1, 0, 1], [("paint", (0.5, 0.1, 0.1)), ("glass", (0.1, 0.1, 0.1))])
    lines = (tmp_path / "m.obj").read_text().splitlines()
    assert lines[0] == "mtllib m.mtl"
    assert sum(ln.startswith("v ") for ln in lines) == 4
    body = [ln for ln in lines if ln.startswith(("usemtl", "f "))]
    assert body == ["usemtl paint", "f 1 3 4", "usemtl glass", "f 1 2 3", "f 2 3 4 1"]
    mtl = (tmp_path / "m.mtl").read_text()
    assert "newmtl glass\nKd 0.100000 0.100000 0.100000" in mtl
