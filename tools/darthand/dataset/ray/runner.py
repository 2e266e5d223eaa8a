"""RayRunner, the driver's side of a Ray run (dataset/ray/__init__.py): a dataset's chunks rendered by actors
(node.NodeWorker) spread over the nodes of a Ray cluster.

Workers: one actor per CPU of the cluster (or `processes`), placed by Ray over the nodes (SPREAD). The driver keeps
two chunks on each actor (one rendering, one waiting, so no actor idles on a round trip) and the rest in its own
queue, so a fast node takes more chunks than a slow one. A node that needs input files it does not see answers with
their paths, and the chunk goes again with them in Ray's object store (shipping.py).

Node loss: an actor that dies (its node lost, killed) has its chunks queued again, without the frames it had
finished (their labels carry the job's digest), so nothing is rendered or written twice but the frame it was
writing; a replacement actor is asked for and joins when the cluster has a CPU for it. A chunk whose actors died
MAX_ATTEMPTS times stops the run.

Clocks: results carry the worker's monotonic time; the driver rebases frame times on its own clock (offset taken
when a result arrives, off by the result's transit time, milliseconds), so run.py's timings and rates hold across
machines. Results also name their node, for the per-node progress.
"""

from __future__ import annotations

import hashlib
import os
import queue
import threading
import time
from concurrent.futures import Future
from pathlib import Path

from darthand.dataset.frames import existing_frame
from darthand.dataset.jobs import job_sides
from darthand.dataset.ray.connect import code_digest, connect
from darthand.dataset.ray.node import NodeWorker
from darthand.dataset.ray.shipping import FILES_MODES, InputFiles
from darthand.dataset.runner import Runner
from darthand.errors import InputError
from darthand.fileio import write_bytes

PER_ACTOR = 2                     # chunks in flight per actor
MAX_ATTEMPTS = 3                  # actors lost on one chunk before the run stops
START_TIMEOUT_S = 300.0           # for the first actor to be up (imports, a busy cluster)
GATHER_S = 30.0                   # then for the others, before rendering starts without them
STOP_GRACE_S = 10.0               # close(): how long running chunks get to finish their frame


