"""Writes stay inside the output folder, whatever the package's strings say."""

import pytest

from symdrive_core.cli import main
from symdrive_core.pipeline.outputs import OutputError, OutputTree
from tests.security.hostile import created_outside, snapshot, write_package


def _camera(name):
    return lambda d: d["cameras"][0].update(name=name)


def _actor(name):
    def edit(d):
        d["actors"][0]["id"] = name
    return edit


@pytest.mark.parametrize("edit", [
    _camera("/elsewhere/CAM"), _camera("../../CAM"), _camera("a/../../../CAM"),
    _actor("../../../A"), _actor("/elsewhere/A"), _actor("a\x00b"),
], ids=["camera-absolute", "camera-dotdot", "camera-nested-dotdot", "actor-dotdot", "actor-absolute", "actor-nul"])
def test_names_never_lead_a_write_outside_the_output(tmp_path, capsys, edit):
    sandbox = tmp_path / "sandbox"
    pkg = write_package(sandbox / "deep" / "er" / "pkg", edit)
    before = snapshot(tmp_path)
    code = main(["run", str(pkg), "--out", str(sandbox / "deep" / "er" / "out"), "--quiet"])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "symdrive run: error:" in err[0]
    assert created_outside(before, snapshot(tmp_path), "sandbox/deep/er/out") == []


@pytest.mark.parametrize("output", ["/some/absolute/dir", "../outside", "a/../../outside"])
def test_manifest_output_outside_the_package_is_refused(tmp_path, capsys, output):
    pkg = write_package(tmp_path / "pkg", lambda d: d.update(output=str(tmp_path / "x") if output.startswith("/")
                                                              else output))
    before = snapshot(tmp_path)
    assert main(["run", str(pkg), "--quiet"]) == 2
    assert "output" in capsys.readouterr().err
    assert snapshot(tmp_path) == before


def test_out_naming_a_file_exits_2(tmp_path, capsys):
    pkg = write_package(tmp_path / "pkg")
    (tmp_path / "out").write_text("not a folder")
    assert main(["run", str(pkg), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert "names a file" in capsys.readouterr().err
    assert (tmp_path / "out").read_text() == "not a folder"


def test_a_link_inside_the_output_leading_out_is_not_written_through(tmp_path):
    (tmp_path / "elsewhere").mkdir()
    tree = OutputTree(tmp_path / "out")
    tree.root.mkdir()
    (tree.root / "render").symlink_to(tmp_path / "elsewhere")
    with pytest.raises(OutputError, match="outside the output folder"):
        tree.frame("render", "front", 0)


@pytest.mark.parametrize("parts", [("..", "x"), ("/etc", "x"), ("a\\..\\b",), ("",), ("a\nb",)])
def test_output_tree_refuses_components_that_are_not_names(tmp_path, parts):
    with pytest.raises(OutputError):
        OutputTree(tmp_path).path(*parts)


def test_an_output_folder_linked_out_of_the_package_is_refused(tmp_path, capsys):
    """The package's own ``output`` is a link to a folder elsewhere: a run without --out refuses
    it rather than writing through it."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    pkg = write_package(tmp_path / "pkg")
    (pkg.parent / "output").symlink_to(elsewhere)
    assert main(["run", str(pkg), "--quiet"]) == 2
    assert "output" in capsys.readouterr().err
    assert list(elsewhere.iterdir()) == []


def test_reconstruct_does_not_write_through_a_link_the_package_ships(tmp_path, capsys):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    pkg = write_package(tmp_path / "pkg")
    (pkg.parent / "reconstruction").symlink_to(elsewhere)
    assert main(["reconstruct", str(pkg), "--iters", "1"]) == 2
    assert "reconstruction" in capsys.readouterr().err and list(elsewhere.iterdir()) == []
