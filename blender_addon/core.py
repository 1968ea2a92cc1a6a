"""The numpy-only parts of ``symdrive_core`` the add-on uses, vendored or installed.

``scripts/build_addon`` copies them into the zip as the subpackage ``vendor.symdrive_core`` so
the add-on works in a stock Blender; in a development checkout (or where ``symdrive`` is
installed into Blender's Python) the installed package is used. The vendored copy wins when
present, so an installed zip always runs the core code it was built with.
"""

from __future__ import annotations

import importlib
import importlib.util


def _core_package() -> str:
    vendored = f"{__package__}.vendor.symdrive_core"
    if importlib.util.find_spec(f"{__package__}.vendor") is not None:
        return vendored
    if importlib.util.find_spec("symdrive_core") is None:
        raise ImportError(
            "SymDrive: symdrive_core is neither vendored in the add-on nor installed; "
            "build the add-on with scripts/build_addon or pip install the symdrive package"
        )
    return "symdrive_core"


CORE = _core_package()
conventions = importlib.import_module(f"{CORE}.conventions")
errors = importlib.import_module(f"{CORE}.errors")
gaussians = importlib.import_module(f"{CORE}.gaussians")
ply = importlib.import_module(f"{CORE}.io.ply")
atomic = importlib.import_module(f"{CORE}.io.atomic")
scene = importlib.import_module(f"{CORE}.scene")
poses = importlib.import_module(f"{CORE}.scene.poses")
wlh = importlib.import_module(f"{CORE}.io.wlh")
fcd = importlib.import_module(f"{CORE}.traffic.fcd")


def images():
    """Image writers (OpenImageIO, bundled with Blender); imported only when masks are written."""
    return importlib.import_module(f"{CORE}.io.images")
