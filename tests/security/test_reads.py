"""Reads stay inside the package unless asked: paths that climb out, absolute paths and symlinks
out are refused naming the field (and pass with ``allow_external``); only regular files are
opened (a FIFO or /dev/zero fails at once), and a Git LFS pointer is named as one; PLY headers
are bounded before allocation."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from symdrive_core.errors import InputError
from symdrive_core.io.ply import read_header, read_splats, write_splats
from symdrive_core.scene import check_files, load_manifest
from tests.conftest import random_gaussians

REPO = Path(__file__).resolve().parents[2]


def _cli(*args, timeout=60) -> subprocess.CompletedProcess:
    """``symdrive ARGS`` in a child process: a read that blocks fails the test instead of hanging it."""
    return subprocess.run([sys.executable, "-m", "symdrive_core.cli", *map(str, args)], cwd=REPO,
                          capture_output=True, text=True, timeout=timeout)


def _set_background(manifest: Path, value: str) -> None:
    d = json.loads(manifest.read_text())
    d["background"]["splats"] = value
    manifest.write_text(json.dumps(d))


def _outside_ply(tmp_path) -> Path:
    path = tmp_path / "elsewhere" / "bg.ply"
    path.parent.mkdir(exist_ok=True)
    write_splats(path, random_gaussians(20, 0, 3))
    return path


def _refused(manifest: Path, field: str, reason: str):
    """Loading works; resolving and ``check_files`` refuse, naming the manifest and field and
    saying how to allow it."""
    m = load_manifest(manifest)
    for attempt in (lambda: m.resolve(m.background_splats), lambda: check_files(m)):
        with pytest.raises(InputError) as exc:
            attempt()
        text = str(exc.value)
        assert str(manifest) in text and field in text and reason in text, text
        assert "--allow-external-assets" in text and "--copy-assets" in text, text


def test_relative_path_climbing_out_is_refused(make_package):
    manifest = make_package()
    _set_background(manifest, "../../../../etc/passwd")
    _refused(manifest, "background.splats", "outside the package")


def test_climbing_out_to_a_real_ply_passes_with_allow_external(make_package, tmp_path):
    manifest = make_package()
    _outside_ply(tmp_path)
    _set_background(manifest, "../elsewhere/bg.ply")
    _refused(manifest, "background.splats", "outside the package")
    m = load_manifest(manifest, allow_external=True)
    check_files(m)
    assert len(read_splats(m.resolve(m.background_splats))) == 20


def test_absolute_path_is_refused_unless_allowed(make_package, tmp_path):
    manifest = make_package()
    ply = _outside_ply(tmp_path)
    _set_background(manifest, str(ply))
    _refused(manifest, "background.splats", "absolute path")
    m = load_manifest(manifest, allow_external=True)
    check_files(m)
    assert m.resolve(m.background_splats) == ply


def test_symlink_leading_out_is_refused_unless_allowed(make_package, tmp_path):
    manifest = make_package()
    ply = _outside_ply(tmp_path)
    (manifest.parent / "link.ply").symlink_to(ply)
    _set_background(manifest, "link.ply")
    _refused(manifest, "background.splats", "link")
    check_files(load_manifest(manifest, allow_external=True))
    # a folder symlink out is the same thing
    (manifest.parent / "assets").symlink_to(ply.parent, target_is_directory=True)
    _set_background(manifest, "assets/bg.ply")
    _refused(manifest, "background.splats", "link")


def test_symlink_inside_the_package_is_fine(make_package):
    manifest = make_package()
    (manifest.parent / "sub").mkdir()
    os.replace(manifest.parent / "background.ply", manifest.parent / "sub" / "bg.ply")
    (manifest.parent / "background.ply").symlink_to(Path("sub") / "bg.ply")
    check_files(load_manifest(manifest))


def test_actor_and_ground_truth_paths_name_their_field(make_package, tmp_path):
    manifest = make_package()
    d = json.loads(manifest.read_text())
    d["actors"][0]["assets"]["mesh"] = str(_outside_ply(tmp_path))
    d["ground_truth"] = {"insertion": [{"asset": "../../x"}]}
    manifest.write_text(json.dumps(d))
    m = load_manifest(manifest)
    with pytest.raises(InputError, match=r"actors\[0\]\.assets\.mesh: .*absolute path outside the package"):
        check_files(m)
    with pytest.raises(InputError, match=r"ground_truth\.insertion\[0\]\.asset: .*outside the package"):
        m.resolve("../../x")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_fifo_named_like_a_ply_fails_at_once(make_package):
    manifest = make_package()
    fifo = manifest.parent / "x.ply"
    os.mkfifo(fifo)
    _set_background(manifest, "x.ply")
    r = _cli("info", fifo, timeout=30)
    assert r.returncode == 2 and "x.ply" in r.stderr and "not a regular file" in r.stderr, r.stderr
    r = _cli("validate", manifest, timeout=30)
    assert r.returncode == 2 and "background.splats" in r.stderr and "not a regular file" in r.stderr, r.stderr
    # allowing external assets does not allow special files
    m = load_manifest(manifest, allow_external=True)
    with pytest.raises(InputError, match="background.splats: .*not a regular file"):
        m.resolve(m.background_splats)
    with pytest.raises(InputError, match="x.ply: .*FIFO"):
        read_header(fifo)


def test_dev_zero_as_a_ply_fails_at_once(make_package):
    if not Path("/dev/zero").exists():
        pytest.skip("no /dev/zero")
    r = _cli("info", "/dev/zero", timeout=30)
    assert r.returncode == 2 and "/dev/zero" in r.stderr and "not a regular file" in r.stderr, r.stderr
    with pytest.raises(InputError, match="/dev/zero: is a device"):
        read_header("/dev/zero")
    manifest = make_package()
    _set_background(manifest, "/dev/zero")
    m = load_manifest(manifest, allow_external=True)
    with pytest.raises(InputError, match="background.splats: .*not a regular file"):
        check_files(m)


def test_huge_header_line_is_refused_without_reading_it(tmp_path):
    path = tmp_path / "big.ply"
    with open(path, "wb") as f:
        f.write(b"ply\nformat binary_little_endian 1.0\ncomment ")
        f.write(b"x" * (32 * 1024 * 1024))
        f.write(b"\nend_header\n")
    with pytest.raises(InputError) as exc:
        read_header(path)
    assert str(path) in str(exc.value) and "header: header line longer than" in str(exc.value)
    r = _cli("info", path)
    assert r.returncode == 2 and "header line longer than" in r.stderr and r.stderr.count("\n") == 1


def test_huge_header_of_short_lines_is_refused(tmp_path):
    path = tmp_path / "long.ply"
    path.write_bytes(b"ply\nformat binary_little_endian 1.0\n" + b"comment x\n" * 200_000 + b"end_header\n")
    with pytest.raises(InputError, match=r"long\.ply: header: header longer than"):
        read_header(path)


def test_declared_size_larger_than_the_file_is_an_error_not_an_allocation(tmp_path):
    path = tmp_path / "huge.ply"
    path.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000000\n"
                     b"property float x\nproperty float y\nend_header\n" + bytes(64))
    with pytest.raises(InputError, match=r"huge\.ply: element vertex: truncated: header declares 4000000000000"):
        read_header(path)
    ascii_path = tmp_path / "huge_ascii.ply"
    ascii_path.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 4000000000000\nproperty float x\nend_header\n1\n")
    with pytest.raises(InputError, match=r"huge_ascii\.ply: element vertex: header declares 4000000000000"):
        read_header(ascii_path)


def test_output_folder_linked_out_of_the_package_is_refused(make_package, tmp_path):
    manifest = make_package()
    m = load_manifest(manifest)
    assert m.output_dir() == manifest.parent / "output"
    (tmp_path / "elsewhere").mkdir()
    (manifest.parent / "output").symlink_to(tmp_path / "elsewhere", target_is_directory=True)
    with pytest.raises(InputError, match=r"manifest\.json: output: .*leads outside the package"):
        m.output_dir()


LFS_TEXT = ("version https://git-lfs.github.com/spec/v1\n"
            "oid sha256:c105962f886cf2c4c3ecc147ae7d495458abd84ab8c16b04b3d793b548ff3d36\nsize 1936240\n")


def test_a_git_lfs_pointer_is_named_as_one_by_every_reader(make_package, tmp_path):
    from symdrive_core.importers.lidar import read_scan
    from symdrive_core.io.images import read_image, write_image

    manifest = make_package()
    (manifest.parent / "x.ply").write_text(LFS_TEXT)
    _set_background(manifest, "x.ply")
    r = _cli("validate", manifest, timeout=60)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "background.splats" in r.stderr and "Git LFS pointer" in r.stderr and "git lfs pull" in r.stderr, r.stderr
    for name, read in (("a.png", read_image), ("s.bin", read_scan), ("b.ply", read_splats)):
        path = tmp_path / name
        path.write_text(LFS_TEXT)
        with pytest.raises(InputError, match=f"{name}: .*is a Git LFS pointer"):
            read(path)
    small = write_image(tmp_path / "small.png", np.full((2, 3, 3), 0.5, np.float32))  # a real file this short
    assert small.stat().st_size < 1024 and read_image(small).shape == (2, 3, 3)
