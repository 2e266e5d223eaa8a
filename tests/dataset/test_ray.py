"""render-dataset on a real Ray cluster on 127.0.0.1: a head and worker nodes as separate `ray start` process trees
(testkit/ray_cluster.LocalRayCluster, one CPU each), driven through the real command line.

Independent truths: the bytes of a local run (`--processes 1`, no Ray) for every output file; the kernel's record of
renames into the output folders (inotify) for "nothing written twice"; a worker node started in its own mount
namespace with an empty tmpfs over the test's folders, so it truly cannot see the inputs or the output folder (a
cluster without a shared filesystem, on one machine).

Every cluster process is killed by the fixtures (their own process trees only, never `ray stop`), also on failure.
"""

from __future__ import annotations

import ctypes
import json
import os
import re
import struct
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest
from helpers_dataset import SIZE, files_of

from darthand.cli import main

ray = pytest.importorskip("ray", reason="Ray is not installed (make test installs it: pip install '.[cluster]')")
from testkit.ray_cluster import LocalRayCluster, can_hide_folders, free_port  # noqa: E402

RUN_TIMEOUT_S = 240
HIDE = can_hide_folders()
NO_HIDE = "needs root and `unshare` to start a node without the shared filesystem"
pytestmark = pytest.mark.xdist_group("ray")          # one pytest worker, one cluster (make test: --dist loadgroup)


@pytest.fixture(scope="session")
def head():
    """A one-node cluster (the head, one CPU); tests add worker nodes and kill them. Session-wide: xdist may
    interleave other modules' tests with these, which would restart a module-wide cluster."""
    with LocalRayCluster(nodes=1, cpus=1) as cluster:
        yield cluster


@pytest.fixture(scope="session")
def hidden_node(head, tmp_path_factory):
    """A worker node that sees none of the tests' folders (an empty tmpfs over pytest's temporary root, in a mount
    namespace of its own), or None where that needs what this machine lacks (root, `unshare`)."""
    if not HIDE:
        yield None
        return
    k = head.add_node(hide=[tmp_path_factory.getbasetemp()])
    yield k
    head.kill_node(k)


@pytest.fixture
def worker_node(head):
    """Add worker nodes to the head: worker_node(hide=[folders]) -> its number; each is killed after the test."""
    added = []

    def add(hide=None) -> int:
        added.append(head.add_node(hide))
        return added[-1]

    yield add
    for k in added:
        head.kill_node(k)


def _args(package, *extra):
    model, tex, acc = package
    return ["render-dataset", model, "--textures", tex, "--accessories", acc, "--size", str(SIZE), "--samples", "4",
            *extra]


