"""Files the package writes (``mitld_lp.files.write``): the one rule for an output path, and
the write through a temporary file renamed into place, so that a failed or interrupted
write (SIGINT, in a subprocess, in the middle of a large export) leaves the old file
exactly as it was and no temporary file behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from mitld_lp.cli import main
from mitld_lp.files import write as files

ROOT = Path(__file__).resolve().parent.parent
BUS = ROOT / "models" / "bus_grid.toml"
OLD = b"the old file, which no interrupted write may touch\n"


def _listing(folder: Path) -> list[str]:
    return sorted(os.listdir(folder))


# --------------------------------------------------------------------------- the rule


@pytest.mark.parametrize(
    ("name", "kwargs", "error", "says"),
    [
        ("", {}, files.OutputPathError, "the path is empty"),
        ("x.txt", {"suffixes": (".csv", ".json")}, files.OutputPathError,
         "the suffix must be one of .csv, .json"),
        ("folder", {}, files.OutputPathError, "is a directory"),
        ("nodir/x.csv", {}, files.OutputPathError, "does not exist"),
        ("old.csv", {}, FileExistsError, "exists; pass overwrite=True"),
        ("dangling.csv", {}, FileExistsError, "a dangling symlink"),
    ],
)
def test_the_rule_refuses_with_the_reason(tmp_path, monkeypatch, name, kwargs, error, says):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "folder").mkdir()
    (tmp_path / "old.csv").write_bytes(OLD)
    (tmp_path / "dangling.csv").symlink_to(tmp_path / "nowhere.csv")
    with pytest.raises(error, match=says):
        files.writable_path(name, **kwargs)
    assert not (tmp_path / "nowhere.csv").exists()  # the dangling link was not followed
    assert (tmp_path / "old.csv").read_bytes() == OLD


def test_the_suffix_is_compared_in_any_case(tmp_path):
    assert files.writable_path(tmp_path / "P.CSV", suffixes=(".csv",)) == tmp_path / "P.CSV"


def test_overwrite_writes_through_a_symlink_and_keeps_the_mode(tmp_path):
    real = tmp_path / "real.dot"
    real.write_bytes(OLD)
    real.chmod(0o640)
    link = tmp_path / "link.dot"
    link.symlink_to(real)
    files.write_text(link, "digraph {}\n", overwrite=True)
    assert link.is_symlink() and real.read_text() == "digraph {}\n"
    assert real.stat().st_mode & 0o777 == 0o640
    dangling = tmp_path / "dangling.dot"
    dangling.symlink_to(tmp_path / "made.dot")
    files.write_text(dangling, "x\n", overwrite=True)
    assert (tmp_path / "made.dot").read_text() == "x\n" and dangling.is_symlink()
    assert _listing(tmp_path) == ["dangling.dot", "link.dot", "made.dot", "real.dot"]


def test_a_new_file_gets_the_umask_mode(tmp_path):
    old = os.umask(0o022)
    try:
        out = files.write_text(tmp_path / "new.dot", "digraph {}\n")
    finally:
        os.umask(old)
    assert out.stat().st_mode & 0o777 == 0o644  # 0o666 & ~0o022, as open() would give


def test_two_outputs_naming_one_file_are_refused(tmp_path):
    a = tmp_path / "a.lp"
    alias = tmp_path / "alias.drn"
    alias.symlink_to(a)  # the same file by another name
    with pytest.raises(files.OutputPathError, match="--lp and --drn name the same file"):
        files.distinct_outputs([("--lp", a), ("--drn", alias)])
    files.distinct_outputs([("--lp", a), ("--drn", tmp_path / "b.drn")])


def test_two_outputs_naming_one_file_by_any_name_are_refused(tmp_path):
    # issue 41: the rule compared resolved paths, so a hard link or another path to
    # the same folder could name one file twice
    (tmp_path / "sub").mkdir()
    a = tmp_path / "a.lp"
    a.write_text("x")
    os.link(a, tmp_path / "hard.drn")
    for alias in (tmp_path / "hard.drn", tmp_path / "sub" / ".." / "a.lp"):
        with pytest.raises(files.OutputPathError, match="--lp and --drn name the same file"):
            files.distinct_outputs([("--lp", a), ("--drn", alias)])
    new = tmp_path / "new.lp"  # a file not yet written, reached through a folder link
    (tmp_path / "same").symlink_to(tmp_path / "sub")
    with pytest.raises(files.OutputPathError, match="--lp and --drn name the same file"):
        files.distinct_outputs([("--lp", tmp_path / "sub" / "n.lp"),
                                ("--drn", tmp_path / "same" / "n.lp")])
    files.distinct_outputs([("--lp", new), ("--drn", tmp_path / "sub" / "new.lp")])


def test_cli_refuses_two_outputs_naming_one_file(tmp_path, capsys):
    a = tmp_path / "a.lp"
    (tmp_path / "alias.drn").symlink_to(a)
    argv = ["export", str(BUS), "--lp", str(a), "--drn", str(tmp_path / "alias.drn"),
            "--force", "-q"]
    assert main(argv) == 2
    assert "--lp and --drn name the same file" in capsys.readouterr().err
    assert _listing(tmp_path) == ["alias.drn"]  # refused before any work


def test_cli_refuses_an_empty_output_path(tmp_path, capsys):
    for argv in (["solve", str(BUS), "--policy", ""], ["dta", "F p", "--dot", ""],
                 ["export", str(BUS), "--drn", ""]):
        assert main([*argv, "-q"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "the path is empty" in err[0], err


def test_cli_refuses_a_dangling_symlink_without_force(tmp_path, capsys):
    link = tmp_path / "p.csv"
    link.symlink_to(tmp_path / "target.csv")
    assert main(["solve", str(BUS), "--policy", str(link), "-q"]) == 2
    assert "dangling symlink" in capsys.readouterr().err
    assert not (tmp_path / "target.csv").exists()
    assert main(["solve", str(BUS), "--policy", str(link), "--force", "-q"]) == 0
    assert (tmp_path / "target.csv").read_text().startswith("game_state,")


@pytest.fixture(scope="module")
def solved():
    from mitld_lp import GridWorld, Model, synthesize

    world = GridWorld.make(3, 1, start=(0, 0), regions={"A": [(2, 0)]})
    return synthesize(Model.from_game(world, "D[pmf(0.2, 0.3, 0.4)] b & F(b & F[0,0] A)"))


def _writers(result):
    """Every file writer of the package: (name, suffix, write(path, overwrite))."""
    from mitld_lp import plot, tradeoff
    from mitld_lp.solvers.export import write_drn, write_lp

    mdp = result.mdp
    return [
        ("policy csv", ".csv", lambda p, o: result.write_policy(p, overwrite=o)),
        ("policy json", ".json", lambda p, o: files.write_policy(result, p, overwrite=o)),
        ("drn", ".drn", lambda p, o: write_drn(mdp, mdp.target, p, overwrite=o)),
        ("lp", ".lp", lambda p, o: write_lp(mdp, mdp.target, p, overwrite=o)),
        ("mps", ".mps", lambda p, o: write_lp(mdp, mdp.target, p, overwrite=o)),
        ("dot", ".dot", lambda p, o: files.write_text(p, result.dta.to_dot(), overwrite=o)),
        ("controller", ".ctl", lambda p, o: result.controller.save(p, overwrite=o)),
        ("figure png", ".png", lambda p, o: plot.save(plot.policy_figure(result), p,
                                                      overwrite=o)),
        ("figure svg", ".svg", lambda p, o: plot.save(plot.policy_figure(result), p,
                                                      overwrite=o)),
        ("pareto", ".png", lambda p, o: tradeoff.plot([], p, "P(F A)", "t", overwrite=o)),
    ]


def test_every_writer_follows_the_rule_and_replaces_in_one_step(tmp_path, solved):
    for name, suffix, write in _writers(solved):
        folder = tmp_path / name.replace(" ", "_")
        folder.mkdir()
        out = folder / f"out{suffix}"
        out.write_bytes(OLD)
        with pytest.raises(FileExistsError):
            write(out, False)
        assert out.read_bytes() == OLD, name
        dangling = folder / f"dangling{suffix}"
        dangling.symlink_to(folder / f"nowhere{suffix}")
        with pytest.raises(FileExistsError, match="dangling symlink"):
            write(dangling, False)
        assert not (folder / f"nowhere{suffix}").exists(), name
        with pytest.raises(files.OutputPathError, match="the path is empty"):
            write("", True)
        inode = out.stat().st_ino
        write(out, True)
        # a new file renamed over the old one (another inode), complete, nothing left over
        assert out.stat().st_ino != inode and out.read_bytes() != OLD, name
        assert out.stat().st_size > 0, name
        assert _listing(folder) == [f"dangling{suffix}", f"out{suffix}"], name


# --------------------------------------------------------------------------- the writing


@pytest.mark.parametrize("stop", [RuntimeError, KeyboardInterrupt])
@pytest.mark.parametrize("existing", [True, False])
def test_a_stopped_write_leaves_the_old_file_and_no_temporary(tmp_path, stop, existing):
    out = tmp_path / "table.csv"
    if existing:
        out.write_bytes(OLD)
    with pytest.raises(stop):
        with files.replacing(files.writable_path(out, overwrite=True), "wb") as handle:
            handle.write(b"half a table")
            raise stop()
    assert _listing(tmp_path) == (["table.csv"] if existing else [])
    if existing:
        assert out.read_bytes() == OLD


def test_a_writer_by_name_that_fails_leaves_the_old_file(tmp_path):
    out = tmp_path / "model.lp"
    out.write_bytes(OLD)
    with pytest.raises(OSError, match="disk on fire"):
        with files.replacing_path(out) as scratch:
            assert scratch.name == "model.lp" and scratch.parent.parent == tmp_path
            scratch.write_text("half an LP")
            raise OSError("disk on fire")
    assert _listing(tmp_path) == ["model.lp"] and out.read_bytes() == OLD
    with files.replacing_path(out) as scratch:
        scratch.write_text("a whole LP\n")
    assert _listing(tmp_path) == ["model.lp"] and out.read_text() == "a whole LP\n"


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_a_sweep_results_rewrite_that_fails_leaves_the_old_file(tmp_path, monkeypatch,
                                                                  suffix):
    """A sweep's results file is rewritten by the package's one writer: a rewrite that
    fails half-way leaves the file as it was and no temporary file beside it."""
    if suffix == ".parquet":
        pytest.importorskip("pyarrow")
    from mitld_lp.sweep.results import Results, read_results

    out = tmp_path / f"r{suffix}"
    first = Results(out, "s", "id1", ["p"])
    first.close()
    before = out.read_bytes()
    columns, rows, _ = read_results(out)
    assert rows == [] and "sweep_id" in columns

    def broken(self, target, *args, **kwargs):
        (target.write if hasattr(target, "write") else target.write_bytes)(
            "half a row" if hasattr(target, "write") else b"half a table")
        raise OSError("disk on fire")

    monkeypatch.setattr(Results, "_write_csv" if suffix == ".csv" else "_write_parquet",
                        broken)
    with pytest.raises(OSError, match="disk on fire"):
        Results(out, "s", "id1", ["p"], force=True)
    assert out.read_bytes() == before
    assert _listing(tmp_path) == [f"r{suffix}"]  # no temporary file, no lock file left


def test_an_abandoned_thread_renames_nothing(tmp_path):
    import threading

    out = tmp_path / "x.drn"
    out.write_bytes(OLD)
    started, go_on = threading.Event(), threading.Event()
    raised: list[BaseException] = []

    def write() -> None:
        try:
            with files.replacing(out) as handle:
                handle.write("new")
                started.set()
                go_on.wait(10)
                handle.write(" and more")
        except files.WriteAbandoned as exc:
            raised.append(exc)

    worker = threading.Thread(target=write)
    worker.start()
    assert started.wait(10)
    assert len(_listing(tmp_path)) == 2  # the target and its temporary file
    files.abandon(worker)
    assert _listing(tmp_path) == ["x.drn"]  # removed at once, while the thread still writes
    go_on.set()
    worker.join(10)
    assert len(raised) == 1 and out.read_bytes() == OLD and _listing(tmp_path) == ["x.drn"]


# --------------------------------------------------------------------------- SIGINT

SLOW_WRITER = textwrap.dedent("""
    import sys, time
    from mitld_lp.files import write as files

    out = files.writable_path(sys.argv[1], overwrite=True, suffixes=(".csv",))
    with files.replacing(out) as handle:
        for i in range(100_000):  # a slow generator of rows: minutes in all
            handle.write(f"{i},row\\n")
            handle.flush()
            if i == 10:
                print("writing", flush=True)
            time.sleep(0.01)
