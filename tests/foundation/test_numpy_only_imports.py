import subprocess
import sys

HIDE = """
import sys
class _Block:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in {'torch', 'OpenImageIO', 'numba', 'jsonschema', 'scipy'}:
            raise ImportError(f'{name} is hidden for this test')
sys.meta_path.insert(0, _Block())
"""


def test_addon_modules_import_with_numpy_alone():
    code = HIDE + (
        "import symdrive_core.io.ply, symdrive_core.scene, symdrive_core.conventions\n"
        "import symdrive_core.gaussians\n"
        "assert 'torch' not in sys.modules\n"
        "print('ok')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"


def test_hiding_really_hides_torch():
    out = subprocess.run([sys.executable, "-c", HIDE + "import torch"], capture_output=True, text=True)
    assert out.returncode != 0 and "hidden for this test" in out.stderr
