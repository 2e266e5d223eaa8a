"""The node side of a Ray run: NodeWorker, the actor that renders chunks on its node.

Each actor is a process of its own on a node (one per CPU the driver asked for): it opens a side's source once, on
its first chunk of that side, and renders its chunks with local.render_chunk, single-threaded, as a local worker
does. Its input files are read where its node sees them or shipped into a node-local cache (shipping.NodeFiles);
when its node does not see the output folder, it renders into node-local staging and returns the files.
"""

from __future__ import annotations

import os
import shutil
import socket
import tempfile
import threading
import time
from pathlib import Path

from darthand.dataset import local
from darthand.dataset.frames import frame_names, write_order
from darthand.dataset.jobs import job_sides
from darthand.dataset.ray.connect import code_digest
from darthand.dataset.ray.shipping import NodeFiles
from darthand.errors import InputError

CACHE = "darthand-ray"            # node-local folder (in the temp dir) of shipped inputs and staged outputs


class NodeWorker:
    """The actor: renders chunks on its node with local.render_chunk (this process is dedicated to it, so it holds
    local's per-process state). Files are resolved per group, seen or shipped (shipping.py).

    specs: {side: SourceSpec} with the driver's absolute paths; settings: run.py's; labels: {side: the source name
    the labels carry, as a local run writes it}; token: the run's (names the node-local cache, so a resumed run
    finds what was shipped before); nonce, probe: the output folder's probe file and its content; files: the mode;
    open_files: {side: {path: [group, size, mtime_ns]}} what opening a side reads."""

    def __init__(self, specs: dict, settings: dict, labels: dict, token: str, nonce: str, probe: str, files: str,
                 open_files: dict):
        self.specs, self.labels, self.files_mode, self.open_files = specs, labels, files, open_files
        self.out_dir, self.objects_catalog = settings["out_dir"], settings.get("objects")
        root = Path(tempfile.gettempdir()) / CACHE / token
        self.files = NodeFiles(files, root / "files")
        self.sees_output = files != "ship" and _read(probe) == nonce
        if not self.sees_output:
            root.mkdir(parents=True, exist_ok=True)
            self.staging = Path(tempfile.mkdtemp(prefix="out-", dir=root))
        self.opened: set = set()
        out_dir = settings["out_dir"] if self.sees_output else str(self.staging)
        self.state = local.set_worker_state(specs, {**settings, "out_dir": out_dir}, 1, threading.Event())

    def hello(self) -> dict:
        """Who this actor is, and whether its node sees the inputs and the output folder (an 'error' when files is
        'shared' and it does not)."""
        import ray                                 # optional for darthand; loaded already in an actor

        ctx = ray.get_runtime_context()
        self.node = {"node": ctx.get_node_id(), "ip": ray.util.get_node_ip_address(), "host": socket.gethostname()}
        self.files.node = self.node
        info = {**self.node, "pid": os.getpid(), "code": code_digest(),
                "outputs": "direct" if self.sees_output else "returned"}
        try:
            if self.files_mode == "shared" and not self.sees_output:
                raise InputError(f"--ray-files shared: node {self.node['ip']} ({self.node['node'][:8]}) does not see "
                                 f"the output folder {self.out_dir} (a shared filesystem is "
                                 "needed; --ray-files auto returns frames through Ray)")
            for needed in self.open_files.values():
                for path, (group, size, mtime) in needed.items():
                    self.files.decide(group, path, [size, mtime])
        except InputError as e:
            return {**info, "error": str(e)}
        states = set(self.files.groups.values())
        info["inputs"] = "shared" if states <= {"seen"} else "shipped" if states == {"shipped"} else "mixed"
        return info

    def render(self, items: list, needed: dict, refs: dict) -> dict:
        """Render a chunk [(job, digest)]: its result (local.render_chunk's, plus the node, its clock, and the
        frames' files when this node does not see the output folder), {'need': [paths]} when files must be
        shipped first, or {'error': message}."""
        import ray                                 # optional for darthand; loaded already in an actor

        try:
            missing = self.files.resolve(needed, refs, ray.get)
            if missing:
                return {"need": missing}
            default = next(iter(self.specs))
            for side in dict.fromkeys(side for job, _ in items for side in job_sides(job, default)):
                self._open(side)
            self._locate_objects()
            result = local.render_chunk([(self.files.node_job(job), digest) for job, digest in items])
            if not self.sees_output:
                result["files"] = self._take_staged(result["frames"])
        except InputError as e:
            return {"error": str(e)}
        except Exception as e:                     # a broken cache, a full disk: one line naming the node
            return {"error": f"--ray: node {self.node['ip']} ({self.node['node'][:8]}): {type(e).__name__}: {e}"}
        result.update(node=self.node["node"][:8], ip=self.node["ip"], opened=sorted(self.opened), now=time.monotonic())
        return result

    def stop(self) -> None:
        self.state["stop"].set()

    def cleanup(self) -> None:
        """Remove this run's node-local cache and staging (the run is over), and CACHE itself once no run uses it."""
        shutil.rmtree(self.files.cache.parent, ignore_errors=True)
        try:
            self.files.cache.parent.parent.rmdir()
        except OSError:                            # another run's cache is there, or already removed
            pass

    def _open(self, side: str) -> None:
        """Open a side's source from where this node reads it; its labels name it as the driver does."""
        if side in self.opened:
            return
        self.state["specs"][side] = self.files.node_spec(self.specs[side])
        source = local.worker_renderer(side).source
        label = self.labels.get(side)
        if label is not None:
            source.relabel(label)
        self.opened.add(side)

    def _locate_objects(self) -> None:
        """The object catalogue in the worker's settings as this node reads it (its shipped copy, once shipped)."""
        catalog = self.objects_catalog
        if catalog and os.path.isabs(catalog):
            self.state["settings"]["objects"] = self.files.node_path(catalog, f"catalog:{catalog}")

    def _take_staged(self, frames: list) -> list:
        """[(name, bytes)] of the staged frames' files in the order a local worker writes them (labels last),
        removed from the staging folder."""
        out = []
        maps = tuple(self.state["settings"].get("maps") or ())
        for frame in frames:
            two_hands = "hands" in frame          # a frame of several hands' summary: its instance map too
            held = bool(frame.get("objects"))     # an object frame's: its object mesh too
            names = frame_names(frame["index"], maps, two_hands, held)
            for kind in write_order(maps, two_hands, held):
                path = self.staging / names[kind]
                out.append((names[kind], path.read_bytes()))
                path.unlink()
        return out


def _read(path: str) -> str | None:
    try:
        return Path(path).read_text()
    except OSError:
        return None
