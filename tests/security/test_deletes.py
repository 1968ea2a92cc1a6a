"""A run deletes only what runs in its output folder wrote."""

import json

from symdrive_core.cli import main
from symdrive_core.io.ply import write_splats
from symdrive_core.pipeline.outputs import JOURNAL
from tests.conftest import random_gaussians
from tests.security.hostile import snapshot, write_package


def _users_folder(root):
    """A folder of somebody's own files, named like the run's stage folders and temporaries."""
    files = {"render/mine.png": "a", "masks/notes.txt": "b", "reconstruction/model.ply": "c",
             ".draft.x1y2z3.part.txt": "d", "deep/.other.abc.part": "e", "state.txt": "f"}
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    return files


def test_output_pointing_at_a_users_folder_is_refused_and_nothing_is_deleted(tmp_path, capsys):
    pkg = write_package(tmp_path / "pkg", lambda d: d.update(output="mine"))
    files = _users_folder(tmp_path / "pkg" / "mine")
    before = snapshot(tmp_path)
    assert main(["run", str(pkg), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "no symdrive run wrote" in err and "--force" in err
    assert snapshot(tmp_path) == before
    assert all((tmp_path / "pkg" / "mine" / rel).read_text() == t for rel, t in files.items())


def test_with_force_a_run_beside_users_files_and_its_redo_leave_them_alone(tmp_path):
    pkg = write_package(tmp_path / "pkg")
    out = tmp_path / "out"
    out.mkdir()
    files = _users_folder(out)
    assert main(["run", str(pkg), "--out", str(out), "--quiet", "--force"]) == 0
    assert (out / "render/front/000000.png").exists()
    # Changed inputs: the run redoes everything, removing exactly what it wrote.
    write_splats(tmp_path / "pkg" / "car_0.ply", random_gaussians(60, 1, 99, spread=0.8))
    assert main(["run", str(pkg), "--out", str(out), "--quiet", "--force"]) == 0
    assert all((out / rel).read_text() == t for rel, t in files.items())
    assert (out / "render/front/000001.png").exists()


def test_a_redo_removes_what_the_first_run_wrote(tmp_path):
    pkg = write_package(tmp_path / "pkg", n_frames=3)
    out = tmp_path / "out"
    assert main(["run", str(pkg), "--out", str(out), "--quiet"]) == 0
    assert (out / "render/front/000002.png").exists()
    write_package(tmp_path / "pkg", n_frames=2)  # fewer frames: frame 2 is no longer an output
    assert main(["run", str(pkg), "--out", str(out), "--quiet"]) == 0
    assert not (out / "render/front/000002.png").exists()
    assert sorted(p.name for p in (out / "render/front").glob("*.png")) == ["000000.png", "000001.png"]


def test_a_journal_edited_to_point_outside_deletes_nothing_there(tmp_path):
    pkg = write_package(tmp_path / "pkg")
    out = tmp_path / "out"
    assert main(["run", str(pkg), "--out", str(out), "--quiet"]) == 0
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    (tmp_path / "victim_dir").mkdir()
    (tmp_path / "victim_dir" / "f").write_text("keep")
    with open(out / JOURNAL, "a") as f:
        f.write(f"../victim.txt\n{victim}\n../victim_dir/\n")
    write_splats(tmp_path / "pkg" / "car_0.ply", random_gaussians(60, 1, 99, spread=0.8))
    assert main(["run", str(pkg), "--out", str(out), "--quiet"]) == 0
    assert victim.read_text() == "keep me" and (tmp_path / "victim_dir" / "f").exists()


def test_partial_files_of_a_killed_run_are_removed_but_not_anyone_elses(tmp_path):
    pkg = write_package(tmp_path / "pkg")
    out = tmp_path / "out"
    assert main(["run", str(pkg), "--out", str(out), "--quiet"]) == 0
    ours = out / "render/front/.000000.k1ll3d.part.png"  # a temporary of a file the run writes
    ours.write_bytes(b"half")
    state = json.loads((out / "state.json").read_text())
    assert main(["run", str(pkg), "--out", str(out), "--quiet"]) == 0
    assert not ours.exists()
    assert json.loads((out / "state.json").read_text())["inputs_hash"] == state["inputs_hash"]


def test_a_users_report_or_state_in_the_output_is_theirs_not_the_runs(tmp_path, capsys):
    pkg = write_package(tmp_path / "pkg")
    for name in ("report.json", "state.json"):
        out = tmp_path / f"out_{name}"
        out.mkdir()
        (out / name).write_text('{"my": "quarterly numbers"}')
        for force in ([], ["--force"]):  # refused either way: a run writes its own there
            assert main(["run", str(pkg), "--out", str(out), "--quiet", *force]) == 2
            err = capsys.readouterr().err.strip()
            assert len(err.splitlines()) == 1 and name in err and "no symdrive run wrote" in err, err
            assert sorted(p.name for p in out.iterdir()) == [name]
            assert (out / name).read_text() == '{"my": "quarterly numbers"}'


def test_with_force_a_users_file_where_the_run_writes_is_neither_taken_as_done_nor_written_over(tmp_path, capsys):
    pkg = write_package(tmp_path / "pkg")
    out = tmp_path / "out"
    (out / "render" / "front").mkdir(parents=True)
    (out / "render" / "front" / "000000.png").write_text("my precious image")
    assert main(["run", str(pkg), "--out", str(out), "--quiet", "--force"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "render/front/000000.png is there and no symdrive run wrote it" in err, err
    assert (out / "render" / "front" / "000000.png").read_text() == "my precious image"


def test_a_folder_an_older_run_wrote_without_claiming_its_records_runs_again(tmp_path):
    pkg = write_package(tmp_path / "pkg")
    out = tmp_path / "out"
    assert main(["run", str(pkg), "--out", str(out), "--quiet"]) == 0
    journal = out / JOURNAL
    journal.write_text("".join(line + "\n" for line in journal.read_text().splitlines()
                               if line not in ("state.json", "report.json")))  # as runs before they were claimed
    write_splats(tmp_path / "pkg" / "car_0.ply", random_gaussians(60, 1, 99, spread=0.8))  # other inputs
    assert main(["run", str(pkg), "--out", str(out), "--quiet"]) == 0
    assert "state.json" in journal.read_text().splitlines() and (out / "report.json").exists()
