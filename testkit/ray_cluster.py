"""A throwaway Ray cluster of several nodes on this machine, for the Ray runner's tests and benchmark: a head and
worker nodes as separate `ray start --block` processes on 127.0.0.1, each with its own CPUs, every port chosen
free, one temporary folder for the lot.

Several such clusters (other test sessions, a user's own) can run on one machine at once, so nothing here uses
`ray stop` (it stops every Ray process of the user): a node is stopped by killing exactly its own process tree
(the `ray start` process, its raylet, GCS and agents, the raylet's workers), found through /proc.

    with LocalRayCluster(nodes=2, cpus=1) as cluster:      # head + one worker node, one CPU each
        render_dataset(DatasetOptions(..., cluster=ClusterOptions(cluster.address)))
        cluster.kill_node(1)                               # a node lost: SIGKILL of its whole tree

`hide=[paths]` starts a worker node in its own mount namespace with an empty tmpfs over those folders (root and
util-linux `unshare` needed): a node without the shared filesystem, on one machine.

The cluster uses token authentication with a token of its own, so it never reads the user's Ray state (any
`ray.init()` leaves `~/.ray/auth_token`, which Ray would otherwise pick up in some processes and not others).
Drivers connect with `cluster.env()` (a subprocess's environment) or inside `with cluster.driver():`.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from darthand.errors import InputError

START_TIMEOUT_S = 180.0          # a loaded 2-core machine takes 10-30 s per node
READY_LINE = "block forever"     # what `ray start --block` prints once its node runs


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now (the OS's choice)."""
    return free_ports(1)[0]


def free_ports(n: int) -> list[int]:
    """n different TCP ports free on 127.0.0.1 now: all held open until all are chosen (one at a time, the OS may
    hand out the same port twice, and Ray refuses a node whose components share a port)."""
    with contextlib.ExitStack() as stack:
        socks = [stack.enter_context(socket.socket()) for _ in range(n)]
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]


def can_hide_folders() -> bool:
    """Whether worker nodes can be started with folders hidden (root, `unshare` and tmpfs mounts allowed)."""
    if os.geteuid() != 0 or shutil.which("unshare") is None:
        return False
    probe = tempfile.mkdtemp(prefix="dh-unshare-")
    try:
        return subprocess.run(["unshare", "--mount", "--propagation", "private", "sh", "-c",
                               f"mount -t tmpfs tmpfs {probe}"], capture_output=True, timeout=30).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False
    finally:
        os.rmdir(probe)


class LocalRayCluster:
    """A head node and `nodes - 1` worker nodes (module docstring); `address` is the head's GCS address."""

    def __init__(self, nodes: int = 2, cpus: int = 1, object_store_mb: int = 200, hide: dict | None = None):
        self.cpus, self.object_store_mb = int(cpus), int(object_store_mb)
        self.root = Path(tempfile.mkdtemp(prefix="dh-ray-"))     # short: Ray's socket paths must stay < 108 bytes
        self.ray = str(Path(sys.executable).with_name("ray"))
        self.port, self.dashboard_port = free_ports(2)
        self.address = f"127.0.0.1:{self.port}"
        self.procs: list[subprocess.Popen | None] = []
        self._n, self._hide = int(nodes), dict(hide or {})
        self.token = secrets.token_hex(32)

    def env(self, base: dict | None = None) -> dict:
        """The environment (of `base`, default os.environ) for a node of this cluster or a driver connecting to it:
        token authentication with the cluster's own token; no RAY_ADDRESS or token path of the user's."""
        env = {**(os.environ if base is None else base), "RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "token",
               "RAY_AUTH_TOKEN": self.token}
        for name in ("RAY_ADDRESS", "RAY_AUTH_TOKEN_PATH"):
            env.pop(name, None)
        return env

    @contextlib.contextmanager
    def driver(self):
        """This process's environment set to `env()` for a driver in this process (ray.init), restored after."""
        saved = dict(os.environ)
        os.environ.clear()
        os.environ.update(self.env(saved))
        try:
            yield self
        finally:
            os.environ.clear()
            os.environ.update(saved)

    def __enter__(self) -> "LocalRayCluster":
        try:
            self.start()
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def start(self) -> "LocalRayCluster":
        """Start the head, then the worker nodes (worker node k hides the folders of hide[k], if any)."""
        if not Path(self.ray).is_file():
            raise InputError(f"{self.ray}: Ray's command line is not installed (pip install 'darthand[cluster]')")
        self._start_node(["--head", "--port", str(self.port), "--include-dashboard", "false",
                          "--dashboard-port", str(self.dashboard_port), "--temp-dir", str(self.root / "t")])
        for k in range(1, self._n):
            self.add_node(self._hide.get(k))
        return self

    def add_node(self, hide=None) -> int:
        """Start one more worker node (hide: folders it must not see); returns its number."""
        return self._start_node(["--address", self.address], hide)

    def _start_node(self, role: list[str], hide=None) -> int:
        k = len(self.procs)
        log = self.root / f"node{k}.log"
        # the head's port was chosen earlier and is not held: a node's own ports must not take it again
        ports = [str(p) for p in free_ports(8) if p not in (self.port, self.dashboard_port)][:6]
        cmd = [self.ray, "start", *role, "--num-cpus", str(self.cpus), "--node-ip-address", "127.0.0.1",
               "--object-store-memory", str(self.object_store_mb << 20), "--disable-usage-stats",
               "--include-log-monitor", "false", "--node-manager-port", ports[0],
               "--object-manager-port", ports[1], "--dashboard-agent-listen-port", ports[2],
               "--dashboard-agent-grpc-port", ports[3], "--runtime-env-agent-port", ports[4],
               "--metrics-export-port", ports[5], "--block"]
        if hide:
            mounts = " && ".join(f"mount -t tmpfs tmpfs '{Path(p)}'" for p in hide)
            cmd = ["unshare", "--mount", "--propagation", "private", "sh", "-c",
                   f"{mounts} && exec " + " ".join(f"'{c}'" for c in cmd)]
        with open(log, "w") as out:
            proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, process_group=0, env=self.env(),
                                    cwd=self.root)
        self.procs.append(proc)
        deadline = time.monotonic() + START_TIMEOUT_S
        while READY_LINE not in log.read_text(errors="replace"):
            if proc.poll() is not None or time.monotonic() > deadline:
                tail = log.read_text(errors="replace").strip().splitlines()[-3:]
                raise InputError(f"ray start (node {k}) did not come up: {' | '.join(tail) or 'no output'}")
            time.sleep(0.2)
        return k

    def kill_node(self, k: int) -> None:
        """SIGKILL node k's whole process tree at once (a lost machine) and reap it."""
        proc = self.procs[k]
        if proc is None:
            return
        for pid in process_tree(proc.pid):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            pass
        self.procs[k] = None

    def stop(self) -> None:
        """Kill every node (workers first) and remove the temporary folder."""
        for k in reversed(range(len(self.procs))):
            self.kill_node(k)
        shutil.rmtree(self.root, ignore_errors=True)


def process_tree(pid: int) -> list[int]:
    """pid and all its descendants (by /proc parent links), parents first."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(entry.name))
    tree, todo = [], [pid]
    while todo:
        p = todo.pop(0)
        tree.append(p)
        todo += children.get(p, [])
    return tree
