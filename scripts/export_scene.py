"""Export a .blend as a SymDrive scene package, headless.

    blender --background scene.blend --python-exit-code 1 \\
            --python scripts/export_scene.py -- --out DIR [--frames a:b]

Uses the SymDrive add-on enabled in this Blender (extension or legacy add-on) if there is one,
otherwise the ``blender_addon`` package of this repository. Exit status: 0 ok, 2 bad input, 1 error.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path


def _addon_module():
    import bpy

    for addon in bpy.context.preferences.addons:
        if addon.module == "symdrive" or addon.module.endswith(".symdrive"):
            return importlib.import_module(addon.module)
    repo = Path(__file__).resolve().parent.parent
    if str(repo) not in sys.path:
        sys.path.insert(0, str(repo))
    return importlib.import_module("blender_addon")


if __name__ == "__main__":
    addon = _addon_module()
    headless = importlib.import_module(f"{addon.__name__}.headless")
    sys.exit(headless.main(sys.argv))