class RayRunner(Runner):
    """Chunks on actors over a Ray cluster (module docstring); a runner.Runner.

    specs: {side: SourceSpec}; settings: run.py's (out_dir, size, samples, aa_shading); sources: {side: opened
    source} (the driver's: the labels' source names, and which files a texture or accessory id reads); processes:
    actors (default: the cluster's CPUs); threads: unused (an actor renders single-threaded, as a local worker);
    address: see connect.connect; files: one of shipping.FILES_MODES."""

    def __init__(self, specs: dict, settings: dict, sources: dict | None = None, processes: int | None = None,
                 threads: int | None = None, address: str | None = None, files: str = "auto"):
        self.specs_given = specs
        if files not in FILES_MODES:
            raise InputError(f"--ray-files: {files!r} is not one of {', '.join(FILES_MODES)}")
        self.address, self.files_mode = address or "auto", files
        self.out = Path(settings["out_dir"]).resolve()
        self.settings = {**settings, "out_dir": str(self.out)}
        self.token = hashlib.sha256(str(self.out).encode()).hexdigest()[:12]
        self._probe = self.out / "shards" / f".ray-probe.{self.token}"
        self.actors: dict = {}                 # actor handle -> {"info", "inflight": set of refs}
        self._greeted: list = []               # every actor that started (close() cleans their caches)
        self._pending: dict = {}               # hello ref -> actor handle
        self._inflight: dict = {}              # ref -> (actor, entry)
        self._queue: list = []                 # entries waiting for an actor
        self._submitted: queue.Queue = queue.Queue()
        self._refs: dict = {}                  # path -> ObjectRef of its bytes (shipped files)
        self._shipped: dict = {}               # path -> bytes shipped
        self._lost = 0
        self._stopping = threading.Event()
        self._closed = False
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self.nodes: dict = {}                  # node key -> {"ip", "host", "actors", "inputs", "outputs"}
        self.ray, self._owns_connection = connect(address)
        try:
            self._start(sources, processes)
        except BaseException:
            self.close()
            raise
        self._thread = threading.Thread(target=self._loop, daemon=True, name="darthand-ray-dispatch")
        self._thread.start()

    def _start(self, sources, processes) -> None:
        """The probe file, the actors (one per cluster CPU unless `processes`), their hellos."""
        self.inputs = InputFiles(self.specs_given, sources or {}, self.settings.get("objects"))
        self.settings["objects"] = self.inputs.objects_catalog     # absolute: a node finds its shipped copy by it
        nonce = os.urandom(8).hex()
        self._probe.write_text(nonce)
        self.digest = code_digest()
        cpus = int(self.ray.cluster_resources().get("CPU", 0))
        if cpus < 1 and not processes:
            raise InputError(f"--ray {self.address}: the cluster has no CPUs to render on")
        self.processes = int(processes or cpus)
        self._actor_class = self.ray.remote(num_cpus=1, max_restarts=0,
                                            concurrency_groups={"control": 1})(NodeWorker)
        self._config = (self.inputs.specs, self.settings, self.inputs.labels, self.token, nonce, str(self._probe),
                        self.files_mode, {side: self.inputs.needed([], {side}) for side in self.inputs.specs})
        for _ in range(self.processes):
            self._new_actor()
        self._await_actors()

    # -------------------------------------------------------------------------------------------- actors

    def _new_actor(self) -> None:
        actor = self._actor_class.options(scheduling_strategy="SPREAD").remote(*self._config)
        self._pending[actor.hello.remote()] = actor

    def _await_actors(self) -> None:
        """Wait for the actors' hellos: up to START_TIMEOUT_S for the first, then GATHER_S more for the others (those
        still waiting for a CPU join later). Errors of the files check (files='shared') and of mismatched code stop
        the run here, before anything renders."""
        deadline = time.monotonic() + START_TIMEOUT_S
        while self._pending:
            if self.actors:
                deadline = min(deadline, self._first_hello + GATHER_S)
            left = deadline - time.monotonic()
            if left <= 0 and self.actors:
                break
            if left <= 0:
                raise InputError(f"--ray {self.address}: no worker started on the cluster within "
                                 f"{START_TIMEOUT_S:.0f} s (are its CPUs busy with other jobs?)")
            ready, _ = self.ray.wait(list(self._pending), num_returns=1, timeout=min(left, 1.0))
            for ref in ready:
                self._greet(ref)

    def _greet(self, ref) -> None:
        """An actor's hello arrived: check it, add it to the active actors."""
        actor = self._pending.pop(ref)
        try:
            info = self.ray.get(ref)
        except self.ray.exceptions.RayActorError:
            self._lost += 1
            return
        self._greeted.append(actor)
        if "error" in info:
            raise InputError(info["error"])
        if info["code"] != self.digest:
            raise InputError(f"--ray: node {info['ip']} ({info['node'][:8]}) runs another darthand or other "
                             f"libraries (code {info['code']}, here {self.digest}): install the same version on "
                             "every node")
        if not self.actors:
            self._first_hello = time.monotonic()
        self.actors[actor] = {"info": info, "inflight": set(), "opened": set()}
        node = self.nodes.setdefault(info["node"][:8], {"ip": info["ip"], "host": info["host"], "actors": 0,
                                                        "inputs": info["inputs"], "outputs": info["outputs"]})
        node["actors"] += 1

    def describe(self) -> dict:
        """What dataset.json records of the runner: its kind, the address, the files mode, the nodes used."""
        return {"kind": "ray", "address": self.address, "files": self.files_mode, "actors": len(self.actors),
                "nodes": self.nodes, "actors_lost": self._lost,
                "shipped": {"files": len(self._shipped), "mb": round(sum(self._shipped.values()) / 2**20, 3),
                            "paths": sorted(self._shipped)[:1000]}}

    # -------------------------------------------------------------------------------------------- runner interface

    def submit(self, chunk: list) -> Future:
        future: Future = Future()
        if self._error is not None:
            future.set_exception(self._error)
            return future
        self._submitted.put({"items": chunk, "future": future, "attempts": 0, "recovered": [], "ship": set()})
        return future

    def stop(self) -> None:
        """Ask every actor to stop after its current frame and drop the queued chunks (Ctrl-C, a failed frame)."""
        self._stopping.set()
        for actor in list(self.actors):
            try:
                actor.stop.options(concurrency_group="control").remote()      # beside the running chunk
            except Exception:              # an actor already gone
                pass

    def close(self) -> None:
        """Stop dispatching, give running chunks STOP_GRACE_S to end, clean the nodes' caches, end the actors and
        the connection."""
        if self._closed:
            return
        self._closed = True
        self._stopping.set()
        if self._thread is not None:
            self._thread.join(timeout=STOP_GRACE_S + 5)
        ray = getattr(self, "ray", None)
        if ray is None:
            return
        if self._inflight:
            ray.wait(list(self._inflight), num_returns=len(self._inflight), timeout=STOP_GRACE_S)
        cleanups = []
        for actor in self._greeted:
            try:
                cleanups.append(actor.cleanup.options(concurrency_group="control").remote())
            except Exception:
                pass
        if cleanups:
            ray.wait(cleanups, num_returns=len(cleanups), timeout=STOP_GRACE_S)
        for actor in self._greeted + list(self._pending.values()):
            try:
                ray.kill(actor)
            except Exception:
                pass
        self._probe.unlink(missing_ok=True)
        for entry in self._queue + self._drain_submitted():
            entry["future"].cancel()
        if self._owns_connection:
            ray.shutdown()

    def _drain_submitted(self) -> list:
        entries = []
        while True:
            try:
                entries.append(self._submitted.get_nowait())
            except queue.Empty:
                return entries

    # -------------------------------------------------------------------------------------------- dispatch loop

    def _loop(self) -> None:
        """The driver's dispatcher: queue submitted chunks, hand them to actors with room, collect results."""
        ray = self.ray
        try:
            while not self._stopping.is_set():
                self._queue += self._drain_submitted()
                self._dispatch()
                waiting = list(self._inflight) + list(self._pending)
                if not waiting:
                    try:
                        self._queue.append(self._submitted.get(timeout=0.05))
                    except queue.Empty:
                        pass
                    continue
                ready, _ = ray.wait(waiting, num_returns=1, timeout=0.05)
                if ready:
                    ready, _ = ray.wait(waiting, num_returns=len(waiting), timeout=0)
                for ref in ready:                       # a lost actor's other chunks may be requeued already
                    if ref in self._pending:
                        self._greet(ref)
                    elif ref in self._inflight:
                        self._collect(ref)
        except BaseException as e:                    # fail every waiting chunk with the error, once
            self._error = e if isinstance(e, InputError) else InputError(f"--ray: {type(e).__name__}: {e}")
            for _, entry in list(self._inflight.values()) + [(None, e2) for e2 in self._queue]:
                if not entry["future"].done():
                    entry["future"].set_exception(self._error)
            for entry in self._drain_submitted():
                entry["future"].set_exception(self._error)

    def _dispatch(self) -> None:
        """Queued chunks to the actors with the fewest in flight (below PER_ACTOR)."""
        while self._queue and self.actors:
            actor = min(self.actors, key=lambda a: len(self.actors[a]["inflight"]))
            if len(self.actors[actor]["inflight"]) >= PER_ACTOR:
                return
            entry = self._queue.pop(0)
            items = entry["items"]
            sides = {side for job, _ in items for side in job_sides(job, next(iter(self.inputs.specs)))}
            needed = self.inputs.needed(items, sides - self.actors[actor]["opened"])
            refs = {path: self._ref(path) for path in entry["ship"]}
            ref = actor.render.remote(items, needed, refs)
            self.actors[actor]["inflight"].add(ref)
            self._inflight[ref] = (actor, entry)

    def _ref(self, path: str):
        """The object-store copy of a file's bytes, put once per run."""
        if path not in self._refs:
            data = Path(path).read_bytes()
            self._refs[path] = self.ray.put(data)
            self._shipped[path] = len(data)
        return self._refs[path]

    def _collect(self, ref) -> None:
        actor, entry = self._inflight.pop(ref)
        state = self.actors.get(actor)
        if state is not None:
            state["inflight"].discard(ref)
        try:
            result = self.ray.get(ref)
        except self.ray.exceptions.RayActorError:
            self._actor_lost(actor, entry)
            return
        if "need" in result:                           # files this node must get through Ray: send them along
            entry["ship"] |= set(result["need"])
            self._queue.insert(0, entry)
            return
        if "error" in result:
            raise InputError(result["error"])
        opened = result.pop("opened", ())
        if state is not None:
            state["opened"] |= set(opened)
        self._write_returned(result.pop("files", None) or [])
        offset = time.monotonic() - result.pop("now")
        for frame in result["frames"]:
            frame["end"] += offset
        result["frames"] += entry["recovered"]
        entry["future"].set_result(result)

    def _write_returned(self, files: list) -> None:
        """Write the files a node returned, atomically, in its order (each frame's labels last)."""
        for name, data in files:
            path = (self.out / name).resolve()
            if self.out not in path.parents:
                raise InputError(f"--ray: a worker returned a file outside the output folder: {name}")
            write_bytes(path, data)

    def _actor_lost(self, actor, entry) -> None:
        """An actor died with `entry` on it: keep the frames it finished, queue the rest again, ask for a
        replacement actor."""
        if actor in self.actors:
            info = self.actors.pop(actor)["info"]
            self._lost += 1
            self.nodes[info["node"][:8]]["lost"] = True
            for other_ref, (other_actor, other_entry) in list(self._inflight.items()):
                if other_actor is actor:
                    del self._inflight[other_ref]
                    self._actor_lost(actor, other_entry)
            self._new_actor()
        entry["attempts"] += 1
        todo = []
        for job, digest in entry["items"]:
            found = existing_frame(self.out, job, digest)
            if found is None:
                todo.append((job, digest))
            else:
                entry["recovered"].append(found)
        if not todo:
            entry["future"].set_result({"pid": None, "node": None, "open_s": 0.0, "frames": entry["recovered"],
                                        "steps": {}, "maxrss_mb": 0.0})
            return
        if entry["attempts"] >= MAX_ATTEMPTS:
            raise InputError(f"frame {todo[0][0]['index']}: {MAX_ATTEMPTS} Ray workers died rendering its chunk")
        entry["items"] = todo
        self._queue.insert(0, entry)
