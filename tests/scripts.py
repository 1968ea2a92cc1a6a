"""The repository's ``scripts/*.py`` as modules, for tests that run them in-process."""

import importlib.util
from pathlib import Path

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"


def load_script(name: str):
    """``scripts/<name>.py``, executed as a fresh module."""
    spec = importlib.util.spec_from_file_location(name, SCRIPTS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def write_world(root, argv: list[str]):
    """A street package written into ``root`` in this process by ``scripts/make_world.py``'s
    writer with options ``argv`` (needs bpy, and ``SCRIPTS`` on ``sys.path``); returns the writer,
    so that tests can compare Blender's objects with the manifest."""
    from world.package import PackageWriter

    writer = PackageWriter(root, load_script("make_world").parse_args(["--out", "unused", *argv]))
    for job in writer.plan():
        job()
    writer.finish()
    return writer
