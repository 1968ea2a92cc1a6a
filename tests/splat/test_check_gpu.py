"""``scripts/check_gpu.py`` runs its checks end to end on the CPU kernels (the same code a GPU run
takes), and says plainly when there is no CUDA device to check."""

import json

import pytest
import torch

from tests.scripts import load_script


def _script():
    return load_script("check_gpu")


def test_the_checks_pass_on_the_cpu_kernels(tmp_path, capsys):
    out = tmp_path / "gpu.json"
    assert _script().main(["--backend", "numba", "--quick", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["pass"] and len(result["agreement"]) == 3 and len(result["gradients"]) == 3
    assert all(r["max_rgb_diff"] < 1e-4 for r in result["agreement"])
    assert result["speed"]["numba"]["forward_s"] > 0
    assert result["restorer"]["max_diff_levels"] == 0.0 and result["restorer"]["seconds"]["cpu"] > 0
    assert "all checks pass" in capsys.readouterr().out


def test_a_tolerance_nothing_meets_fails(capsys):
    assert _script().main(["--backend", "numba", "--quick", "--tolerance", "0"]) == 1
    assert "FAIL" in capsys.readouterr().out


@pytest.mark.skipif(torch.cuda.is_available(), reason="a CUDA machine runs the real check")
def test_without_cuda_it_says_so():
    assert _script().main([]) == 3