def _driver(cluster, args, **popen) -> subprocess.Popen:
    """The command in a process of its own (a Ray driver, as a user runs it) with the cluster's environment."""
    env = cluster.env({**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    return subprocess.Popen([sys.executable, "-m", "darthand.cli", *args], env=env, text=True, **popen)


def _cli(cluster, args, timeout=RUN_TIMEOUT_S) -> subprocess.CompletedProcess:
    """_driver run to its end: its exit code, stdout and stderr."""
    with _driver(cluster, args, stdout=subprocess.PIPE, stderr=subprocess.PIPE) as proc:
        try:
            stdout, stderr = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)


def _local(args, out) -> dict:
    assert main([*args, "--processes", "1", "--out", str(out)]) == 0
    return files_of(out)


def _three_texture_catalogue(package, folder: Path) -> str:
    """The fixture's texture catalogue with three entries, each with an albedo file of its own."""
    tex = Path(package[1])
    doc = json.loads((tex / "catalog.json").read_text())
    folder.mkdir()
    entries = []
    for k, tid in enumerate(["light_moles_00", "dark_moles_01", "light_scars_02"]):
        (folder / f"{tid}.png").write_bytes((tex / "skin.png").read_bytes())
        entries.append({**doc["entries"][0], "id": tid, "index": k,
                        "files": {"albedo": f"{tid}.png", "roughness": "rough.png", "tx": None}})
    (folder / "rough.png").write_bytes((tex / "rough.png").read_bytes())
    (folder / "catalog.json").write_text(json.dumps({**doc, "entries": entries}))
    return str(folder)


def test_a_two_node_cluster_without_a_shared_filesystem_writes_a_local_runs_bytes(package, head, hidden_node,
                                                                                  worker_node, tmp_path):
    """Head (sees everything) + a node that sees none of the test's folders: the node gets the inputs through Ray
    (only the textures the plan uses) and returns its frames; every byte equals a local run's. Where no node can be
    started without the filesystem, a shared node with --ray-files ship takes the same paths through Ray."""
    if hidden_node is None:
        worker_node()
    textures = _three_texture_catalogue(package, tmp_path / "textures")
    args = _args((package[0], textures, package[2]), "--count", "12", "--seed", "5", "--shard-size", "4",
                 "--texture-ids", "light_moles_00,dark_moles_01", "--accessory-share", "0.5")
    ship = [] if HIDE else ["--ray-files", "ship"]
    done = _cli(head, [*args, "--ray", head.address, *ship, "--out", str(tmp_path / "ray")])
    assert done.returncode == 0, done.stderr
    assert "Ray workers on 2 nodes" in done.stdout and "node " in done.stdout
    assert files_of(tmp_path / "ray") == _local(args, tmp_path / "local")
    doc = json.loads((tmp_path / "ray" / "dataset.json").read_text())
    runner = doc["runner"]
    assert runner["kind"] == "ray" and runner["actors"] == 2 and runner["actors_lost"] == 0
    modes = sorted((n["inputs"], n["outputs"]) for n in runner["nodes"].values())
    assert modes == ([("shared", "direct")] if HIDE else [("shipped", "returned")]) + [("shipped", "returned")]
    assert all(n["frames"] > 0 for n in doc["timings"]["nodes"].values())         # both nodes rendered
    shipped = {Path(p).name for p in runner["shipped"]["paths"]}
    assert {"right.npz", "catalog.json", "light_moles_00.png", "dark_moles_01.png", "rough.png"} <= shipped
    assert "light_scars_02.png" not in shipped                                        # not used by the plan
    assert not [p for p in (tmp_path / "ray").rglob(".*") if p.is_file()]            # no probe or temporary left


def test_a_users_own_ray_token_does_not_reach_the_cluster(package, head, worker_node, tmp_path, monkeypatch):
    """Any ray.init() on the machine leaves ~/.ray/auth_token; Ray picks it up in a node started after it, which then
    cannot join a head without that token (reproduced: `InvalidAuthToken`). The cluster and its drivers use the
    cluster's own token instead."""
    home = tmp_path / "home"
    (home / ".ray").mkdir(parents=True)
    (home / ".ray" / "auth_token").write_text("f" * 64)
    monkeypatch.setenv("HOME", str(home))
    worker_node()
    args = _args(package, "--count", "4", "--seed", "2", "--size", "48", "--ray", head.address)
    done = _cli(head, [*args, "--out", str(tmp_path / "ray")])
    assert done.returncode == 0, done.stderr
    assert re.search(r"Ray workers on [2-9] nodes", done.stdout), done.stdout


@pytest.mark.skipif(not HIDE, reason=NO_HIDE)
def test_a_node_without_the_files_is_a_one_line_error_when_files_must_be_shared(package, head, hidden_node,
                                                                                tmp_path):
    args = _args(package, "--count", "4", "--ray", head.address, "--ray-files", "shared")
    strict = _cli(head, [*args, "--out", str(tmp_path / "strict")])
    err = strict.stderr.strip().splitlines()
    assert strict.returncode == 2 and len(err) == 1, strict.stderr
    assert re.search(r"--ray-files shared: node \S+ \([0-9a-f]{8}\) does not see (the output folder )?/tmp/",
                     err[0]), err
    assert not list((tmp_path / "strict" / "labels").glob("*"))


class RenameWatch:
    """Counts renames into folders (inotify IN_MOVED_TO), by 'folder/name': every atomic write ends in one."""

    IN_MOVED_TO = 0x80

    def __init__(self, folders):
        self.libc = ctypes.CDLL("libc.so.6", use_errno=True)
        self.fd = self.libc.inotify_init1(os.O_NONBLOCK)
        assert self.fd >= 0
        self.names = {}
        for folder in folders:
            folder.mkdir(parents=True, exist_ok=True)
            wd = self.libc.inotify_add_watch(self.fd, str(folder).encode(), self.IN_MOVED_TO)
            assert wd >= 0
            self.names[wd] = folder.name
        self.counts: Counter = Counter()

    def read(self) -> Counter:
        while True:
            try:
                data = os.read(self.fd, 1 << 16)
            except BlockingIOError:
                return self.counts
            k = 0
            while k < len(data):
                wd, mask, _, length = struct.unpack_from("iIII", data, k)
                name = data[k + 16:k + 16 + length].rstrip(b"\0").decode()
                if mask & self.IN_MOVED_TO and not name.startswith("."):
                    self.counts[f"{self.names[wd]}/{name}"] += 1
                k += 16 + length

    def close(self) -> None:
        os.close(self.fd)


def test_a_node_lost_mid_run_the_run_finishes_with_nothing_lost_or_written_twice(package, head, worker_node,
                                                                                 tmp_path):
    node = worker_node()
    args = _args(package, "--count", "48", "--seed", "8", "--shard-size", "8", "--size", "64")
    out = tmp_path / "ray"
    watch = RenameWatch([out / k for k in ("images", "masks", "labels", "meshes", "shards")])
    proc = _driver(head, [*args, "--ray", head.address, "--out", str(out)], stdout=subprocess.PIPE,
                   stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + RUN_TIMEOUT_S
        while time.monotonic() < deadline and proc.poll() is None and len(list((out / "labels").glob("0*"))) < 8:
            time.sleep(0.05)
        if proc.poll() is not None:           # finished (or failed) before 8 frames were seen: say which
            raise AssertionError(f"the run ended before the node could be lost: {proc.communicate()[1][-2000:]}")
        head.kill_node(node)
        stdout, stderr = proc.communicate(timeout=RUN_TIMEOUT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, stderr
    counts = watch.read()
    watch.close()
    local = _local(args, tmp_path / "local")
    assert files_of(out) == local                                              # nothing lost, same bytes
    frames = [k for k in local if not k.startswith("shards/")]
    assert all(counts[k] == 1 for k in local if k.startswith(("labels/", "shards/"))), counts   # each frame once
    twice = [k for k in frames if counts[k] != 1]
    assert len(twice) <= 3 and all(counts[k] == 2 for k in twice), twice      # the frame being written, at most
    doc = json.loads((out / "dataset.json").read_text())
    assert doc["runner"]["actors_lost"] >= 1 and doc["rendered"] == 48
    assert any(n.get("lost") for n in doc["runner"]["nodes"].values())


def test_truth_maps_come_back_from_a_node_as_a_local_run_writes_them(package, head, tmp_path):
    """--maps through Ray with --ray-files ship (the node renders into staging and returns its files): the maps
    arrive with the frames, every byte a local run's."""
    args = _args(package, "--count", "4", "--seed", "6", "--maps", "depth,normals,parts")
    done = _cli(head, [*args, "--ray", head.address, "--ray-files", "ship", "--out", str(tmp_path / "ray")])
    assert done.returncode == 0, done.stderr
    nodes = json.loads((tmp_path / "ray" / "dataset.json").read_text())["runner"]["nodes"].values()
    outputs = [n["outputs"] for n in nodes]         # the head, and any worker node an earlier test left running
    assert outputs and set(outputs) == {"returned"}, outputs
    got = files_of(tmp_path / "ray")
    assert sum(name.startswith("maps/") for name in got) == 12
    assert got == _local(args, tmp_path / "local")


def test_two_hand_and_object_frames_come_back_from_a_node_as_a_local_run_writes_them(package, head, tmp_path):
    """A two-hand jobs file (tests/dataset/two_hand_jobs.json) and a frame of a hand holding an object through Ray
    with --ray-files ship: the node opens both sides, gets the object catalogue through Ray, and returns each frame's
    instance map (and the object frame's object mesh) with its other files, every byte a local run's."""
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "render"))
    from object_catalog import write_catalog

    doc = json.loads(Path(__file__).with_name("two_hand_jobs.json").read_text())
    held = {"index": len(doc["frames"]), "split": "train",
            "bodies": [{"kind": "hand", "side": "right", "pose": "fist"},
                       {"kind": "object", "object": "bottle_01",      # beside the fist (test_object_frames.py)
                        "placement": [[1, 0, 0, -0.05], [0, 1, 0, -0.08], [0, 0, 1, 0.05], [0, 0, 0, 1]]}]}
    jobs = tmp_path / "jobs.json"
    jobs.write_text(json.dumps({**doc, "frames": doc["frames"] + [held]}))
    catalog = write_catalog(tmp_path / "objects")
    args = _args(package, "--jobs", str(jobs), "--objects-catalog", str(catalog))
    done = _cli(head, [*args, "--ray", head.address, "--ray-files", "ship", "--out", str(tmp_path / "ray")])
    assert done.returncode == 0, done.stderr
    got = files_of(tmp_path / "ray")
    assert sum(name.startswith("instances/") for name in got) == 3 + 1          # the two-hand frames', the object's
    assert f"object_meshes/{held['index']:06d}.npy" in got
    shipped = {Path(p).name for p in json.loads((tmp_path / "ray" / "dataset.json").read_text())["runner"][
        "shipped"]["paths"]}
    assert {"bottle_01.npz", "ball_01.npz"} <= shipped                  # the object catalogue came through Ray
    assert got == _local(args, tmp_path / "local")


@pytest.mark.slow
def test_an_interrupted_cluster_run_resumes_by_shards_to_a_local_runs_bytes(package, head, tmp_path):
    """The driver killed mid-run: a rerun renders only the shards and frames missing, and the whole equals a local
    run byte for byte."""
    args = _args(package, "--count", "24", "--seed", "4", "--shard-size", "4", "--size", "96")
    out = tmp_path / "ray"
    proc = _driver(head, [*args, "--ray", head.address, "--out", str(out)], stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + RUN_TIMEOUT_S
        while time.monotonic() < deadline and proc.poll() is None and len(list((out / "shards").glob("0*"))) < 2:
            time.sleep(0.05)
    finally:
        proc.kill()
        proc.wait()
    finished = len(list((out / "shards").glob("0*")))
    assert 2 <= finished < 6
    again = _cli(head, [*args, "--ray", head.address, "--out", str(out)])
    assert again.returncode == 0, again.stderr
    doc = json.loads((out / "dataset.json").read_text())
    assert doc["skipped"] >= 4 * finished and doc["rendered"] == 24 - doc["skipped"]
    assert files_of(out) == _local(args, tmp_path / "local")


@pytest.mark.parametrize("ray_args, expected", [
    (["--ray", f"127.0.0.1:{free_port()}"], "no Ray cluster answers there"),
    (["--ray", "no-port-here"], "not an address of the form HOST:PORT"),
])
def test_bad_cluster_options_are_one_line_errors(package, tmp_path, capsys, ray_args, expected):
    rc = main([*_args(package, "--count", "2"), *ray_args, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and expected in err, err
    assert not list((tmp_path / "out" / "labels").glob("*"))


def test_ray_not_installed_is_a_one_line_error(package, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)                  # `import ray` raises ImportError
    rc = main([*_args(package, "--count", "2"), "--ray", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "Ray is not installed (pip install 'darthand[cluster]'" in err

