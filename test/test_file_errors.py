"""File errors of every command: one `ERROR:` line, exit 1, nothing half-written.

For each command that reads or writes files (simulate, check-config, montecarlo, analyze, replay,
launch): an output directory that cannot be created (under a regular file, under /proc), a file given
where a directory is expected and a directory where a file is, and a full disk: a tiny tmpfs mounted
for the test (root only; otherwise a read-only directory stands in, and as root without mount the
case is skipped). A full disk is tried twice: already full (the command stops before it works) and
too small for the output (the command stops when a write fails, and no partial file is left under a
final name). The commands run through the CLI's own main() (the console script's code); `launch`
starts its node processes over Fast DDS as usual.
"""

from __future__ import annotations

import os
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from rta_attitude.cli.main import main as cli_main

Cli = Callable[..., subprocess.CompletedProcess[str]]
"""The `cli` fixture: run the CLI with arguments, get (returncode, stdout, stderr)."""


@pytest.fixture()
def cli(capsys: pytest.CaptureFixture[str]) -> Callable[..., subprocess.CompletedProcess[str]]:
    """The CLI's main() in this process (the same code as the console script, without its start-up)."""

    def call(*args: str) -> subprocess.CompletedProcess[str]:
        capsys.readouterr()
        code = cli_main(list(args))
        out, err = capsys.readouterr()
        return subprocess.CompletedProcess(list(args), code, out, err)

    return call


def _one_error_line(proc: subprocess.CompletedProcess[str], *needles: str) -> str:
    """Assert exit 1 and exactly one stderr line, `ERROR: ...` containing every needle."""
    assert proc.returncode == 1, (proc.returncode, proc.stdout[-2000:], proc.stderr[-2000:])
    err = proc.stderr
    assert err.startswith("ERROR: ") and err.count("\n") == 1 and "Traceback" not in err, err
    for n in needles:
        assert n in err, (n, err)
    return err


def _files(d: Path) -> list[str]:
    return sorted(p.name for p in d.iterdir()) if d.is_dir() else []


class _Disk:
    """A mounted tmpfs of `size_kb` (root), or a read-only directory (not root)."""

    def __init__(self, root: Path, size_kb: int, fill: bool) -> None:
        self.path = root / f"disk{size_kb}{'full' if fill else ''}"
        self.path.mkdir()
        self.mounted = False
        if os.geteuid() == 0:
            proc = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_kb}k", "tmpfs", str(self.path)],
                                  capture_output=True, text=True)
            if proc.returncode != 0:
                pytest.skip(f"cannot mount a tmpfs here ({proc.stderr.strip()}); a read-only directory does not "
                            "stop root")
            self.mounted = True
            if fill:
                try:
                    fd = os.open(self.path / "ballast", os.O_WRONLY | os.O_CREAT)
                    try:
                        while os.write(fd, b"\0" * 512):
                            pass
                    except OSError:
                        pass
                    finally:
                        os.close(fd)
                except BaseException:
                    self.close()
                    raise
        else:
            self.path.chmod(0o555)

    def close(self) -> None:
        if self.mounted:
            subprocess.run(["umount", "-l", str(self.path)], check=False)
        else:
            self.path.chmod(0o755)


@pytest.fixture()
def full_disk(tmp_path: Path) -> Iterator[Path]:
    """A disk with no room left (or an unwritable directory)."""
    disk = _Disk(tmp_path, 16, fill=True)
    yield disk.path
    disk.close()


@pytest.fixture()
def small_disk(tmp_path: Path) -> Iterator[Path]:
    """A 32 KB disk: room for a probe and a small file, not for a run's outputs."""
    disk = _Disk(tmp_path, 32, fill=False)
    if not disk.mounted:
        disk.close()
        pytest.skip("a too-small disk needs a tmpfs (root)")
    yield disk.path
    disk.close()


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short bag of paper-example written by the project's bag writer (as the recorder would)."""
    from rta_attitude import config
    from rta_attitude.recording.bag import BagWriter
    from rta_attitude.ros import convert
    from rta_attitude.simulation.closed_loop import ClosedLoop

    cfg = config.load()
    import dataclasses

    loop = ClosedLoop(cfg, dataclasses.replace(cfg.scenario("paper-example"), duration_s=20.0))
    traj = loop.run()
    path = tmp_path_factory.mktemp("file_errors") / "run.mcap"
    with BagWriter(path) as w:
        w.add_topic("/rta/state", "sensor_msgs/msg/JointState")
        for k in range(traj.steps + 1):
            w.write_message("/rta/state", convert.state_msg(traj.x[k], k * 1_000_000_000), k * 1_000_000_000)
    return path


