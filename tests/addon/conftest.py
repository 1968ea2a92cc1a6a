"""A factory-empty Blender session with the add-on registered, per test (real bpy, no mocks)."""

from __future__ import annotations

import atexit
import os
import sys

import pytest


@pytest.fixture
def blender():
    bpy = pytest.importorskip("bpy")
    import blender_addon

    bpy.ops.wm.read_factory_settings(use_empty=True)
    blender_addon.register()
    try:
        yield bpy
    finally:
        blender_addon.unregister()


def _end_now(status: int) -> None:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:
            pass
    os._exit(status)


def pytest_sessionfinish(session, exitstatus):
    """End the process as soon as Python has finished, when bpy was imported.

    The bpy wheel can deadlock in one of its C++ static destructors at process exit (4.5.15:
    ``GlobalState::~GlobalState`` waits on a condition variable its idle file-closing thread still
    holds), after every test has run and the summary is printed: the run would never return.
    The last atexit handler skips the C-level exit handlers and keeps pytest's exit status.
    """
    if "bpy" in sys.modules:
        atexit.register(_end_now, int(exitstatus))
