"""Property: whatever strings a package holds (names, ids, asset paths, output), ``validate``
and ``run`` create nothing outside the output folder and the package."""

import string
import tempfile
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from symdrive_core.cli import main
from tests.security.hostile import created_outside, snapshot, write_package

ELSEWHERE = "@ELSEWHERE@"  # replaced by an absolute folder inside the test's sandbox

piece = st.one_of(
    st.sampled_from(["..", ".", "", "/", "\\", "\x00", "~", "..\\..", "//", "\n", "x/../..", ".hidden"]),
    st.just(ELSEWHERE),
    st.text(alphabet=string.ascii_letters + "-_é漢🚗", min_size=1, max_size=6),
)
hostile = st.lists(piece, min_size=1, max_size=5).map("".join) | st.lists(piece, min_size=1, max_size=4).map("/".join)
field = st.sampled_from(["scene", "camera", "actor", "background", "actor_asset", "output"])


def _apply(d: dict, which: str, value: str) -> None:
    if which == "scene":
        d["name"] = value
    elif which == "camera":
        d["cameras"][0]["name"] = value
    elif which == "actor":
        d["actors"][0]["id"] = value
    elif which == "background":
        d["background"]["splats"] = value
    elif which == "actor_asset":
        d["actors"][0]["assets"]["splats"] = value
    else:
        d["output"] = value


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(changes=st.lists(st.tuples(field, hostile), min_size=1, max_size=3))
def test_no_string_in_a_package_makes_a_run_write_outside(changes):
    with tempfile.TemporaryDirectory() as tmp:
        sandbox = Path(tmp)
        elsewhere = sandbox / "elsewhere"
        elsewhere.mkdir()
        (elsewhere / "keep.ply").write_bytes(b"ply\n")

        def edit(d):
            for which, value in changes:
                _apply(d, which, value.replace(ELSEWHERE, str(elsewhere)))

        pkg = write_package(sandbox / "a" / "b" / "pkg", edit)
        before = snapshot(sandbox)
        # A package that sets its own output runs into it (no --out), as a user would run it.
        out = [] if any(which == "output" for which, _ in changes) else ["--out", str(sandbox / "a/b/out")]
        codes = [main(["validate", str(pkg)]), main(["run", str(pkg), *out, "--quiet"])]
        after = snapshot(sandbox)
        assert set(codes) <= {0, 2}
        assert created_outside(before, after, "a/b/out", "a/b/pkg") == []
        assert all(p in after for p in before), "a run deleted a file it did not write"
        assert (elsewhere / "keep.ply").read_bytes() == b"ply\n"