""")


@pytest.mark.parametrize("existing", [True, False])
def test_sigint_in_the_middle_of_a_library_write(tmp_path, existing):
    out = tmp_path / "rows.csv"
    if existing:
        out.write_bytes(OLD)
    proc = subprocess.Popen([sys.executable, "-c", SLOW_WRITER, str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=tmp_path,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == b"writing"  # eleven rows are in the temporary
    assert len(_listing(tmp_path)) == (2 if existing else 1)
    proc.send_signal(signal.SIGINT)
    proc.communicate(timeout=60)
    assert proc.returncode != 0
    assert _listing(tmp_path) == (["rows.csv"] if existing else [])
    if existing:
        assert out.read_bytes() == OLD


def _export_model(folder: Path) -> Path:
    """A bus grid of 24x24 cells, deadline 8: a 57k-state product whose DRN (20 MB)
    takes a second or more to format and write."""
    text = (BUS.read_text().replace("size = [4, 4]", "size = [24, 24]")
            .replace("F[0,3]", "F[0,8]").replace("A = [[1, 2]]", "A = [[12, 20]]"))
    model = folder / "big.toml"
    model.write_text(text)
    return model


@pytest.mark.parametrize("force", [True, False])
def test_sigint_during_a_large_export_keeps_the_old_file(tmp_path, force):
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    model = _export_model(tmp_path)
    drn = out_dir / "big.drn"
    if force:
        drn.write_bytes(OLD)
    argv = [sys.executable, "-m", "mitld_lp", "export", str(model), "--drn", str(drn), "-q"]
    proc = subprocess.Popen([*argv, *(["--force"] if force else [])], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env={**os.environ, "PYTHONPATH": str(ROOT)})
    # the temporary file appears when the write starts: interrupt it then
    deadline = time.monotonic() + 120
    while not any(n.endswith(".part") for n in _listing(out_dir)):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the export never started writing"
        time.sleep(0.005)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.decode().strip().splitlines() == ["mitld-lp: interrupted"]
    assert _listing(out_dir) == (["big.drn"] if force else [])
    if force:
        assert drn.read_bytes() == OLD
