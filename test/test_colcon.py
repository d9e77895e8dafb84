"""The package is a correct ament_python package: `colcon build` (colcon-common-extensions from
PyPI) against the pip-installed Jazzy wheels gives the layout `ros2 run` and `ros2 launch` need."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE_FILES = ("setup.py", "setup.cfg", "package.xml", "resource", "config", "launch", "rta_attitude")
EXECUTABLES = ("plant_node", "pd_controller_node", "asif_filter_node", "bag_recorder_node", "scene_node")


@pytest.fixture(scope="module")
def install(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """colcon build of a copy of the package; returns install/rta_attitude."""
    work = tmp_path_factory.mktemp("colcon")
    src = work / "src" / "rta_attitude"
    src.mkdir(parents=True)
    for name in PACKAGE_FILES:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy2(path, src / name)
    proc = subprocess.run(
        [sys.executable, "-m", "colcon", "--log-base", str(work / "log"), "build", "--base-paths", str(work / "src"),
         "--build-base", str(work / "build"), "--install-base", str(work / "install")],
        cwd=work, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    return work / "install" / "rta_attitude"


def _env(install: Path) -> dict[str, str]:
    site = next((install / "lib").glob("python3*/site-packages"))
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), env.get("PYTHONPATH", "")])
    env["AMENT_PREFIX_PATH"] = os.pathsep.join([str(install), sys.prefix])
    env.pop("RTA_ATTITUDE_CONFIG", None)
    return env


@pytest.mark.slow
def test_colcon_build_installs_the_ros_layout(install: Path) -> None:
    for exe in EXECUTABLES:
        path = install / "lib" / "rta_attitude" / exe
        assert path.is_file() and os.access(path, os.X_OK), path
    assert (install / "share" / "ament_index" / "resource_index" / "packages" / "rta_attitude").is_file()
    share = install / "share" / "rta_attitude"
    for name in ("package.xml", "config/rta_attitude.yaml", "launch/rta_attitude.launch.py"):
        assert (share / name).is_file(), name
    assert (share / "config" / "rta_attitude.yaml").read_text() == (ROOT / "config" / "rta_attitude.yaml").read_text()


@pytest.mark.slow
def test_installed_package_is_found_through_the_ament_index_and_its_nodes_run(install: Path) -> None:
    env = _env(install)
    code = ("from ament_index_python.packages import get_package_prefix, get_package_share_directory as s; "
            "print(get_package_prefix('rta_attitude')); print(s('rta_attitude'))")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True,
                         timeout=300).stdout.split()
    assert out == [str(install), str(install / "share" / "rta_attitude")]
    # what `ros2 run rta_attitude plant_node --ros-args ...` executes; the installed YAML is found via
    # AMENT_PREFIX_PATH and a bad scenario is one error line, exit code 1
    proc = subprocess.run([str(install / "lib" / "rta_attitude" / "plant_node"), "--ros-args", "-p",
                           "scenario:=nope"], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1
    assert "unknown scenario 'nope'" in proc.stderr + proc.stdout
    assert "Traceback" not in proc.stderr + proc.stdout


def test_launch_file_compiles_and_declares_the_nodes() -> None:
    text = (ROOT / "launch" / "rta_attitude.launch.py").read_text()
    compile(text, "rta_attitude.launch.py", "exec")
    assert "exe = topics.EXECUTABLES" in text  # the node executables by role, as setup.py names them
    assert "exe[role]" in text and "node_roles(a)" in text  # the roles of the run (ros.launch_file.node_roles)
