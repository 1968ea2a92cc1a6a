"""Start SUMO's programs from the ``eclipse-sumo`` Python package (no system install needed).

Every run has a wall-clock limit: a SUMO process never outlives the call that started it.
"""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import tempfile
import threading
from pathlib import Path

from ..errors import SymDriveError

CONNECT_RETRIES = 200
CONNECT_WAIT_S = 0.02  # between attempts to reach a starting sumo's TraCI port


class SumoError(SymDriveError):
    """A SUMO program failed, timed out, or is not installed."""


def sumo_home() -> Path:
    try:
        import sumo
    except ModuleNotFoundError:
        raise SumoError("SUMO is not installed: pip install eclipse-sumo sumolib traci") from None
    return Path(sumo.SUMO_HOME)


def binary(name: str) -> str:
    path = sumo_home() / "bin" / name
    if not path.exists():
        raise SumoError(f"{path} not found (broken eclipse-sumo install?)")
    return str(path)


def _env() -> dict:
    return {**os.environ, "SUMO_HOME": str(sumo_home())}


def run_tool(name: str, args: list[str], timeout: float, cwd: Path) -> None:
    """Run ``netconvert``/``sumo`` to completion; a failure raises with SUMO's own message."""
    cmd = [binary(name), *args]
    try:
        proc = subprocess.run(cmd, cwd=cwd, env=_env(), capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise SumoError(f"{name} did not finish within {timeout:g} s") from None
    if proc.returncode != 0:
        errors = [ln for ln in (proc.stderr + proc.stdout).splitlines() if ln.startswith("Error")]
        raise SumoError(f"{name} failed (exit {proc.returncode}): " + ("; ".join(errors) or proc.stderr.strip()))


@contextlib.contextmanager
def traci_session(args: list[str], timeout: float, cwd: Path):
    """A TraCI connection to a fresh ``sumo`` process, killed after ``timeout`` seconds at most.

    Yields the connection object (``conn.simulationStep()``, ``conn.vehicle...``).
    """
    import traci
    from sumolib.miscutils import getFreeSocketPort
    from traci.exceptions import FatalTraCIError, TraCIException

    port = getFreeSocketPort()
    with tempfile.TemporaryFile("w+") as log:
        process = subprocess.Popen([binary("sumo"), *args, "--remote-port", str(port)], cwd=cwd, env=_env(),
                                   stdout=log, stderr=subprocess.STDOUT, text=True)
        timer = threading.Timer(timeout, process.kill)
        timer.start()
        conn = None
        try:
            try:
                with contextlib.redirect_stdout(io.StringIO()):  # traci prints each retry
                    conn = traci.connect(port, numRetries=CONNECT_RETRIES, proc=process,
                                         waitBetweenRetries=CONNECT_WAIT_S)
            except (FatalTraCIError, TraCIException):
                process.wait()
                log.seek(0)
                errors = [ln for ln in log.read().splitlines() if ln.startswith("Error")]
                raise SumoError("sumo did not start under TraCI: " + ("; ".join(errors) or "no connection")) from None
            yield conn
        except FatalTraCIError:
            if not timer.is_alive():
                raise SumoError(f"sumo did not finish within {timeout:g} s") from None
            raise
        finally:
            if conn is not None:
                with contextlib.suppress(Exception):
                    conn.close()  # lets sumo finish its outputs; the timer still bounds the wait
            timer.cancel()
            if process.poll() is None:
                process.kill()
            process.wait()