def test_simulate_file_errors(cli: Cli, tmp_path: Path, full_disk: Path) -> None:
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    _one_error_line(cli("simulate", "--duration", "5", "--out", str(a_file)), f"--out {a_file}: is a file")
    _one_error_line(cli("simulate", "--duration", "5", "--out", str(a_file / "sub")), "cannot create the directory")
    _one_error_line(cli("simulate", "--duration", "5", "--out", "/proc/forbidden"), "--out /proc/forbidden")
    _one_error_line(cli("simulate", "--duration", "5", "--out", str(full_disk / "out")), str(full_disk / "out"))
    _one_error_line(cli("simulate", "--duration", "5", "--config", str(tmp_path)), "is a directory, not a file")
    # a missing output directory is created, with its parents
    ok = cli("simulate", "--duration", "5", "--no-plot", "--out", str(tmp_path / "new" / "deeper"))
    assert ok.returncode == 0, ok.stderr
    assert _files(tmp_path / "new" / "deeper") == ["summary.json", "timeseries.npz"]


def test_simulate_on_a_disk_too_small_leaves_no_partial_file(cli: Cli, small_disk: Path) -> None:
    _one_error_line(cli("simulate", "--duration", "600", "--out", str(small_disk / "out")),
                    "No space left on device")
    assert _files(small_disk / "out") in ([], ["summary.json"]), _files(small_disk / "out")
    for name in _files(small_disk / "out"):  # a file that is there is whole
        assert (small_disk / "out" / name).read_text().rstrip().endswith("}")


def test_check_config_file_errors(cli: Cli, tmp_path: Path) -> None:
    _one_error_line(cli("check-config", "--config", str(tmp_path)), "is a directory, not a file")
    _one_error_line(cli("check-config", "--config", str(tmp_path / "nope.yaml")), "does not exist")
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    _one_error_line(cli("check-config", "--config", str(binary)), "cannot be read")


def test_montecarlo_file_errors(cli: Cli, tmp_path: Path, full_disk: Path) -> None:
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    args = ("montecarlo", "--runs", "2", "--duration", "5", "--workers", "1", "--no-progress")
    _one_error_line(cli(*args, "--out", str(a_file)), "is a file")
    _one_error_line(cli(*args, "--out", "/proc/forbidden/mc"), "--out /proc/forbidden/mc")
    err = _one_error_line(cli(*args, "--out", str(full_disk / "mc")), str(full_disk / "mc"))
    assert "cannot" in err


def test_montecarlo_on_a_disk_too_small_leaves_whole_files(cli: Cli, small_disk: Path) -> None:
    out = small_disk / "mc"
    _one_error_line(cli("montecarlo", "--runs", "40", "--duration", "5", "--workers", "1", "--no-progress", "--out",
                         str(out)), "No space left on device")
    assert not [n for n in _files(out) if n.startswith(".")], _files(out)  # no temporary file left behind


def test_analyze_and_replay_file_errors(cli: Cli, tmp_path: Path, bag: Path, full_disk: Path) -> None:
    empty_dir = tmp_path / "empty"
    empty_dir.mkdir()
    _one_error_line(cli("analyze", str(empty_dir)), f"{empty_dir}: bag directory with no .mcap file")
    _one_error_line(cli("analyze", str(tmp_path / "nope.mcap")), "no such file")
    _one_error_line(cli("replay", str(empty_dir)), f"{empty_dir}: bag directory with no .mcap file")
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    _one_error_line(cli("analyze", str(bag), "--out", str(a_file)), "is a file")
    _one_error_line(cli("analyze", str(bag), "--out", str(full_disk / "a")), str(full_disk / "a"))
    _one_error_line(cli("analyze", str(bag), "--out", "/proc/forbidden"), "/proc/forbidden")


