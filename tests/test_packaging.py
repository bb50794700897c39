"""Install and run from anywhere: the wheel ships models/ and scenarios/, and a run
works from an empty directory with paths relative to it."""

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DATA = ("models", "scenarios")


def _shipped(folder: Path) -> set[str]:
    """Every file under a data folder, as a path relative to it (no caches)."""
    return {
        p.relative_to(folder).as_posix()
        for p in folder.rglob("*")
        if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".pyc"
    }


def test_pyproject_lists_every_package_folder():
    """The package list is explicit (two of its packages are mapped folders): a new
    subpackage that is not listed would be missing from the wheel."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    found = {
        ".".join(p.parent.relative_to(ROOT).parts)
        for p in (ROOT / "dftc_mujoco").rglob("__init__.py")
        if "__pycache__" not in p.parts
    }
    listed = set(config["packages"])
    assert found <= listed, f"not in pyproject's packages: {sorted(found - listed)}"
    assert config["package-dir"] == {f"dftc_mujoco.{d}": d for d in DATA}
    assert all(config["package-data"][f"dftc_mujoco.{d}"] == ["**/*"] for d in DATA)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """A wheel built from a copy of the source tree (the checkout is left untouched)."""
    src = tmp_path_factory.mktemp("src")
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, src / name)
    skip = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info")
    for name in ("dftc_mujoco", *DATA):
        shutil.copytree(ROOT / name, src / name, ignore=skip)
    dist = tmp_path_factory.mktemp("dist")
    built = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(dist), str(src)],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert built.returncode == 0, built.stderr
    (whl,) = dist.glob("*.whl")
    return whl


@pytest.mark.slow
def test_the_wheel_holds_every_model_and_scenario(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    for d in DATA:
        inside = {
            n.removeprefix(f"dftc_mujoco/{d}/") for n in names if n.startswith(f"dftc_mujoco/{d}/")
        }
        assert inside == _shipped(ROOT / d)
    assert "dftc_mujoco/models/robots/meshes/hexbot.stl" in names


@pytest.mark.slow
def test_an_installed_wheel_runs_from_an_empty_directory(wheel, tmp_path):
    """The wheel in a fresh environment (its dependencies borrowed from this one through
    a .pth line, so nothing is downloaded): paper_case by name from an empty directory,
    then a scenario path and a robot-model path relative to that directory."""
    env_dir = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(env_dir)], check=True)
    python = env_dir / "bin" / "python"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "--python",
            str(python),
            "install",
            "-q",
            "--no-deps",
            str(wheel),
        ],
        check=True,
        capture_output=True,
        timeout=900,
    )
    site = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    Path(site, "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    work = tmp_path / "empty"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    # the installed copy has a numba cache of its own, cold: the general path compiles in
    # a third of the compiled period's time, and what is tested here is where files are
    env["DFTC_PERIOD"] = "general"

    def run(*args: str, cwd: Path = work) -> subprocess.CompletedProcess:
        return subprocess.run(
            [str(python), "-m", "dftc_mujoco.run", *args, "--no-video", "--no-progress"],
            cwd=cwd,
            capture_output=True,
            text=True,
            timeout=900,
            env=env,
        )

    where = subprocess.run(
        [str(python), "-c", "import dftc_mujoco.runtime.paths as p; print(p.MODELS)"],
        cwd=work,
        capture_output=True,
        text=True,
        env=env,
    )
    assert where.stdout.strip() == str(Path(site) / "dftc_mujoco" / "models"), where.stderr
    done = run("paper_case", "--duration", "2")
    assert done.returncode == 0, done.stderr
    assert (work / "renders" / "paper_case" / "summary.json").is_file()
    # paths relative to the working directory, from a sibling directory
    mine = tmp_path / "mine"
    mine.mkdir()
    shutil.copy(ROOT / "scenarios" / "paper_case.toml", mine / "case.toml")
    shutil.copy(ROOT / "models" / "robots" / "disk.xml", mine / "disk.xml")
    shutil.copy(ROOT / "models" / "robots" / "disk.robot.toml", mine / "bot.robot.toml")
    robot = "../mine/bot.robot.toml"
    done = run("../mine/case.toml", "--robot", robot, "--duration", "1", "--out", "two")
    assert done.returncode == 0, done.stderr
    summary = json.loads((work / "two" / "summary.json").read_text())
    assert summary["robot_model"] == str(mine / "bot.robot.toml")  # by its absolute path
    # an MJCF file that MuJoCo cannot load (its mesh is elsewhere): one line, exit 2
    shutil.copy(ROOT / "models" / "robots" / "hexbot.xml", mine / "hex.xml")
    bad = run("paper_case", "--robot", "../mine/hex.xml", "--duration", "1", "--out", "three")
    assert bad.returncode == 2 and bad.stderr.count("error:") == 1
    assert "Traceback" not in bad.stderr and "hex.xml" in bad.stderr
