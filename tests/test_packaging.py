"""What `pip install darthand` installs: the package and its data (the studio's static files, py.typed), never the
benchmarks (`benchmarks/`), the tests' tools (`testkit/`: the browser harness, the local Ray cluster) or the tests.

The wheel is built by setuptools itself, as pyproject.toml configures it, from a copy of the checkout (a build
writes build/ and *.egg-info beside its sources; build/ is the assets' folder), offline: no index, no isolation.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "tools" / "darthand"
NOT_SOURCES = shutil.ignore_patterns(".git", ".venv*", "node_modules", "build", "__pycache__", "*.egg-info",
                                     ".*_cache", ".hypothesis")
OUT_OF_THE_WHEEL = ("benchmarks", "testkit", "tests", "browser.py", "drive.mjs", "bench.py")


def _setuptools_version() -> tuple[int, ...]:
    """The setuptools this interpreter would build with, as (major, minor, ...); () if it has none."""
    try:
        import setuptools
    except ImportError:
        return ()
    return tuple(int(x) for x in setuptools.__version__.split(".")[:2] if x.isdigit())


def _required_setuptools() -> tuple[int, ...]:
    """The lowest setuptools pyproject's [build-system] accepts, e.g. (77,) for "setuptools>=77"."""
    build = tomllib.loads((REPO / "pyproject.toml").read_text())["build-system"]["requires"]
    spec = next(r for r in build if r.replace(" ", "").startswith("setuptools>="))
    return tuple(int(x) for x in spec.split(">=")[1].split(",")[0].split("."))


@pytest.fixture(scope="module")
def wheel_files(tmp_path_factory) -> set[str]:
    """The paths inside the wheel built from this checkout (about 3 s)."""
    if _setuptools_version() < _required_setuptools():
        pytest.skip(f"setuptools {_setuptools_version()} is older than the build needs ({_required_setuptools()}): "
                    "`make venv` installs the test extra, which has it")
    tmp = tmp_path_factory.mktemp("wheel")
    shutil.copytree(REPO, tmp / "src", ignore=NOT_SOURCES, symlinks=True)
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation",
                           "--no-index", "--disable-pip-version-check", "-w", str(tmp / "dist"), str(tmp / "src")],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    (wheel,) = (tmp / "dist").glob("darthand-*.whl")
    with zipfile.ZipFile(wheel) as z:
        return set(z.namelist())


def test_wheel_holds_the_package_only(wheel_files):
    tops = {name.split("/")[0] for name in wheel_files}
    assert {t for t in tops if not t.endswith(".dist-info")} == {"darthand"}
    stray = sorted(n for n in wheel_files if any(part in OUT_OF_THE_WHEEL for part in n.split("/")))
    assert not stray, f"test and benchmark tools in the wheel: {stray}"


def test_wheel_holds_every_module_and_the_package_data(wheel_files):
    expected = {f"darthand/{p.relative_to(PACKAGE).as_posix()}" for p in PACKAGE.rglob("*.py")}
    expected |= {"darthand/py.typed"}
    expected |= {f"darthand/{p.relative_to(PACKAGE).as_posix()}" for p in (PACKAGE / "studio" / "static").iterdir()}
    maps = {f"darthand/{p.relative_to(PACKAGE).as_posix()}" for p in (PACKAGE / "render" / "environments").iterdir()}
    assert len(maps) == 10                              # the 8 built-in environment maps, their licence and README
    expected |= maps
    assert len(expected) > 100
    assert not expected - wheel_files, f"missing from the wheel: {sorted(expected - wheel_files)}"


def test_package_discovery_as_configured_finds_darthand_only():
    """The same question without building (any setuptools): the packages pyproject's [tool.setuptools.packages.find]
    selects, and its package-data patterns, which must each match a file."""
    from setuptools import find_namespace_packages, find_packages

    tool = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    find = tool["packages"]["find"]
    finder = find_namespace_packages if find.get("namespaces", True) else find_packages
    packages = set()
    for where in find.get("where", ["."]):
        packages |= set(finder(where=str(REPO / where), include=find.get("include", ["*"]),
                               exclude=find.get("exclude", [])))
    assert {p.split(".")[0] for p in packages} == {"darthand"}, sorted(packages)
    assert not (PACKAGE / "studio" / "browser.py").exists() and not (PACKAGE / "benchmarks").exists()
    for package, patterns in tool["package-data"].items():
        folder = REPO / find["where"][0] / package.replace(".", "/")
        for pattern in patterns:
            assert list(folder.glob(pattern)), f"package-data {package}: {pattern} matches nothing"


def test_benchmarks_run_from_the_repository_root(tmp_path):
    """`make bench` runs `python -m benchmarks` from the repository root; its cheapest benchmark writes its JSON and
    the markdown table."""
    paths = [str(REPO / "tools"), *filter(None, [os.environ.get("PYTHONPATH")])]     # this checkout's darthand
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}
    proc = subprocess.run([sys.executable, "-m", "benchmarks", "--only", "rotations", "--out", str(tmp_path)],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert json.loads((tmp_path / "rotations.json").read_text())["num_vectors"] > 0
    assert "## rotations" in (tmp_path / "README.md").read_text()