@pytest.mark.dds
def test_launch_file_errors(cli: Cli, tmp_path: Path, full_disk: Path) -> None:
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    _one_error_line(cli("launch", "--bag", str(tmp_path)), "is a directory, not a file")
    _one_error_line(cli("launch", "--bag", str(a_file / "x.mcap")), "is not a directory")
    _one_error_line(cli("launch", "--bag", str(full_disk / "x.mcap")), str(full_disk / "x.mcap"))
    _one_error_line(cli("launch", "--bag", str(tmp_path / "b.mcap"), "--out", str(a_file)), "is a file")
    assert not (tmp_path / "b.mcap").exists()


@pytest.mark.dds
def test_launch_on_a_disk_too_small_stops_with_one_line_and_a_readable_bag(cli: Cli, small_disk: Path) -> None:
    """The recorder's write fails mid-run: it says why, the launcher stops the run (one line, exit 1),
    and the bag is readable up to its last complete chunk."""
    from rta_attitude.recording.bag import read_bag

    bag = small_disk / "x.mcap"
    proc = cli("launch", "--bag", str(bag), "--duration", "300", "-p", "bag_chunk_kb=4")
    _one_error_line(proc, "bag_recorder_node exited with code 1", "No space left on device")
    contents = read_bag(bag, decode=False)
    assert contents.truncated and contents.messages


# ----------------------------------------------------------------------------- a failed command leaves no folder
def test_a_failed_command_leaves_no_new_folder(cli: Cli, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """simulate, analyze and montecarlo create --out (and its missing parents) before they work, so that a
    bad location fails at once; when the work then fails (a bag that does not load, a run that raises, a
    controller that answers nonsense, an interrupt) they remove again what they created and is still empty."""
    from rta_attitude.errors import RtaError
    from rta_attitude.simulation.closed_loop import ClosedLoop

    text_bag = tmp_path / "notes.mcap"
    text_bag.write_text("not a bag")
    _one_error_line(cli("analyze", str(text_bag), "--out", str(tmp_path / "a" / "deeper")), "not an MCAP file")
    assert not (tmp_path / "a").exists()

    (tmp_path / "nan_law.py").write_text("def law(y, q_c, t_s):\n    return [0.0, float('nan'), 0.0]\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    _one_error_line(cli("montecarlo", "--runs", "2", "--duration", "5", "--workers", "1", "--no-progress",
                        "--controller", "nan_law:law", "--out", str(tmp_path / "m" / "deeper")),
                    "returned [0.0, nan, 0.0]")
    assert not (tmp_path / "m").exists()

    def fail(self: ClosedLoop, dt_s: float | None = None) -> None:
        raise RtaError("the run failed")

    monkeypatch.setattr(ClosedLoop, "run", fail)
    _one_error_line(cli("simulate", "--duration", "5", "--out", str(tmp_path / "s" / "deeper")), "the run failed")
    assert not (tmp_path / "s").exists()

    def interrupt(self: ClosedLoop, dt_s: float | None = None) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(ClosedLoop, "run", interrupt)
    existing = tmp_path / "kept"
    existing.mkdir()
    proc = cli("simulate", "--duration", "5", "--out", str(existing / "new"))
    assert proc.returncode == 130 and proc.stderr == "ERROR: interrupted\n"
    assert _files(existing) == []  # what the command created is gone, what was there stays


def test_output_folder_removes_only_what_it_created_and_only_while_empty(tmp_path: Path) -> None:
    from rta_attitude.files import output_folder

    class BoomError(Exception):
        pass

    with pytest.raises(BoomError), output_folder(tmp_path / "a" / "b" / "c") as out:
        assert out.is_dir() and _files(out) == []
        raise BoomError
    assert _files(tmp_path) == []
    with pytest.raises(BoomError), output_folder(tmp_path / "x" / "y") as out:
        (out / "summary.json").write_text("{}")  # a whole file written before the failure stays
        raise BoomError
    assert _files(tmp_path / "x" / "y") == ["summary.json"]
    with output_folder(tmp_path / "ok") as out:
        pass
    assert out.is_dir()  # success: the folder stays, even empty


def test_an_unwritable_output_folder_is_not_left_behind(cli: Cli, full_disk: Path) -> None:
    """On a full disk the directory may be created and its probe fail: it is removed again."""
    for args in (("simulate", "--duration", "5"), ("montecarlo", "--runs", "2", "--duration", "5", "--workers", "1"),
                 ("analyze", "NOPE.mcap")):
        _one_error_line(cli(*args, "--out", str(full_disk / "new" / "out")))
        assert not (full_disk / "new").exists(), args
