"""The command line's own behaviour: --version, devices checked up front, a closed pipe."""

import subprocess
import sys

import pytest

from symdrive_core.cli import main
from symdrive_core.world.demo import DEMO_PACKAGE


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.startswith("symdrive ")


@pytest.mark.parametrize("device, message", [("cuda:7", "cuda"), ("tpu", "torch device"), ("mps", "only cpu and cuda")])
def test_a_device_this_machine_lacks_exits_2_naming_the_option(capsys, device, message):
    import torch

    if torch.cuda.is_available() and device.startswith("cuda") and torch.cuda.device_count() > 7:
        pytest.skip("this machine has that many GPUs")
    with pytest.raises(SystemExit) as exc:
        main(["run", str(DEMO_PACKAGE), "--device", device])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "symdrive run: error: argument --device" in err and message in err


class _ClosedPipe:
    def write(self, text):
        raise BrokenPipeError(32, "Broken pipe")

    def flush(self):
        pass


def test_plan_into_a_closed_pipe_ends_quietly(monkeypatch):
    monkeypatch.setattr(sys, "stdout", _ClosedPipe())
    assert main(["plan", str(DEMO_PACKAGE)]) == 0


def test_plan_piped_into_head_prints_no_traceback():
    cmd = f"{sys.executable} -m symdrive_core.cli plan {DEMO_PACKAGE} --json | head -c 100"
    done = subprocess.run(["bash", "-c", cmd], capture_output=True, text=True, timeout=120)
    assert done.stdout.startswith("{") and "Traceback" not in done.stderr and "BrokenPipe" not in done.stderr
